"""Input limits: the budgeted YAML reader, the run limits of a scenario (and how to raise them),
the map readers' cell limit and the checks on `agvsim run` / `validate` options.

Every count below is worked by hand from the input (nodes of a YAML document, cells of a
random maze, steps of a run, pixels and rays per second), so each limit is pinned exactly:
the input passes at its own size and is refused one below.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from agvsim.cli import app
from agvsim.record.outputs import TrajectoryWriter
from agvsim.safe_yaml import YamlInputError, YamlLimits, load_yaml, load_yaml_file
from agvsim.scenario import ScenarioError, build, load_scenario, parse_scenario, scenario_from_text
from agvsim.scenario_limits import Limits, steps_of
from agvsim.world import loaders
from agvsim.world.ros_map import load_ros_map

BAD = Path(__file__).resolve().parent / "data" / "bad_scenarios"


# ---------------------------------------------------------------------------------- YAML
def test_alias_expansion_is_counted_exactly():
    # root mapping 1 + keys a, b 2 + list x (1 + 2 scalars) 3 + list b (1 + x + x) 7 = 13
    text = "a: &x [1, 2]\nb: [*x, *x]\n"
    assert load_yaml(text, "t", YamlLimits(max_nodes=13)) == {"a": [1, 2], "b": [[1, 2], [1, 2]]}
    with pytest.raises(YamlInputError, match=r"line 2: the document holds more than 12 values"):
        load_yaml(text, "t", YamlLimits(max_nodes=12))


def test_billion_laughs_is_refused_at_once():
    lines = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, 10)]
    with pytest.raises(YamlInputError) as info:
        load_yaml("\n".join(lines), "bomb.yaml")
    # 10 + 1 values in a0, 111 in a1, ...: a5 (line 6) holds 1,111,111, over 250,000 at once
    assert info.value.line == 6
    assert "aliases expand past the limit yaml_max_nodes" in str(info.value)


def test_data_from_anywhere_is_measured_with_shared_parts_expanded():
    from agvsim.safe_yaml import measure_data

    x = [1, 2]
    assert measure_data({"a": x, "b": [x, x]}, "t") == 13  # as the YAML above, aliases as refs
    loop: list = []
    loop.append(loop)  # a list holding itself counts once where it recurs
    assert measure_data(loop, "t") == 2
    with pytest.raises(YamlInputError, match="more than 12 values"):
        measure_data({"a": x, "b": [x, x]}, "t", YamlLimits(max_nodes=12))
    with pytest.raises(YamlInputError, match="nested deeper than 2 levels"):
        measure_data([[[1]]], "t", YamlLimits(max_depth=2))
    # the browser app parses with PyYAML itself: the loader still refuses the bomb unexpanded
    data = yaml.safe_load((BAD / "alias_bomb_robots.yaml").read_text(encoding="utf-8"))
    with pytest.raises(ScenarioError, match="more than 250,000 values"):
        parse_scenario(data, "upload")


def test_nesting_depth_is_limited():
    assert load_yaml("[[[1]]]", "t", YamlLimits(max_depth=3)) == [[[1]]]
    with pytest.raises(YamlInputError, match="nested deeper than 2 levels"):
        load_yaml("[[[1]]]", "t", YamlLimits(max_depth=2))
    for deep in ("[" * 50_000 + "]" * 50_000, "- " * 50_000 + "x"):
        with pytest.raises(YamlInputError) as info:
            load_yaml(deep, "deep.yaml")
        assert info.value.line == 1


def test_encodings():
    assert load_yaml("\ufeffa: 1".encode(), "t") == {"a": 1}  # UTF-8 with a BOM
    with pytest.raises(YamlInputError, match="UTF-16 text; save it as UTF-8"):
        load_yaml("a: 1".encode("utf-16"), "t")
    with pytest.raises(YamlInputError, match=r"line 3: byte 0xe9 is not UTF-8"):
        load_yaml("a: 1\nb: 2\nc: caf\u00e9\n".encode("latin-1"), "t")


def test_size_and_odd_scalars(tmp_path):
    p = tmp_path / "big.yaml"
    p.write_text("a: " + "x" * 100, encoding="utf-8")
    with pytest.raises(YamlInputError, match=r"103 bytes, over the limit yaml_max_bytes = 100"):
        load_yaml_file(p, YamlLimits(max_bytes=100))
    with pytest.raises(YamlInputError, match="not valid YAML .*4300 digits"):
        load_yaml("seed: " + "7" * 5000, "t")
    with pytest.raises(YamlInputError, match="could not determine a constructor"):
        load_yaml("a: !!python/object/apply:os.system [ls]", "t")


# ---------------------------------------------------------------------------------- run limits
def _scenario(**top) -> dict:
    return {
        "dt_s": 0.02,
        "world": {"maze": "thesis_c1"},
        "robots": [{"name": "r1", "model": "differential", "pose": {"x_m": -8.0, "y_m": 5.0}}],
        **top,
    }


def test_steps_limit_and_raising_it():
    assert steps_of(1.0, 0.1, Limits(max_steps=10), "d") == 10
    with pytest.raises(ValueError, match=r"is 10 steps, over the limit max_steps = 9"):
        steps_of(1.0, 0.1, Limits(max_steps=9), "d")
    for bad in (float("inf"), float("nan"), 0.0, -1.0):
        with pytest.raises(ValueError, match="a finite number of s > 0"):
            steps_of(bad, 0.1, Limits(), "--duration")
    data = _scenario(duration_s=50, dt_s=1e-6)  # 50 million steps
    with pytest.raises(ScenarioError, match="max_steps: 50000000"):
        parse_scenario(data)
    raised = parse_scenario({**data, "limits": {"max_steps": 50_000_000}})
    assert raised._limits.max_steps == 50_000_000
    assert parse_scenario(data, limits=Limits(max_steps=50_000_000))._limits.max_steps == 50_000_000


def test_robot_count_is_checked_before_validation():
    robot = {"name": "r", "model": "differential"}
    data = _scenario(robots=[robot] * 3)  # the same name thrice: validation would refuse it
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data, limits=Limits(max_robots=2))
    assert info.value.problems == [
        "robots: 3 robots is over the limit max_robots = 2; raise it with 'limits: "
        "{max_robots: 3}' in the scenario or '--limit max_robots=3' (docs/scenario.md, 'Limits')"
    ]
    with pytest.raises(ScenarioError, match="names must be unique"):  # raised: validated
        parse_scenario({**data, "limits": {"max_robots": 3}}, limits=Limits(max_robots=2))


def test_random_maze_cells():
    # rows 2 x (corridor 2 + wall 1) + wall 1 = 7, cols 3 x 3 + 1 = 10: 70 cells
    data = _scenario(world={"random": {"rows": 2, "cols": 3, "seed": 1}})
    data["robots"][0]["pose"] = {"x_m": -3.5, "y_m": 2.0}
    data["robots"][0]["body"] = {"length_m": 0.5, "width_m": 0.4}
    sim = build(parse_scenario(data, limits=Limits(max_grid_cells=70)))
    assert sim.world.grid.occupied.shape == (7, 10)
    with pytest.raises(
        ScenarioError, match=r"7 x 10 = 70 cells, over the limit max_grid_cells = 69"
    ):
        parse_scenario(data, limits=Limits(max_grid_cells=69))


def test_maze_functions_check_their_inputs():
    from agvsim.world import mazes

    with pytest.raises(ValueError, match=r"7 x 10 = 70 cells is over the limit .* = 69"):
        mazes.random_maze(2, 3, 1, max_cells=69)
    assert mazes.random_maze(2, 3, 1, max_cells=70).occupied.shape == (7, 10)
    for bad in (float("nan"), float("inf"), 0.0, -1.0, "1"):
        with pytest.raises(ValueError, match="resolution_m must be"):
            mazes.random_maze(2, 3, 1, resolution_m=bad)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="resolution_m must be"):
            mazes.thesis_maze("thesis_c1", bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="loop_fraction"):
        mazes.random_maze(2, 3, 1, loop_fraction=float("nan"))


def test_sensor_rates():
    # a 320 x 240 camera at 10 Hz: 768,000 pixels/s; rangers 4 beams x 50 Hz (every step of
    # 0.02 s) + a 240-beam lidar at 10 Hz: 200 + 2,400 = 2,600 rays/s
    data = _scenario()
    data["robots"][0]["sensors"] = [{"type": "camera"}, {"type": "rangers"}, {"type": "lidar"}]
    parse_scenario(data, limits=Limits(max_camera_pixels_per_s=768_000, max_lidar_rays_per_s=2600))
    with pytest.raises(ScenarioError) as info:
        parse_scenario(
            data, limits=Limits(max_camera_pixels_per_s=767_999, max_lidar_rays_per_s=2599)
        )
    text = str(info.value)
    assert "768,000 pixels per simulated second" in text
    assert "2,600 rays per simulated second" in text
    # a camera asking for more frames than steps takes one a step: 1 kHz at dt 0.02 counts 50 Hz
    data["robots"][0]["sensors"] = [{"type": "camera", "rate_hz": 1000}]
    parse_scenario(data, limits=Limits(max_camera_pixels_per_s=320 * 240 * 50))


def test_an_untrusted_file_cannot_raise_its_limits(tmp_path):
    data = _scenario(duration_s=50, dt_s=1e-6, limits={"max_steps": 50_000_000})
    with pytest.raises(ScenarioError, match="cannot raise its own limits"):
        parse_scenario(data, limits_from_file=False)
    lowered = parse_scenario(_scenario(limits={"max_steps": 5000}), limits_from_file=False)
    assert lowered._limits.max_steps == 5000
    text = yaml.safe_dump(data)
    with pytest.raises(ScenarioError, match="limits.max_steps"):
        scenario_from_text(text, "upload")
    with pytest.raises(ScenarioError, match="yaml_max_nodes"):
        scenario_from_text((BAD / "alias_bomb_robots.yaml").read_bytes(), "upload")
    path = tmp_path / "upload.yaml"
    path.write_text(text, encoding="utf-8")
    assert load_scenario(path)._limits.max_steps == 50_000_000  # from the command line: trusted
    with pytest.raises(ScenarioError, match="cannot raise its own limits"):
        load_scenario(path, limits_from_file=False)


def test_limits_from_options():
    got = Limits.from_options(
        ["max_steps=2e7", "yaml_max_depth=100", "max_camera_pixels_per_s=1.5e8"]
    )
    assert (got.max_steps, got.yaml_max_depth, got.max_camera_pixels_per_s) == (
        20_000_000,
        100,
        150_000_000,
    )
    for bad in ("max_step=3", "max_steps", "max_steps=-1", "max_steps=inf", "max_steps=x"):
        with pytest.raises(ValueError, match=re.escape(repr(bad))):
            Limits.from_options([bad])


def test_huge_finite_numbers_are_refused():
    # 1e300 degrees once overflowed the float32 of the recorded LaserScan after the run
    data = _scenario()
    data["robots"][0]["sensors"] = [{"type": "lidar", "angle_min_deg": -1e300, "fov_deg": 90}]
    data["robots"][0]["controller"] = {"type": "goto_goal", "goal_x_m": 1e13, "goal_y_m": 0}
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data)
    assert info.value.problems == [
        "robots[0].sensors[0].angle_min_deg: too large (allowed: magnitude <= 1e+12) (got -1e+300)",
        "robots[0].controller.goal_x_m: too large (allowed: magnitude <= 1e+12) "
        "(got 10000000000000.0)",
    ]
    data["robots"][0]["controller"]["goal_x_m"] = 1e12  # the bound itself is allowed
    data["robots"][0]["sensors"][0]["angle_min_deg"] = -45.0
    assert parse_scenario(data).robots[0].controller.goal_x_m == 1e12
    data["robots"][0]["params"] = {"wheel_radius_m": 10**400}  # no float holds it
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.params\.wheel_radius_m: too large"):
        parse_scenario(data)
    # every block alike, those of other modules too (checked before validation)
    data["robots"][0]["params"] = {}
    data["robots"][0]["dynamics"] = {"mass_kg": 1e300}
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.dynamics\.mass_kg: too large"):
        parse_scenario(data)


def test_names_and_problem_count_are_bounded():
    data = _scenario(name="n" * 5_000_000)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data)
    assert len(str(info.value)) < 500
    data = _scenario(world={"matrix": [["x"] * 100] * 100})  # 10,000 values not integers
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data)
    assert len(info.value.problems) == 31
    assert info.value.problems[-1] == "... and 9,970 more problems"


# ---------------------------------------------------------------------------------- maps
def test_map_files_are_measured_before_they_are_read(tmp_path):
    from PIL import Image

    png = tmp_path / "m.png"
    Image.fromarray(np.full((20, 30), 255, np.uint8)).save(png)
    assert loaders.load_map(png, max_cells=600).occupied.shape == (20, 30)
    with pytest.raises(loaders.MapFormatError, match=r"20 x 30 = 600 cells is over .* = 599"):
        loaders.load_map(png, max_cells=599)
    csv = tmp_path / "m.csv"
    csv.write_text("1,1,1,1\n1,0,0,1\n1,1,1,1\n", encoding="utf-8")
    with pytest.raises(loaders.MapFormatError, match=r"3 x 4 = 12 cells"):
        loaders.load_map(csv, max_cells=11)
    txt = tmp_path / "m.txt"
    txt.write_text(("#" * 1000 + "\n") * 2000, encoding="utf-8")  # 2 MB for a 10-cell limit
    with pytest.raises(loaders.MapFormatError, match="too large for a map of at most"):
        loaders.load_map(txt, max_cells=10)


def test_ros_map_yaml_alias_bomb(tmp_path):
    lines = ["image: m.pgm", "a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, 9)]
    p = tmp_path / "map.yaml"
    p.write_text("\n".join(lines), encoding="utf-8")
    # a0 holds 11 values, a1 111, a2 1,111, a3 (line 5) 11,111: over the ROS map's 10,000
    with pytest.raises(loaders.MapFormatError, match=r"map\.yaml, line 5: the document holds"):
        load_ros_map(p)
    p.write_bytes(b"image: m.pgm\nresolution: \xff\n")
    with pytest.raises(loaders.MapFormatError, match="line 2: byte 0xff is not UTF-8"):
        load_ros_map(p)


# ---------------------------------------------------------------------------------- CLI
def _cli(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(app, list(args), env={"COLUMNS": "300", "NO_COLOR": "1"})
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception
    return res.exit_code, " ".join(res.output.split())


def test_run_options_are_checked(tmp_path):
    ok = tmp_path / "ok.yaml"
    ok.write_text(yaml.safe_dump(_scenario(duration_s=0.1)), encoding="utf-8")
    out = str(tmp_path / "out")
    for option, value, says in [
        ("--duration", "inf", "inf is not allowed (a finite number of seconds > 0)"),
        ("--duration", "nan", "nan is not allowed"),
        ("--duration", "-2", "-2.0 is not allowed"),
        ("--record-every", "0", "--record-every"),
        ("--record-every", "-3", "--record-every"),
        ("--seed", "-5", "--seed"),
        ("--limit", "max_step=3", "NAME one of max_steps"),
    ]:
        rc, text = _cli("run", str(ok), "--out", out, "-q", "--no-plot", option, value)
        assert rc == 2, (option, value, text)
        assert says in text, (option, value, text)
        assert not Path(out).exists()
    rc, text = _cli("run", str(ok), "--out", out, "-q", "--no-plot", "--duration", "1e9")
    assert rc == 2 and "--duration: 1e+09 s in steps of dt_s = 0.02 s" in text
    assert "--limit max_steps=50000000000" in text


def test_validate_takes_raised_limits():
    rc, text = _cli("validate", str(BAD / "tiny_dt.yaml"))
    assert rc == 2 and "max_steps = 10,000,000" in text
    rc, text = _cli("validate", str(BAD / "tiny_dt.yaml"), "--limit", "max_steps=5e10")
    assert rc == 0 and text.endswith("valid"), text


def test_validate_sets_up_metrics_and_slam_as_run_does(tmp_path):
    data = _scenario(metrics={"coverage": {"robot": "r1", "sensor": "lidar"}})
    path = tmp_path / "cov.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    rc, text = _cli("validate", str(path))
    assert rc == 2 and "metrics.coverage.sensor: robot 'r1' has no sensor 'lidar'" in text
    data = _scenario()
    data["robots"][0]["slam"] = {"sensor": "lidar"}
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    rc, text = _cli("validate", str(path))
    assert rc == 2 and "robots[0].slam.sensor: robot 'r1' has no sensor 'lidar'" in text


def test_trajectory_writer_refuses_a_zero_period(tmp_path):
    sim = build(load_scenario(BAD.parent.parent.parent / "scenarios" / "thesis_maze_avoid.yaml"))
    for every in (0, -3, 1.5):
        with pytest.raises(ValueError, match="record_every"):
            TrajectoryWriter(tmp_path / "t.csv", sim, every)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------- behaviours
def _refused(data: dict) -> str:
    with pytest.raises(ScenarioError) as info:
        build(parse_scenario(data))
    return "\n".join(info.value.problems)


def test_goals_that_cannot_be_reached_are_refused():
    data = _scenario()
    robot = data["robots"][0]
    robot["controller"] = {"type": "maze_solver", "goal_cell": [20, 3]}  # the map has rows 0..19
    assert "goal_cell: [20, 3] is outside the 20 x 20 map (allowed: rows 0..19" in _refused(data)
    robot["controller"] = {"type": "maze_solver", "method": "tremaux", "goal_cell": [3, 20]}
    assert "goal_cell: [3, 20] is outside the 20 x 20 map" in _refused(data)
    robot["controller"] = {"type": "maze_solver", "goal_x_m": 10.0, "goal_y_m": 0.0}
    assert "(10, 0) is outside the map, which spans x in [-10, 10)" in _refused(data)
    robot["sensors"] = [{"type": "camera", "width_px": 16, "height_px": 12}]
    robot["controller"] = {"type": "marker_search", "marker_id": 50}  # 4x4_50: ids 0..49
    assert "marker_id: 50 is not in 4x4_50, which holds ids 0..49" in _refused(data)
    robot["controller"] = {"type": "marker_search", "marker_id": 29, "dictionary": "apriltag_16h5"}
    build(parse_scenario(data))  # 16h5 holds 30 tags: 29 is the last


def test_planning_and_slam_rasters_are_bounded():
    # 100 m cells: A* would rasterise the 20 x 20 maze at 5 cm, 40,000 x 40,000 cells
    data = _scenario(world={"maze": "thesis_c1", "cell_size_m": 100.0})
    data["robots"][0]["pose"] = {"x_m": -800.0, "y_m": 500.0}
    data["robots"][0]["controller"] = {"type": "maze_solver", "goal_cell": [17, 17]}
    assert "40,000 x 40,000 = 1,600,000,000 cells of 5 cm" in _refused(data)
    # SLAM: a 1000 m lidar at 6 mm cells rasterises 2 x 1000 / 0.006 = 333,334 cells a side
    data = _scenario()
    data["robots"][0]["sensors"] = [{"type": "lidar", "range_max_m": 1000.0}]
    data["robots"][0]["slam"] = {"resolution_m": 0.006}
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.slam: .* 333,334 x 333,334 cells"):
        parse_scenario(data)
    data["robots"][0]["slam"]["max_range_m"] = 15.0  # 5,000 x 5,000: exactly the default limit
    parse_scenario(data)


def test_a_device_or_folder_is_not_read():
    for path in ("/dev/zero", Path(__file__).parent):
        rc, text = _cli("validate", str(path))
        assert rc == 2 and "the file is a directory or a device, not a regular file" in text


def test_the_static_distance_field_stays_bounded_on_a_huge_map():
    """Every build rasters the walls for telling robots from walls (control.traffic): on a
    2 km map it samples coarser instead of allocating 1.6e9 cells."""
    from agvsim.control.traffic import MAX_RASTER_CELLS, StaticMap
    from agvsim.world.grid import OccupancyGrid

    occupied = np.zeros((20, 20), dtype=bool)
    occupied[0, :] = True
    grid = OccupancyGrid(occupied, 100.0, (-1000.0, -1000.0))
    static = StaticMap.of(grid)
    assert static.dist_m.size <= MAX_RASTER_CELLS * 1.01
    assert static.resolution_m == pytest.approx(2000.0 / 2000.0)
    # the top row of cells is wall: 1 km north of the centre is 50 m from it (within a sample)
    d = static.distance_m(np.array([0.0]), np.array([850.0]))
    assert d[0] == pytest.approx(50.0, abs=1.5)


@pytest.mark.parametrize("command", [["sweep"], ["grade", "ctrl.py", "--suite"]])
def test_sweep_and_suite_files_are_read_within_the_yaml_budget(tmp_path, command):
    """Sweep and grading-suite files go through the scenario loader's bounded reader: an alias
    bomb (10^7 values once expanded) is refused naming the line, not expanded."""
    levels = ['a: &a ["x","x","x","x","x","x","x","x","x","x"]']
    for k in "bcdefg":
        prev = chr(ord(k) - 1)
        levels.append(f"{k}: &{k} [" + ",".join([f"*{prev}"] * 10) + "]")
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("\n".join(levels) + "\n")
    rc, text = _cli(*command, str(bomb))
    assert rc == 2 and "line 6: the document holds more than 250,000 values" in text
