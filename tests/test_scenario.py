"""Scenario files: a broken file is refused with one clear line per fault (field path, what is
wrong, what is allowed), never a stack trace; the shipped scenarios load and build.

The broken files live in tests/data/bad_scenarios/, one fault each (its first line says which).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.kinematics import MODELS
from agvsim.scenario import (
    Scenario,
    ScenarioError,
    build,
    load_scenario,
    parse_scenario,
)
from agvsim.scenario_params import PARAMS

ROOT = Path(__file__).resolve().parents[1]
BAD = Path(__file__).resolve().parent / "data" / "bad_scenarios"
SHIPPED = sorted((ROOT / "scenarios").rglob("*.yaml"))
MISSING = "no_such_scenario.yaml"  # deliberately absent from BAD

# Text that betrays a leaked stack trace or library internals.
LEAKS = ("Traceback", 'File "', "numpy", "np.", "ndarray", "dtype", "float64", "pydantic")

# Field paths as regexes. Messages found while building add the robot's name after the index
# ("robots[0] (r1).pose"), and pydantic puts the union tag in paths inside sensors/controllers
# ("sensors[0].rangers.range_max"); both forms are accepted.
R0 = r"robots\[0\]( \([\w-]+\))?"
STEP0 = r"robots\[0\]\.controller(\.script)?\.steps\[0\]"

# (file in tests/data/bad_scenarios, field path regex, substrings the message must contain)
CASES = [
    ("unknown_top_level_key.yaml", r"\brobts\b", ["unknown key 'robts'", "did you mean 'robots'?"]),
    (
        "robot_key_typo.yaml",
        r"robots\[0\]\.modle\b",
        ["unknown key 'modle'", "robots[0].model: required field is missing"],
    ),
    (
        "sensor_key_typo.yaml",
        r"robots\[0\]\.sensors\[0\](\.rangers)?\.range_max\b",
        ["unknown key 'range_max'", "did you mean 'range_max_m'?"],
    ),
    (
        "unknown_model.yaml",
        r"robots\[0\]\.model\b",
        ["'diferential' is not allowed", "did you mean 'differential'?", "tricycle, ackermann"],
    ),
    (
        "unknown_controller_type.yaml",
        r"robots\[0\]\.controller\b",
        ["unknown type 'scrpt'", "did you mean 'script'?", "avoid, evade, goto_goal"],
    ),
    (
        "negative_wheel_radius.yaml",
        R0 + r"\.params\b",
        ["wheel_radius_m", "must be a positive", "-0.1"],
    ),
    (
        "unknown_model_param.yaml",
        R0 + r"\.params\b",
        [
            "unknown parameter 'wheelbase_m'",
            "'differential'",
            "allowed: half_track_m, max_wheel_speed_rad_s, wheel_radius_m",
        ],
    ),
    ("wrong_type_duration.yaml", r"\bduration_s\b", ["valid number", "'long'"]),
    ("two_map_sources.yaml", r"\bworld\b", ["exactly one map source", "'maze', 'picture'"]),
    ("no_map_source.yaml", r"\bworld\b", ["exactly one map source", "got none"]),
    ("duplicate_robot_names.yaml", r"\(top level\)|\brobots\b", ["names must be unique", "'twin'"]),
    ("robot_outside_map.yaml", R0 + r"\.pose\b", ["(15, 0)", "outside the map", "x in [-10, 10)"]),
    ("robot_inside_wall.yaml", R0 + r"\.pose\b", ["(-9.5, 9.5)", "overlaps a wall"]),
    ("robots_overlapping.yaml", r"robots 'first' and 'second'", ["overlapping each other"]),
    ("robot_on_box.yaml", R0 + r"\.pose\b", ["overlaps a box obstacle"]),
    ("script_twist_and_wheels.yaml", STEP0, ["exactly one of 'twist' or 'wheels'"]),
    (
        "script_twist_wrong_length.yaml",
        STEP0,
        ["twist must be [vx, omega] or [vx, vy, omega]", "[0.5, 0.0, 0.0, 0.1]"],
    ),
    (
        "script_wrong_wheel_count.yaml",
        R0 + r"\.controller\.steps\b",
        [
            "mecanum robot has 4 driven wheel(s)",
            "'front_left', 'front_right', 'rear_left', 'rear_right'",
            "got 2 speeds",
        ],
    ),
    (
        "avoid_missing_sensor.yaml",
        R0 + r"\.controller\.sensor\b",
        ["no sensor 'rangers'", "allowed: lidar"],
    ),
    ("invalid_yaml.yaml", r"\bline 4\b", ["not valid YAML"]),
    (MISSING, re.escape(MISSING), ["no such file"]),
    ("missing_map_file.yaml", r"\bworld\b", ["no_such_map.png", "file not found"]),
    (
        "unknown_maze.yaml",
        r"\bworld\.maze\b",
        ["'thesis_c2' is not allowed", "did you mean 'thesis_c1'?", "thesis_fig16"],
    ),
    (
        "bad_matrix_value.yaml",
        r"\bworld\b",
        ["row 2, column 3", "value 2 is not allowed", "0 or 1"],
    ),
    ("world_key_typo.yaml", r"\bworld\.cell_size\b", ["did you mean 'cell_size_m'?"]),
    ("unknown_mode.yaml", r"robots\[0\]\.mode\b", ["'inverse' or 'forward'", "got 'wheels'"]),
    (
        "python_controller_name.yaml",
        R0 + r"\.controller\.name\b",
        ["'wandr' is not defined", "did you mean 'wander'?"],
    ),
    ("not_a_mapping.yaml", r"not_a_mapping\.yaml", ["must hold a mapping of keys", "got list"]),
    # issue 13: tracebacks, hangs and silent acceptance found by fuzzing
    ("latin1_text.yaml", r"\bline 2\b", ["byte 0xe9 is not UTF-8 text", "save the file as UTF-8"]),
    ("utf16_text.yaml", r"utf16_text\.yaml", ["the file is UTF-16 text", "save it as UTF-8"]),
    (
        "alias_bomb_robots.yaml",
        r"\bline 17\b",  # the first alias of a14: 294,906 values by then
        ["more than 250,000 values", "aliases expand", "yaml_max_nodes"],
    ),
    ("nan_pose.yaml", r"robots\[0\]\.pose\.x_m\b", ["finite number", "nan"]),
    ("inf_box.yaml", r"world\.boxes\[0\]\.length_m\b", ["finite number", "inf"]),
    (
        "bad_colour.yaml",
        r"robots\[0\]\.color\b",
        ["not a colour", "'#rrggbb'", "matplotlib colour name", "(got 'not-a-colour')"],
    ),
    ("negative_seed.yaml", r"\bseed\b", ["greater than or equal to 0", "-5"]),
    (
        "huge_goal_cell.yaml",
        r"robots\[0\]\.controller(\.maze_solver)?\.goal_cell\[0\]",
        ["too large (allowed: magnitude <= 1e+12)", "1e+40"],
    ),
    (
        "tiny_dt.yaml",
        r"\bduration_s\b",
        ["50,000,000,000 steps", "max_steps = 10,000,000", "limits: {max_steps: 50000000000}"],
    ),
    (
        "huge_random_maze.yaml",
        r"\bworld\.random\b",
        ["50,050 x 50,050", "max_grid_cells = 25,000,000", "--limit max_grid_cells="],
    ),
    (
        "camera_4k_1khz.yaml",
        r"\bsensors\b",
        ["16,777,216,000 pixels", "max_camera_pixels_per_s = 100,000,000"],
    ),
    ("inf_noise.yaml", r"robots\[0\]\.sensors\[0\](\.lidar)?\.noise_std_m\b", ["finite"]),
    ("nan_reach_goal.yaml", r"\bmetrics\.reach\.y_m\b", ["finite number"]),
    ("nan_script_twist.yaml", STEP0 + r"\.twist\[0\]", ["finite number", "nan"]),
    ("inf_script_wheels.yaml", STEP0 + r"\.wheels\[1\]", ["finite number", "-inf"]),
    ("long_robot_name.yaml", r"robots\[0\]\.name\b", ["at most 64 characters", "(202 chars)"]),
    ("limits_key_typo.yaml", r"\blimits\.max_step\b", ["did you mean 'max_steps'?"]),
    ("inf_model_param.yaml", r"robots\[0\]\.params\b", ["wheel_radius_m", "finite number"]),
    ("metric_unknown_robot.yaml", r"\bmetrics\.reach\.robot\b", ["'omni' is not a robot", "car"]),
]

# Faults that were once reported badly (kept apart as regression cases).
KNOWN_BUGS = [
    pytest.param(
        "lidar_key_typo.yaml",
        r"robots\[0\]\.sensors\[0\](\.lidar)?\.beam\b",
        ["did you mean 'beams'?", "fov_deg"],
        id="lidar_key_typo.yaml",
    ),
    pytest.param(
        "avoid_key_typo.yaml",
        r"robots\[0\]\.controller(\.avoid)?\.trigger\b",
        ["did you mean 'trigger_m'?"],
        id="avoid_key_typo.yaml",
    ),
    pytest.param(
        "range_min_above_max.yaml",
        R0 + r"\.sensors\b",
        ["range_min_m", "range_max_m"],
        id="range_min_above_max.yaml",
    ),
    pytest.param(
        "python_controller_not_python.yaml",
        R0 + r"\.controller\.file\b",
        ["helper_controller.txt"],
        id="python_controller_not_python.yaml",
    ),
]


def _refusal(path: Path) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        build(load_scenario(path))
    return info.value


def _assert_clear(message: str, where: str, hints: list[str]) -> None:
    assert re.search(where, message), f"no field path /{where}/ in:\n{message}"
    for hint in hints:
        assert hint in message, f"{hint!r} not in:\n{message}"
    for leak in LEAKS:
        assert leak not in message, f"{leak!r} leaked into:\n{message}"


@pytest.mark.parametrize(
    ("filename", "where", "hints"), [*(pytest.param(*c, id=c[0]) for c in CASES), *KNOWN_BUGS]
)
def test_broken_scenario_is_refused_with_a_clear_message(filename, where, hints):
    err = _refusal(BAD / filename)
    assert err.problems and all(isinstance(p, str) and p.strip() for p in err.problems)
    _assert_clear(str(err), where, hints)


def test_every_broken_file_is_in_the_table():
    listed = {c[0] for c in CASES} | {p.values[0] for p in KNOWN_BUGS}
    on_disk = {p.name for p in BAD.glob("*.yaml")}
    assert not (BAD / MISSING).exists()
    assert on_disk == listed - {MISSING}


def test_schema_errors_are_reported_together():
    data = {
        "duration_s": -1,
        "world": {"maze": "thesis_c1", "cell_size_m": 0},
        "robots": [{"name": "r1", "model": "differential", "pose": {"x": 1}}],
    }
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data, "inline")
    joined = "\n".join(info.value.problems)
    assert len(info.value.problems) == 3, joined
    for where in ("duration_s: ", "world.cell_size_m: ", "robots[0].pose.x: "):
        assert where in joined
    assert str(info.value).startswith("inline is not a valid scenario:")


def test_build_errors_name_the_file():
    assert "robot_inside_wall.yaml" in str(_refusal(BAD / "robot_inside_wall.yaml"))


# ---------------------------------------------------------------------------------- CLI
def _cli(*args: str, cwd: Path) -> tuple[int, str, str]:
    env = {**os.environ, "COLUMNS": "500", "NO_COLOR": "1", "TERM": "dumb"}
    proc = subprocess.run(
        [sys.executable, "-m", "agvsim.cli", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=cwd,
        timeout=300,
    )
    # Rich wraps long lines on narrow consoles: compare with whitespace collapsed
    return proc.returncode, " ".join(proc.stdout.split()), " ".join(proc.stderr.split())


def test_cli_validate_refuses_robot_in_wall(tmp_path):
    rc, out, err = _cli("validate", str(BAD / "robot_inside_wall.yaml"), cwd=tmp_path)
    assert rc == 2, (out, err)
    assert "robot_inside_wall.yaml is not a valid scenario" in err
    _assert_clear(err, R0 + r"\.pose\b", ["overlaps a wall"])
    assert "valid" not in out


def test_cli_run_refuses_typo_before_running(tmp_path):
    out_dir = tmp_path / "out"
    rc, out, err = _cli(
        "run",
        str(BAD / "unknown_top_level_key.yaml"),
        "--out",
        str(out_dir),
        "--quiet",
        "--no-plot",
        cwd=tmp_path,
    )
    assert rc == 2, (out, err)
    _assert_clear(err, r"\brobts\b", ["did you mean 'robots'?"])
    assert not out_dir.exists()


def test_cli_validate_accepts_a_shipped_scenario(tmp_path):
    rc, out, err = _cli("validate", str(SHIPPED[0]), cwd=tmp_path)
    assert rc == 0, err
    assert out.endswith("valid")


def test_cli_keeps_brackets_in_messages(tmp_path):
    rc, _, err = _cli("validate", str(BAD / "script_twist_wrong_length.yaml"), cwd=tmp_path)
    assert rc == 2
    assert "[vx, omega] or [vx, vy, omega]" in err


# ---------------------------------------------------------------------------------- valid files
def test_scenarios_folder_is_not_empty():
    assert SHIPPED, ROOT / "scenarios"


@pytest.mark.parametrize("path", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_scenario_loads_and_builds(path):
    sc = load_scenario(path)
    sim = build(sc)
    assert [r.name for r in sim.robots] == [r.name for r in sc.robots]
    assert sim.dt_s == sc.dt_s


VALID = {
    "name": "round trip",
    "seed": 7,
    "duration_s": 5.0,
    "dt_s": 0.05,
    "world": {
        "picture": "#######\n#.....#\n#.....#\n#.....#\n#######\n",
        "cell_size_m": 1.0,
        "boxes": [{"x_m": 2.0, "y_m": 0.0, "theta_deg": 30.0, "length_m": 0.4, "width_m": 0.2}],
    },
    "robots": [
        {
            "name": "car",
            "model": "ackermann",
            "mode": "forward",
            "params": {"wheelbase_m": 0.45, "steering_geometry": "parallel"},
            "body": {"length_m": 0.6, "width_m": 0.4},
            "pose": {"x_m": -1.5, "y_m": 0.0, "theta_deg": 90.0},
            "sensors": [
                {"type": "rangers", "range_max_m": 1.5},
                {
                    "type": "lidar",
                    "name": "front_lidar",
                    "beams": 91,
                    "fov_deg": 180.0,
                    "noise_std_m": 0.01,
                },
            ],
            "odometry": {"wheel_noise_rel": 0.02, "steering_noise_deg": 0.5},
            "controller": {
                "type": "script",
                "loop": True,
                "steps": [
                    {"duration_s": 1.0, "wheels": [5.0, 5.0], "steering_deg": 20.0},
                    {"duration_s": 1.0, "twist": [0.3, -0.2]},
                ],
            },
        },
        {
            "name": "omni",
            "model": "omni3",
            "pose": {"x_m": 0.5, "y_m": 1.0},
            "sensors": [{"type": "rangers"}],
            "controller": {"type": "avoid", "trigger_m": 0.5},
        },
    ],
}


def test_round_trip_dict_yaml_and_dump(tmp_path):
    path = tmp_path / "valid.yaml"
    path.write_text(yaml.safe_dump(VALID, sort_keys=False), encoding="utf-8")
    loaded = load_scenario(path)
    parsed = parse_scenario(VALID)
    # not ``loaded == parsed``: the models differ in the private _base_dir (the file's folder)
    assert loaded.model_dump() == parsed.model_dump()
    assert parse_scenario(parsed.model_dump(mode="json")) == parsed

    sim = build(loaded)
    car, omni = sim.robots
    assert car.initial_pose == pytest.approx((-1.5, 0.0, np.pi / 2))
    assert car.body_offset_x_m == pytest.approx(0.45 / 2)  # car bodies sit ahead of P
    assert car.model.steering_geometry == "parallel"
    assert [s.name for s in car.sensors] == ["rangers", "front_lidar"]
    rangers, lidar = car.sensors
    assert rangers.rate_hz == pytest.approx(1 / 0.05)  # rangers: every step by default
    assert rangers.mount_xy_m == pytest.approx((0.225, 0.0))  # mounted at the body centre
    assert lidar.rate_hz == 10.0
    assert lidar.angle_min_rad == pytest.approx(-np.pi / 2)
    assert lidar.angle_increment_rad == pytest.approx(np.deg2rad(2.0))
    assert omni.body_offset_x_m == 0.0
    assert sim.world.boxes.shape == (1, 5)
    assert sim.world.boxes[0] == pytest.approx([2.0, 0.0, np.deg2rad(30.0), 0.2, 0.1])


# ---------------------------------------------------------------------------------- docs
def _schema_classes() -> list:
    """Every config class reachable from Scenario (so new controller types are checked too)."""
    from agvsim.scenario import _models_in

    seen, todo = [], [Scenario]
    while todo:
        cls = todo.pop()
        if cls in seen:
            continue
        seen.append(cls)
        for f in cls.model_fields.values():
            todo.extend(_models_in(f.annotation))
    return seen


SCHEMA = _schema_classes()


def test_docs_name_every_key_and_model_parameter():
    doc = (ROOT / "docs" / "scenario.md").read_text(encoding="utf-8")
    keys = {name for cls in SCHEMA for name in cls.model_fields}
    params = {f.name for cls in MODELS.values() for f in fields(cls)}
    # a key counts when it is written in backticks, alone or at the end of a path
    names = keys | params | set(MODELS)
    missing = sorted(k for k in names if not re.search(rf"`[\w.\[\]]*\b{k}`", doc))
    assert not missing, f"docs/scenario.md does not mention {missing}"


# ---------------------------------------------------------------------------------- known bugs
def _one_robot(**robot) -> dict:
    return {
        "world": {"maze": "thesis_c1"},
        "robots": [
            {"name": "r1", "model": "differential", "pose": {"x_m": -8.0, "y_m": 5.0}, **robot}
        ],
    }


def test_heading_minus_180_deg_wraps_to_pi():
    sim = build(parse_scenario(_one_robot(pose={"x_m": -8.0, "y_m": 5.0, "theta_deg": -180})))
    assert sim.state.poses[0, 2] == np.pi


def test_random_maze_honours_origin():
    data = _one_robot(pose={"x_m": 2.0, "y_m": 2.0}, body={"length_m": 0.5, "width_m": 0.4})
    data["world"] = {"random": {"rows": 2, "cols": 2, "seed": 3}, "origin_xy_m": [0.0, 0.0]}
    assert build(parse_scenario(data)).world.grid.origin_xy_m == (0.0, 0.0)


def test_ros_map_file_loads(tmp_path):
    from agvsim.world import loaders

    grid = loaders.grid_from_matrix(
        [[1, 1, 1, 1], [1, 0, 0, 1], [1, 0, 0, 1], [1, 1, 1, 1]], 0.5, (0.0, 0.0)
    )
    loaders.save_ros_map(grid, tmp_path / "map.yaml")
    data = _one_robot(pose={"x_m": 1.0, "y_m": 1.0}, body={"length_m": 0.4, "width_m": 0.3})
    data["world"] = {"file": "map.yaml"}
    sim = build(parse_scenario(data), base_dir=tmp_path)
    assert sim.world.grid.resolution_m == 0.5


def test_quoted_number_param_is_refused():
    data = _one_robot(
        params={"wheel_radius_m": "0.1"},
        controller={"type": "script", "steps": [{"duration_s": 1, "twist": [1, 0]}]},
    )
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data)
    assert info.value.problems == ["robots[0].params.wheel_radius_m: must be a number (got '0.1')"]


def test_python_controller_with_syntax_error_is_refused(tmp_path):
    (tmp_path / "broken.py").write_text("def controller(obs)\n    return (0, 0, 0)\n")
    data = _one_robot(controller={"type": "python", "file": "broken.py"})
    with pytest.raises(ScenarioError) as info:
        build(parse_scenario(data), base_dir=tmp_path)
    _assert_clear(str(info.value), R0 + r"\.controller\.file\b", ["broken.py", "line 1"])


# ------------------------------------------------------------------ model parameters typed once
def _params_problems(model: str, params: dict) -> list[str]:
    data = _one_robot(model=model, params=params)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data)
    return info.value.problems


@pytest.mark.parametrize("kind", list(MODELS))
def test_params_block_is_the_model_dataclass(kind):
    """Each model's ``params`` block has exactly the dataclass's fields and defaults."""
    block = PARAMS[kind].model_fields
    assert list(block) == [f.name for f in fields(MODELS[kind])]
    for f in fields(MODELS[kind]):
        assert block[f.name].default is f.default
        assert block[f.name].description  # the panel's hint


@pytest.mark.parametrize(
    "kind,name",
    [
        (k, f.name)
        for k, cls in MODELS.items()
        for f in fields(cls)
        if f.name != "steering_geometry"
    ],
)
@pytest.mark.parametrize("value", [0, -0.25, -1e9])
def test_non_positive_params_are_refused_in_the_file_and_in_python(kind, name, value):
    """One declaration, two checks: the schema and the dataclass refuse the same value."""
    problems = _params_problems(kind, {name: value})
    (line,) = problems
    assert line.startswith(f"robots[0].params.{name}: must be a positive number")
    assert line.endswith(f"(got {value!r})")
    with pytest.raises(ValueError, match=rf"{MODELS[kind].__name__}\.{name} must be a positive"):
        MODELS[kind](**{name: value})


@given(st.floats(min_value=np.pi / 2, max_value=1e12))
@settings(max_examples=25, deadline=None)
def test_ackermann_steering_limit_must_be_below_a_right_angle(limit):
    problems = _params_problems("ackermann", {"max_steer_rad": limit})
    assert problems == [
        f"robots[0].params.max_steer_rad: must be a positive number below pi/2 rad (90 deg) "
        f"(got {limit!r})"
    ]
    assert parse_scenario(_one_robot(model="ackermann", params={"max_steer_rad": 1.5}))


def test_text_params_are_a_choice_with_did_you_mean():
    assert _params_problems("ackermann", {"steering_geometry": "paralel"}) == [
        "robots[0].params.steering_geometry: 'paralel' is not allowed; did you mean 'parallel'? "
        "(allowed: ackermann, parallel)"
    ]
    assert _params_problems("mecanum", {"half_lenght_m": 0.2, "wheel_radius_m": True}) == [
        "robots[0].params.wheel_radius_m: must be a number (got True)",
        "robots[0].params: unknown parameter 'half_lenght_m' for model 'mecanum'; did you mean "
        "'half_length_m'? (allowed: half_length_m, half_width_m, max_wheel_speed_rad_s, "
        "wheel_radius_m)",
    ]


def test_params_keep_what_the_file_wrote():
    """An integer stays an integer (the model and a recording see what was written); unset
    parameters take the dataclass's defaults."""
    data = _one_robot(model="ackermann", params={"wheelbase_m": 1, "half_track_m": 0.25})
    sc = parse_scenario(data)
    rc = sc.robots[0]
    assert sc.model_dump(mode="json", exclude_unset=True)["robots"][0]["params"] == {
        "wheelbase_m": 1,
        "half_track_m": 0.25,
    }
    model = build(sc).robots[0].model
    assert model.wheelbase_m == 1 and type(model.wheelbase_m) is int
    assert model.max_steer_rad == np.deg2rad(35.0) and rc.params.steering_geometry == "ackermann"


def test_a_robot_without_a_known_model_is_still_checked_field_by_field():
    data = _one_robot(model="omni4", body={"lenght_m": 1.0})
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data)
    assert info.value.problems == [
        "robots[0].model: 'omni4' is not allowed; did you mean 'omni3'? (allowed: differential, "
        "tricycle, ackermann, mecanum, omni3)",
        "robots[0].body.lenght_m: unknown key 'lenght_m'; did you mean 'length_m'? (allowed: "
        "length_m, offset_x_m, width_m)",
    ]
