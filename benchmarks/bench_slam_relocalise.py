"""Cost of one global relocalisation try (``GraphSlam.relocalise``) on a real log.

Run ``python benchmarks/bench_slam_relocalise.py [--log intel] [--max-scans N] [--tries 8]``.
It maps the log with the default configuration (one numba thread), keeping the raw scans of
``--tries`` keyframes spread over the log. Each of those scans is then looked for in
everything mapped, as if the robot had been carried off: tracking's pose is put 20 m away
and its score at 0, so the search must find the place on its own. For each try it prints the
CPU time, the score and how far the found pose lies from the one SLAM mapped the scan at
(global frame), and then the median CPU time of a try. The first try builds what the search
needs per submap (cached pyramids): its time is printed apart.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from agvsim.slam.carmen import CarmenLog  # noqa: E402
from agvsim.slam.datasets import datasets_dir  # noqa: E402
from agvsim.slam.graph_slam import GraphSlam  # noqa: E402
from agvsim.slam.se2 import between, compose, inverse  # noqa: E402

LOGS = {"intel": "intel/intel.clf.gz", "aces": "aces/aces.clf.gz"}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", choices=sorted(LOGS), default="intel")
    ap.add_argument("--max-scans", type=int, default=None, help="map only the first N scans")
    ap.add_argument("--tries", type=int, default=8, help="scans looked for (spread over the log)")
    args = ap.parse_args(argv)
    root = datasets_dir()
    if root is None or not (root / LOGS[args.log]).is_file():
        print("relocalisation benchmark skipped: no data sets folder (set AGVSIM_DATASETS)")
        return 0
    log = CarmenLog(root / LOGS[args.log])
    total = len(log) if args.max_scans is None else min(len(log), args.max_scans)
    # scans from the second half of the log, when most of the map is built
    picks = set(np.linspace(total // 2, total - 1, args.tries).astype(int).tolist())
    kept: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    slam: GraphSlam | None = None
    t0 = time.process_time()
    for k, rec in enumerate(log):
        if k >= total:
            break
        if slam is None:
            slam = GraphSlam(rec.range_max_m, rec.mount_pose)
        slam.update(rec.stamp_s, rec.ranges, rec.angles_rad, rec.odom_pose)
        if k in picks:
            kept[k] = (np.asarray(rec.ranges, float), np.asarray(rec.angles_rad, float))
    assert slam is not None
    slam.finish()
    print(
        f"{args.log}: {total} scans mapped in {time.process_time() - t0:.1f} s CPU, "
        f"{sum(s.finished for s in slam.submaps)} finished submaps, "
        f"{slam.n_global_relocalised} global relocalisations during the run"
    )
    _, traj = slam.trajectory()
    times: list[float] = []
    found = 0
    for i, (k, (ranges, angles)) in enumerate(sorted(kept.items())):
        points, _, _ = slam.scan_points(ranges, angles)
        away = compose(slam.scan_local[k], np.array([20.0, 20.0, 1.0]))
        t = time.process_time()
        res = slam.relocalise(points, away, 0.0)
        dt = time.process_time() - t
        if i > 0:
            times.append(dt)
        if res is None:
            print(f"  scan {k:6d}: {dt:6.3f} s CPU, not found")
            continue
        pose, s = res
        sub = slam.submaps[s]
        g_s = slam.graph.poses[slam.submap_var[s]]
        g = compose(compose(g_s, inverse(sub.origin)), pose)  # the found pose, global frame
        d = between(traj[k], g)
        err_m, err_deg = math.hypot(d[0], d[1]), math.degrees(abs(d[2]))
        found += err_m < 0.3 and err_deg < 3.0
        print(
            f"  scan {k:6d}: {dt:6.3f} s CPU{' (first: builds caches)' if i == 0 else ''}, "
            f"submap {s}, {err_m:.3f} m / {err_deg:.2f} deg from SLAM's pose"
        )
    if times:
        print(f"median try {float(np.median(times)):.3f} s CPU (max {max(times):.3f} s)")
    print(f"found within 0.3 m / 3 deg of SLAM's own pose: {found} of {len(kept)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
