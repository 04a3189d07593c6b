"""Planar dynamics (issue 20): steps per CPU second of 1000 robots with and without dynamics.

Run ``python benchmarks/bench_dynamics.py [--quick] [--robots N]`` (also part of ``agvsim
bench``, under ``dynamics``). ``bare``: robots on an open floor with no sensors, so the ratio
is the dynamics' own cost against the kinematic step; ``fleet``: the ``agvsim bench`` fleet
(maze, 240-beam lidars, obstacle avoidance). Figures are printed, never asserted.
"""

from __future__ import annotations

import argparse
import json

from agvsim.bench_dynamics import dynamics_benchmark

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer steps")
    ap.add_argument("--robots", type=int, default=1000)
    args = ap.parse_args()
    print(json.dumps(dynamics_benchmark(quick=args.quick, n=args.robots), indent=2))
