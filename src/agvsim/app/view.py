"""What the panel shows, as immutable snapshots built under the session's lock: the run's
status and the picked robot's numbers, plots and camera frame. The panel reads these, never
the live simulation, so it holds the lock only while one is built."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class RobotView:
    """One robot now: its numbers, its recent history and its first camera's latest frame."""

    name: str
    model_name: str
    mode: str
    wheel_names: tuple[str, ...]
    wheel_speeds: np.ndarray  # (W,) rad/s
    twist: np.ndarray  # (3,) vx, vy, omega
    pose: np.ndarray  # (3,) x, y, theta
    state_name: str  # its controller's active state
    wall_collisions: int
    robot_collisions: int
    history_t: np.ndarray  # (K,) s
    history_wheels: np.ndarray | None  # (K, W) rad/s, None before the first sample
    history_twist: np.ndarray | None  # (K, 3)
    camera: Any  # its first CameraSpec, None without a camera
    frame: tuple[np.ndarray, str, tuple] | None  # (image, camera name, a key that changes)


@dataclass(frozen=True)
class SessionView:
    """The run now (time, playing, speed, the last error, the layout version and robot
    names) and, when one is picked and exists, that robot."""

    t_s: float
    playing: bool
    speed_label: str
    error: str | None
    layout: int
    robot_names: tuple[str, ...]
    robot: RobotView | None


def robot_view(session: Any, name: str) -> RobotView | None:
    """Robot ``name`` of ``session``'s simulation, copied; call under the session's lock."""
    sim = session.sim
    try:
        i = sim.robot_index(name)
    except (KeyError, ValueError):
        return None
    spec, st = sim.robots[i], sim.state
    wheels = tuple(spec.model.wheel_names)
    h = session.history.get(name)
    frame = None
    cams = sim.cameras
    if cams is not None and cams.slots_of[i]:
        c = cams.slots_of[i][0]
        frame = (st.images[c], cams.specs[c].name, (id(sim), name, int(st.image_seq[c])))
    return RobotView(
        name=name,
        model_name=spec.model.__class__.__name__,
        mode=spec.mode.value,
        wheel_names=wheels,
        wheel_speeds=st.wheel_speeds[i, : len(wheels)].copy(),
        twist=st.twists[i].copy(),
        pose=st.poses[i].copy(),
        state_name=sim.active_states()[i],
        wall_collisions=int(st.wall_collisions[i]),
        robot_collisions=int(st.robot_collisions[i]),
        history_t=np.array(h.t) if h else np.zeros(0),
        history_wheels=np.array(h.wheels)[:, : len(wheels)] if h and len(h.wheels) else None,
        history_twist=np.array(h.twist) if h and len(h.twist) else None,
        camera=spec.cameras[0] if spec.cameras else None,
        frame=frame,
    )


def session_view(session: Any, selected: str | None) -> SessionView:
    """The run and the ``selected`` robot of ``session``; call under the session's lock."""
    return SessionView(
        t_s=float(session.sim.state.t_s),
        playing=bool(session.playing),
        speed_label=str(session.speed_label),
        error=session.error,
        layout=int(session.layout),
        robot_names=tuple(session.robot_names()),
        robot=None if selected is None else robot_view(session, selected),
    )
