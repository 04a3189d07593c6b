"""The browser app's logic without a browser: the session behind the panel."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from agvsim.app.mask import MaskError, controller_types, mask_fields, robot_from_mask
from agvsim.app.session import EditError, Session
from agvsim.scenario import ScenarioError, parse_scenario

ROOM = "\n".join(["#########"] + ["#.......#"] * 7 + ["#########"])


def scenario(**robot) -> dict:
    r = {
        "name": "agv",
        "model": "differential",
        "mode": "forward",
        "pose": {"x_m": -2.0, "y_m": 0.0, "theta_deg": 0.0},
        "sensors": [{"type": "lidar", "beams": 8, "range_max_m": 10.0, "rate_hz": 50}],
        "controller": {"type": "script", "steps": [{"duration_s": 100, "wheels": [5.0, 5.0]}]},
    }
    r.update(robot)
    return {"name": "room", "world": {"picture": ROOM}, "robots": [r]}


def session(**robot) -> Session:
    return Session(parse_scenario(scenario(**robot)), "test")


def forward_range(s: Session) -> float:
    """The lidar beam pointing straight ahead (beam 4 of 8 spans -180..135 deg: 0 deg)."""
    s.step(1)
    return float(s.sim.state.scans[0, 4])


def test_wheel_radius_in_the_mask_changes_the_motion():
    s = session()
    s.step(50)  # 1 s at 5 rad/s
    d1 = s.sim.state.poses[0, 0] - (-2.0)
    assert d1 == pytest.approx(5.0 * 0.1 * 1.0, abs=1e-9)
    values = {f.key: f.value for f in mask_fields(s.robot_config("agv"))}
    values["params.wheel_radius_m"] = 0.05
    s.apply_robot("agv", robot_from_mask(s.robot_config("agv"), values))
    assert s.robot_config("agv")["params"]["wheel_radius_m"] == 0.05
    x0 = s.sim.state.poses[0, 0]
    assert x0 == -2.0  # rebuilt at its initial pose
    s.step(50)
    assert s.sim.state.poses[0, 0] - x0 == pytest.approx(5.0 * 0.05 * 1.0, abs=1e-9)


def test_an_invalid_value_is_refused_with_the_validation_message_and_nothing_changes():
    s = session()
    before = s.robot_config("agv")
    values = {f.key: f.value for f in mask_fields(before)}
    values["body.length_m"] = -1.0
    with pytest.raises(ScenarioError) as err:
        s.apply_robot("agv", robot_from_mask(before, values))
    assert any("body.length_m" in p and "greater than 0" in p for p in err.value.problems)
    assert s.robot_config("agv") == before
    values = {f.key: f.value for f in mask_fields(before)}
    values["pose.x_m"] = -4.0  # inside the west wall
    with pytest.raises(ScenarioError, match="overlaps a wall"):
        s.apply_robot("agv", robot_from_mask(before, values))
    values["controller.settings"] = "steps: [oops"
    with pytest.raises(MaskError, match="not valid YAML"):
        robot_from_mask(before, values)


def test_changing_the_model_gives_its_own_parameters():
    s = session()
    values = {f.key: f.value for f in mask_fields(s.robot_config("agv"))}
    values["model"] = "mecanum"
    draft = robot_from_mask(s.robot_config("agv"), values)
    keys = [f.key for f in mask_fields(draft)]
    assert "params.half_length_m" in keys and "params.half_track_m" not in keys
    values = {f.key: f.value for f in mask_fields(draft)}
    values["controller.type"] = "avoid"
    values["controller.settings"] = "sensor: lidar"
    values["mode"] = "inverse"
    s.apply_robot("agv", robot_from_mask(draft, values))
    assert type(s.sim.robots[0].model).__name__.lower().startswith("mecanum")
    s.step(100)
    assert s.sim.state.distance_m[0] > 0.5


def test_the_mask_reads_defaults_and_labels_from_the_schema():
    robot = {"name": "car", "model": "ackermann", "sensors": [{"type": "rangers"}]}
    fields = {f.key: f for f in mask_fields(robot, dt_s=0.05)}
    geometry = fields["params.steering_geometry"]
    assert (geometry.kind, geometry.value, geometry.options) == (
        "dropdown",
        "ackermann",
        ("ackermann", "parallel"),
    )
    steer = fields["params.max_steer_rad"]
    assert (steer.label, steer.value) == ("max steer (rad)", float(np.deg2rad(35.0)))
    assert steer.hint == "steering angle limit"
    # the rangers tick every step of the scenario (1 / dt_s), the lidar at 10 Hz
    assert fields["sensors.rangers.rate_hz"].value == pytest.approx(20.0)
    assert fields["sensors.lidar.rate_hz"].value == 10.0
    assert fields["sensors.lidar.fov_deg"].label == "lidar field of view (deg)"
    assert fields["sensors.lidar.beams"].kind == "int"
    # shown defaults stay unset in the entry when the panel hands them back unchanged
    values = {k: f.value for k, f in fields.items()}
    assert robot_from_mask(robot, values, dt_s=0.05)["sensors"] == [{"type": "rangers"}]
    values["sensors.rangers.rate_hz"] = 50.0  # not the default at dt_s = 0.05: written
    assert robot_from_mask(robot, values, dt_s=0.05)["sensors"] == [
        {"type": "rangers", "rate_hz": 50.0}
    ]


def test_a_camera_set_in_the_mask_is_built_and_removed():
    s = session(controller={"type": "idle"})
    fields = {f.key: f for f in mask_fields(s.robot_config("agv"))}
    assert fields["sensors.camera"].value is False
    assert fields["sensors.camera.mount_z_m"].value == pytest.approx(0.4)  # derived default
    values = {k: f.value for k, f in fields.items()}
    values.update(
        {
            "sensors.camera": True,
            "sensors.camera.width_px": 64.0,  # a number widget may hand back a float
            "sensors.camera.height_px": 48,
            "sensors.camera.hfov_deg": 90.0,
            "sensors.camera.pitch_deg": 10.0,
        }
    )
    s.apply_robot("agv", robot_from_mask(s.robot_config("agv"), values))
    (cam,) = [c for c in s.robot_config("agv")["sensors"] if c["type"] == "camera"]
    assert cam == {
        "type": "camera",
        "width_px": 64,
        "height_px": 48,
        "hfov_deg": 90.0,
        "pitch_deg": 10.0,
    }  # the keys left at their defaults stay unset, as in a hand-written file
    (spec,) = s.sim.robots[0].cameras
    assert (spec.width_px, spec.height_px) == (64, 48)
    assert spec.hfov_rad == pytest.approx(np.pi / 2)
    assert spec.pitch_rad == pytest.approx(np.deg2rad(10.0))
    assert spec.mount_z_m == pytest.approx(0.4)
    s.step(1)
    (frame,) = s.sim.camera_frames()
    assert frame.rgb.shape == (48, 64, 3)
    assert s.sim.robots[0].sensors[0].name == "lidar"  # the lidar is kept
    # the panel shows what was applied; switching the camera off removes it
    values = {f.key: f.value for f in mask_fields(s.robot_config("agv"))}
    assert values["sensors.camera.width_px"] == 64
    values["sensors.camera"] = False
    s.apply_robot("agv", robot_from_mask(s.robot_config("agv"), values))
    assert [c["type"] for c in s.robot_config("agv")["sensors"]] == ["lidar"]
    assert s.sim.robots[0].cameras == ()
    assert s.sim.camera_frames() == []


def test_a_bad_camera_value_is_refused_with_the_field_named():
    s = session()
    before = s.robot_config("agv")
    values = {f.key: f.value for f in mask_fields(before)}
    values["sensors.camera"] = True
    values["sensors.camera.width_px"] = 0
    with pytest.raises(ScenarioError) as err:
        s.apply_robot("agv", robot_from_mask(before, values))
    assert any("width_px" in p and "greater than or equal to 8" in p for p in err.value.problems)
    values["sensors.camera.width_px"] = 320
    values["sensors.camera.mount_z_m"] = 1.5  # above the 1 m walls
    with pytest.raises(ScenarioError, match="mount_z_m"):
        s.apply_robot("agv", robot_from_mask(before, values))
    assert s.robot_config("agv") == before
    assert s.sim.cameras is None


def test_a_second_camera_the_mask_does_not_show_is_kept():
    two = [
        {"type": "camera", "name": "front", "width_px": 32, "height_px": 24},
        {"type": "camera", "name": "rear", "mount_yaw_deg": 180.0},
    ]
    s = session(sensors=two)
    values = {f.key: f.value for f in mask_fields(s.robot_config("agv"))}
    assert values["sensors.camera.width_px"] == 32
    values["sensors.camera.hfov_deg"] = 80.0
    s.apply_robot("agv", robot_from_mask(s.robot_config("agv"), values))
    specs = {c.name: c for c in s.sim.robots[0].cameras}
    assert specs["front"].hfov_rad == pytest.approx(np.deg2rad(80.0))
    assert specs["rear"].hfov_rad == pytest.approx(np.deg2rad(60.0))


def test_other_robots_keep_their_live_state_when_one_is_rebuilt():
    s = session()
    name = s.add_robot("tricycle", 1.5, 2.0, 0.0)
    assert s.robot_names() == ["agv", name]
    s.step(100)
    pose_agv = s.sim.state.poses[0].copy()
    t = s.sim.state.t_s
    cfg = s.robot_config(name)
    cfg["body"] = {"length_m": 0.5, "width_m": 0.4}
    s.apply_robot(name, cfg)
    np.testing.assert_array_equal(s.sim.state.poses[0], pose_agv)
    assert s.sim.state.t_s == t
    s.remove_robot(name)
    assert s.robot_names() == ["agv"]
    with pytest.raises(EditError, match="at least one robot"):
        s.remove_robot("agv")


def test_a_wall_toggled_in_the_maze_is_seen_by_the_lidar():
    s = session(controller={"type": "idle"})
    free = forward_range(s)
    assert free == pytest.approx(5.5, abs=1e-6)  # x = -2 to the east wall at +3.5
    row, col = s.cell_at(0.0, 0.0)
    assert s.toggle_cell(row, col) is True
    assert forward_range(s) == pytest.approx(1.5, abs=1e-6)  # the new cell's west face at -0.5
    assert "#" == s.config["world"]["picture"].splitlines()[row][col]
    assert s.toggle_cell(row, col) is False
    assert forward_range(s) == pytest.approx(5.5, abs=1e-6)
    r, c = s.cell_at(-2.0, 0.0)
    with pytest.raises(EditError, match="under robot 'agv'"):
        s.toggle_cell(r, c)
    with pytest.raises(EditError, match="outside"):
        s.toggle_cell(99, 0)


def test_run_controls_pace_the_simulation_by_the_clock_given():
    s = session(controller={"type": "idle"})
    assert s.advance(1.0) == 0  # paused
    s.play()
    assert s.advance(0.1, max_work_s=1e9) == 5  # real time, dt 0.02
    s.set_speed("x10")
    assert s.advance(0.1, max_work_s=1e9) == 50
    s.pause()
    s.step(3)
    assert s.sim.state.step == 58
    s.reset()
    assert s.sim.state.step == 0 and s.sim.state.t_s == 0.0
    with pytest.raises(EditError, match="unknown speed"):
        s.set_speed("x3")


def test_keyboard_drives_the_robot_through_its_kinematics():
    s = session(mode="inverse")
    s.set_keyboard("agv")
    assert s.config["robots"][0]["controller"]["type"] == "teleop"
    for _ in range(3):
        s.key("ArrowUp")
    assert s.key("w") == pytest.approx((0.4, 0.0, 0.0))
    s.step(50)
    assert s.sim.state.twists[0, 0] == pytest.approx(0.4)
    assert s.key("space") == (0.0, 0.0, 0.0)
    s.step(5)
    assert s.sim.state.twists[0, 0] == 0.0
    s.key("a")
    s.step(5)
    assert s.sim.state.twists[0, 2] == pytest.approx(0.25)
    s.set_keyboard(None)  # the script comes back
    assert s.config["robots"][0]["controller"]["type"] == "script"
    with pytest.raises(EditError, match="unknown key"):
        s.key("F5")


def test_keyboard_in_forward_mode_commands_wheel_speeds():
    s = session(mode="forward")
    s.set_keyboard("agv")
    s.key("up")
    s.step(10)
    # 0.1 m/s on 0.1 m wheels: both wheels at 1 rad/s
    np.testing.assert_allclose(s.sim.state.wheel_speeds[0, :2], [1.0, 1.0], atol=1e-12)


def test_scenario_yaml_round_trip_keeps_edits():
    s = session()
    s.toggle_cell(*s.cell_at(1.0, 1.0))
    text = s.scenario_yaml()
    data = yaml.safe_load(text)
    assert data["world"]["picture"].splitlines()[s.cell_at(1.0, 1.0)[0]].count("#") == 3
    other = session()
    other.load_yaml(text)
    np.testing.assert_array_equal(other.sim.world.grid.occupied, s.sim.world.grid.occupied)
    with pytest.raises(ScenarioError, match="robots"):
        other.load_yaml("name: x\nworld: {maze: thesis_c1}\nrobots: []\n")


def test_scenarios_from_the_browser_cannot_load_python_code(tmp_path):
    (tmp_path / "ok.py").write_text("def controller(obs):\n    return None\n")
    sc = parse_scenario(scenario(controller={"type": "python", "file": "ok.py"}))
    sc._base_dir = tmp_path
    s = Session(sc, "test")
    bad = scenario(controller={"type": "python", "file": "evil.py"})
    with pytest.raises(ScenarioError, match="python controllers cannot come from the browser"):
        s.load_yaml(yaml.safe_dump(bad))
    # the mask cannot point the trusted robot at another file either
    robot = s.robot_config("agv")
    robot["controller"] = {"type": "python", "file": "evil.py"}
    with pytest.raises(ScenarioError, match="cannot come from the browser"):
        s.apply_robot("agv", robot)
    robot["controller"] = {"type": "python", "file": "ok.py"}
    s.apply_robot("agv", robot)  # the command line's own controller stays allowed
    s.load_yaml(yaml.safe_dump(scenario()))  # after a browser upload, none is trusted
    with pytest.raises(ScenarioError, match="cannot come from the browser"):
        s.apply_robot("agv", robot)
    assert "python" not in controller_types(allow_python=False)


def test_random_maze_and_map_files():
    s = session()
    s.random_maze(3, 4, seed=2)
    g = s.sim.world.grid
    assert g.occupied.shape == (3 * 3 + 1, 4 * 3 + 1)
    fp = s.sim.footprints(s.sim.state.poses)
    assert not s.sim.collider.hit_walls(fp).any()  # robots moved onto free floor
    for fmt in ("txt", "csv", "png"):
        name, data = s.save_grid(fmt)
        other = session()
        other.load_grid(name, data)
        np.testing.assert_array_equal(other.sim.world.grid.occupied, g.occupied)
    with pytest.raises(EditError, match="bad.csv"):
        s.load_grid("bad.csv", b"0,1\n1,2,3\n")
    with pytest.raises(EditError, match=r"\.txt, \.csv"):
        s.load_grid("maze.exe", b"")


def test_a_failing_controller_pauses_the_app_with_its_message(tmp_path):
    (tmp_path / "bad.py").write_text("def controller(obs):\n    raise RuntimeError('boom')\n")
    sc = parse_scenario(scenario(controller={"type": "python", "file": "bad.py"}))
    sc._base_dir = tmp_path
    s = Session(sc, "test")
    s.play()
    s.advance(0.1)
    assert not s.playing and "boom" in s.error and "agv" in s.error
