"""Cost of the per-call time limit on python controllers (agvsim.sim.watchdog): steps/s of a
simulation whose robots each run a trivial user controller, with and without the limit.

Run ``python benchmarks/bench_controller_limit.py [--steps 4000]``. While the limit is
enforced, each user controller call reads the monotonic clock twice and a timer ticks every
quarter of the limit; the figures show what that adds per step and per call. Figures are
printed, never asserted.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from agvsim.kinematics import DifferentialDrive
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.spec import RobotSpec, World
from agvsim.world.grid import OccupancyGrid


def _still(obs):
    return (0.0, 0.0, 0.0)


def _sim(n_robots: int, limit_s: float | None) -> Simulation:
    m = np.zeros((12, 12), dtype=int)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = 1
    world = World(OccupancyGrid.from_matrix(m, 1.0, (0.0, 0.0)))
    model = DifferentialDrive(wheel_radius_m=0.1, half_track_m=0.25)
    robots = [
        RobotSpec(name=f"r{i}", model=model, initial_pose=(2.0 + 0.8 * (i % 10), 2.0 + i // 10, 0))
        for i in range(n_robots)
    ]
    bindings = [Binding(_still, (i,), user_code=True) for i in range(n_robots)]
    return Simulation(world, robots, bindings, controller_time_limit_s=limit_s)


def _steps_per_s(n_robots: int, limit_s: float | None, steps: int) -> float:
    sim = _sim(n_robots, limit_s)
    sim.run(0.2)  # warm up (kernels from numba's cache)
    with sim.enforcing_time_limit():
        t0 = time.perf_counter()
        for _ in range(steps):
            sim.step()
        return steps / (time.perf_counter() - t0)


def main(steps: int) -> dict:
    out = {}
    for n in (1, 20):
        best = {}
        for label, limit in (("no_limit", None), ("limit_10s", 10.0)):
            best[label] = max(_steps_per_s(n, limit, steps) for _ in range(3))  # best of 3
        extra_us = (1 / best["limit_10s"] - 1 / best["no_limit"]) * 1e6
        out[f"{n}_robots"] = {
            "steps_per_s_no_limit": round(best["no_limit"]),
            "steps_per_s_limit": round(best["limit_10s"]),
            "extra_us_per_step": round(extra_us, 1),
            "extra_us_per_call": round(extra_us / n, 2),
        }
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=4000)
    print(json.dumps(main(ap.parse_args().steps), indent=2))
