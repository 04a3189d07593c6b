"""The safety scanner in a run (robot ``safety:`` blocks, agvsim.sim.safety, issue 18.1):
field sets switched at their speed thresholds, a box ahead stopping every model before
contact from every speed up to its top speed, warning fields slowing, clearing resuming,
and the scenario's checks of the fields' lengths."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from agvsim.scenario import ScenarioError, build, parse_scenario
from agvsim.scenario_guidance import top_speed_m_s
from agvsim.sensors.safety_fields import CLEAR, PROTECTIVE, WARNING

DT = 0.02
RESPONSE_S, DECEL = 0.1, 1.0
# every model limited to a top speed near 1 m/s (omni3: 0.9988 m/s), so that one field
# geometry fits them all
PARAMS = {
    "differential": {"max_wheel_speed_rad_s": 10.0},
    "tricycle": {"max_wheel_speed_rad_s": 10.0},
    "ackermann": {"max_wheel_speed_rad_s": 10.0},
    "mecanum": {"max_wheel_speed_rad_s": 20.0},
    "omni3": {"max_wheel_speed_rad_s": 17.3},
}
CAR = ("tricycle", "ackermann")


def box(x0: float, x1: float, y: float) -> list[list[float]]:
    return [[x0, -y], [x1, -y], [x1, y], [x0, y]]


def fields(front_m: float, rear_m: float, warning: bool = True) -> list[dict]:
    """Field sets for a body reaching ``front_m`` ahead of and ``rear_m`` behind P: 'slow'
    below 0.5 m/s, 'fast' from 0.5 m/s, 'reverse' below -0.05 m/s; each long enough for a
    1 m/s top speed with the scan every step (0.02 s)."""
    d_top = 1.0 * (RESPONSE_S + DT) + 1.0 / (2 * DECEL)  # 0.62 m
    warn = {"warning": box(-rear_m - 0.1, front_m + 2.0, 0.45)} if warning else {}
    return [
        {
            "name": "reverse",
            "speed_max_m_s": -0.05,
            "protective": box(-rear_m - d_top - 0.05, front_m, 0.3),
        },
        {
            "name": "slow",
            "speed_min_m_s": -0.05,
            "speed_max_m_s": 0.5,
            "protective": box(-rear_m - 0.1, front_m + 0.3, 0.3),
            **warn,
        },
        {
            "name": "fast",
            "speed_min_m_s": 0.5,
            "protective": box(-rear_m - 0.1, front_m + d_top + 0.05, 0.3),
            **warn,
        },
    ]


def body(model: str) -> tuple[float, float, float]:
    """(length, front of P, rear of P): car-like bodies sit wheelbase/2 = 0.25 m ahead."""
    length = 0.8 if model in CAR else 0.6
    off = 0.25 if model in CAR else 0.0
    return length, off + length / 2, length / 2 - off


def scenario(
    model: str,
    steps: list[dict],
    box_at_m: float | None = 4.0,
    warning: bool = True,
    mode: str = "inverse",
    extra: dict | None = None,
    safety: dict | None = None,
) -> dict:
    """One robot of ``model`` at the origin heading east, a 1.2 m wide box whose near face is
    ``box_at_m`` ahead of the robot's front."""
    length, front, rear = body(model)
    robot = {
        "name": "agv",
        "model": model,
        "mode": mode,
        "params": PARAMS[model],
        "body": {"length_m": length, "width_m": 0.5},
        "pose": {"x_m": -8.0, "y_m": 0.0},
        "odometry": {"wheel_noise_rel": 0.0},
        "sensors": [{"type": "lidar", "beams": 720, "fov_deg": 360, "rate_hz": 1 / DT}],
        "controller": {"type": "script", "steps": steps},
        "safety": safety
        or {
            "sensor": "lidar",
            "response_time_s": RESPONSE_S,
            "decel_m_s2": DECEL,
            "warning_speed_m_s": 0.3,
            "field_sets": fields(front, rear, warning),
        },
        **(extra or {}),
    }
    world: dict = {"matrix": [[0] * 24 for _ in range(24)]}
    if box_at_m is not None:
        world["boxes"] = [
            {"x_m": -8.0 + front + box_at_m + 0.3, "y_m": 0.0, "length_m": 0.6, "width_m": 1.2}
        ]
    return {"name": "safety", "seed": 0, "dt_s": DT, "world": world, "robots": [robot]}


