"""A random policy in the maze-goal Gymnasium env, one world and then 16 worlds batched.

    python examples/gym_random.py [--model mecanum] [--mode forward] [--steps 300]
                                  [--frame maze.png]

Prints the episodes' returns and, with ``--frame``, saves the last top view as a PNG.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import agvsim.gym  # noqa: F401 - registers the agvsim/ ids


def main(model: str = "differential", mode: str = "inverse", steps: int = 300, frame=None):
    env = gym.make("agvsim/MazeGoal-v0", model=model, mode=mode, render_mode="rgb_array")
    obs, info = env.reset(seed=42)
    env.action_space.seed(42)
    episode_return, returns = 0.0, []
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        episode_return += reward
        if terminated or truncated:
            returns.append(round(episode_return, 2))
            episode_return = 0.0
            obs, info = env.reset()
    print(f"{model} ({mode}): observation {obs.shape}, action {env.action_space.shape}")
    print(f"  finished episodes' returns {returns}; now {info['distance_m']:.2f} m from the goal")
    if frame:
        from PIL import Image

        Image.fromarray(env.render()).save(frame)
        print(f"  top view saved to {frame}")
    env.close()

    envs = gym.make_vec("agvsim/MazeGoal-v0", num_envs=16, model=model, mode=mode)
    obs, info = envs.reset(seed=42)
    envs.action_space.seed(42)
    successes = 0
    for _ in range(steps):
        obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
        successes += int(np.sum(info["is_success"]))
    print(f"16 worlds in one simulation: observations {obs.shape}, {successes} goals reached")
    envs.close()


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="differential")
    ap.add_argument("--mode", default="inverse")
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--frame", default=None, help="save the last top view to this PNG")
    a = ap.parse_args()
    main(a.model, a.mode, a.steps, a.frame)
