"""Robustness suite: SLAM with the one default configuration on every log, unchanged and with
faults a real robot's log may carry (:mod:`agvsim.slam.perturb`).

Run ``python benchmarks/bench_slam_robustness.py [--logs aces intel mit-killian]
[--faults none freeze ...] [--jobs N] [--seed S] [--seeds K]``. Each (log, fault, seed) case
runs in its own process (one numba thread; ``--jobs`` cases at a time, 1 by default) and
prints

* scans and keyframes processed, loop-closure edges, CPU and wall seconds and the real-time
  factor on CPU time (log duration / CPU seconds: a busy machine stretches wall time);
* the mean translational error (m) of SLAM and of the faulty odometry alone on the relations
  whose two scans survived the fault (Kümmerle et al.), and their count; a simulated
  recording (``--mcap run.mcap``, from ``agvsim run``) is scored on relations drawn from its
  ground truth (every scan with the scan 10 later and with a random one; with ``--passes``,
  over every pass);
* SLAM's error over the unperturbed SLAM error of the same log (``/base``, target <= 1.5),
  the same ratio on only the relations both runs scored (``/same``: a fault that drops
  scans leaves a subset of the relations, whose unperturbed error differs from the whole
  set's; thinning the simulated log to 1.5 Hz leaves 24 of 2242), the ratio on every
  relation with poses read between the kept scans (``/kept``, :func:`kept_ratio`: thinning
  ACES to 1 Hz leaves 11 of its 1279 relations with both scans; nan where reading between
  the scans costs the unperturbed run more than half its own error), and over odometry's
  (target < 1);
* ``vsB m`` (and ``odom``, the faulty odometry's): the faulty run against the unperturbed
  SLAM run of the same log on relations drawn from the latter at the scans both kept
  (:func:`vs_base`; thinning a real log to 1 Hz leaves about 10 of its relations);
* the process's peak resident memory (MiB) when SLAM is done, and after rendering and scoring
  the final map (which grows with the mapped area).

A fault is one random draw (which scans a thinned log keeps, the range noise, where odometry
freezes): ``--seeds K`` runs every faulty case with seeds ``S .. S+K-1`` and ends with the
mean and the worst of each ratio over them (the unperturbed case runs once).

Faults combine with ``+``, applied left to right (``scale+thin``: a wheel-scale error, then
thinned); ``--scale`` sets the scale fault's factor (1.05) and ``--rate`` the rate in Hz of
``thin`` and ``sparse`` (1.5 and 1); ``--point-samples`` runs ``SlamConfig.point_samples()``
instead of the defaults, and ``--edge-on-max-step M`` spreads edge-on samples while the scans
move up to M metres (the default: the tracking window, 0.15 m; 9 spreads at every rate).
docs/slam.md's rate sweep is ``--logs --mcap runs/slam_hospital/run.mcap --faults
scale+thin --scale 0.97 --rate R`` with ``--point-samples`` and with ``--edge-on-max-step
9``.

MIT Killian Court has no usable relations (synthetic time stamps): it is scored by the map's
own consistency, the share of keyframe returns that land within 0.1 m of an occupied cell of
the final map, and by the *revisit agreement* (:func:`revisit_agreement`): the map of the
first half of the keyframes against the returns of the second half where the first half saw
space at all, for SLAM's poses and, as the scale of a broken map, for odometry's. A doubled
wall puts the second visit's returns into the first visit's free space. Prints numbers;
does not gate. Without the data sets folder it prints a note and exits.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import sys
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

if __name__ == "__main__":  # one thread a case; imported (tests), it leaves numba as it is
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from agvsim.scan import LaserScan  # noqa: E402
from agvsim.slam.datasets import datasets_dir  # noqa: E402
from agvsim.slam.evaluate import (  # noqa: E402
    Relations,
    Trajectory,
    evaluate_relations,
    load_relations,
)
from agvsim.slam.graph_slam import SlamConfig  # noqa: E402
from agvsim.slam.offline import map_scans  # noqa: E402
from agvsim.slam.perturb import Fault, FaultConfig, apply_fault  # noqa: E402

LOGS = {
    "aces": ("aces/aces.clf.gz", "aces/aces.relations"),
    "intel": ("intel/intel.clf.gz", "intel/intel.relations"),
    "mit-killian": ("mit-killian/mit-killian.synthetic-time.clf.gz", None),
}


def _odometry_error(stamps: np.ndarray, odom: np.ndarray, rel: Relations) -> float:
    return evaluate_relations(Trajectory(stamps, odom), rel).translation_mean_m


def truth_relations(path: Path, seed: int = 0, passes: int = 1) -> Relations:
    """Relations of a simulated recording from its ground truth, Kümmerle-style: every
    scan paired with the scan 10 later (short) and with a random scan (long, loop-closing);
    over all ``passes`` of :func:`there_and_back` (the random scan from any pass)."""
    from agvsim.record.mcap_reader import Recording
    from agvsim.record.ros2msg import topic_name
    from agvsim.record.scan_log import McapScanLog, interpolate_poses
    from agvsim.slam.se2 import between

    log = McapScanLog(path)
    t_gt, gt, _ = Recording(path).odometry(f"/{topic_name(log.robot)}/ground_truth")
    t = log.scans.stamp_s
    truth = interpolate_poses(t, t_gt, gt)
    if passes > 1:
        t, k = pass_stamps(t, passes)
        truth = truth[k]
    # every scan (not every 5th): a log thinned to 1.5 Hz keeps both ends of a few hundred
    # of them, not of two dozen
    i = np.arange(0, len(t) - 10)
    j = np.concatenate([i + 10, np.random.default_rng(seed).integers(0, len(t), len(i))])
    i = np.concatenate([i, i])
    return Relations(t[i], t[j], between(truth[i], truth[j]))


def vs_base(t: np.ndarray, poses: np.ndarray, t_base: np.ndarray, p_base: np.ndarray) -> float:
    """A faulty run against the unperturbed SLAM run of the same log, for real logs whose
    relations a fault thins to a handful: relations drawn from the unperturbed trajectory at
    the scans the faulty run kept (each with the kept scan 10 later and a random one, seeded),
    mean translational error (m). It measures how far the fault moved SLAM from where it was,
    not accuracy (the unperturbed run is off by its own error)."""
    from agvsim.slam.se2 import between

    where = {float(x): k for k, x in enumerate(t_base)}
    keep = np.array([float(x) in where for x in t])
    tk = t[keep]
    ref = p_base[[where[float(x)] for x in tk]]
    if len(tk) < 12:
        return float("nan")
    i = np.arange(0, len(tk) - 10)
    j = np.concatenate([i + 10, np.random.default_rng(0).integers(0, len(tk), len(i))])
    i = np.concatenate([i, i])
    rel = Relations(tk[i], tk[j], between(ref[i], ref[j]))
    return evaluate_relations(Trajectory(t, poses), rel).translation_mean_m


# /kept is left out (nan) where reading the unperturbed run between the kept scans costs it more
# than half its own error: on the simulated 1 Hz faults 0.136 m against 0.018 m (the robot turns
# at every corner of the maze; a second of turning is no straight line), on ACES at 1 Hz 0.044 m
# against 0.036 m
_KEPT_MAX_READ = 1.5


def kept_ratio(
    t: np.ndarray,
    poses: np.ndarray,
    t_base: np.ndarray,
    p_base: np.ndarray,
    rel: Relations,
    max_gap_s: float = 2.5,
) -> tuple[float, int, float]:
    """A thinned run scored on every relation, not only the few whose two scans it kept: both
    ends read off its trajectory, linear between the kept scans (relations with an end outside
    them, or between two kept scans more than ``max_gap_s`` apart, left out), over the same
    error of the unperturbed run's poses *at the same kept scans*, read the same way, so that
    what the interpolation itself gets wrong stands on both sides. Returns the ratio, the
    number of relations scored and the unperturbed run's error read that way (nan, 0, nan
    when none): where that is much more than its own error, the interpolation's share
    swamps both and the ratio says little."""
    from agvsim.record.scan_log import interpolate_poses

    where = {float(x): k for k, x in enumerate(t_base)}
    keep = np.array([float(x) in where for x in t])
    tk = t[keep]
    if len(tk) < 2:
        return float("nan"), 0, float("nan")

    def inside(q: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(tk, q), 1, len(tk) - 1)
        near = (tk[i] - tk[i - 1] <= max_gap_s) | np.isin(q, tk)
        return (q >= tk[0]) & (q <= tk[-1]) & near

    ok = inside(rel.t1_s) & inside(rel.t2_s)
    if not ok.any():
        return float("nan"), 0, float("nan")
    sub = Relations(rel.t1_s[ok], rel.t2_s[ok], rel.d_true[ok])
    q = np.unique(np.concatenate([sub.t1_s, sub.t2_s]))
    errs = []
    for p in (poses[keep], p_base[[where[float(x)] for x in tk]]):
        est = Trajectory(q, interpolate_poses(q, tk, p))
        errs.append(evaluate_relations(est, sub).translation_mean_m)
    return errs[0] / errs[1], int(ok.sum()), errs[1]


def pass_stamps(t: np.ndarray, passes: int) -> tuple[np.ndarray, np.ndarray]:
    """The time stamps of :func:`there_and_back`'s scans for a log stamped ``t`` (n,), and
    the index into ``t`` of each: forward, then backward with the time mirrored, ..."""
    t = np.asarray(t, dtype=np.float64)
    t0, t1 = float(t[0]), float(t[-1])
    span = t1 - t0 + 0.1
    stamps, index = [t], [np.arange(len(t))]
    for k in range(1, passes):
        idx = np.arange(len(t))[::-1] if k % 2 else np.arange(len(t))
        base = (t1 + (t1 - t[idx])) if k % 2 else t[idx]
        stamps.append(base + (k - (k % 2)) * span + (0.1 if k % 2 else 0.0))
        index.append(idx)
    return np.concatenate(stamps), np.concatenate(index)


def there_and_back(scans: Iterable[LaserScan], passes: int) -> Iterator[LaserScan]:
    """The log driven ``passes`` times: forward, backward (the scans in reverse order, time
    mirrored), forward, ... (:func:`pass_stamps`). A long log from a short one, for memory
    (the scans are held)."""
    from dataclasses import replace

    first = list(scans)
    stamps, index = pass_stamps(np.array([rec.stamp_s for rec in first]), passes)
    for t, i in zip(stamps, index, strict=True):
        yield replace(first[i], stamp_s=float(t))


def fault_spec(text: str) -> str:
    """A fault, or faults joined by ``+`` (applied left to right): each one of
    :class:`~agvsim.slam.perturb.Fault` (argparse type)."""
    names = [f.value for f in Fault]
    for part in text.split("+"):
        if part not in names:
            raise argparse.ArgumentTypeError(
                f"fault {part!r} in {text!r}: use one of {', '.join(names)}, joined by +"
            )
    return text


def run_case(
    root: Path,
    log: str,
    fault: str,
    seed: int,
    passes: int = 1,
    maps: Path | None = None,
    fault_cfg: FaultConfig | None = None,
    config: SlamConfig | None = None,
) -> dict[str, float | int | str]:
    """One (log, fault) case; returns its figures (runs in a worker process). ``log`` is a
    data set name of :data:`LOGS` or the path of a simulated ``run.mcap``; ``fault`` one
    fault or several joined by ``+`` (:func:`fault_spec`), with ``fault_cfg``'s parameters;
    ``config`` the SLAM's (None: the defaults)."""
    from agvsim.record.scan_log import open_scan_log

    if log.endswith(".mcap"):
        path, rel_path = Path(log), None
    else:
        path, rel_path = root / LOGS[log][0], LOGS[log][1]
    rng = np.random.default_rng(seed)
    stamps: list[float] = []
    odoms: list[np.ndarray] = []

    def tap(scans: Iterable[LaserScan]) -> Iterator[LaserScan]:
        for part in fault.split("+"):
            scans = apply_fault(scans, part, rng, fault_cfg)
        for rec in scans:
            stamps.append(rec.stamp_s)
            odoms.append(rec.odom_pose)
            yield rec

    t0, c0 = time.perf_counter(), time.process_time()
    source: Iterable[LaserScan] = open_scan_log(path)
    if passes > 1:
        source = there_and_back(source, passes)
    slam = map_scans(tap(source), config)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    slam_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # before the map
    assert slam is not None
    t, poses = slam.trajectory()
    out: dict[str, float | int | str] = {
        "traj_t": t,  # type: ignore[dict-item]
        "traj_p": poses,  # type: ignore[dict-item]
        "odom_t": np.asarray(stamps),  # type: ignore[dict-item]
        "odom_p": np.asarray(odoms),  # type: ignore[dict-item]
        "log": log,
        "fault": fault,
        "scans": len(t),
        "keyframes": len(slam.keyframes),
        "loops": len(slam.loop_edges),
        "reloc": slam.n_global_relocalised,
        "wall_s": wall,
        "rt": float(t[-1] - t[0]) / cpu,
        "cpu_s": cpu,
        "slam_mib": slam_mib,
    }
    rel = None
    if rel_path is not None:
        rel = load_relations(root / rel_path)
    elif path.suffix == ".mcap":
        rel = truth_relations(path, passes=passes)
    if rel is not None:
        err = evaluate_relations(Trajectory(t, poses), rel)
        out["slam_m"] = err.translation_mean_m
        out["relations"] = err.count
        per = np.full(err.matched.shape[0], np.nan)  # every relation's error, nan: not scored
        per[err.matched] = err.translation_error_m
        out["per_relation_m"] = per  # type: ignore[assignment]
        out["odom_m"] = _odometry_error(np.asarray(stamps), np.asarray(odoms), rel)
        out["rel_all"] = rel  # type: ignore[assignment]
    else:
        out["consistency"] = map_consistency(slam)
        out["revisit"] = revisit_agreement(slam, slam.keyframe_poses())
        odom = np.array([k.odom for k in slam.keyframes])
        out["revisit_odom"] = revisit_agreement(slam, odom)
    if maps is not None:
        from agvsim.slam.mapping import save_map_png

        maps.mkdir(parents=True, exist_ok=True)
        save_map_png(slam.occupancy_map(), maps / f"{path.name.split('.')[0]}-{fault}.png")
    out["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


def revisit_agreement(slam, poses: np.ndarray) -> float:  # type: ignore[no-untyped-def]
    """With the keyframes at ``poses`` (K, 3): the map of the first half of them (occupied
    cells grown by 2 cells, 0.1 m), and the returns of every 5th keyframe of the second half
    that land in a cell the first half observed (free or occupied). Returns the share of
    those within 0.1 m of an occupied cell: 1 when the later visits agree with the earlier
    ones, low when they map the same walls elsewhere (doubled walls, an open loop)."""
    from scipy.ndimage import binary_dilation

    from agvsim.slam.mapping import render_occupancy
    from agvsim.slam.se2 import compose

    def world(k: int) -> np.ndarray:
        kf = slam.keyframes[k]
        pts = kf.ends.astype(np.float64)
        return compose(poses[k], np.column_stack([pts, np.zeros(len(pts))]))[:, :2]

    half = len(slam.keyframes) // 2
    if half == 0:
        return float("nan")
    first = range(half)
    sensors = compose(poses[:half], slam.laser_offset)
    grid = render_occupancy(
        sensors,
        [world(k) for k in first],
        [slam.keyframes[k].hits for k in first],
        slam.cfg.tracking.resolution_m,
    )
    occ = binary_dilation(grid.logodds > 0, iterations=2)
    known = grid.logodds != 0
    agree = total = 0
    h, w = occ.shape
    for k in range(half, len(slam.keyframes), 5):
        pts = world(k)[slam.keyframes[k].hits]
        ij = np.floor((pts - np.asarray(grid.origin_xy_m)) / grid.resolution_m).astype(int)
        ok = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < w) & (ij[:, 1] < h)
        ij = ij[ok]
        seen = known[ij[:, 1], ij[:, 0]]
        agree += int(occ[ij[seen, 1], ij[seen, 0]].sum())
        total += int(seen.sum())
    return agree / max(total, 1)


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


