"""Grading: run a student's controller on a suite of tasks and score each one.

A suite file lists tasks, each a scenario (a file or inline), the robot that gets the
student's controller, a success criterion (reach a goal, capture a robot, evade one, cover a
maze), a simulated duration, a wall-clock time limit and the points it is worth:

```yaml
name: Mazes, assignment 2
time_limit_s: 60            # wall clock per task (default for every task)
tasks:
  - name: thesis maze
    scenario: ../../scenarios/maze_solve_differential.yaml
    robot: differential      # default: the first robot
    duration_s: 120          # simulated
    goal: {reach: {x_m: 4.5, y_m: -4.5, radius_m: 0.5}}
    points: 10
```

Each task runs in its own process: a controller that hangs is stopped at the time limit, one
that raises (or cannot be loaded) ends its task with no points, and the other tasks go on.
The student's controller file is a ``python`` controller as in a scenario (see
docs/controllers.md): a function ``obs -> command``, or a class with ``reset()``/``step()``.
"""

from __future__ import annotations

import copy
import multiprocessing
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from pydantic import Field, ValidationError, model_validator

from agvsim.config_base import StrictConfig
from agvsim.experiments.runs import RunTask, execute
from agvsim.safe_yaml import YamlInputError, load_yaml_file
from agvsim.scenario import ScenarioError, build, parse_scenario

STARTUP_LIMIT_S = 120.0  # a task's process must have imported agvsim within this


class ReachGoal(StrictConfig):
    x_m: float
    y_m: float
    radius_m: float = Field(0.5, gt=0, le=1000)


class CaptureGoal(StrictConfig):
    evader: str = Field(min_length=1, description="the robot to catch")
    radius_m: float = Field(0.8, gt=0, le=1000)


class EvadeGoal(StrictConfig):
    pursuer: str = Field(min_length=1, description="the robot not to be caught by")
    radius_m: float = Field(0.8, gt=0, le=1000)


class CoverageGoal(StrictConfig):
    min_visited_fraction: float | None = Field(None, gt=0, le=1)
    min_seen_fraction: float | None = Field(None, gt=0, le=1)
    return_to_start: bool = False


class Goal(StrictConfig):
    reach: ReachGoal | None = None
    capture: CaptureGoal | None = None
    evade: EvadeGoal | None = None
    coverage: CoverageGoal | None = None

    @model_validator(mode="after")
    def _one(self) -> Goal:
        given = [k for k in ("reach", "capture", "evade", "coverage") if getattr(self, k)]
        if len(given) != 1:
            raise ValueError(
                f"give exactly one of reach, capture, evade, coverage (got {given or 'none'})"
            )
        return self

    @property
    def kind(self) -> str:
        return next(k for k in ("reach", "capture", "evade", "coverage") if getattr(self, k))


class TaskConfig(StrictConfig):
    name: str = Field(min_length=1)
    scenario: str | dict[str, Any] = Field(description="file (relative to the suite) or inline")
    robot: str | None = Field(None, description="robot driven by the student (default: first)")
    goal: Goal
    duration_s: float | None = Field(None, gt=0, le=1e6, description="simulated seconds")
    time_limit_s: float | None = Field(None, gt=0, le=86400, description="wall-clock seconds")
    seed: int | None = Field(None, ge=0)
    points: float = Field(10.0, gt=0)
    collision_penalty: float | None = Field(None, ge=0, description="points off per collision")


class SuiteConfig(StrictConfig):
    name: str = "grading suite"
    description: str = ""
    controller_name: str = Field("controller", description="the function or class to grade")
    time_limit_s: float = Field(60.0, gt=0, le=86400)
    collision_penalty: float = Field(0.0, ge=0)
    tasks: list[TaskConfig] = Field(min_length=1)

    @model_validator(mode="after")
    def _unique(self) -> SuiteConfig:
        names = [t.name for t in self.tasks]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"task names must be unique; repeated: {dup}")
        return self


class SuiteError(ValueError):
    def __init__(self, source: str, problems: list[str]):
        self.source, self.problems = source, problems
        super().__init__(f"{source}: " + "; ".join(problems))

    def __str__(self) -> str:
        lines = "\n".join(f"  - {p}" for p in self.problems)
        return f"{self.source} is not a valid grading suite:\n{lines}"


@dataclass(frozen=True)
class PreparedTask:
    config: TaskConfig
    scenario: dict  # with the student's robot on an ``idle`` placeholder controller
    robot_index: int
    robot: str
    base_dir: str
    time_limit_s: float
    collision_penalty: float


@dataclass
class TaskGrade:
    student: str
    task: str
    status: str  # success, fail, timeout, controller_error, error
    success: bool
    time_s: float | None  # to the goal / capture / return, else the time run (simulated)
    collisions: int | None
    path_length_m: float | None
    score: float
    points: float
    message: str = ""


