"""Maze solving: A* planning, the A* solver on random mazes for every model, the map-less
explorer, configs and the thesis Fig. 16 scenarios."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from agvsim.behaviours import MazeSolverConfig, build_maze_solver
from agvsim.control.api import ControllerContext, ControlMode
from agvsim.control.maze_solver import (
    AStarMazeSolver,
    ClearanceMap,
    TremauxExplorer,
    astar,
    plan_path,
)
from agvsim.kinematics import MODELS
from agvsim.scenario import ScenarioError, load_scenario, parse_scenario
from agvsim.scenario import build as build_scenario
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.spec import OdometrySpec, RobotSpec, World
from agvsim.world.grid import OccupancyGrid
from agvsim.world.mazes import random_maze

ALL_MODELS = ["differential", "tricycle", "ackermann", "mecanum", "omni3"]
SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def room_center(grid: OccupancyGrid, i: int, j: int, corridor: int = 2, wall: int = 1):
    """World centre of room (i, j) of a ``random_maze``."""
    r0, c0 = wall + i * (corridor + wall), wall + j * (corridor + wall)
    x, y = grid.cell_center(r0, c0)
    half = 0.5 * (corridor - 1) * grid.resolution_m
    return float(x) + half, float(y) - half


def robot(model: str, pose, mode: str = "inverse", sensors=()) -> RobotSpec:
    m = MODELS[model]()
    return RobotSpec(
        name="r",
        model=m,
        mode=ControlMode(mode),
        body_offset_x_m=float(getattr(m, "wheelbase_m", 0.0)) / 2,
        initial_pose=pose,
        sensors=tuple(sensors),
        odometry=OdometrySpec(wheel_noise_rel=0.01),
    )


def run_until_done(sim: Simulation, ctrl, max_s: float) -> None:
    while ctrl.state_name not in ("reached", "no_path") and sim.state.t_s < max_s:
        sim.step()


# ------------------------------------------------------------------------------------ planning
def test_astar_shortest_paths_and_connectivity():
    cost = np.ones((5, 5))
    cost[1:4, 2] = np.inf  # a wall in the middle column
    path8 = astar(cost, (2, 0), (2, 4), 8)
    path4 = astar(cost, (2, 0), (2, 4), 4)
    assert path8[0] == (2, 0) and path8[-1] == (2, 4)
    assert all(cost[r, c] == 1 for r, c in path8)

    def length(path):
        return sum(
            math.hypot(a[0] - b[0], a[1] - b[1]) for a, b in zip(path, path[1:], strict=False)
        )

    # 8-connected: diagonal up, straight over the wall's end (no corner cutting), diagonal
    # and straight down: 2 sqrt2 + 4
    assert length(path8) == pytest.approx(4 + 2 * math.sqrt(2))
    assert length(path4) == pytest.approx(8.0)  # 2 up, 4 across, 2 down
    cost[:, 2] = np.inf
    assert astar(cost, (2, 0), (2, 4), 8) is None
    with pytest.raises(ValueError, match="connectivity"):
        astar(cost, (0, 0), (0, 1), 6)


def test_astar_does_not_cut_corners():
    cost = np.ones((2, 2))
    cost[0, 1] = cost[1, 0] = np.inf
    assert astar(cost, (0, 0), (1, 1), 8) is None


def test_clearance_map_distances():
    grid = random_maze(3, 3, 0, corridor_cells=2)
    cmap = ClearanceMap(grid, plan_resolution_m=0.25)
    assert cmap.res_m == pytest.approx(0.25)
    x, y = room_center(grid, 0, 0)
    r, c = cmap.cell_of(x + 0.125, y + 0.125)  # a lattice centre 1 m from the nearest walls
    # the room is 2 m wide between walls: 0.875 m to the nearest from this cell centre
    assert cmap.dist[r, c] == pytest.approx(0.875, abs=0.03)
    assert cmap.dist[0, 0] == 0.0  # the border


def test_planned_path_keeps_clear_of_walls():
    grid = random_maze(5, 5, 3, corridor_cells=2)
    cmap = ClearanceMap(grid)
    start, goal = room_center(grid, 0, 0), room_center(grid, 4, 4)
    path = plan_path(cmap, start, goal, half_width_m=0.3, clearance_m=0.05)
    assert path is not None
    np.testing.assert_allclose(path[0], start)
    np.testing.assert_allclose(path[-1], goal)
    dense = np.concatenate(
        [np.linspace(a, b, 10) for a, b in zip(path[:-1], path[1:], strict=True)]
    )
    rows, cols = grid.cell_of(dense[:, 0], dense[:, 1])
    assert not grid.occupied[rows, cols].any()
    r, c = zip(*(cmap.cell_of(x, y) for x, y in dense), strict=True)
    assert cmap.dist[r, c].min() > 0.3  # half width + clearance, less the smoothing
    # the middles of the 2 m corridors are preferred: most of the path is 1 m from walls
    assert np.median(cmap.dist[r, c]) > 0.8


# ------------------------------------------------------------------------------------ A* solver
@pytest.mark.parametrize(
    "seed", [0, 1, *(pytest.param(s, marks=pytest.mark.slow) for s in range(2, 20))]
)  # the fast tier: two mazes a model
@pytest.mark.parametrize("model", ALL_MODELS)
def test_astar_solver_reaches_goal_in_random_mazes(model, seed):
    """Corner room to opposite corner room of a 5 x 5 maze (2 m corridors, 16 m square), the
    robot starting in one of four headings (a car must often K-turn out of its corner room),
    default model parameters and a 0.6 x 0.45 m body; 120 s simulated at most."""
    grid = random_maze(5, 5, seed, corridor_cells=2)
    sx, sy = room_center(grid, 0, 0)
    goal = room_center(grid, 4, 4)
    heading = (seed % 4) * math.pi / 2
    mode = "forward" if seed % 2 else "inverse"
    spec = robot(model, (sx, sy, heading), mode)
    ctrl = AStarMazeSolver(grid, goal_xy_m=goal, body_offset_x_m=spec.body_offset_x_m)
    sim = Simulation(World(grid), [spec], [Binding(ctrl, (0,))], dt_s=0.05)
    run_until_done(sim, ctrl, 120.0)
    assert ctrl.state_name == "reached", f"{model} seed {seed}: {ctrl.state_name}"
    assert np.hypot(*(sim.state.poses[0, :2] - goal)) < 0.3
    assert sim.state.wall_collisions[0] == 0


def test_astar_solver_goal_cell_and_no_path():
    grid = random_maze(3, 3, 1, corridor_cells=2)
    solver = AStarMazeSolver(grid, goal_cell=(7, 7))
    np.testing.assert_allclose(solver.goal, grid.cell_center(7, 7))
    with pytest.raises(ValueError, match="wall"):
        AStarMazeSolver(grid, goal_cell=(0, 0))
    with pytest.raises(ValueError, match="exactly one"):
        AStarMazeSolver(grid)
    # a goal walled off from the robot: the solver says so and stands still
    occ = np.zeros((10, 10), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = occ[:, 5] = True
    walled = OccupancyGrid.from_matrix(occ)
    ctrl = AStarMazeSolver(walled, goal_cell=(4, 7))
    sim = Simulation(
        World(walled), [robot("differential", (-2.5, 0.0, 0.0))], [Binding(ctrl, (0,))]
    )
    sim.run(1.0)
    assert ctrl.state_name == "no_path"
    np.testing.assert_allclose(sim.state.poses[0], [-2.5, 0.0, 0.0])


# ------------------------------------------------------------------------------------ explorer
def lidar(beams: int = 72) -> RangeSensorSpec:
    return RangeSensorSpec.fan("lidar", beams, 2 * np.pi, 4.0, rate_hz=20.0)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
def test_tremaux_explorer_reaches_goal_without_a_map(seed, one_numba_thread):
    """Perfect 5 x 5 mazes, differential drive with a 72-beam 4 m lidar, right hand."""
    grid = random_maze(5, 5, seed, corridor_cells=2)
    start, goal = room_center(grid, 0, 0), room_center(grid, 4, 4)
    ctrl = TremauxExplorer(goal)
    spec = robot("differential", (*start, 0.0), sensors=[lidar()])
    sim = Simulation(World(grid), [spec], [Binding(ctrl, (0,))], dt_s=0.05)
    run_until_done(sim, ctrl, 600.0)
    assert ctrl.state_name == "reached"
    # it stops by odometry: the true position is within the 2 m goal room
    assert np.hypot(*(sim.state.poses[0, :2] - goal)) < 0.8
    assert sim.state.wall_collisions[0] == 0


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_tremaux_explorer_leaves_islands_in_mazes_with_loops(seed, one_numba_thread):
    # with loops a wall follower can circle a free-standing wall for ever: the marks see the
    # lap and the Bug1 rule leaves the island from its point nearest the goal
    grid = random_maze(5, 5, seed, corridor_cells=2, loop_fraction=0.3)
    start, goal = room_center(grid, 0, 0), room_center(grid, 4, 4)
    ctrl = TremauxExplorer(goal, hand="left")
    spec = robot("differential", (*start, 0.0), sensors=[lidar()])
    sim = Simulation(World(grid), [spec], [Binding(ctrl, (0,))], dt_s=0.05)
    run_until_done(sim, ctrl, 600.0)
    assert ctrl.state_name == "reached"
    assert sim.state.wall_collisions[0] == 0


def test_tremaux_explorer_needs_its_sensor():
    grid = random_maze(2, 2, 0)
    ctrl = TremauxExplorer((0.0, 0.0), sensor="lidar")
    sim = Simulation(World(grid), [robot("differential", (*room_center(grid, 0, 0), 0.0))])
    with pytest.raises(ValueError, match="needs the sensor 'lidar'"):
        ctrl.step(sim.observation(0))


# ------------------------------------------------------------------------------------ configs
def test_maze_solver_config_validation_and_build():
    grid = random_maze(3, 3, 0)
    spec = robot("ackermann", (*room_center(grid, 0, 0), 0.0), sensors=[lidar()])
    ctx = ControllerContext(0, spec, grid)
    a = build_maze_solver(
        MazeSolverConfig(type="maze_solver", goal_cell=(7, 7), speed_m_s=0.5), ctx
    )
    assert isinstance(a, AStarMazeSolver) and a.speed == 0.5
    t = build_maze_solver(
        MazeSolverConfig.model_validate(
            {"type": "maze_solver", "method": "tremaux", "goal_x_m": 1.0, "goal_y_m": -1.0}
        ),
        ctx,
    )
    assert isinstance(t, TremauxExplorer)
    np.testing.assert_allclose(t.goal, [1.0, -1.0])
    bad = [
        {"type": "maze_solver"},  # no goal
        {"type": "maze_solver", "goal_cell": [1, 1], "goal_x_m": 1.0, "goal_y_m": 1.0},
        {"type": "maze_solver", "goal_x_m": 1.0},
        {"type": "maze_solver", "goal_cell": [1, 1], "method": "dfs"},
        {"type": "maze_solver", "goal_cell": [1, 1], "connectivity": 6},
        {"type": "maze_solver", "goal_cell": [1, 1], "speed": 1.0},
    ]
    for data in bad:
        with pytest.raises(ValidationError):
            MazeSolverConfig.model_validate(data)
    no_lidar = ControllerContext(0, robot("differential", (0.0, 0.0, 0.0)), grid)
    with pytest.raises(ValueError, match="sensor"):
        build_maze_solver(
            MazeSolverConfig(type="maze_solver", method="tremaux", goal_cell=(7, 7)), no_lidar
        )


# ------------------------------------------------------------------------------------ scenarios
def simulation_from_yaml(path: Path) -> tuple[Simulation, AStarMazeSolver]:
    """The scenario's simulation and its robot's solver. Until the scenario schema knows the
    ``maze_solver`` type, the robot is built with an idle controller and the solver is built
    from the file's controller section here (which must match MazeSolverConfig exactly)."""
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    cfg = MazeSolverConfig.model_validate(data["robots"][0]["controller"])
    try:
        sim = build_scenario(load_scenario(path))
        return sim, sim.bindings[0].controller
    except ScenarioError:
        data["robots"][0]["controller"] = {"type": "idle"}
        sc = parse_scenario(data, str(path))
        bare = build_scenario(sc, base_dir=path.parent)
        ctx = ControllerContext(0, bare.robots[0], bare.world.grid, (bare.robots[0].name,))
        ctrl = build_maze_solver(cfg, ctx)
        sim = Simulation(bare.world, bare.robots, [Binding(ctrl, (0,))], sc.dt_s, sc.seed)
        return sim, ctrl


@pytest.mark.slow
@pytest.mark.parametrize("model", ["differential", "tricycle", "ackermann", "mecanum"])
def test_thesis_maze_scenarios_reach_their_goal(model, one_numba_thread):
    path = SCENARIOS / f"maze_solve_{model}.yaml"
    sim, ctrl = simulation_from_yaml(path)
    assert sim.world.grid.occupied.shape == (20, 20)
    assert sim.robots[0].model.kind == model
    run_until_done(sim, ctrl, 120.0)
    assert ctrl.state_name == "reached"
    assert sim.state.wall_collisions[0] == 0
    np.testing.assert_allclose(ctrl.goal, sim.world.grid.cell_center(14, 14))
