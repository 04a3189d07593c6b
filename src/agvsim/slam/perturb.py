"""Faults a real robot's log may carry, applied to a stream of scans (robustness suite).

Each :class:`Fault` turns a stream of :class:`~agvsim.scan.LaserScan` into another, lazily
(a log is never held in memory), with the randomness from a ``numpy.random.Generator``:

* ``freeze``: odometry stops changing for 2 to 10 scans (a stalled encoder message), then
  jumps by everything it missed; one freeze starts on average every ``freeze_every_scans``;
* ``thin``: only scans at least ``1 / thin_rate_hz`` after the last kept one remain, the
  first kept one drawn uniformly within the first period (the phase: which scans a thinned
  log keeps is chance, so repeated seeds show the spread);
* ``scale``: odometry's translation increments are ``odometry_scale`` times too long;
* ``heading-bias``: odometry's heading drifts by ``heading_bias_rad_per_s`` (a gyro bias);
* ``drop``: each scan is lost with probability ``drop_fraction``;
* ``range-noise``: ranges get Gaussian noise of ``range_noise_m`` (returns stay returns);
* ``freeze-turn``: odometry freezes while the robot *turns*: at a freeze (on average one every
  ``freeze_every_scans``) it waits for the next stretch of at most ``turn_freeze_max_scans``
  scans over which odometry turns by an angle drawn from ``turn_freeze_rad`` (45-90 deg) and
  stays frozen for that stretch, then jumps by the whole turn in one step (a stalled driver on
  a multi-wing building's corners);
* ``sparse``: thinned to ``sparse_rate_hz`` (1 Hz, the phase drawn as for ``thin``) and the
  odometry made very regular: each kept increment is the mean of the last ``smooth_scans``
  kept increments (robot frame), so odometry looks precise from scan to scan while it lags on
  every turn (a hospital log's sparse, regular scans);
* ``long-loop``: ``sparse`` plus a systematic heading drift of ``drift_rad_per_m`` per metre
  driven (a wheel-radius difference): each loop of the log comes back off by its length times
  that, as a long loop does, and the drift looks like signal, not noise.

Odometry faults act on the increments between consecutive scans, ``u_k = o_{k-1}^-1 o_k``,
and compose the faulty increments again from the first scan's pose.

``with_false_closures`` is the pose-graph fault: wrong loop closures added to a graph.
"""

from __future__ import annotations

import collections
import enum
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace

import numpy as np

from agvsim.angles import wrap_scalar
from agvsim.scan import LaserScan
from agvsim.slam.posegraph import PoseGraph
from agvsim.slam.se2 import between, compose

__all__ = ["Fault", "FaultConfig", "apply_fault", "with_false_closures"]


class Fault(enum.StrEnum):
    """The faults of the robustness suite (module docstring)."""

    NONE = "none"
    FREEZE = "freeze"
    THIN = "thin"
    SCALE = "scale"
    HEADING_BIAS = "heading-bias"
    DROP = "drop"
    RANGE_NOISE = "range-noise"
    FREEZE_TURN = "freeze-turn"
    SPARSE = "sparse"
    LONG_LOOP = "long-loop"


