"""One run of a sweep: build the scenario with its seed, step it to the end (or until a metric
ends it), and return the run's summary as one flat row. Nothing is written: the caller owns
the files, so the same function runs in this process, in a process pool or in a Ray worker.

The loop is the runner's (:func:`agvsim.run_loop.run_loop`) with only the metrics and SLAM
observing, no trajectory and no plot: the same scenario and seed give the same numbers as
``agvsim run --seed``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agvsim.record.outputs import summary
from agvsim.run_loop import Metrics, run_loop
from agvsim.runner import CONTROLLER_TIME_LIMIT_S, build_metrics, build_slams
from agvsim.scenario import Scenario, ScenarioError, build, parse_scenario
from agvsim.sim.engine import ControllerError, Simulation

# statuses of a run that finished (its row is kept; a rerun skips it); anything else ("error":
# the run itself broke, e.g. its worker died) is redone by the next run of the sweep
FINISHED = ("completed", "ended_by_metric", "controller_error", "completed_with_controller_errors")


@dataclass(frozen=True)
class RunTask:
    """One run: a variation's scenario data and a seed. Plain data, so it pickles cheaply."""

    run_id: str
    variation: int
    seed: int
    scenario: dict
    base_dir: str  # the scenario's relative files (maps, controllers) are found from here
    source: str  # for messages
    # wall clock per call of a python controller: a hanging one ends its run, not the sweep
    controller_time_limit_s: float | None = CONTROLLER_TIME_LIMIT_S


def execute(task: RunTask) -> dict:
    """Run ``task``; return its flat row (``status`` ``error`` when the run itself broke)."""
    try:
        sc = parse_scenario(task.scenario, task.source)
        sc._base_dir, sc._source = Path(task.base_dir), task.source
        if sc.master is not None:  # a fleet with its master control (docs/master.md)
            from agvsim.master.sweep import fleet_row, is_fleet

            if is_fleet(sc):
                return fleet_row(sc, task.seed)
        sim = build(sc, seed=task.seed)
        sim.controller_time_limit_s = task.controller_time_limit_s
        return _simulate(sc, sim, task.source)
    except ScenarioError as err:  # e.g. a controller file that does not load
        return {"status": "error", "error": "; ".join(err.problems)}
    except Exception as err:  # noqa: BLE001 - one broken run must not end the sweep
        return {"status": "error", "error": f"{type(err).__name__}: {err}"}


def _simulate(sc: Scenario, sim: Simulation, source: str) -> dict:
    metrics = Metrics(build_metrics(sc, sim, source))
    slams = build_slams(sc, sim, source)  # robots with a ``slam:`` block: scored, no files
    n_steps = int(round(float(sc.duration_s) / sim.dt_s))
    error = None
    t0 = time.perf_counter()
    try:
        status = run_loop(sim, n_steps, [*slams, metrics])
    except ControllerError as err:
        status, error = "controller_error", str(err)
    wall = time.perf_counter() - t0
    data = summary(sim, wall, {"status": status, "error": error})
    data["metrics"] = metrics.results()
    row = flatten(data)
    for s in slams:
        row.update(_flat(s.results().scores, f"slam.{s.name}"))
    return row


def _flat(values: dict, prefix: str) -> dict[str, Any]:
    """Nested mappings as dotted keys: {"map": {"iou": 0.9}} -> {"<prefix>.map.iou": 0.9}."""
    out: dict[str, Any] = {}
    for k, v in values.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}.{k}"))
        else:
            out[f"{prefix}.{k}"] = v
    return out


def dry_row(sc: Scenario, sim: Simulation, source: str) -> dict:
    """The row a run of ``sim`` will give, before any step (for its column names)."""
    data = summary(sim, 0.0, {"status": "completed", "error": None})
    data["metrics"] = {name: m.result() for name, m in build_metrics(sc, sim, source).items()}
    return flatten(data)


def flatten(data: dict) -> dict[str, Any]:
    """A summary (``summary.json``'s layout) as one flat row: run columns, then
    ``<robot>.<quantity>`` per robot, then ``<metric>.<quantity>``."""
    run = data["run"]
    row: dict[str, Any] = {
        "status": run["status"],
        "error": run.get("error"),
        "simulated_time_s": run["simulated_time_s"],
        "steps": run["steps"],
        "controller_errors": len(run.get("controller_errors", [])),
        "wall_time_s": run["wall_time_s"],
        "real_time_factor": run["real_time_factor"],
    }
    for rb in data["robots"]:
        n = rb["name"]
        p = rb["final_pose"]
        row.update(
            {
                f"{n}.model": rb["model"],
                f"{n}.distance_m": rb["distance_m"],
                f"{n}.collisions": rb["collisions"],
                f"{n}.wall_collisions": rb["wall_collisions"],
                f"{n}.robot_collisions": rb["robot_collisions"],
                f"{n}.odometry_error_m": rb["odometry_error_m"],
                f"{n}.final_x_m": p["x_m"],
                f"{n}.final_y_m": p["y_m"],
                f"{n}.final_theta_rad": p["theta_rad"],
                f"{n}.stopped_by_error": rb["stopped_by_error"],
            }
        )
    for metric, values in data.get("metrics", {}).items():
        for k, v in values.items():
            row[f"{metric}.{k}"] = v
    return row
