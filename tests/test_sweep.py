"""Sweeps (``agvsim sweep``): a 2 x 2 x 3 grid of runs gives hand-worked numbers, the same table
in this process, in a pool of processes and on Ray; an interrupted sweep resumes where it
stopped; bad sweeps are refused, naming the variation and the field, before anything runs."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from agvsim.cli import app
from agvsim.experiments import SweepError, plan_sweep, run_sweep
from agvsim.experiments.paths import PathError, get_path, set_path
from agvsim.experiments.spec import WALL_COLUMNS
from agvsim.runner import run_scenario

# a 10 x 6 m room; the robot drives east from x = -3 by a script, so its path is hand-worked:
# it covers v * T metres unless its wheels saturate at 20 rad/s, i.e. v <= 20 rad/s * r
BASE = {
    "name": "straight line",
    "duration_s": 2.0,
    "world": {
        "picture": "##########\n#........#\n#........#\n#........#\n##########",
        "cell_size_m": 1.2,
    },
    "robots": [
        {
            "name": "r",
            "model": "differential",
            "pose": {"x_m": -3.0, "y_m": 0.0},
            "sensors": [{"type": "rangers", "range_max_m": 1.5, "noise_std_m": 0.01}],
            "controller": {"type": "script", "steps": [{"duration_s": 10, "twist": [0.3, 0]}]},
        }
    ],
}
GRID = {
    "name": "speed x wheel",
    "base": "base.yaml",
    "vary": {
        "robots.r.controller.steps.0.twist": [[0.2, 0.0], [0.4, 0.0]],
        "robots.0.params.wheel_radius_m": [0.1, 0.01],
    },
    "seeds": 3,
}


def write(folder: Path, sweep: dict, base: dict | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "base.yaml").write_text(yaml.safe_dump(base or BASE), encoding="utf-8")
    path = folder / "sweep.yaml"
    path.write_text(yaml.safe_dump(sweep, sort_keys=False), encoding="utf-8")
    return path


def without_wall(table):
    return table.drop_columns([c for c in WALL_COLUMNS if c in table.column_names])


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """The grid run in this process (workers=1): the reference table."""
    folder = tmp_path_factory.mktemp("clean")
    return run_sweep(write(folder, GRID), out_dir=folder / "out", workers=1)


def test_grid_gives_hand_worked_rows(clean):
    rows = clean.table.to_pylist()
    assert clean.executed == 12 and clean.skipped == 0 and not clean.failed
    assert [(r["variation"], r["seed"]) for r in rows] == [
        (v, s) for v in range(4) for s in range(3)
    ]
    # variation order: the last key varies fastest
    assert [r["robots.0.params.wheel_radius_m"] for r in rows[::3]] == [0.1, 0.01, 0.1, 0.01]
    for r in rows:
        v = r["robots.r.controller.steps.0.twist"]
        assert v in ("[0.2, 0.0]", "[0.4, 0.0]")  # a list value is kept as its JSON text
        speed = min(json.loads(v)[0], 20.0 * r["robots.0.params.wheel_radius_m"])
        assert r["status"] == "completed" and r["steps"] == 100
        assert r["r.distance_m"] == pytest.approx(2.0 * speed, abs=1e-6)
        assert r["r.final_x_m"] == pytest.approx(-3.0 + 2.0 * speed, abs=1e-9)
        assert r["r.collisions"] == 0
    # encoder noise comes from the seed: the three seeds of a variation differ ...
    odo = [r["r.odometry_error_m"] for r in rows]
    assert len(set(odo[0:3])) == 3
    # ... and the table's files hold the same numbers
    assert pq.read_table(clean.parquet_path).equals(clean.table)
    csv = pcsv.read_csv(clean.csv_path)
    assert csv.column("r.distance_m").to_pylist() == clean.table.column("r.distance_m").to_pylist()
    assert sorted(p.name for p in clean.plots) == ["plot_r_collisions.png", "plot_r_distance_m.png"]
    assert all(p.stat().st_size > 10_000 for p in clean.plots)


def test_a_row_is_what_agvsim_run_reports(clean, tmp_path):
    """The sweep's light loop gives the runner's numbers for the same scenario and seed."""
    plan = clean.plan
    task = next(t for t in plan.tasks if t.variation == 1 and t.seed == 2)
    from agvsim.scenario import parse_scenario

    sc = parse_scenario(task.scenario)
    data = run_scenario(sc, tmp_path / "one", seed=2, plot=False)
    row = next(r for r in clean.table.to_pylist() if r["variation"] == 1 and r["seed"] == 2)
    robot = data["robots"][0]
    assert row["r.distance_m"] == robot["distance_m"]
    assert row["r.odometry_error_m"] == robot["odometry_error_m"]
    assert row["r.final_x_m"] == robot["final_pose"]["x_m"]


@pytest.mark.slow  # starts worker processes
def test_local_processes_give_the_same_table(clean, tmp_path):
    pool = run_sweep(write(tmp_path, GRID), out_dir=tmp_path / "out", workers=2, plots=False)
    assert pool.executed == 12
    assert without_wall(pool.table).equals(without_wall(clean.table))


@pytest.mark.slow
def test_ray_gives_the_same_table(clean, tmp_path):
    pytest.importorskip("ray")
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    on_ray = run_sweep(
        write(tmp_path, GRID), out_dir=tmp_path / "out", workers=2, ray=True, plots=False
    )
    assert on_ray.executed == 12 and not on_ray.failed
    assert without_wall(on_ray.table).equals(without_wall(clean.table))
    # the Ray it started is gone, and so are the handlers it set: Ctrl-C and SIGTERM do in
    # the caller's program what they did before (Ray's SIGTERM handler had stayed behind)
    assert {s: signal.getsignal(s) for s in before} == before


def test_an_interrupted_sweep_resumes_where_it_stopped(clean, tmp_path):
    path = write(tmp_path, GRID)
    seen: list[tuple[int, int]] = []

    def stop_after_five(done, total, task, row):
        if task is not None:
            seen.append((task.variation, task.seed))
        if done == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(path, out_dir=tmp_path / "out", workers=1, progress=stop_after_five)
    assert len(list((tmp_path / "out" / "runs").glob("*.json"))) == 5
    assert not (tmp_path / "out" / "results.parquet").exists()

    again: list[tuple[int, int]] = []
    resumed = run_sweep(
        path,
        out_dir=tmp_path / "out",
        workers=1,
        progress=lambda d, t, task, row: (
            task is not None and again.append((task.variation, task.seed))
        ),
    )
    assert (resumed.skipped, resumed.executed) == (5, 7)
    assert sorted(again + seen) == [(v, s) for v in range(4) for s in range(3)]
    assert without_wall(resumed.table).equals(without_wall(clean.table))
    # a third time nothing runs, and the table is the same to the bit, wall times included
    third = run_sweep(path, out_dir=tmp_path / "out", workers=1, plots=False)
    assert (third.skipped, third.executed) == (12, 0)
    assert third.table.equals(resumed.table)


def test_limit_runs_part_of_a_sweep(tmp_path):
    part = run_sweep(
        write(tmp_path, GRID), out_dir=tmp_path / "out", workers=1, limit=4, plots=False
    )
    assert part.executed == 4 and part.table.num_rows == 4 and not part.complete


def test_a_changed_scenario_gets_new_run_ids(tmp_path):
    ids = [t.run_id for t in plan_sweep(write(tmp_path, GRID)).tasks]
    assert ids == [t.run_id for t in plan_sweep(write(tmp_path, GRID)).tasks]
    assert len(set(ids)) == 12
    changed = dict(BASE, duration_s=3.0)
    assert not set(ids) & {t.run_id for t in plan_sweep(write(tmp_path, GRID, changed)).tasks}


def test_cases_change_several_values_together(tmp_path):
    sweep = {
        "base": "base.yaml",
        "cases": {
            "diff": {"robots.0.model": "differential"},
            "mec": {"robots.0.model": "mecanum", "robots.0.params": {"wheel_radius_m": 0.05}},
        },
        "vary": {"robots.0.controller.steps.0.twist": [[0.2, 0.0]]},
        "seeds": [7],
        "duration_s": 1.0,
    }
    res = run_sweep(write(tmp_path, sweep), out_dir=tmp_path / "out", workers=1, plots=False)
    rows = res.table.to_pylist()
    assert [r["case"] for r in rows] == ["diff", "mec"]
    assert [r["r.model"] for r in rows] == ["differential", "mecanum"]
    assert [r["seed"] for r in rows] == [7, 7]
    assert [v.label for v in res.plan.variations] == [
        "case=diff, twist=[0.2,0.0]",
        "case=mec, twist=[0.2,0.0]",
    ]
    assert all(r["r.distance_m"] == pytest.approx(0.2) for r in rows)


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (
            {"vary": {"robots.3.model": ["mecanum"]}},
            ["vary.robots.3.model", "index 3 is out of range"],
        ),
        (
            {"vary": {"robots.rr.pose.x_m": [0.0]}},
            ["robots has no item named 'rr'", "did you mean 'r'?"],
        ),
        (
            {"vary": {"robots.0.params.wheel_radius_m": [0.1, -0.2]}},
            ["variation 1 (wheel_radius_m=-0.2)", "robots[0].params.wheel_radius_m", "-0.2"],
        ),
        (
            {"vary": {"robots.0.controller.steps.0.twst": [[0.1, 0]]}},
            ["variation 0", "unknown key 'twst'", "did you mean 'twist'?"],
        ),
        (
            {"vary": {"robots.0.pose.x_m": [-3.0, -5.9]}},
            ["variation 1 (x_m=-5.9)", "robots[0] (r).pose", "overlaps a wall"],
        ),
        ({"seeds": 0}, ["seeds: the number of seeds must be 1..1000000"]),
        ({"vary": {"seed": [1, 2]}}, ["'seeds:' sets it"]),
        ({"vary": {"robots.0.pose.x_m": [1.0, 1.0]}}, ["values repeat: 1.0"]),
        ({"plots": ["r.distanc_m"]}, ["no column 'r.distanc_m'", "did you mean 'r.distance_m'?"]),
        ({"sedes": 2}, ["unknown key 'sedes'", "did you mean 'seeds'?"]),
        ({"base": "nowhere.yaml"}, ["base: no such scenario file"]),
        (
            {
                "vary": {
                    "robots.0.pose.x_m": list(range(400)),
                    "robots.0.pose.y_m": list(range(300)),
                }
            },
            ["400 x 300 = 120000 variations; at most 100000"],
        ),
    ],
)
def test_bad_sweeps_are_refused_before_anything_runs(tmp_path, change, expected):
    path = write(tmp_path, {**GRID, **change})
    with pytest.raises(SweepError) as info:
        run_sweep(path, out_dir=tmp_path / "out", workers=1)
    text = str(info.value)
    for part in expected:
        assert part in text, text
    assert "Traceback" not in text and "pydantic" not in text
    assert not (tmp_path / "out").exists()


def test_cli_runs_resumes_and_refuses(tmp_path):
    path = write(tmp_path, {**GRID, "seeds": 1, "duration_s": 0.5})
    runner = CliRunner()
    first = runner.invoke(
        app, ["sweep", str(path), "--out", str(tmp_path / "o"), "--workers", "1", "-q", "--no-plot"]
    )
    assert first.exit_code == 0, first.output
    assert "4 run(s) done now, 0 already finished" in first.output
    again = runner.invoke(
        app, ["sweep", str(path), "--out", str(tmp_path / "o"), "-q", "--no-plot"]
    )
    assert again.exit_code == 0 and "0 run(s) done now, 4 already finished" in again.output
    bad = write(tmp_path / "bad", {**GRID, "vary": {"robots.9.model": ["mecanum"]}})
    refused = runner.invoke(app, ["sweep", str(bad), "--out", str(tmp_path / "b"), "-q"])
    assert refused.exit_code == 2
    assert "index 9 is out of range" in refused.output


def test_paths_pick_items_by_index_or_name():
    data = {
        "robots": [
            {"name": "a", "sensors": [{"type": "lidar"}, {"type": "rangers", "name": "front"}]}
        ]
    }
    set_path(data, "robots.a.sensors.lidar.noise_std_m", 0.1)
    set_path(data, "robots.0.sensors.front.range_max_m", 2.0)
    set_path(data, "robots.0.params.wheel_radius_m", 0.2)  # params created on the way
    assert data["robots"][0]["sensors"][0]["noise_std_m"] == 0.1
    assert get_path(data, "robots.a.sensors.1.range_max_m") == 2.0
    assert data["robots"][0]["params"] == {"wheel_radius_m": 0.2}
    set_path(data, "robots.0.sensors.lidar.beams", 5)
    with pytest.raises(PathError, match=r"beams.x: robots.0.sensors.lidar.beams is 5, not a"):
        set_path(data, "robots.0.sensors.lidar.beams.x", 1)
    with pytest.raises(PathError, match="not a dotted path"):
        set_path(data, "robots..name", "x")
