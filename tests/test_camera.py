"""The onboard camera: depth and colour images checked against hand-worked geometry, against
the lidar (same ray caster: the horizon row's depth is the lidar range along each column),
back-projection onto the scene's surfaces, frame scheduling, and scenario errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.kinematics import DifferentialDrive
from agvsim.scenario import ScenarioError, build, parse_scenario
from agvsim.sensors.camera import CameraSpec, pixel_rays, pixels_to_robot, project_points
from agvsim.sensors.raycast import RayCaster
from agvsim.sim.engine import Simulation
from agvsim.sim.spec import BODY_HEIGHT_M, WALL_HEIGHT_M, RobotSpec, World
from agvsim.world.grid import OccupancyGrid
from agvsim.world.markers import Appearance
from agvsim.world.mazes import thesis_maze

from helpers import walled_room

WALL, FLOOR, SKY = (175, 175, 185), (225, 225, 215), (200, 220, 240)
FLAT = Appearance(shade_faces=False, floor_checker=False)


pytestmark = pytest.mark.usefixtures("one_numba_thread")  # from conftest.py


def room() -> OccupancyGrid:
    """A walled room of 9 x 7 cells, origin (0, 0): free x in [1, 6], y in [1, 8]."""
    return walled_room(rows=9, cols=7)


def robot(name="a", pose=(2.0, 4.5, 0.0), cameras=(), color="#d62728", **kw) -> RobotSpec:
    return RobotSpec(
        name,
        DifferentialDrive(wheel_radius_m=0.1),
        initial_pose=pose,
        body_length_m=0.6,
        body_width_m=0.45,
        cameras=cameras,
        color=color,
        **kw,
    )


def cam(**kw) -> CameraSpec:
    kw.setdefault("mount_xy_m", (0.3, 0.0))
    return CameraSpec(**kw)


# ---------------------------------------------------------------------------- hand-worked
def test_facing_a_wall_depth_floor_and_sky_are_exact():
    """Camera 3.7 m from the east wall (x = 6), 0.4 m up, level: every wall pixel has z-depth
    3.7 (a plane square to the axis), a floor pixel in row v has z-depth 0.4 f / (v - cy), and
    the wall's top edge is at row cy - f (1.0 - 0.4) / 3.7."""
    spec = cam(width_px=321, height_px=241, mount_z_m=0.4)
    sim = Simulation(World(room(), appearance=FLAT), [robot(cameras=(spec,))])
    depth = np.asarray(sim.state.depths[0], dtype=np.float64)
    rgb = np.asarray(sim.state.images[0])
    f = spec.focal_px
    cx, cy = spec.principal_point_px
    assert (cx, cy) == (160.0, 120.0)
    v = np.arange(spec.height_px)[:, None] * np.ones((1, spec.width_px))
    floor_depth = np.where(v > cy, 0.4 * f / np.maximum(v - cy, 1e-300), np.inf)
    is_floor = floor_depth < 3.7
    top_row = cy - f * (WALL_HEIGHT_M - 0.4) / 3.7
    is_wall = ~is_floor & (v >= top_row)
    is_sky = v < top_row
    assert is_floor.any() and is_wall.any() and is_sky.any()
    np.testing.assert_allclose(depth[is_wall], 3.7, rtol=1e-6)
    np.testing.assert_allclose(depth[is_floor], floor_depth[is_floor], rtol=1e-6)
    assert np.isposinf(depth[is_sky]).all()
    assert (rgb[is_wall] == WALL).all() and (rgb[is_floor] == FLOOR).all()
    assert (rgb[is_sky] == SKY).all()
    # the centre pixel looks along the optical axis: the lidar's forward beam from the camera
    lidar = RayCaster(room()).cast_single(2.3, 4.5, [0.0], 30.0)[0]
    assert lidar == pytest.approx(3.7, abs=1e-12)
    assert depth[120, 160] == np.float32(lidar)


def test_wall_faces_are_shaded_and_painted():
    look = Appearance(floor_checker=False)
    g = room()
    sim = Simulation(
        World(g, appearance=look), [robot(pose=(3.5, 4.5, math.pi / 4), cameras=(cam(),))]
    )
    rgb = np.asarray(sim.state.images[0])
    row = rgb[110]  # above the horizon, below the wall tops
    # looking north-east: the east wall's west face (shade 0.92) and the north wall's south
    # face (0.7) both show, in two blocks of one colour each
    shades = {tuple(c) for c in row}
    want = {tuple(np.floor(np.array(WALL) * k).astype(int)) for k in (0.92, 0.7)}
    assert shades == want


