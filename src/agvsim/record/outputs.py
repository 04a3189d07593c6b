"""Run outputs: ``trajectory.csv`` streamed while the run goes, ``summary.json`` at the end.

The CSV is flushed about once a second of wall time, so an interrupted or failed run keeps
what it recorded.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from agvsim.sensors.safety_fields import STATUS_NAMES
from agvsim.sim.engine import W_MAX, Simulation

COLUMNS = (
    ["t", "robot", "x", "y", "theta", "vx", "vy", "omega"]
    + [f"wheel{k + 1}_rad_s" for k in range(W_MAX)]
    + ["steering_rad", "odom_x", "odom_y", "odom_theta", "bump", "state"]
)
# appended only when a robot has dynamics (agvsim.dynamics): per wheel, empty for kinematic
# robots and unused wheels
DYNAMICS_COLUMNS = [
    f"wheel{k + 1}_{q}" for q in ("torque_nm", "slip_m_s", "power_w") for k in range(W_MAX)
]
# appended only when a controller estimates its pose (the route follower, docs/guidance.md):
# the estimate the controller acted on in the row's step and its distance from the ground
# truth of that observation (the step's start: one step before the row's x, y), empty for
# the other robots
ESTIMATE_COLUMNS = ["est_x", "est_y", "est_theta", "est_error_m"]

# appended only when a robot has a safety scanner (docs/safety_fields.md): its status after
# the step's safety stage (clear / warning / protective), empty for robots without one
SAFETY_COLUMNS = ["safety"]


class TrajectoryWriter:
    """Appends one row per robot every ``every`` steps. Wheel columns follow each model's
    ``wheel_names`` order (listed per robot in summary.json); unused columns stay empty."""

    def __init__(self, path: Path, sim: Simulation, every: int = 1):
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise ValueError(f"record_every: {every!r} is not allowed (an integer >= 1)")
        self.path, self.sim, self.every = Path(path), sim, every
        self._f = self.path.open("w", encoding="utf-8", newline="")
        self._dyn = sim.dynamics is not None
        #: robot index -> its controller, for the robots whose controller has an ``estimate``
        self._est = {
            int(i): b.controller
            for b in sim.bindings
            if not b.batch and hasattr(b.controller, "estimate")
            for i in b.robots
        }
        self._safety = sim.safety is not None
        head = COLUMNS + (DYNAMICS_COLUMNS if self._dyn else [])
        head += ESTIMATE_COLUMNS if self._est else []
        self._f.write(",".join(head + (SAFETY_COLUMNS if self._safety else [])) + "\n")
        self._has_safety = [r.safety is not None for r in sim.robots]
        self._names = [r.name for r in sim.robots]
        self._nw = [len(r.model.wheel_names) for r in sim.robots]
        self._has_dyn = [r.dynamics is not None for r in sim.robots]
        self._last_flush = time.monotonic()
        self.rows = 0

    def record(self) -> None:
        st = self.sim.state
        if st.step % self.every:
            return
        lines = []
        states = self.sim.active_states()
        for i, name in enumerate(self._names):
            w = st.wheel_speeds[i]
            wheels = [f"{w[k]:.6g}" if k < self._nw[i] else "" for k in range(W_MAX)]
            p, v, o = st.poses[i], st.twists[i], st.odom_poses[i]
            line = (
                f"{st.t_s:.4f},{name},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f},"
                f"{v[0]:.6g},{v[1]:.6g},{v[2]:.6g},{','.join(wheels)},{st.steering[i]:.6g},"
                f"{o[0]:.6f},{o[1]:.6f},{o[2]:.6f},{int(st.bump[i])},{states[i]}"
            )
            if self._dyn:
                line += "," + self._dynamics_cells(i)
            if self._est:
                line += "," + self._estimate_cells(i)
            if self._safety:
                line += "," + (STATUS_NAMES[st.safety_status[i]] if self._has_safety[i] else "")
            lines.append(line + "\n")
        self._f.write("".join(lines))
        self.rows += len(lines)
        now = time.monotonic()
        if now - self._last_flush > 1.0:
            self._f.flush()
            self._last_flush = now

    def _dynamics_cells(self, i: int) -> str:
        st, n = self.sim.state, self._nw[i] if self._has_dyn[i] else 0
        cells = []
        for arr in (st.wheel_torque_nm, st.wheel_slip_m_s, st.wheel_power_w):
            cells += [f"{arr[i, k]:.6g}" if k < n else "" for k in range(W_MAX)]
        return ",".join(cells)

    def _estimate_cells(self, i: int) -> str:
        ctrl = self._est.get(i)
        est = getattr(ctrl, "estimate", None)
        if est is None:
            return ",,,"
        err = float(getattr(ctrl, "pose_error_m", math.nan))
        return f"{est[0]:.6f},{est[1]:.6f},{est[2]:.6f},{err:.6f}"

    def close(self) -> None:
        if not self._f.closed:
            self._f.flush()
            self._f.close()


def summary(sim: Simulation, wall_s: float, extra: dict[str, Any] | None = None) -> dict:
    st = sim.state
    robots = []
    for i, r in enumerate(sim.robots):
        p, o = st.poses[i], st.odom_poses[i]
        robots.append(
            {
                "name": r.name,
                "model": r.model.kind,
                "mode": str(r.mode),
                "wheel_names": list(r.model.wheel_names),
                "distance_m": round(float(st.distance_m[i]), 6),
                "collisions": int(st.collisions[i]),
                "wall_collisions": int(st.wall_collisions[i]),
                "robot_collisions": int(st.robot_collisions[i]),
                "final_pose": {"x_m": float(p[0]), "y_m": float(p[1]), "theta_rad": float(p[2])},
                "odometry_final_pose": {
                    "x_m": float(o[0]),
                    "y_m": float(o[1]),
                    "theta_rad": float(o[2]),
                },
                "odometry_error_m": float(math.hypot(o[0] - p[0], o[1] - p[1])),
                "stopped_by_error": bool(st.stopped[i]),
            }
        )
    for b in sim.bindings:  # what a behaviour came to (marker_search: was the marker found?)
        report = getattr(b.controller, "report", None)
        if not b.batch and callable(report):
            for i in b.robots:
                robots[int(i)]["controller"] = report()
    run = {
        "simulated_time_s": float(st.t_s),
        "steps": int(st.step),
        "wall_time_s": float(wall_s),
        "real_time_factor": float(st.t_s / wall_s) if wall_s > 0 else None,
        "seed": sim.seed,
        "dt_s": sim.dt_s,
        "controller_errors": [
            {"robot": e.robot, "t_s": round(e.t_s, 6), "error": str(e.cause)} for e in sim.errors
        ],
    }
    if extra:
        run.update(extra)
    out: dict[str, Any] = {"run": run, "robots": robots}
    if sim.dynamics is not None:  # mass, motor energy, stops against the closed form
        out["dynamics"] = sim.dynamics.summary()
    if sim.safety is not None:
        out["safety"] = safety_summary(sim)
    return out


def safety_summary(sim: Simulation) -> dict[str, Any]:
    """Per robot with a safety scanner: its warning and protective field violations (how
    many began, when the first began, the last time a field was violated; null: never)."""
    st, out = sim.state, {}
    for i, r in enumerate(sim.robots):
        if r.safety is None:
            continue
        row: dict[str, Any] = {"sensor": r.safety.sensor}
        for col, kind in enumerate(("warning", "protective")):
            first, last = st.safety_first_s[i, col], st.safety_last_s[i, col]
            row[kind] = {
                "count": int(st.safety_events[i, col]),
                "first_t_s": None if np.isnan(first) else round(float(first), 6),
                "last_t_s": None if np.isnan(last) else round(float(last), 6),
            }
        out[r.name] = row
    return out


def write_summary(path: Path, data: dict) -> None:
    Path(path).write_text(json.dumps(data, indent=2, default=_jsonable) + "\n", encoding="utf-8")


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, Path):
        return str(v)
    raise TypeError(f"not JSON serialisable: {type(v).__name__}")