def sim_of(data: dict):
    return build(parse_scenario(copy.deepcopy(data)))


def gap_m(sim) -> float:
    """Free floor between the robot's front and the box's near face."""
    _, front, _ = body(sim.robots[0].model.kind)
    face = sim.world.boxes[0, 0] - sim.world.boxes[0, 3]
    return float(face - (sim.state.poses[0, 0] + front))


def test_the_active_field_set_switches_exactly_at_the_speed_threshold():
    # 0.4 m/s, then exactly 0.5 (0.5 / 0.1 = 5 rad/s and back: the executed speed is 0.5 to
    # the bit), then 0.4 again: 'slow' below 0.5, 'fast' from 0.5 on
    steps = [{"duration_s": 0.2, "twist": [v, 0.0]} for v in (0.4, 0.5, 0.5, 0.4)]
    sim = sim_of(scenario("differential", steps, box_at_m=None, warning=False))
    names = [f.name for f in sim.robots[0].safety.field_sets]
    speeds, active = [], []
    for _ in range(40):
        sim.step()
        speeds.append(float(sim.state.twists[0, 0]))
        active.append(names[int(sim.state.safety_set[0])])
    up, down = speeds.index(0.5), speeds.index(0.4, speeds.index(0.5))
    assert speeds[up - 1] == 0.4 and speeds[up] == 0.5  # exactly the threshold
    assert set(active[:up]) == {"slow"}
    # on the way up the faster commanded speed selects 'fast' in the step it is driven; on
    # the way down 'fast' stays for the step of the change (the speed driven before was 0.5)
    assert set(active[up : down + 1]) == {"fast"}
    assert set(active[down + 1 :]) == {"slow"}


def test_steering_selects_the_field_set_of_a_car_like_model():
    length, front, rear = body("ackermann")
    sets = [{**f, "steer_max_deg": -5.0, "name": f["name"] + "_right"} for f in fields(front, rear)]
    sets += [{**f, "steer_min_deg": -5.0, "steer_max_deg": 5.0} for f in fields(front, rear)]
    sets += [{**f, "steer_min_deg": 5.0, "name": f["name"] + "_left"} for f in fields(front, rear)]
    safety = {"sensor": "lidar", "response_time_s": RESPONSE_S, "field_sets": sets}
    # 0.4 m/s with omega 0.4 rad/s: delta = atan(0.5 x 0.4 / 0.4) = 26.6 deg, to the left
    steps = [{"duration_s": 0.5, "twist": [0.4, 0.0]}, {"duration_s": 0.5, "twist": [0.4, 0.4]}]
    sim = sim_of(scenario("ackermann", steps, box_at_m=None, safety=safety))
    names = [f.name for f in sim.robots[0].safety.field_sets]
    got = []
    for _ in range(50):
        sim.step()
        got.append(names[int(sim.state.safety_set[0])])
    assert got[5] == "slow" and got[-1] == "slow_left"
    assert math.degrees(sim.state.steering[0]) == pytest.approx(math.degrees(math.atan(0.5)))


SPEEDS = (0.25, 0.5, 0.75, 1.0)  # fractions of the top speed


