"""Gymnasium throughput: env steps per second of the maze-goal task, N worlds in ONE simulation
(``MazeGoalVectorEnv``) against N single ``MazeGoalEnv`` (each its own simulation) stepped in
a Python loop, and against Gymnasium's ``SyncVectorEnv`` of N single envs.

Run ``python benchmarks/bench_gym.py [--worlds 64] [--steps 200] [--model differential]``.
Every world takes a random action each step (a seeded generator), episodes autoreset. The first
env creation and steps (numba compile or cache load) are timed apart and not counted.
Prints one line per way of stepping and the speed-up of the vector env.
"""

from __future__ import annotations

import argparse
import json
import time

import gymnasium as gym
import numpy as np

from agvsim.gym import MazeGoalEnv, MazeGoalVectorEnv


def _rate(step, n_worlds: int, steps: int) -> float:
    """World-steps per second of ``steps`` calls of ``step(t)`` that each advance n worlds."""
    t0 = time.perf_counter()
    for t in range(steps):
        step(t)
    return n_worlds * steps / (time.perf_counter() - t0)


def bench_gym(worlds: int = 64, steps: int = 200, model: str = "differential") -> dict:
    kw = {"model": model}
    t0 = time.perf_counter()
    warm = MazeGoalEnv(**kw)
    warm.reset(seed=0)
    for _ in range(5):
        warm.step(warm.action_space.sample())
    first_s = time.perf_counter() - t0

    rng = np.random.default_rng(0)
    vec = MazeGoalVectorEnv(worlds, **kw)
    vec.reset(seed=0)
    width = vec.single_action_space.shape[0]
    acts = rng.uniform(-1, 1, (steps, worlds, width)).astype(np.float32)

    def step_vector(t: int) -> None:
        vec.step(acts[t])

    singles = [MazeGoalEnv(**kw) for _ in range(worlds)]
    for k, e in enumerate(singles):
        e.reset(seed=k)

    def step_singles(t: int) -> None:
        for k, e in enumerate(singles):
            _, _, term, trunc, _ = e.step(acts[t, k])
            if term or trunc:
                e.reset()

    sync = gym.vector.SyncVectorEnv([lambda: MazeGoalEnv(**kw) for _ in range(worlds)])
    sync.reset(seed=0)

    def step_sync(t: int) -> None:
        sync.step(acts[t])

    out = {
        "worlds": worlds,
        "steps": steps,
        "model": model,
        "first_env_and_steps_s": round(first_s, 3),
        "vector_env_steps_per_s": round(_rate(step_vector, worlds, steps)),
        "single_envs_loop_steps_per_s": round(_rate(step_singles, worlds, steps)),
        "sync_vector_env_steps_per_s": round(_rate(step_sync, worlds, steps)),
    }
    out["vector_speedup_vs_single_loop"] = round(
        out["vector_env_steps_per_s"] / out["single_envs_loop_steps_per_s"], 1
    )
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--worlds", type=int, default=64)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--model", default="differential")
    args = ap.parse_args()
    print(json.dumps(bench_gym(args.worlds, args.steps, args.model), indent=2))
