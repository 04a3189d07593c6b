"""The vehicles' batch tick (agvsim.fleet.bank): the numba leg follower computes the pure-pursuit
law written out in plain Python here, and a fleet run with the batch tick is, bit for bit, the
run where every vehicle's Python ``control`` runs every step, only faster."""

from __future__ import annotations

import math
from bisect import bisect_right
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.control.mobility import Mobility, pursuit_twist
from agvsim.fleet import messages
from agvsim.fleet.bank import VehicleBank
from agvsim.fleet.driver import FleetDriver
from agvsim.fleet.messages import periodic_state
from agvsim.fleet.motion import Leg
from agvsim.fleet.order import OrderEdge, OrderNode
from agvsim.master.config import GenerateConfig, MasterConfig
from agvsim.master.run import InProcessRun, with_fleet_size
from agvsim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]

MOBILITIES = {
    "differential": Mobility(False, True, math.inf, 0.0, 0.0, 0.0),
    "mecanum": Mobility(True, True, math.inf, 0.0, 0.0, 0.0),
    "ackermann": Mobility(False, False, math.tan(0.5) / 0.8, 0.8, 0.5, 1.0),
}

coord = st.floats(-10.0, 10.0, allow_nan=False)


def make_leg(xy: list[tuple[float, float]], speeds: list[float]) -> Leg:
    nodes = [OrderNode(f"n{i}", 2 * i, True, p, None, 0.1, 0.1, "map") for i, p in enumerate(xy)]
    edges = [
        OrderEdge(f"e{i}", 2 * i + 1, True, f"n{i}", f"n{i + 1}", None, None)
        for i in range(len(xy) - 1)
    ]
    return Leg(nodes, edges, speeds, 0.6, 0.1)


def oracle_twist(leg: Leg, s0: float, pose: np.ndarray, mob: Mobility):
    """The leg follower written out in plain Python (what the kernel must compute):
    (progress, twist, reached)."""
    pts, cum = leg.pts, leg.cum
    x, y = float(pose[0]), float(pose[1])
    ld = max(leg.lookahead_m, 1.2 * mob.min_radius_m)
    best, best_d = s0, math.inf
    i = max(bisect_right(cum, s0) - 1, 0)
    while i < len(pts) - 1 and cum[i] <= s0 + ld + 0.5:
        (ax, ay), (bx, by) = pts[i], pts[i + 1]
        dx, dy = bx - ax, by - ay
        t = min(max(((x - ax) * dx + (y - ay) * dy) / (dx * dx + dy * dy), 0.0), 1.0)
        d = math.hypot(ax + t * dx - x, ay + t * dy - y)
        if d < best_d:
            best, best_d = cum[i] + t * (cum[i + 1] - cum[i]), d
        i += 1
    s = max(best, s0)
    end = pts[-1]
    to_end = math.hypot(end[0] - x, end[1] - y)
    remaining = cum[-1] - s
    if remaining < ld and to_end < leg.tolerance_m:
        return s, (0.0, 0.0, 0.0), True
    sc = min(max(s + ld, 0.0), cum[-1])
    j = min(max(bisect_right(cum, sc) - 1, 0), len(pts) - 2)
    (ax, ay), (bx, by) = pts[j], pts[j + 1]
    ln = cum[j + 1] - cum[j]
    t = 0.0 if ln <= 0 else (sc - cum[j]) / ln
    target = (ax + t * (bx - ax), ay + t * (by - ay))
    heading = math.atan2(by - ay, bx - ax)
    k = bisect_right(leg.node_s, s) - 1
    speed = leg.speeds[min(max(k, 0), len(leg.speeds) - 1)]
    if remaining < ld:
        target = end
        speed = min(speed, max(0.1, to_end) * speed)
    tw = pursuit_twist(
        pose, np.asarray(target), speed, mob, travel_heading_rad=heading, max_turn_rate_rad_s=1.5
    )
    return s, tw, False


@settings(max_examples=300, deadline=None)
@given(
    pts=st.lists(st.tuples(coord, coord), min_size=2, max_size=6),
    speeds=st.lists(st.floats(0.1, 2.0), min_size=5, max_size=5),
    pose=st.tuples(coord, coord, st.floats(-math.pi, math.pi)),
    s0=st.floats(0.0, 30.0),
    kind=st.sampled_from(sorted(MOBILITIES)),
)
def test_the_kernel_follows_a_leg_as_the_python_leg_does(pts, speeds, pose, s0, kind) -> None:
    # successive points at least 1 cm apart, as the layouts' nodes are
    xy = [pts[0]]
    for p in pts[1:]:
        if math.hypot(p[0] - xy[-1][0], p[1] - xy[-1][1]) > 0.01:
            xy.append(p)
    if len(xy) < 2:
        return
    mob, p = MOBILITIES[kind], np.array(pose)
    leg = make_leg(xy, speeds[: len(xy) - 1])
    s0 = min(s0, leg.length_m)
    s_ref, tw_ref, done_ref = oracle_twist(leg, s0, p, mob)
    leg.s = s0
    tw = leg.twist(p, mob)  # the numba kernel, as the batch tick runs it
    assert leg.reached == done_ref
    assert leg.s == pytest.approx(s_ref, abs=1e-12)
    assert tw == pytest.approx(tw_ref, abs=1e-12)  # numba's sin/cos may differ in the last bit


