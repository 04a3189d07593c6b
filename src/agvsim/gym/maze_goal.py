"""``MazeGoalEnv``: reach a goal in a random maze from lidar scans, for any kinematic model
and control mode (Gymnasium ``Env``; ids ``agvsim/MazeGoal-v0`` and one per model).

The physics, observation, action and reward are those of :class:`agvsim.gym.maze_task.MazeTask`
with one world; the vector env (:mod:`agvsim.gym.vector`) steps many worlds with the same code.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from agvsim.gym.actions import check_actions
from agvsim.gym.maze_task import MazeTask
from agvsim.gym.render import check_render_mode, frame


def observation_space(task: MazeTask) -> spaces.Box:
    """The Box of one world's observation (layout: ``agvsim.gym.maze_task``)."""
    b = task.beams
    low = np.concatenate([np.zeros(b + 1), -np.ones(6)]).astype(np.float32)
    return spaces.Box(low, np.ones(b + 7, dtype=np.float32), dtype=np.float32)


def action_space(task: MazeTask) -> spaces.Box:
    """``[-1, 1]^A``: see ``agvsim.gym.actions`` for what each component means."""
    a = task.actions.width
    return spaces.Box(-np.ones(a, np.float32), np.ones(a, np.float32), dtype=np.float32)


class MazeGoalEnv(gym.Env):
    """Drive a robot from one room of a random maze to the centre of another.

    Every ``reset`` draws a new maze (``agvsim.world.mazes.random_maze``), start room, goal room
    and heading from the env's generator, so ``reset(seed=s)`` gives the same episode bit for
    bit. Keyword arguments are those of :class:`~agvsim.gym.maze_task.MazeTask` plus
    ``render_mode`` (None or ``"rgb_array"``) and ``render_width_px``.

    ``reset(options=...)`` may fix the episode: ``maze_seed`` (int), ``start_pose`` (x m, y m,
    theta rad; world frame, the maze is centred on the origin) and ``goal_xy`` (x m, y m).

    ``info``: ``distance_m`` (P to goal), ``is_success``, ``collided`` (bumped during the step),
    ``maze_seed`` (rebuild the maze with ``world: {random: {seed: ...}}``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, render_mode: str | None = None, render_width_px: int = 320, **task: Any):
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])
        self.render_width_px = int(render_width_px)
        self.task = MazeTask(1, source="MazeGoalEnv", **task)
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.step_s)}
        self.observation_space = observation_space(self.task)
        self.action_space = action_space(self.task)

    @property
    def step_s(self) -> float:
        """Simulated seconds per env step."""
        return self.task.dt_s * self.task.action_repeat

    @property
    def sim(self):
        """The underlying :class:`agvsim.sim.engine.Simulation` (read it, do not step it)."""
        return self.task.sim

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        opts = dict(options or {})
        unknown = sorted(set(opts) - {"maze_seed", "start_pose", "goal_xy"})
        if unknown:
            raise ValueError(
                f"reset options: unknown key(s) {unknown} (allowed: goal_xy, maze_seed, start_pose)"
            )
        ep = self.task.draw_episode(self.np_random)
        if "maze_seed" in opts:
            from dataclasses import replace

            ep = replace(ep, maze_seed=_int_option("maze_seed", opts["maze_seed"]))
        start = _xy_option("start_pose", opts["start_pose"], 3) if "start_pose" in opts else None
        goal = _xy_option("goal_xy", opts["goal_xy"], 2) if "goal_xy" in opts else None
        obs = self.task.start_all([ep], start, goal)
        self._check_options(start, goal)
        return obs[0], self._info()

    def _check_options(self, start, goal) -> None:
        sim = self.task.sim
        if start is not None and sim.collider.hit_walls(sim.footprints(sim.state.poses))[0]:
            raise ValueError(
                f"reset options: start_pose {tuple(start)} puts the robot's body in a wall or "
                "outside the maze; pick a pose on free floor"
            )
        if goal is not None and bool(sim.world.grid.is_occupied_at(goal[0], goal[1])):
            raise ValueError(
                f"reset options: goal_xy {tuple(goal)} is on a wall or outside the maze, which "
                f"spans {sim.world.grid.extent_m} m (xmin, xmax, ymin, ymax)"
            )

    def _info(self) -> dict[str, Any]:
        return {
            "distance_m": float(self.task.distance[0]),
            "is_success": False,
            "collided": False,
            "maze_seed": int(self.task.maze_seeds[0]),
        }

    def step(self, action) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = check_actions(action, (self.task.actions.width,), "MazeGoalEnv.step action")
        obs, reward, terminated, truncated, info = self.task.step(a[None, :])
        out = {k: v[0].item() for k, v in info.items()}
        return obs[0], float(reward[0]), bool(terminated[0]), bool(truncated[0]), out

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        t = self.task
        return frame(t.sim, t.goals, t.goal_radius_m, self.render_width_px)


def _int_option(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise ValueError(f"reset options: {name} must be an integer >= 0, got {value!r}")
    return int(value)


def _xy_option(name: str, value: object, n: int) -> tuple[float, ...]:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        v = np.zeros(0)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        what = "(x m, y m, theta rad)" if n == 3 else "(x m, y m)"
        raise ValueError(f"reset options: {name} must be {n} finite numbers {what}, got {value!r}")
    return tuple(float(x) for x in v)
