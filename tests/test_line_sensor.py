"""Guidance tape and the line sensor: arcs cut into chords within their error, the elements a
bar lights over a tape at a known offset, forks as two runs, spots under the reader."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.sensors.line_sensor import LineSensorSpec, line_offsets, read_elements, spots_under
from agvsim.world.tape import Arc, Spot, Tape


@settings(max_examples=50, deadline=None)
@given(
    r=st.floats(0.2, 20.0),
    start=st.floats(-180, 180),
    sweep=st.floats(-360, 360).filter(lambda s: abs(s) > 1),
    err=st.sampled_from([0.0005, 0.001, 0.01]),
)
def test_arc_chords_stay_within_the_chord_error(r, start, sweep, err):
    arc = Arc(1.0, -2.0, r, start, sweep)
    tape = Tape([arc], chord_error_m=err)
    # points on the true arc are within err of the chords, chord ends on the arc
    a = np.radians(start) + np.linspace(0, np.radians(sweep), 997)
    on_arc = np.column_stack([1.0 + r * np.cos(a), -2.0 + r * np.sin(a)])
    assert tape.distance_m(on_arc).max() <= err * (1 + 1e-9) + 1e-12
    ends = tape.segments[:, :2]
    np.testing.assert_allclose(np.hypot(ends[:, 0] - 1.0, ends[:, 1] + 2.0), r, rtol=1e-12)
    assert tape.length_m == pytest.approx(r * abs(np.radians(sweep)), rel=err / r + 1e-3)


def test_elements_over_a_straight_tape_at_a_known_offset():
    spec = LineSensorSpec(elements=16, span_m=0.15, mount_x_m=0.3)  # 10 mm pitch
    tape = Tape([[(-5.0, 0.0), (5.0, 0.0)]], width_m=0.05)
    y = spec.positions_m
    for d in (0.0, 0.012, -0.031, 0.06):
        pose = np.array([[0.0, d, 0.0]])  # the bar's element y sits at world y = d + y
        on = read_elements(pose, np.array([0.3]), y[None, :], tape.segments, 0.025)[0]
        np.testing.assert_array_equal(on, np.abs(d + y) <= 0.025)
        (runs,) = line_offsets(on[None, :], y[None, :])
        assert len(runs) == 1
        assert runs[0] == pytest.approx(-d, abs=0.005 + 1e-12)  # within half a pitch


def test_a_turned_robot_sees_the_tape_where_geometry_puts_it():
    # robot at the origin facing +y (90 deg): its bar 0.3 m ahead lies along x at y = 0.3;
    # a tape along x = 0.02 crosses it at lateral position -0.02 (to the robot's right)
    spec = LineSensorSpec(elements=41, span_m=0.4)
    tape = Tape([[(0.02, -5.0), (0.02, 5.0)]], width_m=0.01)
    on = read_elements(
        np.array([[0.0, 0.0, math.pi / 2]]),
        np.array([0.3]),
        spec.positions_m[None],
        tape.segments,
        0.005,
    )
    (runs,) = line_offsets(on, spec.positions_m[None])
    assert runs == [pytest.approx(-0.02, abs=1e-9)]


def test_a_fork_under_the_bar_reads_as_two_runs_right_to_left():
    spec = LineSensorSpec(elements=31, span_m=0.3)
    tape = Tape([[(0.0, 0.0), (1.0, 0.1)], [(0.0, 0.0), (1.0, -0.1)]], width_m=0.02)
    # bar at x = 0.8: the branches at y = +0.08 and -0.08
    on = read_elements(
        np.array([[0.5, 0.0, 0.0]]), np.array([0.3]), spec.positions_m[None], tape.segments, 0.01
    )
    (runs,) = line_offsets(on, spec.positions_m[None])
    assert runs == [pytest.approx(-0.08, abs=0.006), pytest.approx(0.08, abs=0.006)]


def test_no_tape_lights_nothing_and_padded_bars_skip_their_padding():
    on = read_elements(
        np.zeros((2, 3)),
        np.zeros(2),
        np.array([[0.0, np.nan], [0.0, 0.1]]),
        np.zeros((0, 4)),
        0.025,
    )
    assert not on.any()
    tape = Tape([[(-1.0, 0.0), (1.0, 0.0)]])
    on = read_elements(
        np.zeros((2, 3)), np.zeros(2), np.array([[0.0, np.nan], [0.0, 0.1]]), tape.segments, 0.025
    )
    assert on.tolist() == [[True, False], [True, False]]


def test_spots_under_the_reader():
    tape = Tape([], spots=[Spot(1.0, 0.0, 7), Spot(3.0, 0.0, 9)])
    poses = np.array([[0.7, 0.0, 0.0], [0.7, 0.1, 0.0], [2.0, 0.0, 0.0], [2.7, 0.04, 0.0]])
    got = spots_under(poses, np.full(4, 0.3), tape.spot_xy, np.full(4, 0.05))
    assert got.tolist() == [0, -1, -1, 1]
    assert tape.spot_code[got[got >= 0]].tolist() == [7, 9]


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"elements": 1}, "elements"),
        ({"span_m": 0.0}, "span_m"),
        ({"noise_std_m": -1.0}, "noise_std_m"),
    ],
)
def test_bad_line_sensor_settings_are_refused(kw, message):
    with pytest.raises(ValueError, match=message):
        LineSensorSpec(**kw)


def test_bad_tape_is_refused_naming_the_line():
    with pytest.raises(ValueError, match="tape line 1: needs at least 2"):
        Tape([[(0, 0), (1, 0)], [(0, 0)]])
    with pytest.raises(ValueError, match="width_m"):
        Tape([], width_m=0.0)