# ------------------------------------------------------------------------------ the suite
def load_suite(path: str | Path) -> tuple[SuiteConfig, list[PreparedTask]]:
    """Read a suite and check every task (its scenario built with an idle placeholder for the
    student's controller) before any student code runs."""
    path = Path(path)
    if not path.is_file():
        raise SuiteError(str(path), ["no such file"])
    try:  # the scenario loader's bounded reader (UTF-8, size, depth, aliases)
        data = load_yaml_file(path)
    except YamlInputError as err:
        line = f"line {err.line}: " if err.line is not None else ""
        raise SuiteError(str(path), [f"{line}{err.problem}"]) from None
    if not isinstance(data, dict):
        raise SuiteError(str(path), ["the file must hold a mapping of keys"])
    try:
        cfg = SuiteConfig.model_validate(data)
    except ValidationError as err:
        from agvsim.experiments.spec import _format

        raise SuiteError(str(path), _format(err)) from None
    prepared, problems = [], []
    for k, task in enumerate(cfg.tasks):
        try:
            prepared.append(_prepare(cfg, task, path.parent))
        except (ScenarioError, ValueError) as err:
            lines = err.problems if isinstance(err, ScenarioError) else [str(err)]
            problems += [f"tasks[{k}] ({task.name}): {p}" for p in lines]
    if problems:
        raise SuiteError(str(path), problems)
    return cfg, prepared


def _prepare(cfg: SuiteConfig, task: TaskConfig, here: Path) -> PreparedTask:
    if isinstance(task.scenario, dict):
        data, base_dir = copy.deepcopy(task.scenario), here
    else:
        file = Path(task.scenario)
        file = file if file.is_absolute() else here / file
        if not file.is_file():
            raise ValueError(f"scenario: no such file {str(file)!r}")
        try:
            data, base_dir = load_yaml_file(file), file.parent
        except YamlInputError as err:
            raise ValueError(f"scenario: {err}") from None
        if not isinstance(data, dict):
            raise ValueError(f"scenario: {file} does not hold a scenario mapping")
    robots = data.get("robots") or []
    names = [r.get("name") for r in robots if isinstance(r, dict)]
    if not names:
        raise ValueError("scenario: it has no robots")
    name = str(task.robot or names[0])
    if name not in names:
        raise ValueError(f"robot: the scenario has no robot {name!r} (robots: {names})")
    i = names.index(name)
    data["robots"][i]["controller"] = {"type": "idle"}
    data["metrics"] = _metrics(task.goal, name)
    data["on_controller_error"] = "stop_run"
    if task.duration_s is not None:
        data["duration_s"] = task.duration_s
    if task.seed is not None:
        data["seed"] = task.seed
    sc = parse_scenario(data, "scenario")
    sc._base_dir = base_dir
    _warm_up(sc)
    return PreparedTask(
        task,
        data,
        i,
        name,
        str(base_dir.resolve()),
        task.time_limit_s or cfg.time_limit_s,
        cfg.collision_penalty if task.collision_penalty is None else task.collision_penalty,
    )


def _metrics(goal: Goal, robot: str) -> dict:
    if goal.reach:
        g = goal.reach
        return {"reach": {"robot": robot, "x_m": g.x_m, "y_m": g.y_m, "radius_m": g.radius_m}}
    if goal.capture:
        c = goal.capture
        return {"capture": {"pursuer": robot, "evader": c.evader, "radius_m": c.radius_m}}
    if goal.evade:
        e = goal.evade
        return {"capture": {"pursuer": e.pursuer, "evader": robot, "radius_m": e.radius_m}}
    cov = goal.coverage
    assert cov is not None  # Goal holds exactly one criterion
    return {"coverage": {"robot": robot, "end_run": cov.return_to_start}}


def _warm_up(sc: Any) -> None:
    """Build the task and take one step: checks it, and compiles the kernels it needs into
    numba's cache, so no task's time limit pays for a compilation."""
    from agvsim.runner import build_metrics

    sim = build(sc)
    metrics = build_metrics(sc, sim, "scenario")
    sim.step()
    for m in metrics.values():
        m.update(sim)


# ------------------------------------------------------------------------------ grading
def grade(
    controller: str | Path,
    suite: str | Path | tuple[SuiteConfig, list[PreparedTask]],
    out_dir: str | Path | None = None,
    on_task: Callable[[TaskGrade], None] | None = None,
    name: str | None = None,
    student: str | None = None,
) -> list[TaskGrade]:
    """Grade one controller file on every task of a suite (each task in its own process).
    ``name``: the function or class in the file (default: the suite's ``controller_name``);
    ``student``: the name in the grades (default: the file's stem); ``out_dir``: where each
    task's printed output is kept (``logs/<student>/<task>.log``)."""
    cfg, tasks = load_suite(suite) if isinstance(suite, str | Path) else suite
    file = Path(controller).resolve()
    student = student or file.stem
    grades = []
    for t in tasks:
        log = None
        if out_dir is not None:
            log = Path(out_dir) / "logs" / _slug(student) / f"{_slug(t.config.name)}.log"
            log.parent.mkdir(parents=True, exist_ok=True)
        if not file.is_file():
            row: dict = {"status": "error", "error": f"no such controller file {str(file)!r}"}
        else:
            row = run_isolated(_student_task(t, file, name or cfg.controller_name), t, log)
        g = score(student, t, row)
        grades.append(g)
        if on_task is not None:
            on_task(g)
    return grades


