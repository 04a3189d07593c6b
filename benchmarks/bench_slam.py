"""Offline graph SLAM on real laser logs: speed (real-time factor) and accuracy (Kümmerle metric).

Run ``python benchmarks/bench_slam.py [--mit] [--out DIR] [--no-pin]``. For Intel and ACES (and
MIT Killian Court with ``--mit``, unscored: its time stamps are synthetic) it runs
:func:`agvsim.slam.offline.run_offline` with the one default configuration and prints

* wall and CPU seconds and the real-time factor (log duration / processing time), on one core:
  the process is pinned to one CPU and numba to one thread (``--no-pin`` leaves it free);
* the mean and standard deviation of the translational (m) and rotational (deg) relative-pose
  errors over all relations, beside the published results.

The numba compile (or cache load) is timed apart, on a short slice, before the runs. The data
sets come from :func:`agvsim.slam.datasets.datasets_dir`; without them it prints a note and exits.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

from agvsim.slam.datasets import datasets_dir  # noqa: E402
from agvsim.slam.evaluate import evaluate_relations, load_relations, load_trajectory  # noqa: E402
from agvsim.slam.offline import run_offline  # noqa: E402

# (log, relations, published mean translational error in m: Cartographer, graph mapping, odometry)
DATASETS = {
    "intel": ("intel/intel.clf.gz", "intel/intel.relations", (0.0229, 0.031, 7.38)),
    "aces": ("aces/aces.clf.gz", "aces/aces.relations", (0.0375, 0.044, 0.549)),
    "mit-killian": ("mit-killian/mit-killian.synthetic-time.clf.gz", None, None),
}


def _pin_one_core() -> str:
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned (no sched_setaffinity)"
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return f"pinned to CPU {cpu}"


def bench(name: str, root: Path, out: Path) -> None:
    log, rel, published = DATASETS[name]
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    res = run_offline(root / log, out / name)
    wall, cpu = time.perf_counter() - t_wall, time.process_time() - t_cpu
    dur = res.log_duration_s
    print(
        f"\n{name}: {res.n_scans} scans, {dur:.0f} s of data, {res.n_keyframes} keyframes, "
        f"{res.n_submaps} submaps, {res.n_loop_closures} loop-closure edges"
    )
    print(f"  processing      {wall:7.1f} s wall  {cpu:7.1f} s CPU")
    if rel is not None:
        print(f"  real time x     {dur / wall:7.1f} wall  {dur / cpu:7.1f} CPU")
    print(f"  map             {res.map_png_path}")
    if rel is None or published is None:
        return
    err = evaluate_relations(load_trajectory(res.trajectory_path), load_relations(root / rel))
    carto, graph, odom = published
    print(
        f"  translation m   {err.translation_mean_m:.4f} +- {err.translation_std_m:.4f}   "
        f"(Cartographer {carto}, graph mapping {graph}, odometry {odom}; "
        f"{err.count} relations)"
    )
    print(f"  rotation deg    {err.rotation_mean_deg:.3f} +- {err.rotation_std_deg:.3f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mit", action="store_true", help="also run MIT Killian Court (unscored)")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: temporary)")
    ap.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU")
    args = ap.parse_args(argv)
    root = datasets_dir()
    if root is None:
        print("SLAM benchmark skipped: no data sets folder (set AGVSIM_DATASETS)")
        return 0
    print(
        "single core:",
        "not pinned" if args.no_pin else _pin_one_core(),
        f"NUMBA_NUM_THREADS={os.environ['NUMBA_NUM_THREADS']}",
    )
    names = ["intel", "aces"] + (["mit-killian"] if args.mit else [])
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        t0 = time.perf_counter()
        run_offline(root / DATASETS["intel"][0], out / "warmup", max_scans=200)
        print(f"numba compile / cache load + 200 scans: {time.perf_counter() - t0:.1f} s")
        for name in names:
            if (root / DATASETS[name][0]).is_file():
                bench(name, root, out)
            else:
                print(f"\n{name}: skipped, {root / DATASETS[name][0]} not found")
    return 0


if __name__ == "__main__":
    sys.exit(main())
