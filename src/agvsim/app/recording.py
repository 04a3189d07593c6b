"""What the app records while it runs, each an observer of its step loop
(agvsim.run_loop: ``on_step(sim)``, ``close()``): the recent history of every robot for the
plots and trails, the online SLAM of the robots with a ``slam:`` block, and "Record video".

Each follows the session's simulation across rebuilds (an edit, a reset): ``on_step`` gets the
simulation that stepped. No lock of their own: the session calls them under its lock.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from agvsim.sim.engine import Simulation

if TYPE_CHECKING:
    from agvsim.scenario import Scenario
    from agvsim.viz.video import VideoRecorder

#: seconds of history kept for the live plots, and samples of trail kept per robot
PLOT_WINDOW_S = 10.0
TRAIL_POINTS = 4000
SAMPLE_PERIOD_S = 0.05  # plots at 20 Hz of simulated time


@dataclass
class History:
    """Recent samples of one robot for the plots: time, wheel speeds, body twist."""

    t: deque = field(default_factory=lambda: deque(maxlen=2000))
    wheels: deque = field(default_factory=lambda: deque(maxlen=2000))
    twist: deque = field(default_factory=lambda: deque(maxlen=2000))
    trail: deque = field(default_factory=lambda: deque(maxlen=TRAIL_POINTS))


class Histories:
    """Each robot's recent ``History``, sampled every ``SAMPLE_PERIOD_S`` of simulated time."""

    def __init__(self, sim: Simulation):
        self.by_robot: dict[str, History] = {}
        self.restart(sim)

    def restart(self, sim: Simulation) -> None:
        """Every robot starts a new history, with the current state as its first sample."""
        self.by_robot = {r.name: History() for r in sim.robots}
        self.on_step(sim)

    def rebuilt(self, sim: Simulation, fresh: set[str]) -> None:
        """The robots of a rebuilt ``sim`` keep their history, except the ``fresh`` ones."""
        old = self.by_robot
        self.by_robot = {
            r.name: (History() if r.name in fresh else old.get(r.name, History()))
            for r in sim.robots
        }

    def on_step(self, sim: Simulation) -> None:
        st = sim.state
        every = max(1, int(round(SAMPLE_PERIOD_S / sim.dt_s)))
        if st.step % every:
            return
        for i, r in enumerate(sim.robots):
            h = self.by_robot.get(r.name)
            if h is None:
                continue
            h.t.append(st.t_s)
            h.wheels.append(st.wheel_speeds[i].copy())
            h.twist.append(st.twists[i].copy())
            h.trail.append((float(st.poses[i, 0]), float(st.poses[i, 1])))

    def close(self) -> None:
        pass


class LiveSlam:
    """Online SLAM (agvsim.online_slam) of the robots with a ``slam:`` block, built afresh
    for every new simulation from ``scenario()``; a block that does not build is reported to
    ``report`` and the run goes on without it."""

    def __init__(
        self,
        scenario: Callable[[], Scenario],
        wanted: Callable[[], bool],
        report: Callable[[str], None],
    ):
        self.scenario, self.wanted, self.report = scenario, wanted, report
        self.sim: Simulation | None = None
        self.slams: dict[str, Any] = {}

    def on_step(self, sim: Simulation) -> None:
        if self.sim is not sim:
            self.sim, self.slams = sim, {}
            if self.wanted():
                from agvsim.online_slam import build_online_slams
                from agvsim.scenario import ScenarioError

                try:
                    slams = build_online_slams(self.scenario(), sim)
                except (ValueError, ScenarioError) as err:
                    self.report(f"slam: {err}")
                    return
                self.slams = {o.name: o for o in slams}
        for o in self.slams.values():
            o.on_step(sim)

    def live_map(self, sim: Simulation, name: str) -> Any:
        """Robot ``name``'s live SLAM map in ``sim`` (an OccupancyMap), or None."""
        o = self.slams.get(name) if self.sim is sim else None
        return None if o is None else o.live_map()

    def close(self) -> None:
        pass


class Video:
    """ "Record video": ``top.mp4`` and one MP4 per onboard camera, as ``agvsim run --video``
    writes them, into a new folder ``<out_dir>/video_<k>``, a frame every 1/fps of simulated
    time from the step loop (paused: no frames)."""

    def __init__(self, out_dir: Path):
        self.out_dir = out_dir
        self.recorder: VideoRecorder | None = None  # while recording
        self.error: str | None = None

    def next_folder(self) -> Path:
        """``<out_dir>/video_<k>``, the first that does not exist."""
        k = 1
        while (self.out_dir / f"video_{k}").exists():
            k += 1
        return self.out_dir / f"video_{k}"

    def start(self, sim: Simulation, folder: Path, fps: float, width_px: int) -> None:
        """Start recording into ``folder``; OSError / RuntimeError when it cannot. The caller
        checks that none is running."""
        from agvsim.viz.video import VideoRecorder

        self.recorder = VideoRecorder(sim, folder, fps=fps, width_px=width_px)
        self.error = None

    def stop(self) -> list[Path]:
        """Finish the files (the frames still due first); their paths (none: not recording)."""
        video, self.recorder = self.recorder, None
        if video is None:
            return []
        try:
            video.close()
        except (OSError, RuntimeError, ValueError) as err:
            self.error = f"video: {err}"
        return video.paths

    def status(self) -> tuple[Path, int, float] | None:
        """(folder, frames written, seconds of video) while recording, else None."""
        v = self.recorder
        return None if v is None else (v.out, v.frames, v.seconds)

    def on_step(self, sim: Simulation) -> None:
        video = self.recorder
        if video is None:
            return
        try:
            video.follow(sim)  # a rebuilt simulation (edit, reset) carries on
            video.record()
        except (OSError, RuntimeError, ValueError) as err:  # e.g. a full disk, ffmpeg gone
            self.stop()
            self.error = f"video stopped: {err}"

    def close(self) -> None:
        self.stop()


def free_map(grid: Any) -> tuple[np.ndarray, float, tuple[float, float]]:
    """A SLAM map for the panel: ``(0 occupied .. 1 free, row 0 north; unknown 0.5),
    resolution, lower-left corner)``."""
    free = 1.0 - grid.probability[::-1]
    free[grid.logodds[::-1] == 0] = 0.5
    return free, grid.resolution_m, grid.origin_xy_m