def _student_task(t: PreparedTask, file: Path, name: str) -> RunTask:
    data = copy.deepcopy(t.scenario)
    data["robots"][t.robot_index]["controller"] = {
        "type": "python",
        "file": str(file),
        "name": name,
    }
    return RunTask("", 0, int(data.get("seed", 0)), data, t.base_dir, f"task {t.config.name!r}")


def run_isolated(task: RunTask, t: PreparedTask, log: Path | None) -> dict:
    """Run ``task`` in a fresh process; stop it at ``t.time_limit_s`` of wall clock (counted
    from when the process is ready). Returns the run's row, or status timeout / error."""
    ctx = multiprocessing.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(
        target=_child, args=(send, task, None if log is None else str(log)), daemon=True
    )
    proc.start()
    send.close()
    try:
        if not _wait(recv, STARTUP_LIMIT_S) or _get(recv) != "ready":
            return {"status": "error", "error": f"the task's process did not start ({proc.pid})"}
        t0 = time.monotonic()
        if not _wait(recv, t.time_limit_s):
            return {
                "status": "timeout",
                "error": f"stopped after the time limit of {t.time_limit_s:g} s "
                f"(wall clock; {time.monotonic() - t0:.1f} s)",
            }
        row = _get(recv)
        if not isinstance(row, dict):
            proc.join(2.0)
            code = proc.exitcode
            return {"status": "error", "error": f"the task's process died (exit code {code})"}
        return row
    finally:
        recv.close()
        if proc.is_alive():
            proc.terminate()
            proc.join(2.0)
            if proc.is_alive():
                proc.kill()
        proc.join(5.0)


def _wait(conn: Any, timeout_s: float) -> bool:
    return bool(conn.poll(timeout_s))


def _get(conn: Any) -> Any:
    try:
        return conn.recv()
    except (EOFError, OSError):
        return None


def _child(conn: Any, task: RunTask, log: str | None) -> None:
    """In the task's process: keep the student's printing in the log, run, send the row."""
    if log is not None:
        fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
    conn.send("ready")
    try:
        row = execute(task)
    except BaseException as err:  # noqa: BLE001 - SystemExit, KeyboardInterrupt from the student
        row = {"status": "error", "error": f"{type(err).__name__}: {err}"}
    conn.send(row)
    conn.close()


def score(student: str, t: PreparedTask, row: dict) -> TaskGrade:
    """The grade of one task from its run's row."""
    status, kind, name = row.get("status", "error"), t.config.goal.kind, t.robot
    points = t.config.points
    if status not in ("completed", "ended_by_metric"):
        label = status if status in ("timeout", "controller_error") else "error"
        message = str(row.get("error") or status)
        return TaskGrade(
            student, t.config.name, label, False, None, None, None, 0.0, points, message
        )
    sim_t = row.get("simulated_time_s")
    closest = row.get(f"{kind if kind != 'evade' else 'capture'}.min_distance_m")
    near = f" (closest {closest:.2f} m)" if isinstance(closest, float) else ""
    if kind == "reach":
        ok, when = bool(row.get("reach.reached")), row.get("reach.time_to_goal_s")
        message = "" if ok else f"goal not reached in {sim_t:g} s{near}"
    elif kind == "capture":
        ok, when = bool(row.get("capture.captured")), row.get("capture.time_to_capture_s")
        message = "" if ok else f"not caught in {sim_t:g} s{near}"
    elif kind == "evade":
        ok, when = not row.get("capture.captured"), row.get("capture.survival_time_s")
        message = "" if ok else f"caught at t = {when:g} s"
    else:
        g = t.config.goal.coverage
        assert g is not None
        visited = float(row.get("coverage.visited_fraction") or 0.0)
        seen = float(row.get("coverage.seen_fraction") or 0.0)
        ok = (
            (g.min_visited_fraction is None or visited >= g.min_visited_fraction)
            and (g.min_seen_fraction is None or seen >= g.min_seen_fraction)
            and (not g.return_to_start or bool(row.get("coverage.returned_to_start")))
        )
        when = row.get("coverage.return_time_s") if g.return_to_start else sim_t
        message = f"visited {visited:.0%}, seen {seen:.0%}"
        if g.return_to_start and not row.get("coverage.returned_to_start"):
            message += ", not back at the start"
    collisions = int(row.get(f"{name}.collisions", 0))
    value = max(0.0, points - t.collision_penalty * collisions) if ok else 0.0
    return TaskGrade(
        student,
        t.config.name,
        "success" if ok else "fail",
        ok,
        when if ok else sim_t,
        collisions,
        row.get(f"{name}.distance_m"),
        round(value, 3),
        points,
        message,
    )


def grades_to_records(grades: list[TaskGrade]) -> list[dict]:
    return [asdict(g) for g in grades]


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in text) or "task"
