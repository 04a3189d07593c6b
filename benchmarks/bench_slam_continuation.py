"""Where the live field's guesses land: the continuations of surfaces that go out of sight
(:func:`agvsim.slam.frontend.extend_occluded`, ``TrackingConfig.occluded_reach_m``) and the
farthest edge-on samples spread (``last_sample_spread``), against the true walls of a
simulated recording.

Run ``python benchmarks/bench_slam_continuation.py runs/NAME/run.mcap ... [--tracking
FIELD=VALUE ...] [--plot DIR]`` (``occluded_reach_m=0.5`` by default). SLAM runs over each
recording as the robustness suite runs it; every point a keyframe stamps by either rule is
taken through that keyframe's tracked pose into its true pose (the recording's ground truth)
and measured against the recording's ``/map`` (upsampled to 1.25 cm cells): its distance to
the nearest wall face, inside a wall as well as outside. Printed per recording and rule: the
keyframes that stamped any, the points, the share more than 0.1 and 0.2 m off every wall (a
wall guessed where there is none, or into a solid block), and the points within 0.1 m of
one. ``--plot DIR`` draws each recording's continued points over its true walls
(``DIR/NAME_continued.png``: green within 0.1 m of a wall, red farther off).

It observes the rules (by wrapping the two kernels for the run) and changes nothing of what
SLAM computes. Prints numbers; does not gate.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from contextlib import ExitStack
from pathlib import Path
from unittest import mock

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_slam_robustness import tracking_override  # noqa: E402

RULES = {"continued": "extend_occluded", "last sample": "spread_last_sample"}


def wall_distance(occupied: np.ndarray, resolution_m: float) -> tuple[np.ndarray, float]:
    """The distance (m) of every cell of ``occupied`` (rows north first) upsampled to at most
    1.25 cm cells to the nearest wall face, from either side; and the cell size."""
    from scipy.ndimage import distance_transform_edt

    f = max(1, math.ceil(resolution_m / 0.0125 - 1e-9))
    occ = np.repeat(np.repeat(occupied, f, axis=0), f, axis=1)
    res = resolution_m / f
    return (distance_transform_edt(~occ) + distance_transform_edt(occ)) * res, res


def config(overrides: dict[str, object]):  # noqa: ANN201
    """The default SlamConfig with ``overrides`` of its TrackingConfig (a field it lacks or a
    value it refuses: ValueError naming it)."""
    from agvsim.slam.graph_slam import SlamConfig

    base = SlamConfig()
    try:
        tracking = dataclasses.replace(base.tracking, **overrides)
    except TypeError as exc:  # an unknown field
        raise ValueError(str(exc)) from exc
    return dataclasses.replace(base, tracking=tracking)


def measure(path: Path, cfg) -> tuple[dict[str, tuple[int, np.ndarray, np.ndarray]], object]:  # noqa: ANN001
    """Run SLAM with ``cfg`` over the recording; per rule, the keyframes that stamped points,
    the points in the true frame (n, 2) and their distances to the true walls (m); and the
    recording's map."""
    from agvsim.record.mcap_reader import Recording
    from agvsim.record.ros2msg import topic_name
    from agvsim.record.scan_log import McapScanLog, interpolate_poses
    from agvsim.slam import frontend
    from agvsim.slam.graph_slam import GraphSlam
    from agvsim.slam.offline import map_scans
    from agvsim.slam.se2 import between, compose

    log = McapScanLog(path)
    rec = Recording(path)
    t_gt, gt, _ = rec.odometry(f"/{topic_name(log.robot)}/ground_truth")
    grids = rec.occupancy("/map")
    if not grids:
        raise ValueError(f"{path}: the recording holds no /map to measure against")
    grid = grids[0]
    dist, res = wall_distance(grid.cells[::-1] >= 50, grid.resolution_m)

    now: dict[str, object] = {}
    taken: dict[str, list[tuple[float, np.ndarray, np.ndarray]]] = {r: [] for r in RULES}
    seen: set[tuple[str, int]] = set()
    step, insert = GraphSlam._step, frontend.Tracker.insert

    def timed_step(self, timestamp, ranges, angles, odom_pose):  # noqa: ANN001, ANN202
        now["t"] = float(timestamp)
        return step(self, timestamp, ranges, angles, odom_pose)

    def posed_insert(self, node, pose, sensor_xy, ends, hits):  # noqa: ANN001, ANN202
        now["node"], now["pose"] = node, np.array(pose, float)
        return insert(self, node, pose, sensor_xy, ends, hits)

    def watched(rule: str, kernel):  # noqa: ANN001, ANN202
        def run(*args):  # noqa: ANN002, ANN202
            out = kernel(*args)
            key = (rule, int(now["node"]))  # once a keyframe, not once per active submap
            if key not in seen:
                seen.add(key)
                taken[rule].append((float(now["t"]), now["pose"].copy(), out.copy()))
            return out

        return run

    with ExitStack() as stack:
        stack.enter_context(mock.patch.object(GraphSlam, "_step", timed_step))
        stack.enter_context(mock.patch.object(frontend.Tracker, "insert", posed_insert))
        for rule, name in RULES.items():
            kernel = getattr(frontend, name)
            stack.enter_context(mock.patch.object(frontend, name, watched(rule, kernel)))
        map_scans(log, cfg, None, len(log))

    h, w = dist.shape
    out: dict[str, tuple[int, np.ndarray, np.ndarray]] = {}
    for rule, rows in taken.items():
        parts, where = [], []
        for t, pose, pts in rows:
            if len(pts) == 0:
                continue
            truth = interpolate_poses(np.array([t]), t_gt, gt)[0]
            rel = between(pose, np.column_stack([pts, np.zeros(len(pts))]))
            xy = compose(truth, rel)[:, :2]
            col = np.floor((xy[:, 0] - grid.origin_xy_m[0]) / res).astype(int)
            row = h - 1 - np.floor((xy[:, 1] - grid.origin_xy_m[1]) / res).astype(int)
            ok = (row >= 0) & (row < h) & (col >= 0) & (col < w)
            d = np.full(len(xy), np.inf)  # outside the map: off every wall
            d[ok] = dist[row[ok], col[ok]]
            parts.append(d)
            where.append(xy)
        if not parts:
            out[rule] = (0, np.zeros((0, 2)), np.zeros(0))
        else:
            out[rule] = (len(parts), np.concatenate(where), np.concatenate(parts))
    return out, grid


