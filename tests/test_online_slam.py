"""Online SLAM in a run (a robot's ``slam:`` block) and the map/trajectory scores."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agvsim.metrics.map_quality import map_iou, trajectory_error, truth_raster, wall_surface
from agvsim.runner import run_scenario
from agvsim.scenario import ScenarioError, parse_scenario
from agvsim.world.grid import OccupancyGrid

pytestmark = pytest.mark.slow  # SLAM during whole runs

ROOM = [
    [1, 1, 1, 1, 1, 1],
    [1, 0, 0, 0, 0, 1],
    [1, 0, 0, 0, 0, 1],
    [1, 0, 0, 1, 0, 1],
    [1, 0, 0, 0, 0, 1],
    [1, 1, 1, 1, 1, 1],
]


def _grid() -> OccupancyGrid:
    return OccupancyGrid.from_matrix(np.array(ROOM, bool), 1.0)  # x, y in [-3, 3]


def test_wall_surface_counts_cells_facing_free_space():
    grid = _grid()
    occ, origin = truth_raster(grid, np.zeros((0, 5)), 0.5)
    assert occ.shape == (12, 12) and origin == (-3.0, -3.0)
    surf = wall_surface(occ, origin, 0.5, (-1.5, 1.5))
    # the room's free space is 8 x 8 half-cells; the wall half-cells along its four sides face
    # it (4 x 8; the ring's corners touch it only diagonally) and so do the pillar's 2 x 2
    assert surf.sum() == 4 * 8 + 4
    assert not surf[0].any() and not surf[:, 0].any()  # the outermost ring sees nothing


def test_map_iou_perfect_shifted_and_tolerant():
    grid = _grid()
    res = 0.1
    occ, origin = truth_raster(grid, np.zeros((0, 5)), res, margin_m=0.0)
    surf = wall_surface(occ, origin, res, (-1.5, 1.5))
    prob = np.where(surf, 0.9, 0.1)
    perfect = map_iou(prob, origin, res, grid, np.zeros((0, 5)), (-1.5, 1.5))
    assert perfect["exact"]["iou"] == 1.0 and perfect["tolerant"]["iou"] == 1.0
    assert perfect["surface_cells"] == perfect["map_cells"] == int(surf.sum())
    # one cell off: nothing matches exactly, everything within the one-cell tolerance
    one = map_iou(prob, (origin[0] + res, origin[1]), res, grid, np.zeros((0, 5)), (-1.5, 1.5))
    assert one["tolerant"]["iou"] == 1.0
    assert one["exact"]["iou"] < 0.6
    # three cells off: the side walls are lost (the walls along x still overlap themselves)
    far = map_iou(prob, (origin[0] + 3 * res, origin[1]), res, grid, np.zeros((0, 5)), (-1.5, 1.5))
    assert far["tolerant"]["iou"] < 0.7


def test_map_iou_counts_cells_outside_the_world_as_wrong():
    grid = _grid()
    prob = np.full((2, 2), 0.9)
    r = map_iou(prob, (50.0, 50.0), 0.1, grid, np.zeros((0, 5)), (-1.5, 1.5))
    assert r["map_cells"] == 4 and r["tolerant"]["precision"] == 0.0 and r["tolerant"]["iou"] == 0.0


def test_trajectory_error_hand_worked():
    truth = np.zeros((4, 3))
    est = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [0.0, 0.0, np.pi], [0.0, 1.0, -0.1]])
    e = trajectory_error(est, truth)
    assert e["mean_m"] == pytest.approx(1.5)
    assert e["max_m"] == 5.0 and e["final_m"] == 1.0
    assert e["rmse_m"] == pytest.approx(np.sqrt(26 / 4))
    assert e["max_deg"] == pytest.approx(180.0)
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        trajectory_error(est[:, :2], truth)


def _scenario(**slam) -> dict:
    return {
        "name": "slam room",
        "seed": 3,
        "duration_s": 40,
        "world": {"matrix": ROOM},
        "robots": [
            {
                "name": "r1",
                "model": "differential",
                "pose": {"x_m": -1.5, "y_m": 1.5, "theta_deg": 0},
                "body": {"length_m": 0.4, "width_m": 0.35},
                "sensors": [
                    {"type": "lidar", "beams": 180, "range_max_m": 8, "noise_std_m": 0.01},
                    {"type": "rangers", "range_max_m": 1.0},
                ],
                "controller": {"type": "avoid", "sensor": "rangers", "speed_m_s": 0.3},
                "slam": slam or {"sensor": "lidar"},
            }
        ],
    }


def test_slam_block_writes_map_trajectory_and_scores(tmp_path):
    sc = parse_scenario(_scenario(), "test")
    data = run_scenario(sc, tmp_path, plot=False)
    s = data["slam"]["r1"]
    d = tmp_path / "slam_r1"
    for name in ("trajectory.txt", "map.pgm", "map.yaml", "map.png", "compare.png"):
        assert (d / name).is_file(), name
    traj = np.loadtxt(d / "trajectory.txt")
    assert traj.shape == (s["scans"], 4)
    assert s["scans"] == 401  # 10 Hz lidar over 40 s, t = 0 included
    assert np.all(np.diff(traj[:, 0]) > 0)
    # a small room with 1 cm range noise: the map lies on the true walls
    assert s["trajectory_error"]["max_m"] < 0.1
    assert s["map"]["tolerant"]["iou"] > 0.8
    assert s["map"]["tolerant"]["iou"] >= s["map"]["exact"]["iou"]
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["slam"]["r1"]["map"] == s["map"]


def test_slam_is_deterministic(tmp_path):
    sc = parse_scenario(_scenario(), "test")
    a = run_scenario(sc, tmp_path / "a", duration_s=10, plot=False)
    b = run_scenario(sc, tmp_path / "b", duration_s=10, plot=False)
    assert a["slam"] == b["slam"]
    ta = (tmp_path / "a" / "slam_r1" / "trajectory.txt").read_bytes()
    assert ta == (tmp_path / "b" / "slam_r1" / "trajectory.txt").read_bytes()


@pytest.mark.parametrize(
    ("slam", "message"),
    [
        (
            {"sensor": "lidr"},
            "robots[0].slam.sensor: robot 'r1' has no sensor 'lidr'; did you mean 'lidar'?",
        ),
        ({"sensor": "rangers"}, "has 4 beams; SLAM needs a lidar"),
    ],
)
def test_slam_block_bad_sensor_is_refused(tmp_path, slam, message):
    sc = parse_scenario(_scenario(**slam), "test")
    with pytest.raises(ScenarioError) as err:
        run_scenario(sc, tmp_path, plot=False)
    assert message in str(err.value)


def test_slam_block_schema_errors():
    bad = _scenario(sensor="lidar", resolution_m=0)
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.slam\.resolution_m"):
        parse_scenario(bad, "test")
    bad = _scenario(sensor="lidar", loop_radius_m=3)
    with pytest.raises(ScenarioError, match="did you mean 'loop_search_radius_m'"):
        parse_scenario(bad, "test")


def test_browser_session_runs_slam_and_serves_its_live_map():
    from agvsim.app.session import Session

    s = Session(parse_scenario(_scenario(), "test"))
    assert s.slam_map("r1") is None  # nothing fed yet
    s.step(300)  # 6 s: 61 scans
    free, res, origin = s.slam_map("r1")
    assert res == 0.05
    assert free.min() < 0.2 and free.max() > 0.8  # walls and free space
    # every occupied cell of the map lies within 10 cm of a true wall (row 0 north)
    rows, cols = np.nonzero(free < 0.2)
    x = origin[0] + (cols + 0.5) * res
    y = origin[1] + (free.shape[0] - rows - 0.5) * res
    g = _grid()
    near = np.zeros(len(x), bool)
    for dx, dy in ((0, 0), (0.1, 0), (-0.1, 0), (0, 0.1), (0, -0.1)):
        near |= g.is_occupied_at(x + dx, y + dy)
    assert len(x) > 50 and near.all()
    s.reset()
    assert s.slam_map("r1") is None  # a new run, a new SLAM
    assert s.slam_map("nobody") is None


def test_slam_block_long_corridors_reaches_the_tracking(tmp_path):
    from agvsim.online_slam import OnlineSlam
    from agvsim.scenario import build

    for flag, want in ((False, None), (True, np.radians(15.0)), (None, np.radians(15.0))):
        keys = {} if flag is None else {"long_corridors": flag}  # None: the key left out
        sc = parse_scenario(_scenario(sensor="lidar", resolution_m=0.1, **keys), "t")
        sim = build(sc)
        slam = OnlineSlam(sim, 0, sc.robots[0].slam)
        tracking = slam.slam.cfg.tracking
        assert tracking.edge_on_turn_rad == (pytest.approx(want) if want else None)
        assert tracking.resolution_m == 0.1  # the block's other keys still apply
    # and a run with it writes its map
    sc = parse_scenario(_scenario(sensor="lidar", long_corridors=False), "t")
    data = run_scenario(sc, tmp_path, duration_s=10, plot=False)
    assert data["slam"]["r1"]["scans"] == 101 and (tmp_path / "slam_r1" / "map.png").is_file()