@dataclass(frozen=True)
class FaultConfig:
    """How strong each fault is (SI units)."""

    freeze_every_scans: int = 150
    freeze_min_scans: int = 2
    freeze_max_scans: int = 10
    thin_rate_hz: float = 1.5
    odometry_scale: float = 1.05
    heading_bias_rad_per_s: float = math.radians(1.0) / 60.0  # 1 deg a minute
    drop_fraction: float = 0.1
    range_noise_m: float = 0.03
    turn_freeze_rad: tuple[float, float] = (math.radians(45.0), math.radians(90.0))
    turn_freeze_max_scans: int = 40
    sparse_rate_hz: float = 1.0
    smooth_scans: int = 3
    drift_rad_per_m: float = math.radians(1.0) / 5.0  # 1 deg every 5 m driven

    def __post_init__(self) -> None:
        if not 1 <= self.freeze_min_scans <= self.freeze_max_scans:
            raise ValueError(
                f"freeze scans must satisfy 1 <= min <= max, got "
                f"{self.freeze_min_scans}, {self.freeze_max_scans}"
            )
        for name in ("freeze_every_scans", "thin_rate_hz", "odometry_scale"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if not 0.0 <= self.drop_fraction < 1.0:
            raise ValueError(f"drop_fraction must lie in [0, 1), got {self.drop_fraction}")
        lo, hi = self.turn_freeze_rad
        if not 0 < lo <= hi <= math.pi:
            raise ValueError(f"turn_freeze_rad must satisfy 0 < lo <= hi <= pi, got {lo}, {hi}")
        for name in ("turn_freeze_max_scans", "sparse_rate_hz", "smooth_scans"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if self.range_noise_m < 0:
            raise ValueError(f"range_noise_m must be >= 0, got {self.range_noise_m}")


def apply_fault(
    scans: Iterable[LaserScan],
    fault: Fault | str,
    rng: np.random.Generator,
    cfg: FaultConfig | None = None,
) -> Iterator[LaserScan]:
    """The scans with ``fault`` applied (see the module docstring)."""
    kind = Fault(fault)
    c = cfg or FaultConfig()
    if kind is Fault.NONE:
        yield from scans
    elif kind is Fault.THIN:
        yield from _thin(scans, c.thin_rate_hz, rng)
    elif kind in (Fault.SPARSE, Fault.LONG_LOOP):
        drift = c.drift_rad_per_m if kind is Fault.LONG_LOOP else 0.0
        yield from _regular(_thin(scans, c.sparse_rate_hz, rng), c.smooth_scans, drift)
    elif kind is Fault.FREEZE_TURN:
        yield from _freeze_turns(scans, rng, c)
    elif kind is Fault.DROP:
        for rec in scans:
            if rng.random() >= c.drop_fraction:
                yield rec
    elif kind is Fault.RANGE_NOISE:
        for rec in scans:
            r = rec.ranges
            noisy = r + rng.normal(0.0, c.range_noise_m, r.shape)
            noisy = np.where(np.isfinite(r), np.clip(noisy, 0.0, rec.range_max_m * 0.999), r)
            yield replace(rec, ranges=noisy)
    else:
        yield from _odometry_fault(scans, kind, rng, c)


def _thin(
    scans: Iterable[LaserScan], rate_hz: float, rng: np.random.Generator
) -> Iterator[LaserScan]:
    period = 1.0 / rate_hz
    phase = float(rng.uniform(0.0, period))
    last = -math.inf
    for rec in scans:
        if last == -math.inf:  # the first kept scan: at or after the phase
            last = rec.stamp_s + phase - period
        if rec.stamp_s - last >= period:
            last = rec.stamp_s
            yield rec


def _regular(
    scans: Iterable[LaserScan], smooth: int, drift_rad_per_m: float
) -> Iterator[LaserScan]:
    """Odometry whose increment is the mean of the last ``smooth`` true increments (robot
    frame), plus ``drift_rad_per_m`` of heading per metre driven."""
    prev_true: np.ndarray | None = None
    pose = np.zeros(3)
    recent: list[np.ndarray] = []
    for rec in scans:
        true = _odometry(rec)
        if prev_true is None:
            pose = true.copy()
        else:
            recent = (
                [*recent[-(smooth - 1) :], between(prev_true, true)]
                if smooth > 1
                else [between(prev_true, true)]
            )
            u = np.mean(recent, axis=0)
            u[2] += drift_rad_per_m * math.hypot(u[0], u[1])
            pose = compose(pose, u)
        prev_true = true
        yield replace(rec, odom_pose=np.asarray(pose, np.float64).copy())


def _freeze_turns(
    scans: Iterable[LaserScan], rng: np.random.Generator, c: FaultConfig
) -> Iterator[LaserScan]:
    """``freeze-turn`` (module docstring): a look-ahead of ``turn_freeze_max_scans`` scans."""
    ahead: collections.deque[LaserScan] = collections.deque()
    it = iter(scans)
    frozen_left, armed, target, jump = 0, False, 0.0, False
    last_out: np.ndarray | None = None
    done = False
    while True:
        while not done and len(ahead) <= c.turn_freeze_max_scans:
            try:
                ahead.append(next(it))
            except StopIteration:
                done = True
        if not ahead:
            return
        rec = ahead.popleft()
        if frozen_left == 0 and not jump and last_out is not None:
            if not armed and rng.random() < 1.0 / c.freeze_every_scans:
                armed, target = True, float(rng.uniform(*c.turn_freeze_rad))
            if armed and ahead and _turning(rec, ahead[0]):
                frozen_left = _turn_length(rec, ahead, target)
                armed = frozen_left == 0
        if frozen_left > 0 and last_out is not None:
            frozen_left -= 1
            jump = frozen_left == 0  # the scan after the last frozen one reports the truth
            yield replace(rec, odom_pose=last_out.copy())
            continue
        jump = False
        last_out = _odometry(rec).copy()
        yield rec


def _turn_length(rec: LaserScan, ahead: Iterable[LaserScan], target: float) -> int:
    """Scans from ``rec`` until odometry has turned by ``target`` in one turn (every step
    turning at least 0.5 deg the same way); 0 if the turn ends short or beyond ``ahead``."""
    th0 = prev = float(_odometry(rec)[2])
    sign = 0.0
    for k, nxt in enumerate(ahead):
        th = float(_odometry(nxt)[2])
        step = wrap_scalar(th - prev)
        sign = sign or math.copysign(1.0, step)
        if sign * step < math.radians(0.5):
            return 0
        prev = th
        if abs(wrap_scalar(th - th0)) >= target:
            return k + 1  # rec and the k scans after it freeze; ahead[k] jumps
    return 0


def _turning(a: LaserScan, b: LaserScan) -> bool:
    """Odometry turns by at least 1 deg from ``a`` to ``b`` (a turn begins)."""
    return abs(wrap_scalar(_odometry(b)[2] - _odometry(a)[2])) >= math.radians(1.0)


def _odometry_fault(
    scans: Iterable[LaserScan], kind: Fault, rng: np.random.Generator, c: FaultConfig
) -> Iterator[LaserScan]:
    prev_true: np.ndarray | None = None
    prev_time = 0.0
    pose = np.zeros(3)  # the faulty odometry as it would have run on (no freeze)
    frozen_left = 0
    last_out = np.zeros(3)
    for rec in scans:
        true = _odometry(rec)
        if prev_true is None:
            pose = true.copy()
        else:
            u = between(prev_true, true)
            if kind is Fault.SCALE:
                u = np.array([u[0] * c.odometry_scale, u[1] * c.odometry_scale, u[2]])
            elif kind is Fault.HEADING_BIAS:
                dt_s = rec.stamp_s - prev_time
                u = u + np.array([0.0, 0.0, c.heading_bias_rad_per_s * dt_s])
            pose = compose(pose, u)
        prev_true, prev_time = true, rec.stamp_s
        out = pose
        if kind is Fault.FREEZE:
            if frozen_left == 0 and rng.random() < 1.0 / c.freeze_every_scans:
                frozen_left = int(rng.integers(c.freeze_min_scans, c.freeze_max_scans + 1))
            if frozen_left > 0:  # repeats the last pose; the scan after the last frozen one
                out = last_out  # jumps by all the motion it missed
                frozen_left -= 1
        last_out = np.asarray(out, np.float64).copy()
        yield replace(rec, odom_pose=last_out.copy())


def _odometry(scan: LaserScan) -> np.ndarray:
    if scan.odom_pose is None:
        raise ValueError(f"the scan at {scan.stamp_s} s has no odometry pose")
    return scan.odom_pose


def with_false_closures(graph: PoseGraph, n: int, seed: int) -> tuple[PoseGraph, np.ndarray]:
    """The graph plus ``n`` false loop closures between random nodes (random relative poses,
    up to 5 m and any heading, as sure as the graph's own closures) and the switchable flags
    (every edge that is not between consecutive nodes, the false ones included)."""
    rng = np.random.default_rng(seed)
    i, j = rng.integers(0, graph.n_nodes, n), rng.integers(0, graph.n_nodes, n)
    keep = np.abs(i - j) > 1
    i, j = i[keep], j[keep]
    z = np.column_stack(
        [rng.uniform(-5, 5, i.size), rng.uniform(-5, 5, i.size), rng.uniform(-3, 3, i.size)]
    )
    loop = np.abs(graph.edge_i - graph.edge_j) != 1
    info = graph.information[loop][rng.integers(0, int(loop.sum()), i.size)]
    bad = graph.copy()
    bad.add_edges(i, j, z, info)
    return bad, np.concatenate([loop, np.ones(i.size, dtype=bool)])