def plot(png: Path, name: str, grid, xy: np.ndarray, d: np.ndarray) -> None:  # noqa: ANN001
    """The true walls with the continued points on them: green within 0.1 m of a wall, red
    farther off."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    occ = grid.cells[::-1] >= 50
    h, w = occ.shape
    x0, y0 = grid.origin_xy_m
    extent = (x0, x0 + w * grid.resolution_m, y0, y0 + h * grid.resolution_m)
    fig, ax = plt.subplots(figsize=(12, 12 * h / max(w, 1) + 0.6))
    ax.imshow(occ, cmap="Greys", extent=extent, interpolation="nearest")
    off = d > 0.1
    ax.plot(xy[~off, 0], xy[~off, 1], ",", color="tab:green", alpha=0.4)
    ax.plot(xy[off, 0], xy[off, 1], ".", color="tab:red", ms=1.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{name}: continued points, {np.mean(off):.1%} more than 0.1 m off a wall (red)")
    fig.savefig(png, dpi=100, bbox_inches="tight")
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="simulated recordings (agvsim run)")
    ap.add_argument(
        "--tracking",
        nargs="*",
        default=["occluded_reach_m=0.5"],
        metavar="FIELD=VALUE",
        help="TrackingConfig fields for the run (default occluded_reach_m=0.5)",
    )
    ap.add_argument("--plot", type=Path, help="write NAME_continued.png per recording here")
    args = ap.parse_args(argv)
    try:
        cfg = config(dict(tracking_override(s) for s in args.tracking))
    except ValueError as exc:
        ap.error(f"--tracking: {exc}")
    print(f"tracking: {' '.join(args.tracking) or 'the defaults'}")
    print(
        f"{'recording':<22}{'rule':<13}{'keyframes':>10}{'points':>9}"
        f"{'>0.1 m':>9}{'>0.2 m':>9}{'on walls':>10}"
    )
    for path in args.mcap:
        if not path.is_file():
            ap.error(f"{path}: no such recording")
        result, grid = measure(path, cfg)
        if args.plot is not None:
            args.plot.mkdir(parents=True, exist_ok=True)
            _, xy, d = result["continued"]
            png = args.plot / f"{path.parent.name}_continued.png"
            plot(png, path.parent.name, grid, xy, d)
            print(f"{png}: the continued points on the true walls")
        for rule, (frames, _, d) in result.items():
            n = len(d)
            off1 = float(np.mean(d > 0.1)) if n else float("nan")
            off2 = float(np.mean(d > 0.2)) if n else float("nan")
            print(
                f"{path.parent.name:<22}{rule:<13}{frames:>10}{n:>9}"
                f"{off1:>9.3f}{off2:>9.3f}{int(np.sum(d <= 0.1)):>10}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
