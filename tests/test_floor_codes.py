"""Floor codes: the downward camera's picture decoded by OpenCV gives the robot's pose within
about a pixel, the right code id, nothing off the codes; fixes bound odometry drift on a route."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agvsim.sensors.floor_codes import (
    FloorCameraSpec,
    FloorCodeGrid,
    _rigid_fit,
    read_fix,
    render,
)

GRID = FloorCodeGrid(cols=10, rows=4, spacing_m=1.0, size_m=0.06, origin_xy_m=(0.0, 0.0))
QR_GRID = FloorCodeGrid(cols=10, rows=4, spacing_m=1.0, size_m=0.06, kind="qr")  # text = id
CAM = FloorCameraSpec(width_px=160, height_px=160, m_per_px=0.001, mount_xy_m=(0.1, 0.0))


@pytest.mark.parametrize(
    "pose",
    [
        (2.0 - 0.1, 1.0, 0.0),  # the camera right over code (2, 1)
        (5.03 - 0.1, 2.98, 0.0),
        (7.0, 3.0 - 0.1, math.pi / 2),
        (4.01 - 0.1 * math.cos(-2.5), 0.0 - 0.1 * math.sin(-2.5), -2.5),
        (0.01 - 0.1 * math.cos(1.0), -0.01 - 0.1 * math.sin(1.0), 1.0),
    ],
)
@pytest.mark.parametrize("kind", ["aruco", "qr"])
def test_a_code_in_view_gives_the_pose_within_about_a_pixel(pose, kind):
    grid = GRID if kind == "aruco" else QR_GRID
    pose = np.array(pose, dtype=np.float64)
    img = render(CAM, grid, pose)
    fix = read_fix(CAM, grid, img)
    assert fix is not None
    cam = pose[:2] + 0.1 * np.array([math.cos(pose[2]), math.sin(pose[2])])
    assert grid.code_xy(fix.code_id) == (round(cam[0]), round(cam[1]))
    assert np.hypot(*(fix.pose[:2] - pose[:2])) < 0.003  # 3 px
    dth = math.remainder(fix.pose[2] - pose[2], 2 * math.pi)
    assert abs(dth) < 0.05  # the code is 60 px wide: ~1/60 rad a pixel at its corners


def test_no_code_in_view_reads_nothing():
    assert read_fix(CAM, GRID, render(CAM, GRID, np.array([0.5, 0.5, 0.3]))) is None
    assert read_fix(CAM, QR_GRID, render(CAM, QR_GRID, np.array([0.5, 0.5, 0.3]))) is None
    assert read_fix(CAM, GRID, render(CAM, GRID, np.array([-3.0, 0.0, 0.0]))) is None


def test_the_rendered_code_is_where_the_grid_puts_it():
    img = render(CAM, GRID, np.array([3.0 - 0.1, 2.0, 0.0]))
    # the code's 60 px black border square sits in the middle of the picture
    mid = img[50:110, 50:110]
    assert (mid[0, :] == 0).all() and (mid[:, 0] == 0).all()
    assert (img[:40, :] == 150).all()  # bare floor around the quiet zone


def test_rigid_fit_is_exact_on_exact_points():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(5, 2))
    x, y, th = 1.5, -0.3, 2.2
    c, s = math.cos(th), math.sin(th)
    b = a @ np.array([[c, s], [-s, c]]) + [x, y]
    np.testing.assert_allclose(_rigid_fit(a, b), [x, y, th], atol=1e-12)


def test_floor_code_fixes_bound_the_odometry_drift_along_a_route():
    """Drive along the row y = 1 (codes every metre) with a 2 % odometry scale error and a
    heading bias; dead reckoning alone drifts, with fixes the error stays within what one
    metre of drift adds."""
    dt, v = 0.05, 0.8
    truth = np.array([0.0 - 0.1, 1.0, 0.0])
    odo = truth.copy()
    est = truth.copy()
    err_odo, err_est, fixes = [], [], 0
    for _ in range(int(9.0 / (v * dt))):
        truth = truth + [v * dt, 0.0, 0.0]
        d = v * dt * 1.02
        for p in (odo, est):
            p[2] += 0.002 * dt  # heading bias: 0.1 deg/s
            p[0] += d * math.cos(p[2])
            p[1] += d * math.sin(p[2])
        fix = read_fix(CAM, GRID, render(CAM, GRID, truth))
        if fix is not None:
            est = fix.pose.copy()
            fixes += 1
        err_odo.append(math.hypot(*(odo[:2] - truth[:2])))
        err_est.append(math.hypot(*(est[:2] - truth[:2])))
    assert fixes >= 8  # one per code passed at least
    assert err_odo[-1] > 0.15
    assert max(err_est) < 0.03  # 2 % of a metre, plus a pixel or two


def test_codes_and_their_quiet_zone_must_fit_the_spacing():
    with pytest.raises(ValueError, match="do not fit"):
        FloorCodeGrid(cols=2, rows=2, spacing_m=0.08, size_m=0.06, kind="qr")
    with pytest.raises(ValueError, match="not aruco, apriltag or qr"):
        FloorCodeGrid(cols=2, rows=2, kind="datamatrix")
