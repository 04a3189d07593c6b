"""The maze-goal task for N worlds stepped by ONE simulation: the core that the Gymnasium
single env (N = 1) and vector env (N worlds) share, so neither holds its own physics.

World k is a random maze (``agvsim.world.mazes.random_maze``) drawn into tile k of one big
occupancy grid; the tiles are laid out on a near-square lattice and every maze has its own
solid border, so robots in different tiles can neither meet nor see each other. Robot k starts
at the centre of one room of its maze (its body centre there, heading random) and must bring
its reference point P within ``goal_radius_m`` of the centre of another room.

An episode is drawn from a ``numpy.random.Generator`` in a fixed order (maze seed, start room,
goal room, heading, noise seed), so a world's episode depends only on its own generator.

Observation (float32, every component in its Box bounds), ``B`` lidar beams:

====================  ==========  =============================================================
slice                 range       meaning
====================  ==========  =============================================================
``[0, B)``            [0, 1]      lidar ranges / ``range_max_m`` (no return reads 1, too close 0)
``B``                 [0, 1]      distance P -> goal / the maze's diagonal (clipped)
``B + 1, B + 2``      [-1, 1]     sin, cos of the goal's bearing in the robot frame
``B + 3 .. B + 5``    [-1, 1]     executed twist (vx, vy, omega) / ``twist_limits`` (0 if none)
``B + 6``             [-1, 1]     steering angle / ``max_steer_rad`` (0 for models without)
====================  ==========  =============================================================

Reward per step: ``progress_per_m`` x (metres of distance to the goal gained) - ``collision``
if the body bumped into a wall during the step + ``success`` on reaching the goal - ``step``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from agvsim.control.api import ControlMode
from agvsim.gym.actions import ActionMap, twist_limits
from agvsim.scenario import ScenarioError, parse_scenario, robot_spec
from agvsim.scenario_schema import RandomMaze
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.spec import World
from agvsim.world.grid import OccupancyGrid
from agvsim.world.mazes import random_maze

DEFAULT_LIDAR: dict[str, Any] = {"beams": 32, "range_max_m": 4.0}
DEFAULT_MAZE: dict[str, Any] = {"rows": 3, "cols": 3, "corridor_cells": 3, "wall_cells": 1}
_SEED_MAX = 2**31


@dataclass(frozen=True)
class Rewards:
    """Reward terms: see the module docstring."""

    progress_per_m: float = 1.0
    collision: float = 0.1
    success: float = 10.0
    step: float = 0.01


@dataclass(frozen=True)
class Episode:
    """What one world's episode is made of, drawn by ``draw_episode``."""

    maze_seed: int
    start_room: int  # room index i * cols + j (row-major, row 0 north)
    goal_room: int
    heading_rad: float
    noise_seed: int  # seeds the simulation's generator (sensor noise) on a full reset


class _Pilot:
    """A batch controller that hands the simulation the env's pending commands."""

    def __init__(self, n: int, width: int):
        self.command = np.zeros((n, width))

    def reset(self, k: int, rng: np.random.Generator) -> None:
        self.command[:] = 0.0

    def step(self, obs: object) -> np.ndarray:
        return self.command


def _renamed(problem: str) -> str:
    """A scenario-schema problem line, in the words of the env's keyword arguments."""
    for old, new in (
        ("robots[0].sensors[0].lidar", "lidar"),
        ("robots[0].sensors[0]", "lidar"),
        ("robots[0].", ""),
        ("robot.params", "params"),
        ("world.random", "maze"),
        ("world.", ""),
    ):
        problem = problem.replace(old, new)
    return problem


def _number(name: str, value: Any, low: float, integer: bool = False) -> float:
    ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    ok = ok and math.isfinite(float(value)) and float(value) >= low
    if ok and integer:
        ok = float(value) == int(value)
    if not ok:
        kind = "an integer" if integer else "a number"
        raise ValueError(f"{name}: must be {kind} >= {low:g}, got {value!r}")
    return float(value)