def test_legs_survive_the_buffers_being_compacted_and_grown() -> None:
    bank = VehicleBank(3, points=8)
    legs = {}
    rng = np.random.default_rng(5)
    for round_ in range(40):
        k = round_ % 3
        n = int(rng.integers(2, 9))
        xy = [(float(i), float(rng.uniform(-1, 1))) for i in range(n)]
        legs[k] = make_leg(xy, [1.0] * (n - 1))
        legs[k].attach(bank, k)
        for j, leg in legs.items():  # every live leg still reads back as written
            a, m = bank.pstart[j], bank.npts[j]
            assert m == len(leg.pts)
            assert np.array_equal(bank.px[a : a + m], [q[0] for q in leg.pts])
            assert np.array_equal(bank.cum[a : a + m], leg.cum)
            b, c = bank.nstart[j], bank.nnodes[j]
            assert np.array_equal(bank.node_s[b : b + c], leg.node_s)


def fleet_run(batch: bool, n: int = 8, seconds: float = 150.0) -> InProcessRun:
    sc = load_scenario(ROOT / "scenarios" / "fleet_warehouse.yaml")
    small = with_fleet_size(sc, n)
    cfg = MasterConfig(generate=GenerateConfig(rate_per_h=400))
    out = small.model_copy(update={"master": cfg})
    out._base_dir, out._source = sc._base_dir, sc._source
    run = InProcessRun(out, seed=3, duration_s=seconds, master_period_s=0.25)
    for b in run.fleet.sim.bindings:
        if isinstance(b.controller, FleetDriver):
            b.controller.batch = batch
    poses = []
    while run.t_s < seconds - 1e-9:
        run.step()
        poses.append(run.fleet.sim.state.poses.copy())
    run.poses = np.array(poses)  # type: ignore[attr-defined]
    return run


def test_the_batch_tick_changes_nothing_but_the_speed() -> None:
    fast, ref = fleet_run(True), fleet_run(False)
    assert np.array_equal(fast.poses, ref.poses)  # type: ignore[attr-defined]
    assert fast.summary() == ref.summary()
    assert fast.summary()["orders_completed"] > 0
    for a, b in zip(fast.fleet.vehicles, ref.fleet.vehicles, strict=True):
        assert a.state() | {"headerId": 0} == b.state() | {"headerId": 0}
        assert a.battery.charge_pct == b.battery.charge_pct
    drivers = [
        b.controller for b in fast.fleet.sim.bindings if isinstance(b.controller, FleetDriver)
    ]
    ticks = sum(d.python_ticks for d in drivers)
    steps = round(150.0 / fast.fleet.sim.dt_s)
    assert ticks < 0.5 * steps * 8  # most control ticks never reached Python


def test_a_periodic_state_is_the_state_built_afresh(monkeypatch: pytest.MonkeyPatch) -> None:
    """Between events a vehicle's periodic state is its last one with new motion and charge
    (``messages.periodic_state``): it must equal the full message built at the same moment."""
    built = periodic_state
    checked = [0]

    def both(v, last):
        light, full = built(v, last), messages.state(v)
        assert light | {"headerId": 0} == full | {"headerId": 0}
        checked[0] += 1
        return light

    monkeypatch.setattr(messages, "periodic_state", both)
    fleet_run(True, seconds=80.0)
    assert checked[0] > 300


def test_a_periodic_publish_leaves_the_bank_as_a_full_settle_would(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """After a periodic message from the batch tick the vehicle updates only its wake-up
    time in the bank; a full ``_settle`` at that moment must write the very same row."""
    from agvsim.fleet.vehicle import Vehicle

    light = Vehicle.publish_periodic
    fields = ("next_node_s", "next_wake_s", "driving", "quiet", "has_leg")
    checked = [0]

    def both(v: Vehicle) -> None:
        light(v)
        b, k = v._b, v._k
        after = [getattr(b, f)[k].copy() for f in fields]
        v._settle()
        assert [getattr(b, f)[k] for f in fields] == after
        checked[0] += 1

    monkeypatch.setattr(Vehicle, "publish_periodic", both)
    fleet_run(True, seconds=80.0)
    assert checked[0] > 300