@pytest.mark.parametrize("model", list(PARAMS))
def test_a_box_ahead_stops_every_model_before_contact_from_every_speed(model):
    for frac in SPEEDS:
        mode = "forward" if model == "tricycle" else "inverse"
        data = scenario(model, [{"duration_s": 10.0, "twist": [1.0, 0.0]}], 3.0, warning=False)
        sim0 = sim_of(data)
        top = top_speed_m_s(sim0.robots[0].model)
        v = frac * top
        if mode == "forward":  # the tricycle's driven front wheel, in rad/s, straight
            step = {"duration_s": 30.0, "wheels": [v / 0.1], "steering_deg": 0.0}
        else:
            step = {"duration_s": 30.0, "twist": [v, 0.0, 0.0]}
        data = scenario(model, [step], 3.0, warning=False, mode=mode)
        sim = sim_of(data)
        x_hit = t_hit = x_stop = None
        for _ in range(int((3.0 / v + 2.0) / DT)):
            sim.step()
            st = sim.state
            if x_hit is None and st.safety_status[0] == PROTECTIVE:
                x_hit, t_hit = float(st.poses[0, 0]), st.t_s
                v_hit = float(st.twists[0, 0])
            if x_hit is not None and x_stop is None and st.twists[0, 0] == 0.0:
                x_stop = float(st.poses[0, 0])
        st = sim.state
        assert x_hit is not None, f"{model} at {v:.2f} m/s: no protective violation"
        assert v_hit == pytest.approx(v, rel=1e-9)  # it met the field at full speed
        assert st.collisions[0] == 0 and gap_m(sim) > 0.0, f"{model} at {v:.2f} m/s hit"
        assert abs(st.twists[0]).max() == 0.0  # it stands
        # it stopped within the stopping distance from where the violation was seen
        # (response at full speed, then decel x dt off each step: no more than v t + v^2/2a)
        assert x_stop is not None
        assert x_stop - x_hit <= v * RESPONSE_S + v * v / (2 * DECEL) + 1e-9
        assert st.safety_events[0, 1] >= 1
        assert st.safety_first_s[0, 1] == pytest.approx(t_hit - DT)


def test_a_robot_with_dynamics_stops_before_the_box_braking_on_friction():
    dyn = {"dynamics": {"mass_kg": 60.0, "motor": {"torque_max_nm": 3.0, "gear_ratio": 20}}}
    world_floor = {"mu": 0.05}
    length, front, rear = body("differential")
    # ask for 3 m/s^2: the floor gives less; fields sized for the friction limit
    safety = {
        "sensor": "lidar",
        "response_time_s": RESPONSE_S,
        "decel_m_s2": 3.0,
        "field_sets": fields(front, rear, warning=False),
    }
    data = scenario(
        "differential", [{"duration_s": 10, "twist": [1.0, 0.0]}], 4.0, extra=dyn, safety=safety
    )
    data["world"]["floor"] = world_floor
    with pytest.raises(ScenarioError) as err:
        sim_of(data)
    msg = str(err.value)
    assert "robots[0] (agv).safety.field_sets[2]: the protective field reaches" in msg
    assert "decel_m_s2 3 is not reachable: the robot's dynamics brake at most" in msg
    # the limit the message names, and fields long enough for it
    a = float(msg.split("brake at most ")[1].split(" m/s^2")[0])
    assert 0.1 < a < 0.05 * 9.81
    d = 1.0 * (RESPONSE_S + DT) + 1.0 / (2 * a)
    for f in safety["field_sets"]:
        if f["name"] == "fast":
            f["protective"] = box(-rear - 0.1, front + d + 0.05, 0.3)
        if f["name"] == "reverse":
            f["protective"] = box(-rear - d - 0.05, front, 0.3)
        if f["name"] == "slow":
            f["protective"] = box(-rear - 0.1, front + 0.5, 0.3)
    data["world"]["boxes"][0]["x_m"] = -8.0 + front + 4.0 + d + 0.3
    sim = sim_of(data)
    for _ in range(int(10.0 / DT)):
        sim.step()
    assert sim.state.safety_events[0, 1] >= 1
    assert sim.state.collisions[0] == 0 and gap_m(sim) > 0.0
    assert abs(sim.state.twists[0, 0]) < 1e-3


