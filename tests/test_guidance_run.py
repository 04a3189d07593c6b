"""Industrial guidance in real runs (docs/guidance.md): line following on tape for every model,
floor-code fixes against odometry drift, reflector localisation and its blind spot, the lidar
intensity channel, and the scenario blocks' errors."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from agvsim.runner import run_scenario
from agvsim.scenario import ScenarioError, build, parse_scenario
from agvsim.scenario_limits import Limits
from agvsim.sensors.reflectors import REFLECTOR_INTENSITY, detect
from agvsim.sim.engine import Simulation

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"

MODELS = {
    "differential": {"wheel_radius_m": 0.1, "half_track_m": 0.25},
    "tricycle": {"wheel_radius_m": 0.1, "wheelbase_m": 0.5, "half_track_m": 0.2},
    "ackermann": {"wheel_radius_m": 0.1, "wheelbase_m": 0.5, "half_track_m": 0.2},
    "mecanum": {"wheel_radius_m": 0.05, "half_length_m": 0.2, "half_width_m": 0.2},
    "omni3": {"wheel_radius_m": 0.05, "base_radius_m": 0.2},
}


def _data(stem: str) -> dict:
    return yaml.safe_load((SCENARIOS / f"{stem}.yaml").read_text(encoding="utf-8"))


def _sim(data: dict) -> Simulation:
    return build(parse_scenario(data, "test", Limits()))


def _route_run(stem: str, steps: int = 3000) -> tuple[Simulation, list[np.ndarray]]:
    """Run a route scenario; the (t, true x, true y, error) of every step."""
    sim = _sim(_data(stem))
    ctrl = sim.bindings[0].controller
    rows = []
    for _ in range(steps):
        sim.step()
        p = sim.state.poses[0]
        rows.append(np.array([sim.state.t_s, p[0], p[1], ctrl.pose_error_m]))
    return sim, rows


@pytest.mark.parametrize("model", sorted(MODELS))
def test_the_line_follower_keeps_the_tape_through_the_curves_for_every_model(model):
    data = _data("guidance_tape")
    robot = data["robots"][0]
    robot.update(model=model, params=MODELS[model], body={"length_m": 0.5, "width_m": 0.4})
    sim = _sim(data)
    tape = sim.world.tape
    mount = sim.robots[0].line_sensors[0].mount_x_m
    worst, turned = 0.0, 0.0
    for _ in range(2000):  # 40 s at 0.5 m/s: the south side, two curves, the east side
        sim.step()
        p = sim.state.poses[0]
        bar = p[:2] + mount * np.array([math.cos(p[2]), math.sin(p[2])])
        worst = max(worst, float(tape.distance_m(bar)))
        assert np.isfinite(sim.state.line_offsets[0, 0]), f"line lost at t={sim.state.t_s}"
        turned += sim.state.twists[0, 2] * sim.dt_s
    # the bar's middle never left the tape's centre line by more than half the tape width
    # plus a 15 mm margin (the bar is 160 mm wide: the line is far from its ends)
    assert worst < 0.025 + 0.015
    assert turned > math.radians(150)  # through two quarter circles of 1 m radius
    assert sim.state.distance_m[0] > 17.0
    assert sim.active_states() == ["follow"]


def test_a_spot_before_a_fork_picks_the_branch():
    """A Y fork south of the racks: straight on along y = -3.5, or off to the left up a
    45 deg branch from x = 2. The follower's junction list says ``right`` (straight on here);
    a spot (code 7) at x = 1 asks for ``left`` and wins."""
    data = _data("guidance_tape")
    data["world"]["tape"] = {
        "lines": [
            {"points": [[-6, -3.5], [6, -3.5]]},
            {"points": [[2, -3.5], [4, -1.5]]},
        ],
        "spots": [{"x_m": 1.0, "y_m": -3.5, "code": 7}],
    }
    robot = data["robots"][0]
    robot["pose"] = {"x_m": -1.0, "y_m": -3.5, "theta_deg": 0}
    ends = {}
    for choices in ({7: "left"}, {}):
        robot["controller"] = {
            "type": "line_follow",
            "speed_m_s": 0.4,
            "junctions": ["right"],
            "spot_choices": choices,
        }
        sim = _sim(data)
        sim.run(12.0)
        ends[bool(choices)] = sim.state.poses[0].copy()
        report = sim.bindings[0].controller.report()
        assert report["spots_seen"] == [7]
        assert report["junctions_taken"] == ["left" if choices else "right"]
    # with the spot's choice: up the branch (on the line y = x - 5.5), else along y = -3.5
    left, straight = ends[True], ends[False]
    assert left[1] > -3.0 and abs(left[1] - (left[0] - 5.5)) < 0.05
    assert abs(straight[1] + 3.5) < 0.02 and straight[0] > 3.0


def test_floor_code_fixes_bound_the_odometry_drift():
    sim_o, odo = _route_run("guidance_odometry")
    sim_f, codes = _route_run("guidance_floor_codes")
    e_odo = np.array([r[3] for r in odo])
    e_codes = np.array([r[3] for r in codes])
    rep = sim_f.bindings[0].controller.report()
    assert rep["route_reached"] and rep["fixes"] >= 20  # 24 codes on the route
    # between fixes the vehicle runs on odometry: the error falls back at every code
    assert e_codes.max() < 0.5 * e_odo.max()
    assert e_codes.mean() < 0.2 * e_odo.mean()
    # and the odometry alone drifts: its error grows along the route
    assert e_odo[-500:].mean() > 3 * e_odo[:250].mean()


def test_reflector_localisation_is_accurate_and_the_blind_spot_shows():
    sim, full = _route_run("guidance_reflectors")
    _, blind = _route_run("guidance_reflectors_blind_spot")
    rep = sim.bindings[0].controller.report()
    assert rep["route_reached"]
    e_full = np.array([r[3] for r in full])
    assert e_full.mean() < 0.01 and e_full.max() < 0.02  # against the ground truth
    # the blind spot: along the north side (y > 2) no reflector is in sight; the estimate
    # runs on odometry there and its error grows well beyond the full layout's
    north = np.array([r[2] > 2.0 for r in blind])
    e_blind = np.array([r[3] for r in blind])
    assert e_blind[north].max() > 3 * e_full[north].max()
    assert e_blind[north].max() > 2 * e_blind[~north].mean()


def test_intensities_are_high_exactly_on_the_reflector_beams_of_a_real_scan():
    data = _data("guidance_reflectors")
    data["robots"][0]["sensors"][0]["noise_std_m"] = 0.0
    sim = _sim(data)
    scan = sim.observation(0).scans["lidar"]
    assert scan.intensities is not None and scan.intensities.shape == scan.ranges.shape
    pose = sim.state.poses[0]
    a = pose[2] + scan.angles_rad
    hit = np.isfinite(scan.ranges)
    pts = pose[:2] + scan.ranges[:, None] * np.column_stack([np.cos(a), np.sin(a)])
    refl = sim.world.reflectors
    d = np.hypot(*(pts[:, None, :] - refl.xy[None]).transpose(2, 0, 1)).min(axis=1)
    on = hit & (d <= refl.width_m / 2)
    assert on.sum() > 10
    np.testing.assert_array_equal(scan.intensities == REFLECTOR_INTENSITY, on)
    assert (scan.intensities[~on] < REFLECTOR_INTENSITY / 2).all()
    # each run of bright beams is a reflector: where it lies, seen from the true pose
    dets = detect(scan.ranges, scan.intensities, scan.angles_rad)
    assert len(dets) >= 5
    for det in dets:
        xy = pose[:2] + det.range_m * np.array(
            [math.cos(pose[2] + det.bearing_rad), math.sin(pose[2] + det.bearing_rad)]
        )
        # the mean of returns all within half a width of the centre lies within it too
        assert np.hypot(*(refl.xy - xy).T).min() <= refl.width_m / 2


def test_a_world_without_reflectors_has_no_intensities():
    data = _data("guidance_reflectors")
    del data["world"]["reflectors"]
    data["robots"][0]["controller"] = {"type": "idle"}
    sim = _sim(data)
    assert sim.observation(0).scans["lidar"].intensities is None
    assert sim.guidance is None


def test_line_noise_repeats_bit_for_bit_with_the_seed():
    data = _data("guidance_tape")
    data["robots"][0]["sensors"][0]["noise_std_m"] = 0.005
    runs = []
    for _ in range(2):
        sim = _sim(data)
        sim.run(5.0)
        runs.append((sim.state.poses.copy(), sim.state.line_offsets.copy()))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            lambda d: d["robots"][0]["sensors"].append({"type": "floor_camera", "width_px": 4}),
            r"robots\[0\]\.sensors\[1\]\.floor_camera\.width_px: .*greater than or equal to 16 "
            r"\(got 4\)",
        ),
        (
            lambda d: d["world"].update(tape={"lines": [{"points": [[0, 0]]}]}),
            r"world\.tape\.lines\[0\]\.points",
        ),
        (
            lambda d: d["robots"][0]["controller"].update(localization="reflectors"),
            r"robots\[0\] \(agv\)\.controller\.sensor: localization reflectors needs a range "
            r"sensor 'lidar' \(the robot has \[\]\)",
        ),
        (
            lambda d: d["robots"][0]["controller"].update(localization="gps"),
            r"controller.*localization",
        ),
    ],
)
def test_bad_guidance_input_is_refused_naming_the_field(change, message):
    data = _data("guidance_floor_codes")
    change(data)
    with pytest.raises(ScenarioError, match=message):
        _sim(data)


def test_trajectory_csv_carries_the_estimate_and_its_error(tmp_path):
    data = run_scenario(
        SCENARIOS / "guidance_floor_codes.yaml",
        tmp_path,
        duration_s=6.0,
        plot=False,
        record_mcap=False,
    )
    ctrl = data["robots"][0]["controller"]
    assert ctrl["localization"] == "floor_codes" and ctrl["fixes"] >= 2
    with (tmp_path / "trajectory.csv").open(encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 301
    # the estimate is of the step's start, the row's pose of its end: one step at 0.5 m/s apart
    for r in rows[1:]:
        err = math.hypot(float(r["est_x"]) - float(r["x"]), float(r["est_y"]) - float(r["y"]))
        assert abs(float(r["est_error_m"]) - err) <= 0.5 * 0.02 + 2e-6
    assert max(float(r["est_error_m"]) for r in rows[1:]) == pytest.approx(
        ctrl["pose_error_max_m"], abs=1e-5
    )


def test_run_mcap_carries_intensities_the_estimate_and_the_line_reading(tmp_path):
    from agvsim.record.mcap_reader import Recording

    run_scenario(SCENARIOS / "guidance_reflectors.yaml", tmp_path / "r", duration_s=1.0,
                 plot=False)  # fmt: skip
    run_scenario(SCENARIOS / "guidance_tape.yaml", tmp_path / "t", duration_s=1.0, plot=False)
    rec = Recording(tmp_path / "r" / "run.mcap")
    scans = rec.messages("/agv/lidar")
    assert len(scans) == 11  # 10 Hz over 1 s, and t = 0
    for _, m in scans:
        inten = np.asarray(m.intensities)
        assert inten.shape == (1080,)
        assert (inten == REFLECTOR_INTENSITY).sum() >= 10
    est = rec.messages("/agv/localization")
    truth = rec.messages("/agv/ground_truth")
    assert len(est) == 50 and len(truth) == 51  # the estimate: from the first step on
    # the estimate of each observation's time follows the truth there within the
    # filter's accuracy
    at = {round(t, 6): m for t, m in truth}
    assert [round(t, 6) for t, _ in est] == sorted(at)[:50]
    for t, e in est:
        pe, pg = e.pose.pose.position, at[round(t, 6)].pose.pose.position
        assert math.hypot(pe.x - pg.x, pe.y - pg.y) < 0.03
    rec = Recording(tmp_path / "t" / "run.mcap")
    lines = rec.messages("/agv/line")
    assert len(lines) == 51
    # the robot starts on the tape: one run, near the bar's middle
    assert all(len(m.data) == 1 and abs(m.data[0]) < 0.02 for _, m in lines)
    assert "/agv/localization" not in rec.topics
    # every message of both files, the new topics included, decodes with the independent
    # ROS 2 decoder (mcap-ros2-support) against the ROS 2 message definition it names
    import mcap_ros2.decoder
    from mcap.reader import make_reader

    names = {}
    for run in ("r", "t"):
        with (tmp_path / run / "run.mcap").open("rb") as f:
            reader = make_reader(f, decoder_factories=[mcap_ros2.decoder.DecoderFactory()])
            names[run] = {ch.topic: sc.name for sc, ch, _, _ in reader.iter_decoded_messages()}
    assert names["r"]["/agv/lidar"] == "sensor_msgs/msg/LaserScan"
    assert names["r"]["/agv/localization"] == "nav_msgs/msg/Odometry"
    assert names["t"]["/agv/line"] == "std_msgs/msg/Float64MultiArray"


def test_the_3d_view_draws_tape_codes_and_reflectors_where_the_world_has_them():
    from agvsim.app.guidance_view import guidance_shapes

    world = _sim(_data("guidance_tape")).world
    tape = guidance_shapes(world)
    # the closed loop: 4 straights + 4 arcs of chords (within 1 mm of the arcs, so a bit
    # short of 20 + 2 pi m); its drawn length is the tape's
    d = tape.tape_segments[:, 1, :2] - tape.tape_segments[:, 0, :2]
    drawn = float(np.hypot(d[:, 0], d[:, 1]).sum())
    assert drawn == pytest.approx(world.tape.length_m, abs=1e-4)
    assert 20 + 2 * math.pi - 0.005 < drawn < 20 + 2 * math.pi
    assert tape.tape_width_m == 0.05 and len(tape.spots) == 4
    assert len(tape.code_faces) == 0 and len(tape.reflectors) == 0
    codes = guidance_shapes(_sim(_data("guidance_floor_codes")).world)
    assert len(codes.code_faces) == 2 * 140 and len(codes.code_vertices) == 4 * 140
    # the first code's square: 5 cm wide, centred on the grid's origin (-6.5, -4.5)
    sq = codes.code_vertices[:4, :2]
    np.testing.assert_allclose(sq.mean(axis=0), [-6.5, -4.5], atol=1e-12)
    np.testing.assert_allclose(np.ptp(sq, axis=0), [0.05, 0.05], atol=1e-12)
    refl = guidance_shapes(_sim(_data("guidance_reflectors_blind_spot")).world)
    assert len(refl.reflectors) == 8 and refl.reflector_width_m == 0.1


finite = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)


@given(finite, finite, angle, finite, finite, angle)
def test_the_odometry_between_fixes_carries_a_pose_exactly(ax, ay, at, bx, by, bt):
    """The floor-code estimate is fix (+) (odom_then^-1 odom_now): composing a pose with
    its relative pose to another gives the other back."""
    from agvsim.control.route_follow import compose, relative

    a, b = np.array([ax, ay, at]), np.array([bx, by, bt])
    back = compose(a, relative(a, b))
    np.testing.assert_allclose(back[:2], b[:2], atol=1e-9)
    assert abs(math.remainder(back[2] - b[2], 2 * math.pi)) < 1e-12
    # relative of a pose to itself is no motion
    np.testing.assert_allclose(relative(a, a), 0.0, atol=1e-12)