def test_robots_show_as_boxes_with_their_top_seen_from_above():
    """A second robot 2 m ahead: its rear face (shaded 0.8) fills the centre column between the
    floor and its height (0.1 m wheel + BODY_HEIGHT_M); seen from 0.5 m up, its top too."""
    spec = cam(width_px=101, height_px=101, mount_z_m=0.5)
    other = robot("b", pose=(4.6, 4.5, 0.0), color="#1f77b4")  # rear face at x = 4.3
    sim = Simulation(World(room(), appearance=FLAT), [robot(cameras=(spec,)), other])
    rgb, depth = np.asarray(sim.state.images[0]), np.asarray(sim.state.depths[0])
    col_rgb, col_d = rgb[:, 50], depth[:, 50]
    side = (col_rgb == (24, 95, 144)).all(axis=1)  # floor(0.8 * (31, 119, 180))
    top = (col_rgb == (31, 119, 180)).all(axis=1)
    assert side.any() and top.any()
    np.testing.assert_allclose(col_d[side], 4.3 - 2.3, rtol=1e-6)
    pts = pixels_to_robot(spec, np.full(top.sum(), 50), np.flatnonzero(top), col_d[top])
    np.testing.assert_allclose(pts[:, 2], 0.1 + BODY_HEIGHT_M, atol=1e-5)
    assert (pts[:, 0] >= 4.3 - 2.0 - 1e-6).all() and (pts[:, 0] <= 4.9 - 2.0 + 1e-6).all()


# ---------------------------------------------------------------------------- vs the lidar
MAZE = thesis_maze("thesis_c1")
BOXES = np.array([[-5.5, -6.5, 0.4, 0.4, 0.25], [2.5, 2.5, 0.0, 0.3, 0.3]])


def _free(x: float, y: float) -> bool:
    return not bool(MAZE.is_occupied_at(x, y))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    x=st.floats(-9.6, 9.6),
    y=st.floats(-9.6, 9.6),
    th=st.floats(-math.pi, math.pi),
    hfov=st.floats(20.0, 120.0),
)
def test_horizon_depth_equals_the_lidar_range_along_each_column(x, y, th, hfov):
    """Horizon row (odd height: exactly level) of a camera 0.2 m up, below every box top:
    depth * sqrt(1 + a^2) = the lidar's range at that column's azimuth, for walls, static boxes
    and another robot alike, and inf exactly where the lidar has no return."""
    if not _free(x, y):
        return
    spec = cam(width_px=41, height_px=31, hfov_rad=math.radians(hfov), mount_xy_m=(0.0, 0.0),
               mount_z_m=0.2, range_max_m=10.0)  # fmt: skip
    world = World(MAZE, BOXES)
    me = RobotSpec("me", DifferentialDrive(), initial_pose=(x, y, th), body_length_m=0.1,
                   body_width_m=0.1, cameras=(spec,))  # fmt: skip
    other = RobotSpec("o", DifferentialDrive(), initial_pose=(x + 1.5 * math.cos(th),
                      y + 1.5 * math.sin(th), 0.3))  # fmt: skip
    sim = Simulation(world, [me, other])
    depth = np.asarray(sim.state.depths[0], dtype=np.float64)
    boxes = np.concatenate([sim.footprints(sim.state.poses), BOXES])
    rel = spec.column_azimuths_rad()
    ranges = RayCaster(MAZE).cast(
        np.array([[x, y]]), (th + rel)[None, :], 10.0, boxes, np.array([0])
    )[0]
    a_col = -(np.arange(spec.width_px) - spec.principal_point_px[0]) / spec.focal_px
    got = depth[15] * np.hypot(1.0, a_col)
    assert np.array_equal(np.isinf(got), np.isinf(ranges))
    fin = np.isfinite(ranges)
    np.testing.assert_allclose(got[fin], ranges[fin], rtol=2e-6, atol=1e-9)


# ---------------------------------------------------------------------------- back-projection
@pytest.mark.parametrize("pitch_deg", [0.0, 12.0, -15.0])
def test_every_pixel_back_projects_onto_a_surface_of_the_room(pitch_deg):
    """Each pixel with a depth lands on the floor (z = 0) or on a wall face of the room
    (x = 1, x = 6, y = 1, y = 8, z <= wall height); with a pitched camera to within the
    quarter-pixel azimuth binning (a few mm), level to float32 rounding."""
    spec = cam(width_px=160, height_px=120, pitch_rad=math.radians(pitch_deg))
    sim = Simulation(World(room()), [robot(pose=(3.0, 3.0, 0.6), cameras=(spec,))])
    depth = np.asarray(sim.state.depths[0], dtype=np.float64)
    v, u = np.nonzero(np.isfinite(depth))
    pts = pixels_to_robot(spec, u, v, depth[v, u])
    c, s = math.cos(0.6), math.sin(0.6)
    wx, wy = 3.0 + c * pts[:, 0] - s * pts[:, 1], 3.0 + s * pts[:, 0] + c * pts[:, 1]
    gap = np.min(np.abs(np.stack([pts[:, 2], wx - 1.0, wx - 6.0, wy - 1.0, wy - 8.0])), axis=0)
    tol = 2e-5 if pitch_deg == 0 else 0.01
    assert gap.max() <= tol
    assert (pts[:, 2] <= WALL_HEIGHT_M + tol).all() and (pts[:, 2] >= -tol).all()
    # projecting the points back gives the pixels again
    world = np.column_stack([wx, wy, pts[:, 2]])
    uv, d = project_points(spec, np.array([3.0, 3.0, 0.6]), world)
    np.testing.assert_allclose(uv, np.column_stack([u, v]), atol=1e-6)
    np.testing.assert_allclose(d, depth[v, u], rtol=1e-9)