def test_a_warning_slows_to_the_warning_speed_and_clearing_the_field_resumes():
    steps = [{"duration_s": 30.0, "twist": [0.8, 0.0]}]
    sim = sim_of(scenario("differential", steps, box_at_m=3.5))
    status, speed = [], []
    for _ in range(int(8.0 / DT)):
        sim.step()
        status.append(int(sim.state.safety_status[0]))
        speed.append(float(sim.state.twists[0, 0]))
    k = status.index(WARNING)
    assert speed[k - 1] == 0.8 and speed[k] == pytest.approx(0.3, abs=1e-12)
    assert status[-1] == PROTECTIVE and speed[-1] == 0.0  # then the protective field stops it
    assert sim.state.collisions[0] == 0 and gap_m(sim) > 0.0
    # the box is taken away: the field clears with the next scan and the robot drives on
    sim.set_boxes(np.zeros((0, 5)))
    for _ in range(3):
        sim.step()
    assert sim.state.safety_status[0] == CLEAR
    assert sim.state.twists[0, 0] == pytest.approx(0.8, abs=1e-12)
    assert sim.state.safety_events[0].tolist() == [1, 1]


def test_a_safety_block_names_a_range_sensor_of_its_robot_and_long_enough_fields():
    data = scenario("differential", [{"duration_s": 1, "twist": [0.5, 0.0]}])
    data["robots"][0]["safety"]["sensor"] = "front"
    with pytest.raises(ScenarioError, match=r"robots\[0\] \(agv\).safety.sensor: 'front' is not"):
        sim_of(data)
    data = scenario("differential", [{"duration_s": 1, "twist": [0.5, 0.0]}])
    data["robots"][0]["safety"]["field_sets"][2]["protective"] = box(-0.4, 0.8, 0.3)
    with pytest.raises(ScenarioError) as err:
        sim_of(data)
    # top speed 1 m/s: 0.3 m body + 1 x (0.1 + 0.02) s + 1 / (2 x 1) = 0.92 m needed
    assert (
        "robots[0] (agv).safety.field_sets[2]: the protective field reaches 0.800 m ahead but "
        "at 1.000 m/s the vehicle needs 0.920 m"
    ) in str(err.value)
    data["robots"][0]["safety"]["check_lengths"] = False
    sim_of(data)  # accepted when asked


def test_runs_without_a_safety_block_have_no_safety_stage():
    data = scenario("differential", [{"duration_s": 1, "twist": [0.5, 0.0]}])
    del data["robots"][0]["safety"]
    sim = sim_of(data)
    assert sim.safety is None
    sim.run(0.2)
    assert sim.state.safety_set.tolist() == [-1] and sim.state.safety_status.tolist() == [0]


