"""The engine owns the state: nothing outside agvsim.sim writes a SimState; place, reset with
poses, carry_over and snapshot / restore change it through the engine, bit for bit."""

from __future__ import annotations

import ast
import threading
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from test_sim import arena, robot

from agvsim.scenario import build, load_scenario
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.state import ROBOT_ROWS, SimState

SRC = Path(__file__).resolve().parents[1] / "src" / "agvsim"
SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
STATE_FIELDS = {f.name for f in fields(SimState)}


def _chain(node: ast.expr) -> tuple[str | None, list[str]]:
    """The root name and the attribute names of ``a.b[c].d`` (subscripts skipped)."""
    attrs: list[str] = []
    while isinstance(node, ast.Attribute | ast.Subscript):
        if isinstance(node, ast.Attribute):
            attrs.append(node.attr)
        node = node.value
    if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "getattr" and node.args:
        root, inner = _chain(node.args[0])  # getattr(st, name)[i] = ...: any field may be named
        name = node.args[1] if len(node.args) > 1 else None
        field_name = name.value if isinstance(name, ast.Constant) else "poses"
        return root, inner + [str(field_name)] + attrs[::-1]
    return (node.id if isinstance(node, ast.Name) else None), attrs[::-1]


def writes_into_state(code: str) -> list[int]:
    """Lines of ``code`` that assign into a simulation state: a target ``x.state.<field>``
    (``x.state.poses[i] = ...``), or ``<alias>.<field>`` where ``alias`` was bound to
    ``x.state`` in the same function, or a parameter named ``state``."""
    tree = ast.parse(code)
    bad: list[int] = []
    for fn in [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.Module)]:
        aliases = (
            {"state"}
            if isinstance(fn, ast.FunctionDef) and any(a.arg == "state" for a in fn.args.args)
            else set()
        )
        for node in ast.walk(fn):
            if isinstance(node, ast.Assign):
                pairs: list[tuple[ast.expr, ast.expr]] = []
                for t in node.targets:
                    if isinstance(t, ast.Tuple) and isinstance(node.value, ast.Tuple):
                        pairs += list(zip(t.elts, node.value.elts, strict=False))
                    else:
                        pairs.append((t, node.value))
                for t, v in pairs:
                    if isinstance(t, ast.Name) and isinstance(v, ast.Attribute):
                        if v.attr == "state":
                            aliases.add(t.id)
        for node in ast.walk(fn):
            targets: list[ast.expr] = []
            if isinstance(node, ast.Assign):
                for t in node.targets:
                    targets += list(t.elts) if isinstance(t, ast.Tuple) else [t]
            elif isinstance(node, ast.AugAssign | ast.AnnAssign):
                targets.append(node.target)
            for t in targets:
                if not isinstance(t, ast.Attribute | ast.Subscript):
                    continue
                root, attrs = _chain(t)
                into = any(
                    a == "state" and k + 1 < len(attrs) and attrs[k + 1] in STATE_FIELDS
                    for k, a in enumerate(attrs)
                )
                via_alias = root in aliases and bool(attrs) and attrs[0] in STATE_FIELDS
                if into or via_alias:
                    bad.append(t.lineno)
    return sorted(set(bad))


def test_the_checker_finds_writes_into_the_state():
    code = (
        "def f(sim, i):\n"
        "    sim.state.poses[i] = (0, 0, 0)\n"
        "    st = sim.state\n"
        "    st.t_s = 1.0\n"
        "    st.bump[i] |= True\n"
        "    getattr(st, 'odom_poses')[i] = 0\n"
        "    a, b = sim.state, 3\n"
        "    a.steering[i] = 0.0\n"
        "def g(state):\n"
        "    state.images = []\n"
        "def h(ctrl, sim):\n"
        "    ctrl.state = 3\n"  # a controller's own state: not the simulation's
        "    x = sim.state.poses[0]\n"  # reading is fine
        "    ctrl.state[0] = 1\n"  # (a controller's array named state)
    )
    assert writes_into_state(code) == [2, 4, 5, 6, 8, 10]


def test_no_module_outside_the_engine_writes_the_state():
    offenders = []
    for path in sorted(SRC.rglob("*.py")):
        if path.parent.name == "sim":
            continue
        for line in writes_into_state(path.read_text(encoding="utf-8")):
            offenders.append(f"{path.relative_to(SRC)}:{line}")
    assert offenders == []


def _fingerprint(sim: Simulation, steps: int) -> list[bytes]:
    out = []
    for _ in range(steps):
        sim.step()
        st = sim.state
        out.append(
            b"".join(
                np.ascontiguousarray(a).tobytes()
                for a in (st.poses, st.odom_poses, st.twists, st.steering, st.scans, st.collisions)
            )
        )
    return out