def test_pixel_rays_bin_every_pixel_once():
    for spec in (cam(width_px=64, height_px=48), cam(width_px=64, height_px=48, pitch_rad=0.3)):
        r = pixel_rays(spec)
        assert np.array_equal(np.sort(r.order), np.arange(64 * 48))
        assert r.bin_start[0] == 0 and r.bin_start[-1] == 64 * 48
        assert np.all(np.diff(r.bin_start) >= 0)
        assert r.exact == (spec.pitch_rad == 0.0)


# ---------------------------------------------------------------------------- in a simulation
def test_frames_come_at_the_camera_rate_and_do_not_change_under_a_reader():
    sim = Simulation(
        World(room()), [robot(cameras=(cam(rate_hz=10.0),)), robot("b", pose=(4.0, 2.0, 0.0))]
    )
    st_ = sim.state
    assert st_.image_seq.tolist() == [1] and st_.image_stamp.tolist() == [0.0]
    first = sim.observation(0).images["camera"]
    assert not first.flags.writeable
    kept = first.copy()
    for _ in range(4):
        sim.step()
    assert st_.image_seq.tolist() == [1]
    sim.step()  # t = 0.1 s
    assert st_.image_seq.tolist() == [2] and st_.image_stamp[0] == pytest.approx(0.1)
    for _ in range(45):
        sim.step()
    assert st_.image_seq.tolist() == [11] and st_.image_stamp[0] == pytest.approx(1.0)
    assert np.array_equal(first, kept)
    obs_b = sim.observation(1)
    assert obs_b.images == {} and obs_b.depth == {}
    frames = sim.camera_frames()
    assert [(f.robot_name, f.camera, f.seq) for f in frames] == [("a", "camera", 11)]
    assert frames[0].rgb is sim.state.images[0]


def test_no_cameras_no_camera_work():
    sim = Simulation(World(room()), [robot()])
    assert sim.cameras is None and sim.state.images == [] and sim.camera_frames() == []
    sim.step()
    assert sim.observation(0).images == {}


def test_editing_the_maze_changes_what_the_camera_sees():
    spec = cam(width_px=33, height_px=25)
    sim = Simulation(World(room()), [robot(cameras=(spec,))])
    assert sim.state.depths[0][12, 16] == np.float32(3.7)
    sim.set_grid(room().with_cell(4, 4, True))  # a wall cell at x in [4, 5], y in [4, 5]
    for _ in range(5):  # the next frame, at t = 0.1 s
        sim.step()
    assert sim.state.image_seq[0] == 2
    assert sim.state.depths[0][12, 16] == np.float32(4.0 - 2.3)


def test_same_seed_same_frames():
    def frames():
        sim = build(parse_scenario(_scenario()))
        for _ in range(10):
            sim.step()
        return np.asarray(sim.state.images[0]).tobytes(), np.asarray(sim.state.depths[0]).tobytes()

    assert frames() == frames()


# ---------------------------------------------------------------------------- pixel noise
def _steps(data: dict, n: int = 12) -> Simulation:
    sim = build(parse_scenario(data))
    for _ in range(n):
        sim.step()
    return sim


def test_camera_noise_zero_draws_nothing_and_leaves_the_frames_exact():
    sim = _steps(_scenario({"type": "camera", "noise_std": 0}))
    assert sim.state.image_seq[0] == 3  # 0.24 s at 10 Hz: frames at t = 0, 0.1 and 0.2
    pose = sim.state.image_pose[0]
    clean, _ = sim.cameras.render(0, pose, sim.footprints(pose[None]))
    assert np.array_equal(sim.state.images[0], clean)
    # the generator is where a run without a camera leaves it: odometry noise alone used it
    blind = _scenario()
    blind["robots"][0]["sensors"] = []
    assert sim.rng.bit_generator.state == _steps(blind).rng.bit_generator.state


