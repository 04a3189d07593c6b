"""Safety-scanner field sets: switching by speed and steering, polygon checks, the field-length
check against the stopping distance, the batch inside-test and the braking it triggers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from matplotlib.path import Path as MplPath

from agvsim.sensors.safety_fields import (
    CLEAR,
    PROTECTIVE,
    WARNING,
    FieldSet,
    PackedFields,
    SafetyScannerSpec,
    brake,
    check_fields,
    field_status,
    reach_m,
    scan_points_robot_frame,
    speed_gaps,
)


def rect(x0: float, x1: float, half_w: float) -> tuple:
    return ((x0, -half_w), (x1, -half_w), (x1, half_w), (x0, half_w))


def three_speeds() -> SafetyScannerSpec:
    return SafetyScannerSpec(
        "lidar",
        (
            FieldSet("slow", rect(0.0, 0.6, 0.4), rect(0.0, 1.0, 0.5), -0.2, 0.5),
            FieldSet("medium", rect(0.0, 1.2, 0.4), rect(0.0, 2.0, 0.5), 0.5, 1.0),
            FieldSet("fast", rect(0.0, 2.2, 0.4), rect(0.0, 3.5, 0.6), 1.0, 1.5),
        ),
        response_time_s=0.1,
        decel_m_s2=1.0,
    )


def test_the_field_set_switches_exactly_at_the_speed_thresholds():
    s = three_speeds()
    assert s.select(0.0) == 0
    assert s.select(np.nextafter(0.5, 0.0)) == 0
    assert s.select(0.5) == 1  # a set's minimum is inclusive, its maximum exclusive
    assert s.select(np.nextafter(1.0, 0.0)) == 1
    assert s.select(1.0) == 2
    assert s.select(1.5) == -1  # above every set: no field case
    assert s.select(-0.2) == 0
    assert s.select(-0.21) == -1


def test_car_like_sets_switch_by_steering_too():
    left = FieldSet("left", rect(0.0, 1.0, 0.3), None, 0.0, 1.0, 0.1, 1.0)
    straight = FieldSet("straight", rect(0.0, 1.5, 0.3), None, 0.0, 1.0, -0.1, 0.1)
    right = FieldSet("right", rect(0.0, 1.0, 0.3), None, 0.0, 1.0, -1.0, -0.1)
    s = SafetyScannerSpec("lidar", (left, straight, right))
    assert s.select(0.5, 0.0) == 1
    assert s.select(0.5, 0.1) == 0
    assert s.select(0.5, -0.1) == 1
    assert s.select(0.5, np.nextafter(-0.1, -1.0)) == 2


def test_overlapping_field_sets_are_refused_naming_both():
    with pytest.raises(ValueError, match="'a' and 'b' are both active"):
        SafetyScannerSpec(
            "lidar",
            (
                FieldSet("a", rect(0, 1, 0.3), None, 0.0, 0.6),
                FieldSet("b", rect(0, 1, 0.3), None, 0.5, 1.0),
            ),
        )


@pytest.mark.parametrize(
    ("points", "message"),
    [
        (((0, 0), (1, 0)), "at least 3"),
        (((0, 0), (1, 0), (2, 0)), "no area"),
        (((0, 0), (1, 1), (1, 0), (0, 1)), "edges 0-1 and 2-3 cross"),
        (((0, 0), (1, float("nan")), (1, 1)), "finite"),
    ],
)
def test_bad_polygons_are_refused_with_the_reason(points, message):
    with pytest.raises(ValueError, match=message):
        FieldSet("f", points)


def test_reach_along_a_direction_is_the_far_crossing_of_the_boundary():
    r = rect(0.3, 2.0, 0.4)
    assert reach_m(r, 0.0) == pytest.approx(2.0)
    assert reach_m(r, math.pi) == 0.0  # entirely ahead
    # a field around the body: 1 m ahead, 0.5 m behind
    around = rect(-0.5, 1.0, 0.4)
    assert reach_m(around, 0.0) == pytest.approx(1.0)
    assert reach_m(around, math.pi) == pytest.approx(0.5)
    # a triangle with its tip at (3, 0)
    assert reach_m(((0.0, -1.0), (3.0, 0.0), (0.0, 1.0)), 0.0) == pytest.approx(3.0)


def test_a_field_too_short_for_its_top_speed_is_named_with_the_numbers():
    s = three_speeds()
    # front 0.3 m; the fast set at 1.5 m/s needs 0.3 + 0.15 + 1.125 = 1.575 m: it has 2.2
    assert check_fields(s, front_m=0.3, rear_m=0.3, max_speed_m_s=1.4999) == []
    # with a 0.7 m front: slow at 0.5 m/s needs 0.7 + 0.05 + 0.125 = 0.875 m > 0.6; medium at
    # 1.0 m/s needs 0.7 + 0.1 + 0.5 = 1.3 m > 1.2; fast at 1.4999 m/s needs 1.975 m <= 2.2
    problems = check_fields(s, front_m=0.7, rear_m=0.3, max_speed_m_s=1.4999)
    assert len(problems) == 2
    assert any("'medium'" in p and "reaches 1.200 m ahead" in p for p in problems)
    assert any("'slow'" in p and "needs 0.875 m" in p for p in problems)


def test_reversing_sets_are_checked_behind_the_body():
    s = SafetyScannerSpec(
        "lidar",
        (
            FieldSet("back", rect(-0.8, 0.0, 0.3), None, -0.5, 0.0),
            FieldSet("ahead", rect(0.0, 1.8, 0.3), None, 0.0, 1.1),
        ),
        response_time_s=0.2,
        decel_m_s2=0.5,
    )
    # reversing at 0.5 m/s: rear 0.4 + 0.1 + 0.25 = 0.75 <= 0.8
    assert check_fields(s, 0.4, 0.4, 1.0, max_reverse_m_s=0.5) == []
    # rear 0.5: 0.85 > 0.8
    (problem,) = check_fields(s, 0.4, 0.5, 1.0, max_reverse_m_s=0.5)
    assert "'back'" in problem and "behind" in problem and "0.850 m" in problem


def test_speeds_no_set_covers_are_named():
    s = SafetyScannerSpec(
        "lidar",
        (
            FieldSet("a", rect(0, 3, 0.3), None, 0.0, 0.5),
            FieldSet("b", rect(0, 3, 0.3), None, 0.6, 1.0),
        ),
    )
    assert speed_gaps(s, 0.0, 0.9) == [(0.5, 0.6)]
    assert speed_gaps(s, 0.0, 1.0) == [(0.5, 0.6), (1.0, 1.0)]  # 1.0 itself: max exclusive
    assert speed_gaps(s, -0.1, 0.4) == [(-0.1, 0.0)]
    problems = check_fields(s, 0.3, 0.3, 1.0)
    assert any("between 0.500 and 0.600 m/s" in p for p in problems)
    assert any("at 1.000 m/s" in p for p in problems)


@settings(max_examples=60, deadline=None)
@given(
    v=st.floats(0.05, 3.0),
    response=st.floats(0.0, 0.5),
    decel=st.floats(0.2, 3.0),
    front=st.floats(0.1, 1.0),
)
def test_a_field_exactly_the_stopping_distance_long_passes_and_shorter_fails(
    v, response, decel, front
):
    need = front + v * response + v * v / (2 * decel)

    def spec(length: float) -> SafetyScannerSpec:
        return SafetyScannerSpec(
            "lidar",
            (FieldSet("f", rect(0.0, length, 0.3), None, 0.0, v * 1.01),),
            response_time_s=response,
            decel_m_s2=decel,
        )

    assert check_fields(spec(need + 1e-6), front, front, v) == []
    assert len(check_fields(spec(need - 0.01), front, front, v)) == 1


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_vertices=st.integers(3, 9),
)
def test_the_inside_test_agrees_with_matplotlib_on_star_shaped_polygons(seed, n_vertices):
    rng = np.random.default_rng(seed)
    angles = np.sort(rng.uniform(0, 2 * np.pi, n_vertices))
    if np.ptp(np.diff(np.r_[angles, angles[0] + 2 * np.pi])) > 2.5:
        angles = np.linspace(0, 2 * np.pi, n_vertices, endpoint=False)
    radii = rng.uniform(0.5, 2.0, n_vertices)
    poly = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
    try:
        fs = FieldSet("f", poly)
    except ValueError:
        return  # a degenerate draw
    pts = rng.uniform(-2.5, 2.5, (200, 2))
    verts = np.asarray(fs.protective)
    expected = MplPath(verts).contains_points(pts)
    near = _distance_to_boundary(pts, verts) < 1e-6  # either answer is right on an edge
    packed = PackedFields.of([SafetyScannerSpec("lidar", (fs,))])
    got = field_status(
        pts[:, None, :],
        np.ones((len(pts), 1), bool),
        np.zeros(len(pts), np.int64),
        packed.verts,
        packed.start,
        packed.count,
        packed.prot,
        packed.warn,
    )
    np.testing.assert_array_equal((got == PROTECTIVE)[~near], expected[~near])


def _distance_to_boundary(pts: np.ndarray, verts: np.ndarray) -> np.ndarray:
    a, b = verts, np.roll(verts, -1, axis=0)
    ab = b - a
    t = np.clip(((pts[:, None, :] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.linalg.norm(pts[:, None, :] - closest, axis=-1).min(axis=1)


def test_status_per_scanner_in_one_batch_call():
    s = three_speeds()
    packed = PackedFields.of([s, s, s])
    # robot 0: a return 0.5 m ahead -> in slow's protective field
    # robot 1: a return 0.8 m ahead -> only in slow's warning field
    # robot 2: a return 0.8 m ahead, medium set active -> protective
    pts = np.zeros((3, 2, 2))
    valid = np.zeros((3, 2), bool)
    pts[0, 0], valid[0, 0] = (0.5, 0.0), True
    pts[1, 1], valid[1, 1] = (0.8, 0.0), True
    pts[2, 0], valid[2, 0] = (0.8, 0.0), True
    active = packed.first + np.array([s.select(0.2), s.select(0.2), s.select(0.7)])
    out = field_status(
        pts, valid, active, packed.verts, packed.start, packed.count, packed.prot, packed.warn
    )
    assert out.tolist() == [PROTECTIVE, WARNING, PROTECTIVE]
    # no field case (-1) is a protective stop; invalid beams never count
    active[1] = -1
    valid[2, 0] = False
    out = field_status(
        pts, valid, active, packed.verts, packed.start, packed.count, packed.prot, packed.warn
    )
    assert out.tolist() == [PROTECTIVE, PROTECTIVE, CLEAR]


def test_scan_points_skip_no_returns_and_keep_too_close_ones_at_the_sensor():
    ranges = np.array([1.0, np.inf, -np.inf, np.nan])
    angles = np.array([0.0, 0.5, np.pi / 2, 1.0])
    pts, valid = scan_points_robot_frame(ranges, angles, (0.2, 0.0), 0.0)
    assert valid.tolist() == [True, False, True, False]
    np.testing.assert_allclose(pts[0], [1.2, 0.0])
    np.testing.assert_allclose(pts[2], [0.2, 0.0])


@pytest.mark.parametrize("v0", [0.3, 1.0, 2.0])
@pytest.mark.parametrize("dt", [0.02, 0.005])
def test_braking_travels_the_stopping_distance(v0, dt):
    """Drive straight at v0; a return enters the protective field at t = 0.5 s; integrate the
    twists brake() gives: the distance from then to the stop is v t_r + v^2 / (2 a) (up to
    the step: the speed is held per step)."""
    response, decel = 0.12, 0.8
    x, t = 0.0, 0.0
    prev = np.array([[v0, 0.0, 0.0]])
    since = np.full(1, np.nan)
    x_violation = None
    while t < 60.0:
        status = np.array([PROTECTIVE if t >= 0.5 - 1e-12 else CLEAR], np.int8)
        if status[0] == PROTECTIVE and x_violation is None:
            x_violation = x
        cmd = np.array([[v0, 0.0, 0.0]])
        tw = brake(
            cmd,
            prev,
            status,
            since,
            t,
            dt,
            np.array([response]),
            np.array([decel]),
            np.array([0.3]),
        )
        x += tw[0, 0] * dt
        prev = tw
        t += dt
        if x_violation is not None and tw[0, 0] == 0.0:
            break
    expected = v0 * response + v0 * v0 / (2 * decel)
    travelled = x - x_violation
    # per step the speed is held: the response lasts up to one step longer (+ v0 dt at most)
    # and the stepped braking falls short of the continuous one by about v0 dt / 2
    assert abs(travelled - expected) <= v0 * dt + 1e-9


def test_a_warning_caps_the_speed_and_clearing_resets_the_violation():
    since = np.full(2, np.nan)
    cmd = np.array([[1.0, 0.0, 0.5], [0.2, 0.0, 0.0]])
    tw = brake(
        cmd,
        cmd,
        np.array([WARNING, WARNING], np.int8),
        since,
        0.0,
        0.02,
        np.full(2, 0.1),
        np.full(2, 1.0),
        np.full(2, 0.3),
    )
    np.testing.assert_allclose(tw[0], [0.3, 0.0, 0.15])  # direction and curvature kept
    np.testing.assert_allclose(tw[1], cmd[1])  # already slower
    brake(
        cmd,
        cmd,
        np.array([PROTECTIVE, CLEAR], np.int8),
        since,
        1.0,
        0.02,
        np.full(2, 0.1),
        np.full(2, 1.0),
        np.full(2, 0.3),
    )
    assert since[0] == 1.0 and np.isnan(since[1])
    brake(
        cmd,
        cmd,
        np.array([CLEAR, CLEAR], np.int8),
        since,
        1.02,
        0.02,
        np.full(2, 0.1),
        np.full(2, 1.0),
        np.full(2, 0.3),
    )
    assert np.isnan(since).all()