@pytest.mark.parametrize(
    "scenario", ["thesis_maze_avoid.yaml", "dynamics_thesis_maze.yaml", "thesis_wall_follow.yaml"]
)
def test_snapshot_run_restore_run_is_bit_identical(scenario):
    sim = build(load_scenario(SCENARIOS / scenario), seed=5)
    sim.run(1.0)
    snap = sim.snapshot()
    first = _fingerprint(sim, 60)
    rng_after = sim.rng.bit_generator.state
    sim.restore(snap)
    second = _fingerprint(sim, 60)
    assert first == second
    assert sim.rng.bit_generator.state == rng_after
    # the snapshot holds: restoring it again repeats the same steps once more
    sim.restore(snap)
    assert _fingerprint(sim, 60) == first
    # and a fresh simulation run straight through agrees with the restored one
    fresh = build(load_scenario(SCENARIOS / scenario), seed=5)
    fresh.run(1.0)
    assert _fingerprint(fresh, 60) == first


def test_snapshot_is_independent_of_the_running_state():
    sim = Simulation(arena(), [robot(pose=(1.0, 2.0, 0.5))])
    snap = sim.snapshot()
    sim.place(0, (3.0, 3.0, 0.0))
    assert snap.state.poses[0].tolist() == [1.0, 2.0, 0.5]
    sim.restore(snap)
    assert sim.state.poses[0].tolist() == [1.0, 2.0, 0.5]
    sim.place(0, (4.0, 4.0, 0.0))  # the restored state is a copy, not the snapshot itself
    assert snap.state.poses[0].tolist() == [1.0, 2.0, 0.5]


def test_snapshot_of_a_controller_that_cannot_be_copied_names_the_robot():
    class Locked:
        def __init__(self) -> None:
            self.lock = threading.Lock()

        def __call__(self, obs):
            return (0.0, 0.0, 0.0)

    sim = Simulation(arena(), [robot(name="bob")], [Binding(Locked(), (0,))])
    with pytest.raises(ValueError, match="robot 'bob' cannot be copied"):
        sim.snapshot()


def test_place_moves_pose_and_odometry_and_at_rest_stops_the_robot():
    sim = Simulation(arena(), [robot(pose=(0.0, 0.0, 0.0))])
    st = sim.state
    st_twists = st.twists  # the engine writes in place: our reference sees the change
    sim.place(0, (1.5, -2.0, 0.25))
    assert st.poses[0].tolist() == [1.5, -2.0, 0.25]
    assert st.odom_poses[0].tolist() == [1.5, -2.0, 0.25]
    sim.state.twists[0] = (1.0, 0.0, 0.5)  # (a test may write: it is not in src/agvsim)
    sim.place(0, (1.0, 1.0, 0.0))
    assert st_twists[0].tolist() == [1.0, 0.0, 0.5]  # kept without at_rest
    sim.place(0, (1.0, 1.0, 0.0), at_rest=True)
    assert st_twists[0].tolist() == [0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="3 finite numbers"):
        sim.place(0, (1.0, np.nan, 0.0))


def test_reset_with_poses_starts_there_and_repeats_with_the_seed():
    sim = Simulation(arena(), [robot("a", pose=(0.0, 0.0, 0.0)), robot("b", pose=(3.0, 0, 0))])
    start = np.array([[1.0, 1.0, 0.5], [-2.0, -1.0, -1.0]])
    sim.reset(seed=7, poses=start)
    assert sim.state.t_s == 0.0 and sim.seed == 7
    np.testing.assert_array_equal(sim.state.poses, start)
    np.testing.assert_array_equal(sim.state.odom_poses, start)
    draws = sim.rng.standard_normal(3)
    sim.reset(seed=7, poses=start)
    np.testing.assert_array_equal(sim.rng.standard_normal(3), draws)
    with pytest.raises(ValueError, match=r"\(2, 3\)"):
        sim.reset(poses=start[:1])


def test_carry_over_takes_every_robot_row_and_the_clock():
    old = Simulation(arena(), [robot("a"), robot("b", pose=(3.0, 0.0, 0.0))])
    for name in ROBOT_ROWS:  # every row of robot b gets its own value
        rows = getattr(old.state, name)
        rows[1] = np.arange(rows[1].size).reshape(rows[1].shape) + 1
    old.state.t_s, old.state.step = 4.2, 210
    new = Simulation(arena(), [robot("b", pose=(-3.0, 0.0, 0.0)), robot("c")])
    new.carry_over(old.state, {0: 1})
    for name in ROBOT_ROWS:
        np.testing.assert_array_equal(getattr(new.state, name)[0], getattr(old.state, name)[1])
    assert (new.state.t_s, new.state.step) == (4.2, 210)
    assert new.state.poses[1].tolist() == [0.0, 0.0, 0.0]  # c is new: untouched