def tracking_override(spec: str) -> tuple[str, object]:
    """``FIELD=VALUE`` of ``--tracking`` (and ``--slam``): VALUE read as a Python literal
    (``None``, ``0.3``, ``True``); a field the config lacks is refused by
    ``dataclasses.replace``."""
    import ast

    name, sep, value = spec.partition("=")
    if not sep or not name:
        raise ValueError(f"{spec!r} is not FIELD=VALUE")
    try:
        return name, ast.literal_eval(value)
    except (ValueError, SyntaxError) as exc:
        raise ValueError(f"{spec!r}: VALUE must be a number, True, False or None") from exc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", nargs="*", default=["aces", "intel"], choices=list(LOGS))
    ap.add_argument(
        "--mcap",
        nargs="*",
        default=[],
        type=Path,
        help="simulated recordings (agvsim run ... run.mcap), scored on their ground truth",
    )
    ap.add_argument(
        "--faults",
        nargs="*",
        default=[f.value for f in Fault],
        type=fault_spec,
        help="faults to run, each one or several joined by + (scale+thin)",
    )
    ap.add_argument("--scale", type=float, default=None, help="the scale fault's factor (1.05)")
    ap.add_argument(
        "--rate", type=float, default=None, help="thin's and sparse's rate, Hz (1.5 and 1)"
    )
    ap.add_argument(
        "--point-samples",
        action="store_true",
        help="run SlamConfig.point_samples() instead of the defaults",
    )
    ap.add_argument(
        "--edge-on-max-step",
        type=float,
        default=None,
        help="spread edge-on samples while the scans move up to this, m (default 0.15)",
    )
    ap.add_argument(
        "--tracking",
        nargs="*",
        default=[],
        metavar="FIELD=VALUE",
        help="override TrackingConfig fields for an A/B run (occluded_reach_m=None)",
    )
    ap.add_argument(
        "--slam",
        nargs="*",
        default=[],
        metavar="FIELD=VALUE",
        help="override SlamConfig fields for an A/B run (scale_pairs=None: the scale from "
        "matches against the submap, as before the twenty-fourth round)",
    )
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--seeds", type=int, default=1, help="run each faulty case with this many seeds"
    )
    ap.add_argument(
        "--passes",
        type=int,
        default=1,
        help="drive each log this many times, forward and back (a long log, for memory)",
    )
    ap.add_argument("--maps", type=Path, default=None, help="write each case's map.png here")
    args = ap.parse_args(argv)
    root = datasets_dir()
    if root is None:
        print("robustness suite skipped: no data sets folder (set AGVSIM_DATASETS)")
        return 0
    logs = list(args.logs) + [str(p.resolve()) for p in args.mcap]
    fault_cfg = FaultConfig()
    if args.scale is not None:
        fault_cfg = dataclasses.replace(fault_cfg, odometry_scale=args.scale)
    if args.rate is not None:
        fault_cfg = dataclasses.replace(fault_cfg, thin_rate_hz=args.rate, sparse_rate_hz=args.rate)
    config = SlamConfig.point_samples() if args.point_samples else None
    if args.edge_on_max_step is not None:
        if args.point_samples:
            ap.error("--edge-on-max-step spreads edge-on samples; --point-samples never does")
        tracking = dataclasses.replace(
            SlamConfig().tracking, edge_on_max_step_m=args.edge_on_max_step
        )
        config = dataclasses.replace(SlamConfig(), tracking=tracking)
    if args.tracking:
        base_cfg = config if config is not None else SlamConfig()
        try:
            tracking = dataclasses.replace(
                base_cfg.tracking, **dict(tracking_override(x) for x in args.tracking)
            )
        except (TypeError, ValueError) as exc:
            ap.error(f"--tracking: {exc}")
        config = dataclasses.replace(base_cfg, tracking=tracking)
    if args.slam:
        try:
            config = dataclasses.replace(
                config if config is not None else SlamConfig(),
                **dict(tracking_override(x) for x in args.slam),
            )
        except (TypeError, ValueError) as exc:
            ap.error(f"--slam: {exc}")
    if args.seeds < 1:
        ap.error(f"--seeds must be at least 1, got {args.seeds}")
    cases = [
        (log, f, seed)
        for log in logs
        for f in args.faults
        for seed in range(args.seed, args.seed + (1 if f == "none" else args.seeds))
    ]
    print(
        f"{'log':<20}{'fault':<13}{'seed':>5}{'scans':>6}{'kf':>6}{'loops':>6}{'reloc':>6}"
        f"{'SLAM m':>9}{'odom m':>9}"
        f"{'/base':>7}{'/same':>7}{'/kept':>7}{'/odom':>7}{'rel':>6}{'vsB m':>8}{'odom':>8}"
        f"{'RTx':>7}"
        f"{'CPU s':>8}{'wall s':>8}"
        f"{'MiB':>7}{'map MiB':>8}",
        flush=True,
    )
    base: dict[str, float] = {}
    base_traj: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    base_per: dict[str, np.ndarray] = {}
    ratios: dict[tuple[str, str], list[tuple[float, float, float, float]]] = {}
    with ProcessPoolExecutor(max_workers=args.jobs, max_tasks_per_child=1) as pool:
        futures = [
            pool.submit(run_case, root, log, f, seed, args.passes, args.maps, fault_cfg, config)
            for log, f, seed in cases
        ]
        for fut, (_, _, seed) in zip(futures, cases, strict=True):
            r = fut.result()
            log = str(r["log"])
            if log.endswith(".mcap"):
                log = "sim:" + Path(log).parent.name
            traj = (np.asarray(r.pop("traj_t")), np.asarray(r.pop("traj_p")))
            if r["fault"] == "none":
                base_traj[log] = traj
            odo = (np.asarray(r.pop("odom_t")), np.asarray(r.pop("odom_p")))
            rel_all = r.pop("rel_all", None)
            vsb = vsb_o = float("nan")
            if log in base_traj:
                vsb, vsb_o = vs_base(*traj, *base_traj[log]), vs_base(*odo, *base_traj[log])
            if "slam_m" in r:
                slam_m, odom_m = float(r["slam_m"]), float(r["odom_m"])
                per = np.asarray(r["per_relation_m"])
                if r["fault"] == "none":
                    base[log], base_per[log] = slam_m, per
                ratio = slam_m / base[log] if log in base else float("nan")
                same = float("nan")  # the two means on the relations both runs scored
                if log in base_per:
                    both = np.isfinite(per) & np.isfinite(base_per[log])
                    if both.any():
                        same = float(per[both].mean() / base_per[log][both].mean())
                kept = float("nan")
                if log in base_traj and isinstance(rel_all, Relations):
                    kept, _, read = kept_ratio(*traj, *base_traj[log], rel_all)
                    if log in base and read > _KEPT_MAX_READ * base[log]:
                        kept = float("nan")  # reading between the kept scans costs more
                ratios.setdefault((log, str(r["fault"])), []).append(
                    (ratio, same, kept, slam_m / odom_m)
                )
                score = (
                    f"{slam_m:>9.4f}{odom_m:>9.3f}{ratio:>7.2f}{same:>7.2f}{kept:>7.2f}"
                    f"{slam_m / odom_m:>7.3f}{int(r['relations']):>6d}{vsb:>8.4f}{vsb_o:>8.3f}"
                )
            else:
                score = (
                    f"  consistency {float(r['consistency']):.3f} revisit "
                    f"{float(r['revisit']):.3f} (odometry {float(r['revisit_odom']):.3f})"
                )
            print(
                f"{log:<20}{str(r['fault']):<13}{seed:>5d}{int(r['scans']):>6d}{int(r['keyframes']):>6d}"
                f"{int(r['loops']):>6d}{int(r['reloc']):>6d}{score}{float(r['rt']):>7.1f}{float(r['cpu_s']):>8.1f}"
                f"{float(r['wall_s']):>8.1f}{float(r['slam_mib']):>7.0f}"
                f"{float(r['peak_mib']):>8.0f}",
                flush=True,
            )
    if args.seeds > 1:
        print(
            f"\n{'log':<20}{'fault':<13}{'seeds':>6}  /base mean (worst)  /same mean (worst)  "
            "/kept mean (worst)  /odom mean (worst)"
        )
        for (log, fault), vals in ratios.items():
            if fault == "none":
                continue
            v = np.asarray(vals)
            cols = "".join(f"{np.mean(v[:, k]):>11.2f} ({np.max(v[:, k]):.2f}) " for k in range(4))
            print(f"{log:<20}{fault:<13}{len(v):>6d}{cols}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
