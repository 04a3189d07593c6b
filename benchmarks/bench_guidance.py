"""The guidance stage's cost: steps/s of each guidance scenario (docs/guidance.md) against the
same vehicle on odometry alone, on ONE core; figures are printed, never asserted.

python benchmarks/bench_guidance.py [--quick]

Each scenario is built and stepped once first (numba compile or cache load), then timed over
its whole 60 s route (--quick: 10 s). The controllers run too (the route follower's filter, the
line follower's PID), as in ``agvsim run`` without outputs.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from agvsim.scenario import build, load_scenario

ROOT = Path(__file__).resolve().parent.parent
STEMS = (
    "guidance_odometry",
    "guidance_tape",
    "guidance_floor_codes",
    "guidance_reflectors",
    "guidance_reflectors_blind_spot",
)


def bench(quick: bool) -> dict:
    out: dict = {}
    for stem in STEMS:
        sc = load_scenario(ROOT / "scenarios" / f"{stem}.yaml")
        build(sc).step()  # compile / load the kernels
        sim = build(sc)
        steps = int(round((10.0 if quick else sc.duration_s) / sim.dt_s))
        t0 = time.perf_counter()
        for _ in range(steps):
            sim.step()
        wall = time.perf_counter() - t0
        out[stem] = {
            "steps": steps,
            "steps_per_s": round(steps / wall, 1),
            "real_time_factor": round(steps * sim.dt_s / wall, 1),
        }
    base = out["guidance_odometry"]["steps_per_s"]
    for v in out.values():
        v["vs_odometry"] = round(v["steps_per_s"] / base, 3)
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10 s of each route")
    args = ap.parse_args()
    print(json.dumps(bench(args.quick), indent=2))
