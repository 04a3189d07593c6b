"""``MazeGoalVectorEnv``: N maze-goal worlds stepped by ONE simulation (one batched engine
step for every robot), as a Gymnasium ``VectorEnv`` with next-step autoreset.

World k behaves exactly as a ``MazeGoalEnv`` seeded with ``seed + k`` (same mazes, starts,
goals and, without sensor noise, the same observations to float rounding: the worlds sit in
tiles of one big map, so their coordinates differ by the tile offsets) and run under
Gymnasium's next-step autoreset, as ``gymnasium.vector.SyncVectorEnv`` runs single envs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from agvsim.gym.actions import check_actions
from agvsim.gym.maze_goal import action_space, observation_space
from agvsim.gym.maze_task import MazeTask
from agvsim.gym.render import check_render_mode, frame


class MazeGoalVectorEnv(VectorEnv):
    """``num_envs`` maze-goal worlds in one simulation. Keyword arguments: those of
    :class:`~agvsim.gym.maze_task.MazeTask`, ``render_mode`` (None or ``"rgb_array"``: a
    top view per world; ``render_all`` draws them all in one picture) and ``render_width_px``
    (of one world).

    ``reset(seed=s)`` seeds world k with ``s + k`` (a list seeds each world); worlds that end
    (terminated or truncated) are reset on the next ``step``, whose action for them is ignored
    (``metadata["autoreset_mode"]`` is ``NEXT_STEP``). ``info`` holds (N,) arrays
    ``distance_m``, ``is_success``, ``collided``, ``maze_seed``, each with its ``_name`` mask.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 16,
        render_mode: str | None = None,
        render_width_px: int = 160,
        **task: Any,
    ):
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])
        self.render_width_px = int(render_width_px)
        self.task = MazeTask(num_envs, source="MazeGoalVectorEnv", **task)
        self.num_envs = self.task.n
        self.single_observation_space = observation_space(self.task)
        self.single_action_space = action_space(self.task)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._rngs = [seeding.np_random(None)[0] for _ in range(self.num_envs)]
        self._autoreset = np.zeros(self.num_envs, dtype=bool)

    @property
    def sim(self):
        """The one :class:`agvsim.sim.engine.Simulation` of all worlds (read it, do not step it)."""
        return self.task.sim

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if options:
            raise ValueError(
                f"MazeGoalVectorEnv.reset: options are not supported, got {sorted(options)}; "
                "fix an episode with a single MazeGoalEnv"
            )
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, int | np.integer) and not isinstance(seed, bool):
            seeds = [int(seed) + k for k in range(self.num_envs)]
        else:
            seeds = list(seed)  # type: ignore[arg-type]
            if len(seeds) != self.num_envs:
                raise ValueError(
                    f"MazeGoalVectorEnv.reset: {len(seeds)} seeds for {self.num_envs} worlds"
                )
        for k, s in enumerate(seeds):
            if s is not None:
                self._rngs[k] = seeding.np_random(s)[0]
        self._np_random = self._rngs[0]  # reported by `np_random`, as for one env
        episodes = [self.task.draw_episode(r) for r in self._rngs]
        obs = self.task.start_all(episodes)
        self._autoreset[:] = False
        t = self.task
        info = self._with_masks(
            {
                "distance_m": t.distance.copy(),
                "is_success": np.zeros(self.num_envs, bool),
                "collided": np.zeros(self.num_envs, bool),
                "maze_seed": t.maze_seeds.copy(),
            }
        )
        return obs, info

    def step(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        shape = (self.num_envs, self.task.actions.width)
        a = check_actions(actions, shape, "MazeGoalVectorEnv.step actions")
        fresh = self._autoreset.copy()
        if fresh.any():
            worlds = np.flatnonzero(fresh)
            self.task.restart(worlds, [self.task.draw_episode(self._rngs[k]) for k in worlds])
        obs, reward, terminated, truncated, info = self.task.step(a, fresh)
        self._autoreset = terminated | truncated
        return obs, reward, terminated, truncated, self._with_masks(info)

    def _with_masks(self, info: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        mask = np.ones(self.num_envs, dtype=bool)
        return {**info, **{f"_{k}": mask for k in info}}

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One ``(H, W, 3) uint8`` top view per world (``render_width_px`` wide), as
        Gymnasium's vector wrappers (e.g. ``RecordVideo``) expect; cut from ``render_all``."""
        if self.render_mode != "rgb_array":
            return None
        t = self.task
        img = self.render_all()
        scale = self.render_width_px / t.tile_w_m
        h = int(round(t.tile_h_m * scale))
        out = []
        for k in range(self.num_envs):
            by, bx = divmod(k, t.tiles_x)
            r0, c0 = int(round(by * t.tile_h_m * scale)), bx * self.render_width_px
            out.append(img[r0 : r0 + h, c0 : c0 + self.render_width_px].copy())
        return tuple(out)

    def render_all(self) -> np.ndarray:
        """One ``(H, W, 3) uint8`` top view of every world's tile (goals in green)."""
        t = self.task
        return frame(t.sim, t.goals, t.goal_radius_m, self.render_width_px * t.tiles_x)