class MazeTask:
    """N maze-goal worlds in one ``Simulation``; see the module docstring.

    Keyword arguments (all validated here, with errors naming the argument):
    ``model`` (differential | tricycle | ackermann | mecanum | omni3), ``mode`` (inverse |
    forward), ``params`` (model parameters, as in a scenario's ``params``), ``body``
    (``length_m``, ``width_m``, ``offset_x_m``), ``lidar`` (a scenario lidar's keys but
    ``type`` and ``rate_hz``: it scans once per env step), ``maze`` (a scenario ``random``
    maze's keys but ``seed``), ``cell_size_m``, ``dt_s`` (kinematics step), ``action_repeat``
    (kinematics steps per env step), ``max_steps`` (env steps before truncation),
    ``goal_radius_m``, ``rewards`` (a ``Rewards`` or a mapping of its fields).
    """

    def __init__(
        self,
        n: int = 1,
        *,
        model: str = "differential",
        mode: str = "inverse",
        params: Mapping[str, float | str] | None = None,
        body: Mapping[str, float] | None = None,
        lidar: Mapping[str, Any] | None = None,
        maze: Mapping[str, Any] | None = None,
        cell_size_m: float = 0.5,
        dt_s: float = 0.05,
        action_repeat: int = 2,
        max_steps: int = 500,
        goal_radius_m: float = 0.3,
        rewards: Rewards | Mapping[str, float] | None = None,
        source: str = "MazeGoal",
    ):
        self.n = int(_number("num_envs", n, 1, integer=True))
        self.action_repeat = int(_number("action_repeat", action_repeat, 1, integer=True))
        self.max_steps = int(_number("max_steps", max_steps, 1, integer=True))
        self.goal_radius_m = _number("goal_radius_m", goal_radius_m, 0.0)
        if self.goal_radius_m <= 0:
            raise ValueError(f"goal_radius_m: must be > 0, got {goal_radius_m!r}")
        self.rewards = self._rewards(rewards)
        lidar, maze = dict(lidar or {}), dict(maze or {})
        for key, where, why in (
            ("rate_hz", lidar, "the lidar scans once per env step"),
            ("type", lidar, "it is always a lidar"),
            ("seed", maze, "each episode draws its maze seed from the env's generator"),
        ):
            if key in where:
                name = "lidar" if where is lidar else "maze"
                raise ValueError(f"{source}: {name}.{key} cannot be set: {why}")
        data = {
            "dt_s": dt_s,
            "world": {"random": {**DEFAULT_MAZE, **maze}, "cell_size_m": cell_size_m},
            "robots": [
                {
                    "name": "agv",
                    "model": model,
                    "mode": mode,
                    "params": dict(params or {}),
                    "body": dict(body or {}),
                    "sensors": [{"type": "lidar", **DEFAULT_LIDAR, **lidar}],
                    "odometry": {"wheel_noise_rel": 0.0},
                }
            ],
        }
        try:
            sc = parse_scenario(data, source)
            spec = robot_spec(sc.robots[0], "robot", sc.dt_s)
        except ScenarioError as err:
            raise ValueError(f"{source}: " + "; ".join(_renamed(p) for p in err.problems)) from None
        self.dt_s = sc.dt_s
        assert sc.world.random is not None
        self.maze_cfg: RandomMaze = sc.world.random
        self.res_m = sc.world.cell_size_m
        m = self.maze_cfg
        if m.rows * m.cols < 2:
            raise ValueError(f"{source}: maze: needs at least 2 rooms, got {m.rows} x {m.cols}")
        room_m = m.corridor_cells * self.res_m
        hl, hw = spec.footprint_half_m
        if math.hypot(hl, hw) >= room_m / 2:
            raise ValueError(
                f"{source}: body: a {2 * hl:g} x {2 * hw:g} m body cannot turn in a room "
                f"{room_m:g} m wide; use a larger maze.corridor_cells or cell_size_m"
            )
        lidar_spec = replace(spec.sensors[0], rate_hz=1.0 / (self.dt_s * self.action_repeat))
        spec = replace(spec, sensors=(lidar_spec,), color="#d62728")
        self.model, self.mode = spec.model, ControlMode(spec.mode)
        self.actions = ActionMap.for_model(self.model, self.mode)
        self.limits = twist_limits(self.model)
        steer = getattr(self.model, "max_steer_rad", 1.0) if self.model.has_steering else 1.0
        self.max_steer = float(np.min(steer))
        self.beams = lidar_spec.num_beams
        self.range_max_m = lidar_spec.range_max_m
        self.offset_m = spec.body_offset_x_m

        # the lattice of tiles, each one maze of tile_rows x tile_cols cells
        pitch = m.corridor_cells + m.wall_cells
        self.tile_rows = m.rows * pitch + m.wall_cells
        self.tile_cols = m.cols * pitch + m.wall_cells
        self.tiles_x = math.ceil(math.sqrt(self.n))
        self.tiles_y = math.ceil(self.n / self.tiles_x)
        self.tile_w_m, self.tile_h_m = self.tile_cols * self.res_m, self.tile_rows * self.res_m
        self.diag_m = math.hypot(self.tile_w_m, self.tile_h_m)
        self._occ = np.ones((self.tiles_y * self.tile_rows, self.tiles_x * self.tile_cols), bool)
        self._xmin = -self._occ.shape[1] * self.res_m / 2.0
        self._ymax = self._occ.shape[0] * self.res_m / 2.0

        self.goals = np.zeros((self.n, 2))
        self.steps = np.zeros(self.n, dtype=np.int64)
        self.distance = np.zeros(self.n)
        self.maze_seeds = np.zeros(self.n, dtype=np.int64)
        first = [self.draw_episode(np.random.default_rng(k)) for k in range(self.n)]
        for k, ep in enumerate(first):
            self._draw_tile(k, ep.maze_seed)
        specs = [
            replace(spec, name=f"agv{k}", initial_pose=self.start_pose(k, ep))
            for k, ep in enumerate(first)
        ]
        self.pilot = _Pilot(self.n, self.actions.cmd_width)
        self.sim = Simulation(
            World(self._grid()),
            specs,
            [Binding(self.pilot, tuple(range(self.n)), batch=True)],
            dt_s=self.dt_s,
            seed=0,
        )

    # ------------------------------------------------------------------ set-up helpers
    @staticmethod
    def _rewards(rewards: Rewards | Mapping[str, float] | None) -> Rewards:
        if rewards is None or isinstance(rewards, Rewards):
            return rewards or Rewards()
        allowed = [f for f in Rewards.__dataclass_fields__]
        for k, v in dict(rewards).items():
            if k not in allowed:
                raise ValueError(f"rewards: unknown term {k!r} (allowed: {', '.join(allowed)})")
            _number(f"rewards.{k}", v, -math.inf)
        return Rewards(**{k: float(v) for k, v in dict(rewards).items()})

    @property
    def rooms(self) -> int:
        return self.maze_cfg.rows * self.maze_cfg.cols

    def draw_episode(self, rng: np.random.Generator) -> Episode:
        """One episode from ``rng``, always in the same order of draws."""
        maze_seed = int(rng.integers(_SEED_MAX))
        start = int(rng.integers(self.rooms))
        goal = (start + 1 + int(rng.integers(self.rooms - 1))) % self.rooms
        heading = float(rng.uniform(-math.pi, math.pi))
        return Episode(maze_seed, start, goal, heading, int(rng.integers(_SEED_MAX)))

    def _tile_origin(self, k: int) -> tuple[int, int]:
        """(row, col) in the big grid of the top-left cell of tile k."""
        return (k // self.tiles_x) * self.tile_rows, (k % self.tiles_x) * self.tile_cols

    def _draw_tile(self, k: int, maze_seed: int) -> None:
        m = self.maze_cfg
        grid = random_maze(
            m.rows,
            m.cols,
            maze_seed,
            corridor_cells=m.corridor_cells,
            wall_cells=m.wall_cells,
            resolution_m=self.res_m,
            loop_fraction=m.loop_fraction,
        )
        r0, c0 = self._tile_origin(k)
        self._occ[r0 : r0 + self.tile_rows, c0 : c0 + self.tile_cols] = grid.occupied
        self.maze_seeds[k] = maze_seed

    def _grid(self) -> OccupancyGrid:
        return OccupancyGrid.from_matrix(self._occ, self.res_m)

    def tile_extent(self, k: int) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) m of world k's tile."""
        r0, c0 = self._tile_origin(k)
        x0 = self._xmin + c0 * self.res_m
        y1 = self._ymax - r0 * self.res_m
        return (x0, x0 + self.tile_w_m, y1 - self.tile_h_m, y1)

    def room_centre(self, k: int, room: int) -> tuple[float, float]:
        """World (x, y) of the centre of room ``room`` (row-major) of world k's maze."""
        m = self.maze_cfg
        i, j = divmod(room, m.cols)
        pitch = m.corridor_cells + m.wall_cells
        r0, c0 = self._tile_origin(k)
        col = c0 + m.wall_cells + j * pitch + m.corridor_cells / 2.0
        row = r0 + m.wall_cells + i * pitch + m.corridor_cells / 2.0
        return self._xmin + col * self.res_m, self._ymax - row * self.res_m

    def start_pose(self, k: int, ep: Episode) -> tuple[float, float, float]:
        """The pose of P that puts the body centre at the start room's centre."""
        cx, cy = self.room_centre(k, ep.start_room)
        th = ep.heading_rad
        return (cx - self.offset_m * math.cos(th), cy - self.offset_m * math.sin(th), th)

    # ------------------------------------------------------------------ episodes
    def start_all(
        self,
        episodes: list[Episode],
        start: Sequence[float] | None = None,
        goal: Sequence[float] | None = None,
    ) -> np.ndarray:
        """Begin an episode in every world (the simulation restarts at t = 0, its generator
        seeded with the first episode's noise seed). ``start`` / ``goal`` override world 0's
        drawn start pose (x m, y m, theta rad) and goal (x m, y m). Returns the observations."""
        for k, ep in enumerate(episodes):
            self._draw_tile(k, ep.maze_seed)
            self.goals[k] = self.room_centre(k, ep.goal_room)
        sim = self.sim
        sim.set_grid(self._grid())
        for k, ep in enumerate(episodes):
            pose = self.start_pose(k, ep) if (k or start is None) else start
            x, y, th = (float(v) for v in pose)
            sim.robots[k] = replace(sim.robots[k], initial_pose=(x, y, th))
        if goal is not None:
            self.goals[0] = goal
        sim.reset(seed=episodes[0].noise_seed)
        self.steps[:] = 0
        obs, self.distance = self.observe()
        return obs

    def restart(self, worlds: np.ndarray, episodes: list[Episode]) -> None:
        """Put new episodes in ``worlds`` while the others run on: their mazes are redrawn and
        their robots moved to the start, at rest. Their observations come from the next
        ``step``, in which they are commanded to stand still."""
        for k, ep in zip(worlds, episodes, strict=True):
            self._draw_tile(int(k), ep.maze_seed)
            self.goals[k] = self.room_centre(int(k), ep.goal_room)
            pose = self.start_pose(int(k), ep)
            self.sim.robots[k] = replace(self.sim.robots[k], initial_pose=pose)
            self.sim.place(int(k), pose, at_rest=True)
        self.sim.set_grid(self._grid())

    # ------------------------------------------------------------------ the step
    def step(
        self, actions: np.ndarray, resetting: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Apply ``(N, A)`` normalised actions for ``action_repeat`` kinematics steps.

        ``resetting`` (N,) bool marks worlds just ``restart``-ed: they stand still, and their
        reward is 0, terminated and truncated False, step count 0. Returns observations
        (N, D) float32, rewards (N,), terminated (N,), truncated (N,) and an info dict of (N,)
        arrays: ``distance_m``, ``is_success``, ``collided``, ``maze_seed``."""
        cmd = self.actions.to_command(actions)
        fresh = np.zeros(self.n, bool) if resetting is None else np.asarray(resetting, bool)
        cmd[fresh] = 0.0
        self.pilot.command[:] = cmd
        bumped = np.zeros(self.n, dtype=bool)
        for _ in range(self.action_repeat):
            self.sim.step()
            bumped |= self.sim.state.bump
        obs, dist = self.observe()
        reached = (dist <= self.goal_radius_m) & ~fresh
        bumped &= ~fresh
        rw = self.rewards
        reward = (
            rw.progress_per_m * (self.distance - dist)
            - rw.collision * bumped
            + rw.success * reached
            - rw.step
        )
        reward[fresh] = 0.0
        self.distance = dist
        self.steps += 1
        self.steps[fresh] = 0
        truncated = self.steps >= self.max_steps
        info = {
            "distance_m": dist.copy(),
            "is_success": reached.copy(),
            "collided": bumped,
            "maze_seed": self.maze_seeds.copy(),
        }
        return obs, reward, reached, truncated, info

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        """Observations (N, D) float32 (layout in the module docstring) and the distances (N,)
        from P to the goal, m."""
        st, b = self.sim.state, self.beams
        ranges = st.scans[: self.n, :b]  # robot k owns sensor slot k
        out = np.empty((self.n, b + 7))
        np.divide(ranges, self.range_max_m, out=out[:, :b])
        np.clip(out[:, :b], 0.0, 1.0, out=out[:, :b])  # +inf (no return) -> 1, -inf -> 0
        x, y, th = st.poses[:, 0], st.poses[:, 1], st.poses[:, 2]
        dx, dy = self.goals[:, 0] - x, self.goals[:, 1] - y
        c, s = np.cos(th), np.sin(th)
        dist = np.hypot(dx, dy)
        safe = np.where(dist > 1e-12, dist, 1.0)
        out[:, b] = np.minimum(dist / self.diag_m, 1.0)
        out[:, b + 1] = np.where(dist > 1e-12, (-s * dx + c * dy) / safe, 0.0)
        out[:, b + 2] = np.where(dist > 1e-12, (c * dx + s * dy) / safe, 1.0)
        lim = np.where(self.limits > 0, self.limits, 1.0)
        out[:, b + 3 : b + 6] = np.where(self.limits > 0, st.twists / lim, 0.0)
        out[:, b + 6] = st.steering / self.max_steer
        np.clip(out[:, b + 1 :], -1.0, 1.0, out=out[:, b + 1 :])
        return out.astype(np.float32), dist

    @property
    def obs_size(self) -> int:
        return self.beams + 7
