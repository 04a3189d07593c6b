"""Robustness suite: SLAM with the one default configuration on every log, unchanged and with
faults a real robot's log may carry (:mod:`agvsim.slam.perturb`).

Run ``python benchmarks/bench_slam_robustness.py [--logs aces intel mit-killian]
[--faults none freeze ...] [--jobs N] [--seed S]``. Each (log, fault) case runs in its own
process (one numba thread; ``--jobs`` cases at a time, 1 by default) and prints

* scans and keyframes processed, loop-closure edges, wall seconds and the real-time factor;
* the mean translational error (m) of SLAM and of the faulty odometry alone on the relations
  whose two scans survived the fault (Kümmerle et al.), and their count;
* SLAM's error over the unperturbed SLAM error of the same log (target <= 1.5) and over
  odometry's (target < 1);
* the process's peak resident memory (MiB).

MIT Killian Court has no usable relations (synthetic time stamps): it is scored by the map's
own consistency, the share of keyframe returns that land within 0.1 m of an occupied cell of
the final map (a doubled wall leaves returns of one pass in the other pass's free space).
Prints numbers; does not gate. Without the data sets folder it prints a note and exits.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from agvsim.slam.carmen import CarmenLog  # noqa: E402
from agvsim.slam.datasets import datasets_dir  # noqa: E402
from agvsim.slam.evaluate import (  # noqa: E402
    Relations,
    Trajectory,
    evaluate_relations,
    load_relations,
)
from agvsim.slam.offline import map_scans  # noqa: E402
from agvsim.slam.perturb import Fault, apply_fault  # noqa: E402

LOGS = {
    "aces": ("aces/aces.clf.gz", "aces/aces.relations"),
    "intel": ("intel/intel.clf.gz", "intel/intel.relations"),
    "mit-killian": ("mit-killian/mit-killian.synthetic-time.clf.gz", None),
}


def _odometry_error(stamps: np.ndarray, odom: np.ndarray, rel: Relations) -> float:
    return evaluate_relations(Trajectory(stamps, odom), rel).translation_mean_m


def run_case(root: Path, log: str, fault: str, seed: int) -> dict[str, float | int | str]:
    """One (log, fault) case; returns its figures (runs in a worker process)."""
    path, rel_path = LOGS[log]
    rng = np.random.default_rng(seed)
    stamps: list[float] = []
    odoms: list[np.ndarray] = []

    def tap(scans: CarmenLog):  # type: ignore[no-untyped-def]
        for rec in apply_fault(scans, fault, rng):
            stamps.append(rec.timestamp_s)
            odoms.append(rec.odom_pose)
            yield rec

    t0 = time.perf_counter()
    slam = map_scans(tap(CarmenLog(root / path)))
    wall = time.perf_counter() - t0
    assert slam is not None
    t, poses = slam.trajectory()
    out: dict[str, float | int | str] = {
        "log": log,
        "fault": fault,
        "scans": len(t),
        "keyframes": len(slam.keyframes),
        "loops": len(slam.loop_edges),
        "wall_s": wall,
        "rt": float(t[-1] - t[0]) / wall,
    }
    if rel_path is not None:
        rel = load_relations(root / rel_path)
        err = evaluate_relations(Trajectory(t, poses), rel)
        out["slam_m"] = err.translation_mean_m
        out["relations"] = err.count
        out["odom_m"] = _odometry_error(np.asarray(stamps), np.asarray(odoms), rel)
    else:
        out["consistency"] = map_consistency(slam)
    out["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


def map_consistency(slam) -> float:  # type: ignore[no-untyped-def]
    """Share of keyframe returns (every 5th keyframe) within 0.1 m of an occupied cell of the
    final map."""
    from scipy.ndimage import binary_dilation

    from agvsim.slam.se2 import compose

    grid = slam.occupancy_map()
    occ = binary_dilation(grid.logodds > 0, iterations=2)  # 2 cells of 0.05 m
    poses = slam.keyframe_poses()
    hits = total = 0
    for p, kf in list(zip(poses, slam.keyframes, strict=True))[::5]:
        pts = kf.ends[kf.hits].astype(np.float64)
        world = compose(p, np.column_stack([pts, np.zeros(len(pts))]))[:, :2]
        ij = np.floor((world - np.asarray(grid.origin_xy_m)) / grid.resolution_m).astype(int)
        h, w = occ.shape
        ok = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < w) & (ij[:, 1] < h)
        hits += int(occ[ij[ok, 1], ij[ok, 0]].sum())
        total += len(pts)
    return hits / max(total, 1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", nargs="*", default=["aces", "intel"], choices=list(LOGS))
    ap.add_argument("--faults", nargs="*", default=[f.value for f in Fault], choices=list(Fault))
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    root = datasets_dir()
    if root is None:
        print("robustness suite skipped: no data sets folder (set AGVSIM_DATASETS)")
        return 0
    cases = [(log, f) for log in args.logs for f in args.faults]
    print(
        f"{'log':<12}{'fault':<13}{'scans':>6}{'kf':>6}{'loops':>6}{'SLAM m':>9}{'odom m':>9}"
        f"{'/base':>7}{'/odom':>7}{'rel':>6}{'RTx':>7}{'wall s':>8}{'MiB':>7}",
        flush=True,
    )
    base: dict[str, float] = {}
    with ProcessPoolExecutor(max_workers=args.jobs, max_tasks_per_child=1) as pool:
        futures = [pool.submit(run_case, root, log, f, args.seed) for log, f in cases]
        for fut in futures:
            r = fut.result()
            log = str(r["log"])
            if "slam_m" in r:
                slam_m, odom_m = float(r["slam_m"]), float(r["odom_m"])
                if r["fault"] == "none":
                    base[log] = slam_m
                ratio = slam_m / base[log] if log in base else float("nan")
                score = (
                    f"{slam_m:>9.4f}{odom_m:>9.3f}{ratio:>7.2f}{slam_m / odom_m:>7.3f}"
                    f"{int(r['relations']):>6d}"
                )
            else:
                score = f"{'consistency ' + format(float(r['consistency']), '.3f'):>38}"
            print(
                f"{log:<12}{str(r['fault']):<13}{int(r['scans']):>6d}{int(r['keyframes']):>6d}"
                f"{int(r['loops']):>6d}{score}{float(r['rt']):>7.1f}{float(r['wall_s']):>8.1f}"
                f"{float(r['peak_mib']):>7.0f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
