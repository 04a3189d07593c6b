"""The line-following law in closed loop with a unicycle and the real line-sensor kernel:
it holds the tape through a curve, takes the branch it is told at a fork, stops when lost."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agvsim.control.line_follow import LineFollowLaw
from agvsim.sensors.line_sensor import LineSensorSpec, line_offsets, read_elements
from agvsim.world.tape import Arc, Tape

SENSOR = LineSensorSpec(elements=16, span_m=0.16, mount_x_m=0.3)


def drive(tape: Tape, law: LineFollowLaw, pose, seconds: float, dt: float = 0.02):
    pose = np.array(pose, dtype=np.float64)
    y = SENSOR.positions_m[None, :]
    offsets, poses = [], []
    for _ in range(int(seconds / dt)):
        on = read_elements(
            pose[None], np.array([SENSOR.mount_x_m]), y, tape.segments, tape.width_m / 2
        )
        (runs,) = line_offsets(on, y)
        v, w = law.step(runs, dt)
        if runs:
            offsets.append(min(runs, key=abs))
        pose = pose + [v * math.cos(pose[2]) * dt, v * math.sin(pose[2]) * dt, w * dt]
        poses.append(pose.copy())
    return np.array(offsets), np.array(poses)


def test_the_follower_holds_the_tape_through_a_curve():
    tape = Tape([[(-1.0, 0.0), (3.0, 0.0)], Arc(3.0, 1.5, 1.5, -90, 90), [(4.5, 1.5), (4.5, 6.0)]])
    law = LineFollowLaw(speed_m_s=0.5)
    offsets, poses = drive(tape, law, (-0.8, 0.02, 0.0), 20.0)
    assert law.state == "follow"
    assert np.abs(offsets).max() < 0.03  # the bar stays on the tape (+-8 cm is its reach)
    assert poses[-1, 1] > 4.0  # came round the curve and up the last straight
    # the reference point stays near the tape (it cuts the curve a little)
    assert tape.distance_m(poses[:, :2]).max() < 0.05


@pytest.mark.parametrize(("choice", "branch_y"), [("left", 1.0), ("right", -1.0)])
def test_at_a_fork_the_follower_takes_the_branch_it_is_told(choice, branch_y):
    tape = Tape(
        [
            [(-1.0, 0.0), (2.0, 0.0)],
            [(2.0, 0.0), (4.0, 1.0), (8.0, 1.0)],
            [(2.0, 0.0), (4.0, -1.0), (8.0, -1.0)],
        ]
    )
    law = LineFollowLaw(speed_m_s=0.4, junctions=[choice])
    _, poses = drive(tape, law, (-0.8, 0.0, 0.0), 20.0)
    assert law.taken == [choice]
    assert poses[-1, 0] > 6.0
    assert poses[-1, 1] == pytest.approx(branch_y, abs=0.05)


def test_off_the_tape_the_follower_stops_and_says_lost():
    law = LineFollowLaw()
    assert law.step([], 0.02) == (0.0, 0.0)
    assert law.state == "lost"
    with pytest.raises(ValueError, match="'up' is not one of"):
        LineFollowLaw(junctions=["up"])