def test_run_outputs_carry_the_safety_status_events_and_field_markers(tmp_path):
    import csv
    import json

    import mcap_ros2.decoder
    from mcap.reader import make_reader

    from agvsim.record.mcap_writer import Recorder
    from agvsim.record.outputs import TrajectoryWriter, summary
    from agvsim.sim.safety import STATUS_RGB

    steps = [{"duration_s": 30.0, "twist": [0.8, 0.0]}]
    sim = sim_of(scenario("differential", steps, box_at_m=3.5))
    traj = TrajectoryWriter(tmp_path / "trajectory.csv", sim)
    rec = Recorder(tmp_path / "run.mcap", sim)
    statuses = []
    for _ in range(int(8.0 / DT)):
        sim.step()
        traj.record()
        rec.record()
        statuses.append(int(sim.state.safety_status[0]))
    traj.close()
    rec.close()
    rows = list(csv.DictReader((tmp_path / "trajectory.csv").open()))
    assert [r["safety"] for r in rows] == [("clear", "warning", "protective")[s] for s in statuses]
    data = json.loads(json.dumps(summary(sim, 1.0)))
    got = data["safety"]["agv"]
    k_warn, k_prot = statuses.index(WARNING), statuses.index(PROTECTIVE)
    assert got["warning"]["count"] == 1 and got["protective"]["count"] == 1
    # the status of step k is decided at its start, t = k dt
    assert got["warning"]["first_t_s"] == pytest.approx(k_warn * DT)
    assert got["protective"]["first_t_s"] == pytest.approx(k_prot * DT)
    assert got["protective"]["last_t_s"] == pytest.approx((len(statuses) - 1) * DT)
    markers, texts = [], []
    with (tmp_path / "run.mcap").open("rb") as f:
        reader = make_reader(f, decoder_factories=[mcap_ros2.decoder.DecoderFactory()])
        for _, ch, _, m in reader.iter_decoded_messages():
            if ch.topic == "/agv/safety_fields":
                markers.append(m)
            elif ch.topic == "/agv/safety_status":
                texts.append(m.data)
    # written at t = 0 and at each change of the set or the status
    assert texts[-1] == "protective" and "warning" in texts and texts[0] == "clear"
    last = markers[-1].markers
    assert [m.ns for m in last] == ["agv/protective", "agv/warning"]
    assert last[0].header.frame_id == "agv/base_link"
    assert (last[0].color.r, last[0].color.g) == pytest.approx(STATUS_RGB[PROTECTIVE][:2])
    spec = sim.robots[0].safety
    poly = spec.field_sets[int(sim.state.safety_set[0])].protective
    assert [(p.x, p.y) for p in last[0].points] == [*poly, poly[0]]


def test_the_shipped_scenario_stops_every_agv_and_lets_the_blocked_one_drive_on():
    from pathlib import Path

    from agvsim.scenario import load_scenario

    path = Path(__file__).resolve().parents[1] / "scenarios" / "safety_fields.yaml"
    sim = build(load_scenario(path))
    k = sim.robot_index("differential")
    resumed = False
    while sim.state.t_s < 36.0 - 1e-9:
        sim.step()
        st = sim.state
        # stopped for the cart (its first protective stop), then back at its 0.8 m/s
        resumed |= bool(st.safety_events[k, 1] == 1 and st.twists[k, 0] == 0.8)
    st = sim.state
    scanners = [i for i, r in enumerate(sim.robots) if r.safety is not None]
    assert len(scanners) == 5 and st.collisions.sum() == 0
    assert (st.safety_events[scanners, 1] >= 1).all()  # every AGV had a protective stop
    assert (st.safety_events[scanners, 0] >= 1).all()  # after a warning
    assert np.abs(st.twists[scanners, 0]).max() == 0.0  # and stands before its box
    assert resumed and st.safety_events[k, 1] == 2


def test_batched_scan_points_match_the_one_scan_function():
    from agvsim.sensors.safety_fields import scan_points_robot_frame
    from agvsim.sim.safety import robot_frame_points

    rng = np.random.default_rng(0)
    r = rng.uniform(0, 5, (3, 10))
    r[0, 1], r[1, 2], r[2, 3] = np.inf, -np.inf, np.nan  # no return, too close, dropped
    ang = np.linspace(-3, 3, 10)[None].repeat(3, 0)
    ang[2, 8:] = np.nan  # a sensor with 8 beams in a table 10 wide
    mount = np.array([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0], [-0.2, 0.1, -1.0]])
    a = ang + mount[:, 2:3]
    pts, valid = robot_frame_points(r, np.stack([np.cos(a), np.sin(a)], -1), mount[:, :2].copy())
    for k, n in enumerate((10, 10, 8)):
        one, ok = scan_points_robot_frame(r[k, :n], ang[k, :n], tuple(mount[k, :2]), mount[k, 2])
        assert ok.tolist() == valid[k, :n].tolist() and not valid[k, n:].any()
        np.testing.assert_allclose(pts[k, :n][ok], one[ok], atol=1e-12)
    assert valid[1, 2] and pts[1, 2].tolist() == [0.0, 0.0]  # -inf: a return at the sensor
