"""Run a scenario headless and write its outputs (summary.json, trajectory.csv, plot.png).

Whatever happens (the end, Ctrl-C, SIGTERM, a failing or hanging controller), the outputs
recorded so far are written before returning or re-raising; while they are being written,
Ctrl-C and SIGTERM wait (agvsim.signals), so no file is left half written.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from agvsim.record.outputs import TrajectoryWriter, summary, write_summary
from agvsim.run_loop import (
    Metrics,
    Observer,
    Progress,
    Recording,
    Rows,
    Trail,
    close_all,
    run_loop,
)
from agvsim.scenario import Scenario, ScenarioError, build, load_scenario
from agvsim.scenario_limits import Limits, steps_of
from agvsim.signals import StopRequest, Terminated, hold_signals, terminate_as_interrupt
from agvsim.sim.engine import ControllerError, Simulation

# wall-clock seconds one call of a ``python`` controller may take in a run, a sweep or a
# grading task (agvsim.sim.watchdog); ``agvsim run --controller-time-limit`` changes it
CONTROLLER_TIME_LIMIT_S = 10.0

if TYPE_CHECKING:
    from agvsim.online_slam import OnlineSlam


class _FirstStep:
    """Notes the wall clock (``time.perf_counter``) when the first step ends."""

    def __init__(self) -> None:
        self.at: float | None = None

    def on_step(self, sim: Simulation) -> None:
        if self.at is None:
            self.at = time.perf_counter()

    def close(self) -> None:
        pass


def run_scenario(
    scenario: str | Path | Scenario,
    out_dir: str | Path,
    duration_s: float | None = None,
    seed: int | None = None,
    record_every: int = 1,
    plot: bool = True,
    progress: Callable[[float, float], None] | None = None,
    record_mcap: bool = True,
    video: bool = False,
    controller_time_limit_s: float | None = CONTROLLER_TIME_LIMIT_S,
) -> dict:
    """Run to the end and write outputs; returns the summary dict. Raises ScenarioError for a
    bad scenario (before anything runs); after a ControllerError or KeyboardInterrupt (Ctrl-C,
    or :class:`~agvsim.signals.Terminated` for SIGTERM when called on the main thread) the
    outputs are written and the exception re-raised. ``record_mcap`` streams ``run.mcap``
    (ROS 2 layouts, docs/recording.md); ``video`` writes ``top.mp4`` and camera videos.
    ``controller_time_limit_s``: wall clock per call of a ``python`` controller (None: none);
    a call that takes longer ends the run as a controller error."""
    with terminate_as_interrupt() as stop:
        return _run(
            scenario,
            Path(out_dir),
            duration_s,
            seed,
            record_every,
            plot,
            progress,
            record_mcap,
            video,
            controller_time_limit_s,
            stop,
        )


def _run(
    scenario: str | Path | Scenario,
    out: Path,
    duration_s: float | None,
    seed: int | None,
    record_every: int,
    plot: bool,
    progress: Callable[[float, float], None] | None,
    record_mcap: bool,
    video: bool,
    controller_time_limit_s: float | None,
    stop: StopRequest,
) -> dict:
    if isinstance(scenario, Scenario):
        sc, source = scenario, scenario._source
    else:
        source = str(scenario)
        sc = load_scenario(scenario)
    try:
        sim = build(sc, seed=seed)
    except ScenarioError as err:
        raise ScenarioError(source, err.problems) from None
    try:
        sim.controller_time_limit_s = controller_time_limit_s
    except ValueError as err:
        raise ScenarioError(source, [str(err)]) from None
    out.mkdir(parents=True, exist_ok=True)
    total = float(duration_s if duration_s is not None else sc.duration_s)
    try:  # finite, > 0 and within the scenario's max_steps
        n_steps = steps_of(total, sim.dt_s, sc._limits or Limits(), "duration")
    except ValueError as err:
        raise ScenarioError(source, [str(err)]) from None
    metrics = Metrics(build_metrics(sc, sim, source))
    slams = build_slams(sc, sim, source)
    writer = TrajectoryWriter(out / "trajectory.csv", sim, record_every)
    observers: list[Observer] = _recorders(sc, sim, out, record_mcap, video, slams)
    trail = Trail(sim, n_steps // 4000)
    status, error = "completed", None
    t0 = time.perf_counter()
    first = _FirstStep()
    try:
        # in order: each sees the state the run starts from when made, then every step
        observers = [first, Rows(writer), *observers, *slams, metrics, trail]
        if progress is not None:
            observers.append(Progress(progress, total, n_steps))
        status = run_loop(sim, n_steps, observers, stop)
    except ControllerError as err:
        status, error = "controller_error", str(err)
        raise
    except KeyboardInterrupt as err:
        status = "interrupted"
        error = str(err) if isinstance(err, Terminated) else None
        raise
    finally:
        wall = time.perf_counter() - t0
        with hold_signals():  # Ctrl-C / SIGTERM now wait until every output is written
            writer.close()
            close_all(o for o in observers if not isinstance(o, Rows))
            data = summary(
                sim,
                wall,
                {
                    "scenario": sc.name,
                    "source": source,
                    "status": status,
                    "error": error,
                    "requested_duration_s": total,
                    "trajectory_rows": writer.rows,
                    # wall seconds to the end of the first step: numba's kernels load there
                    # (compiled on a machine's first run, then cached)
                    "first_step_s": None if first.at is None else first.at - t0,
                },
            )
            data["metrics"] = metrics.results()
            if slams:
                data["slam"] = {s.name: s.write(out) for s in slams}
            write_summary(out / "summary.json", data)
            if plot:
                _plot(sim, trail.xy, out / "plot.png", sc.name)
                if sim.dynamics is not None:  # wheel torque and slip (agvsim.dynamics)
                    _plot_wheels(sim, out, sc.name)
    return data


def build_metrics(sc: Scenario, sim: Simulation, source: str) -> dict:
    """The scenario's ``metrics:`` block as metric objects by name (see agvsim.metrics); a bad
    block raises ScenarioError naming ``source``."""
    from agvsim.metrics.capture import build_capture
    from agvsim.metrics.coverage import build_coverage
    from agvsim.metrics.reach import build_reach

    names = [r.name for r in sim.robots]
    out: dict = {}
    try:
        if sc.metrics.capture is not None:
            out["capture"] = build_capture(sc.metrics.capture, names)
        if sc.metrics.reach is not None:
            out["reach"] = build_reach(sc.metrics.reach, names)
        if sc.metrics.coverage is not None:
            out["coverage"] = build_coverage(sc.metrics.coverage, sim)
    except ValueError as err:
        raise ScenarioError(source, [str(err)]) from None
    return out


def _recorders(
    sc: Scenario, sim: Simulation, out: Path, mcap: bool, video: bool, slams: list[OnlineSlam]
) -> list[Observer]:
    """The run's recorders as observers, in order: the final SLAM maps go into run.mcap
    before it closes. Each records the state the run starts from when made."""
    found: list[Observer] = []
    if mcap:
        from agvsim.record.mcap_writer import Recorder, SlamMaps, scenario_yaml

        rec = Recorder(out / "run.mcap", sim, scenario_yaml(sc, sim.seed))
        found += [Recording(SlamMaps(rec, slams)), Recording(rec)] if slams else [Recording(rec)]
    if video:
        from agvsim.viz.video import VideoRecorder

        found.append(Recording(VideoRecorder(sim, out)))
    return found


def build_slams(sc: Scenario, sim: Simulation, source: str) -> list[OnlineSlam]:
    """Online SLAM for the robots with a ``slam:`` block (agvsim.online_slam); a bad block
    raises ScenarioError naming ``source``."""
    if not any(r.slam is not None for r in sc.robots):
        return []
    from agvsim.online_slam import build_online_slams

    try:
        return build_online_slams(sc, sim)
    except ValueError as err:
        raise ScenarioError(source, [str(err)]) from None


def _plot(sim: Simulation, trail: dict[str, list], path: Path, title: str) -> None:
    from agvsim.viz.plot import plot_run

    xy = {k: np.array(v).reshape(-1, 2) for k, v in trail.items()}
    plot_run(sim, xy, path, f"{title} (t = {sim.state.t_s:.1f} s)")


def _plot_wheels(sim: Simulation, out: Path, title: str) -> None:
    from agvsim.viz.wheels_plot import plot_wheels

    robots = {r.name: list(r.model.wheel_names) for r in sim.robots if r.dynamics is not None}
    plot_wheels(out / "trajectory.csv", out / "wheels.png", robots, title)
