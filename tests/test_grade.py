"""Grading (``agvsim grade``): each task runs in its own process, so a controller that hangs is
stopped at the task's time limit and one that raises scores zero on that task, while the other
tasks are graded as usual; bad suites are refused before any student code runs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from agvsim.cli import app
from agvsim.grade import Goal, PreparedTask, SuiteError, TaskConfig, grade, load_suite, score

ROOT = Path(__file__).resolve().parents[1]

# a corridor 12 m long: a robot at x = -3 facing east
ROOM = {
    "duration_s": 20,
    "world": {"picture": "############\n#..........#\n#..........#\n############"},
    "robots": [{"name": "NAME", "model": "differential", "pose": {"x_m": -3.0, "y_m": 0.0}}],
}

# drives east at 0.5 m/s; which robot it drives decides how it misbehaves
STUDENT = """
from agvsim.control.api import Twist


def controller(obs):
    if obs.name == "hanger":
        while True:
            pass
    if obs.name == "crasher" and obs.t_s >= 1.0:
        raise ZeroDivisionError("student bug at one second")
    print("driving", obs.name)
    return Twist(0.5, 0.0, 0.0)
"""


def task(name: str, robot: str, **extra) -> dict:
    scenario = json.loads(json.dumps(ROOM).replace("NAME", robot))
    # the goal 5 m ahead, radius just over 0.5 m: reached after 4.5 m, at t = 9.0 s
    goal = {"reach": {"x_m": 2.0, "y_m": 0.0, "radius_m": 0.505}}
    return {"name": name, "scenario": scenario, "goal": goal, "points": 10, **extra}


def write_suite(folder: Path, tasks: list[dict], **extra) -> Path:
    path = folder / "suite.yaml"
    suite = {"name": "test suite", "time_limit_s": 60, "tasks": tasks, **extra}
    path.write_text(yaml.safe_dump(suite, sort_keys=False), encoding="utf-8")
    return path


@pytest.mark.slow
def test_hanging_and_raising_tasks_score_zero_and_the_others_go_on(tmp_path):
    (tmp_path / "alice.py").write_text(STUDENT, encoding="utf-8")
    suite = write_suite(
        tmp_path,
        [
            task("reach", "runner"),
            task("crash", "crasher"),
            task("hang", "hanger", time_limit_s=2.0),
            task("reach again", "runner2"),
        ],
    )
    res = CliRunner().invoke(
        app,
        [
            "grade",
            str(tmp_path / "alice.py"),
            "--suite",
            str(suite),
            "--out",
            str(tmp_path / "out"),
            "-q",
        ],
    )
    assert res.exit_code == 0, res.output
    grades = json.loads((tmp_path / "out" / "grades.json").read_text())["grades"]
    by = {g["task"]: g for g in grades}
    assert [g["status"] for g in grades] == ["success", "controller_error", "timeout", "success"]
    assert [g["score"] for g in grades] == [10.0, 0.0, 0.0, 10.0]
    for name in ("reach", "reach again"):
        assert by[name]["time_s"] == pytest.approx(9.0, abs=1e-9)  # 4.5 m at 0.5 m/s
        assert by[name]["path_length_m"] == pytest.approx(4.5, abs=1e-6)
        assert by[name]["collisions"] == 0
    assert "crasher" in by["crash"]["message"] and "student bug" in by["crash"]["message"]
    assert "time limit of 2 s" in by["hang"]["message"]
    assert "2/4 passed" in res.output and "20 / 40" in res.output
    assert (tmp_path / "out" / "grades.csv").read_text().count("\n") == 5
    # what the student printed is kept per task, not mixed into the table
    log = (tmp_path / "out" / "logs" / "alice" / "reach.log").read_text()
    assert "driving runner" in log


@pytest.mark.slow
def test_a_file_that_cannot_load_scores_zero_everywhere(tmp_path):
    (tmp_path / "bob.py").write_text("def controller(obs):\n    return (0.1, 0, 0\n")
    (tmp_path / "carol.py").write_text("def step(obs):\n    return (0.1, 0, 0)\n")
    suite = load_suite(write_suite(tmp_path, [task("reach", "runner")]))
    bob = grade(tmp_path / "bob.py", suite)
    assert bob[0].status == "error" and bob[0].score == 0
    assert "could not be loaded (line 2)" in bob[0].message
    carol = grade(tmp_path / "carol.py", suite)
    assert carol[0].status == "error" and "'controller' is not defined" in carol[0].message
    assert "(allowed: step)" in carol[0].message  # what the file does define


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        ({"robot": "nobody"}, ["tasks[0] (reach)", "no robot 'nobody'", "runner"]),
        ({"goal": {}}, ["give exactly one of reach, capture, evade, coverage"]),
        (
            {"goal": {"reach": {"x_m": 1.0, "y_m": 0.0}, "evade": {"pursuer": "x"}}},
            ["exactly one", "reach", "evade"],
        ),
        ({"scenario": "nowhere.yaml"}, ["scenario: no such file"]),
        ({"time_limit_s": -1}, ["time_limit_s", "greater than 0"]),
        ({"goal": {"capture": {"evader": "ghost"}}}, ["metrics.capture.evader", "ghost"]),
        ({"pointz": 3}, ["unknown key 'pointz'"]),
    ],
)
def test_bad_suites_are_refused(tmp_path, change, expected):
    suite = write_suite(tmp_path, [{**task("reach", "runner"), **change}])
    with pytest.raises(SuiteError) as info:
        load_suite(suite)
    for part in expected:
        assert part in str(info.value), str(info.value)
    res = CliRunner().invoke(app, ["grade", str(ROOT / "README.md"), "--suite", str(suite)])
    assert res.exit_code == 2


def _prepared(goal: dict, points=10.0, penalty=1.5) -> PreparedTask:
    cfg = TaskConfig(name="t", scenario={}, goal=Goal.model_validate(goal), points=points)
    return PreparedTask(cfg, {}, 0, "me", ".", 10.0, penalty)


def test_scores_follow_the_criterion_and_the_collision_penalty():
    ok = {
        "status": "ended_by_metric",
        "simulated_time_s": 12.0,
        "me.collisions": 2,
        "me.distance_m": 7.5,
        "reach.reached": True,
        "reach.time_to_goal_s": 11.5,
    }
    g = score("s", _prepared({"reach": {"x_m": 0, "y_m": 0}}), ok)
    assert (g.status, g.score, g.time_s, g.path_length_m) == ("success", 7.0, 11.5, 7.5)
    many = dict(ok, **{"me.collisions": 9})
    assert score("s", _prepared({"reach": {"x_m": 0, "y_m": 0}}), many).score == 0.0
    caught = {
        "status": "ended_by_metric",
        "simulated_time_s": 4.0,
        "me.collisions": 0,
        "capture.captured": True,
        "capture.survival_time_s": 4.0,
    }
    g = score("s", _prepared({"evade": {"pursuer": "red"}}), caught)
    assert (g.status, g.score, g.message) == ("fail", 0.0, "caught at t = 4 s")
    free = dict(caught, **{"capture.captured": False, "capture.survival_time_s": 30.0})
    assert score("s", _prepared({"evade": {"pursuer": "red"}}), free).score == 10.0
    cover = {
        "status": "completed",
        "simulated_time_s": 60.0,
        "me.collisions": 0,
        "coverage.visited_fraction": 0.8,
        "coverage.seen_fraction": 0.95,
        "coverage.returned_to_start": False,
    }
    need = {"coverage": {"min_visited_fraction": 0.75, "min_seen_fraction": 0.9}}
    assert score("s", _prepared(need), cover).status == "success"
    need["coverage"]["return_to_start"] = True
    assert score("s", _prepared(need), cover).status == "fail"


def test_the_example_suite_loads():
    cfg, tasks = load_suite(ROOT / "examples" / "grading" / "suite.yaml")
    assert len(tasks) == 4 and [t.robot for t in tasks][2:] == ["differential", "blue"]
