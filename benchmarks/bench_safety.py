"""Safety scanners (issue 18.1): what the safety stage costs per step.

Run ``python benchmarks/bench_safety.py [--robots N] [--steps K]``. N differential robots, each
with a 360-beam lidar at every step, drive in rows on an open floor; the same fleet is run
with and without a ``safety:`` block (three field sets with warning fields) on every robot.
Prints steps per second of both, the ratio, and the safety stage's own time per step (timed
around ``Simulation._guard``), after a warm-up step that compiles the numba kernels. Figures
are printed, never asserted.
"""

from __future__ import annotations

import argparse
import copy
import json
import time

from agvsim.scenario import build, parse_scenario


def box(x0: float, x1: float, y: float) -> list[list[float]]:
    return [[x0, -y], [x1, -y], [x1, y], [x0, y]]


SAFETY = {
    "sensor": "lidar",
    "field_sets": [
        {"name": "reverse", "speed_max_m_s": -0.05, "protective": box(-1.0, 0.35, 0.3)},
        {
            "name": "slow",
            "speed_min_m_s": -0.05,
            "speed_max_m_s": 0.35,
            "protective": box(-0.4, 0.45, 0.3),
            "warning": box(-0.4, 2.2, 0.45),
        },
        {
            "name": "fast",
            "speed_min_m_s": 0.35,
            "protective": box(-0.4, 1.0, 0.3),
            "warning": box(-0.4, 2.2, 0.45),
        },
    ],
}


def fleet(n: int, safety: bool) -> dict:
    side = 60
    robots = []
    for k in range(n):
        robots.append(
            {
                "name": f"r{k}",
                "model": "differential",
                "params": {"max_wheel_speed_rad_s": 10.0},
                "pose": {"x_m": -25.0 + 2.0 * (k % 20), "y_m": -25.0 + 2.5 * (k // 20)},
                "sensors": [{"type": "lidar", "beams": 360, "fov_deg": 360, "rate_hz": 50}],
                "controller": {"type": "script", "steps": [{"duration_s": 1e4, "twist": [0.6, 0]}]},
                **({"safety": copy.deepcopy(SAFETY)} if safety else {}),
            }
        )
    world = {"matrix": [[0] * side for _ in range(side)]}
    return {"name": "bench", "dt_s": 0.02, "world": world, "robots": robots}


def run(n: int, steps: int, safety: bool) -> dict:
    sim = build(parse_scenario(fleet(n, safety), limits_from_file=False))
    sim.step()  # compile
    guard_s = 0.0
    if safety:
        inner = sim._guard

        def timed() -> None:
            nonlocal guard_s
            t = time.perf_counter()
            inner()
            guard_s += time.perf_counter() - t

        sim._guard = timed  # type: ignore[method-assign]
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
    wall = time.perf_counter() - t0
    out = {"steps_per_s": round(steps / wall, 1)}
    if safety:
        out["safety_stage_us_per_step"] = round(1e6 * guard_s / steps, 1)
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=100)
    ap.add_argument("--steps", type=int, default=200)
    a = ap.parse_args()
    without, with_ = run(a.robots, a.steps, False), run(a.robots, a.steps, True)
    res = {
        "robots": a.robots,
        "beams": 360,
        "without_safety": without,
        "with_safety": with_,
        "ratio": round(with_["steps_per_s"] / without["steps_per_s"], 3),
    }
    print(json.dumps(res, indent=2))
