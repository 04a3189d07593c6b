"""Dynamics in run.mcap: wheel joints (angle, speed, torque) and slip, as standard ROS 2
messages whose bytes equal rosbags' serializer and which mcap-ros2-support decodes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from agvsim.record import ros2msg as R  # noqa: E402

TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types
SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.mark.parametrize("names", [["left", "right"], ["front", "rear_left", "rear_right"], []])
def test_joint_state_and_slip_bytes_equal_rosbags(names):
    n = len(names)
    pos, vel, eff = np.arange(n) * 1.5, np.arange(n) - 0.5, np.arange(n) * -2.25
    ours = R.encode_joint_state(
        3_020_000_000, "a/base_link", names, *(v.tolist() for v in (pos, vel, eff))
    )
    ref = T["sensor_msgs/msg/JointState"](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=3, nanosec=20_000_000),
            frame_id="a/base_link",
        ),
        name=names,
        position=pos,
        velocity=vel,
        effort=eff,
    )
    assert ours == bytes(TS.serialize_cdr(ref, R.JOINT_STATE))
    slip = R.encode_float64_multi_array("wheel", vel.tolist())
    dim = T["std_msgs/msg/MultiArrayDimension"](label="wheel", size=n, stride=1)
    ref_slip = T["std_msgs/msg/Float64MultiArray"](
        layout=T["std_msgs/msg/MultiArrayLayout"](dim=[dim], data_offset=0), data=vel
    )
    assert slip == bytes(TS.serialize_cdr(ref_slip, R.FLOAT64_MULTI_ARRAY))


def test_run_mcap_carries_wheel_torque_and_slip(tmp_path):
    """The braking scenario's recording: joint_states and wheel_slip for each dynamic robot at
    the pose rate, decoded by mcap-ros2-support, equal to trajectory.csv's columns."""
    mcap_ros2 = pytest.importorskip("mcap_ros2.decoder")
    from mcap.reader import make_reader

    from agvsim.runner import run_scenario

    run_scenario(SCENARIOS / "dynamics_braking.yaml", tmp_path, 4.0, plot=False)
    got: dict[str, list] = {}
    with open(tmp_path / "run.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[mcap_ros2.DecoderFactory()])
        for _, channel, message, m in reader.iter_decoded_messages(
            topics=["/loaded_wet/joint_states", "/loaded_wet/wheel_slip"]
        ):
            got.setdefault(channel.topic, []).append((message.log_time, m))
    joints, slips = got["/loaded_wet/joint_states"], got["/loaded_wet/wheel_slip"]
    assert len(joints) == len(slips) > 100
    rows = [
        line.split(",")
        for line in (tmp_path / "trajectory.csv").read_text().splitlines()[1:]
        if ",loaded_wet," in line
    ]
    at_3s = next(r for r in rows if r[0] == "3.0200")
    t_ns, js = next((t, m) for t, m in joints if t == 3_020_000_000)
    assert list(js.name) == ["loaded_wet/left_wheel", "loaded_wet/right_wheel"]
    assert list(js.effort) == pytest.approx([float(v) for v in at_3s[18:20]], rel=1e-5)
    assert list(js.velocity) == pytest.approx([float(v) for v in at_3s[8:10]], rel=1e-5)
    assert js.effort[0] < 0  # braking
    slip = next(m for t, m in slips if t == t_ns)
    assert list(slip.data) == pytest.approx([float(v) for v in at_3s[22:24]], rel=1e-5)
    assert slip.layout.dim[0].label == "wheel"