def test_camera_noise_is_gaussian_with_the_given_std_and_repeats_with_the_seed():
    std = 8.0
    sim = _steps(_scenario({"type": "camera", "noise_std": std}))
    pose = sim.state.image_pose[0]
    clean, _ = sim.cameras.render(0, pose, sim.footprints(pose[None]))
    noisy = np.asarray(sim.state.images[0])
    diff = noisy.astype(np.int64) - clean.astype(np.int64)
    # only values 5 std away from 0 and 255 (walls 131..185, floor 209..225): nothing clipped
    keep = (clean >= 5 * std) & (clean <= 255 - 5 * std)
    assert keep.mean() > 0.5
    d = diff[keep]
    # E|N(0, s)| = s sqrt(2 / pi) = 6.383 for s = 8 (rounding to integers adds ~0.004)
    assert np.abs(d).mean() == pytest.approx(std * math.sqrt(2 / math.pi), rel=0.02)
    assert d.mean() == pytest.approx(0.0, abs=0.1)
    assert d.std() == pytest.approx(std, rel=0.02)
    assert noisy.dtype == np.uint8 and not noisy.flags.writeable
    # same scenario and seed: the same noisy frames, bit for bit; another seed: other noise
    again = _steps(_scenario({"type": "camera", "noise_std": std}))
    assert np.array_equal(again.state.images[0], noisy)
    other = _scenario({"type": "camera", "noise_std": std})
    other["seed"] = 1
    assert not np.array_equal(_steps(other).state.images[0], noisy)


# ---------------------------------------------------------------------------- scenario
def _scenario(sensor: dict | None = None, **world) -> dict:
    return {
        "world": {"matrix": room().occupied.astype(int).tolist(), "origin_xy_m": [0, 0], **world},
        "robots": [
            {
                "name": "a",
                "model": "differential",
                "pose": {"x_m": 2.0, "y_m": 4.5},
                "sensors": [sensor or {"type": "camera"}],
                "controller": {"type": "script", "steps": [{"duration_s": 1, "twist": [0.3, 0.2]}]},
            }
        ],
    }


def test_scenario_camera_defaults_sit_on_the_front_of_the_body():
    sim = build(parse_scenario(_scenario()))
    spec = sim.robots[0].cameras[0]
    assert spec.mount_xy_m == (0.3, 0.0)  # body 0.6 m long, centred on P
    assert spec.mount_z_m == pytest.approx(0.1 + BODY_HEIGHT_M + 0.05)
    assert (spec.width_px, spec.height_px, spec.rate_hz) == (320, 240, 10.0)
    assert spec.hfov_rad == pytest.approx(math.radians(60.0))
    assert sim.state.images[0].shape == (240, 320, 3)


@pytest.mark.parametrize(
    "sensor, where, words",
    [
        ({"type": "camera", "mount_z_m": 1.2}, "robots[0] (a).sensors[0]", ["mount_z_m", "1.2"]),
        ({"type": "camera", "pitch_deg": 70}, "robots[0] (a).sensors[0]", ["pitch", "70"]),
        ({"type": "camera", "hfov_deg": 200}, "robots[0].sensors[0].camera.hfov_deg", ["170"]),
        ({"type": "camera", "widht_px": 64}, "robots[0].sensors[0].camera", ["width_px"]),
        ({"type": "camra"}, "robots[0].sensors[0]", ["'camera'"]),
        ({"type": "camera", "noise_std": -1}, "sensors[0].camera.noise_std", ["0", "-1"]),
        ({"type": "camera", "noise_std": 300}, "sensors[0].camera.noise_std", ["255", "300"]),
    ],
)
def test_bad_camera_settings_are_refused_with_the_field(sensor, where, words):
    with pytest.raises(ScenarioError) as err:
        build(parse_scenario(_scenario(sensor)))
    msg = str(err.value)
    assert where in msg, msg
    for w in words:
        assert w in msg, msg


def test_camera_and_lidar_names_must_differ():
    data = _scenario()
    data["robots"][0]["sensors"] = [
        {"type": "camera", "name": "eye"},
        {"type": "lidar", "name": "eye"},
    ]
    with pytest.raises(ScenarioError, match="names must be unique"):
        build(parse_scenario(data))


def test_the_3d_view_draws_the_robot_as_tall_as_the_camera_sees_it():
    """The browser app's robot body tops out at RobotSpec.height_m, the height the onboard
    cameras render robots to."""
    from agvsim.app import shapes

    spec = robot()
    parts = shapes.robot_parts(spec)
    top = parts.body_center_m[2] + parts.body_size_m[2] / 2
    assert top == pytest.approx(spec.height_m)
