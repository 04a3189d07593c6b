"""Reinforcement-learning environments on agvsim (Gymnasium and PettingZoo).

Importing this package registers the Gymnasium ids (docs/gym.md):

==================================  =============================================================
id                                  environment
==================================  =============================================================
``agvsim/MazeGoal-v0``              reach a goal in a random maze from lidar scans; keyword
                                    ``model`` (differential | tricycle | ackermann | mecanum |
                                    omni3, default differential) and ``mode`` (inverse |
                                    forward); ``gym.make_vec`` gives the batched vector env
``agvsim/MazeGoal<Model>-v0``       the same with the model fixed: ``MazeGoalDifferential``,
                                    ``MazeGoalTricycle``, ``MazeGoalAckermann``,
                                    ``MazeGoalMecanum``, ``MazeGoalOmni3``
==================================  =============================================================

    import gymnasium as gym
    import agvsim.gym  # registers the ids
    env = gym.make("agvsim/MazeGoal-v0", model="mecanum", mode="forward")
    envs = gym.make_vec("agvsim/MazeGoal-v0", num_envs=64)  # one simulation, 64 worlds

The multi-robot pursuit of the thesis is a PettingZoo parallel env:
``from agvsim.gym import pursuit_v0; env = pursuit_v0.parallel_env()``.
"""

from __future__ import annotations

import gymnasium

from agvsim.gym.maze_goal import MazeGoalEnv
from agvsim.gym.maze_task import MazeTask, Rewards
from agvsim.gym.vector import MazeGoalVectorEnv

__all__ = ["ENV_IDS", "MazeGoalEnv", "MazeGoalVectorEnv", "MazeTask", "Rewards"]

#: id -> keyword arguments it fixes; every id has the single and the vector entry point
ENV_IDS: dict[str, dict[str, str]] = {
    "agvsim/MazeGoal-v0": {},
    "agvsim/MazeGoalDifferential-v0": {"model": "differential"},
    "agvsim/MazeGoalTricycle-v0": {"model": "tricycle"},
    "agvsim/MazeGoalAckermann-v0": {"model": "ackermann"},
    "agvsim/MazeGoalMecanum-v0": {"model": "mecanum"},
    "agvsim/MazeGoalOmni3-v0": {"model": "omni3"},
}

for _id, _kwargs in ENV_IDS.items():
    if _id not in gymnasium.registry:  # importing twice (e.g. a reload) registers once
        gymnasium.register(
            _id,
            entry_point=MazeGoalEnv,
            vector_entry_point=MazeGoalVectorEnv,
            kwargs=dict(_kwargs),
        )
