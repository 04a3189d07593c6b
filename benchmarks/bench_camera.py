"""Onboard camera throughput: frames per second of one 320 x 240 RGB-D camera on ONE core.

Run ``python benchmarks/bench_camera.py [--quick]`` (also part of ``agvsim bench``, under
``camera``). The scene is the thesis App. C.1 maze with four ArUco markers and four robots
(seen as boxes); the camera is moved over random free poses, level and pitched 10 deg. The
time of the first frame (numba compile or cache load, and building the simulation) is printed
apart from the steady-state rate, and steps/s of the four robots with a 10 Hz camera each are
set against the same robots without cameras. Figures are printed, never asserted.
"""

from __future__ import annotations

import argparse
import json

from agvsim.bench import camera_benchmark

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames and steps")
    args = ap.parse_args()
    print(json.dumps(camera_benchmark(quick=args.quick), indent=2))
