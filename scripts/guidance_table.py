"""Run the five guidance scenarios and print the README's comparison table (docs/guidance.md).

    python scripts/guidance_table.py [--seeds 3]

For each scenario: the localisation error (estimate vs ground truth along the route, from
summary.json; the tape vehicle estimates no pose), the track error (the true reference
point's distance from the route, from trajectory.csv) and the infrastructure it needs.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
from pathlib import Path

import numpy as np

from agvsim.runner import run_scenario
from agvsim.scenario import build, load_scenario

ROOT = Path(__file__).resolve().parent.parent
STEMS = (
    "guidance_odometry",
    "guidance_tape",
    "guidance_floor_codes",
    "guidance_reflectors",
    "guidance_reflectors_blind_spot",
)


def _route(stem: str) -> np.ndarray:
    """The route (the tape loop for the tape scenario) as (M, 4) segments."""
    sim = build(load_scenario(ROOT / "scenarios" / f"{stem}.yaml"))
    if sim.world.tape is not None:
        return sim.world.tape.segments
    pts = np.asarray(sim.bindings[0].controller.pursuit.tracker.points)
    return np.column_stack([pts[:-1], pts[1:]])


def _distance(xy: np.ndarray, segs: np.ndarray) -> np.ndarray:
    a, b = segs[:, :2], segs[:, 2:]
    ab = b - a
    t = np.clip(((xy[:, None] - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-18), 0, 1)
    d = xy[:, None] - (a + t[..., None] * ab)
    return np.sqrt((d * d).sum(-1)).min(axis=1)


def _infrastructure(stem: str) -> str:
    sim = build(load_scenario(ROOT / "scenarios" / f"{stem}.yaml"))
    w = sim.world
    if w.tape is not None:
        return f"{w.tape.length_m:.1f} m of tape, {len(w.tape.spots)} spots"
    if w.floor_codes is not None:
        g = w.floor_codes
        return f"{g.cols * g.rows} floor codes ({g.cols} x {g.rows}, {g.spacing_m:g} m grid)"
    if w.reflectors is not None:
        return f"{len(w.reflectors.xy)} reflectors"
    return "none"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="runs per scenario (seeds 0..n-1)")
    args = ap.parse_args()
    print("| scenario | localisation error mean / max (m) | track error mean / max (m) "
          "| infrastructure |")  # fmt: skip
    print("|---|---|---|---|")
    for stem in STEMS:
        segs = _route(stem)
        loc: list[tuple[float, float]] = []
        track: list[tuple[float, float]] = []
        for seed in range(args.seeds):
            with tempfile.TemporaryDirectory() as tmp:
                data = run_scenario(
                    ROOT / "scenarios" / f"{stem}.yaml",
                    tmp,
                    seed=seed,
                    plot=False,
                    record_mcap=False,
                )
                with (Path(tmp) / "trajectory.csv").open(encoding="utf-8") as f:
                    xy = np.array([(float(r["x"]), float(r["y"])) for r in csv.DictReader(f)])
            ctrl = data["robots"][0].get("controller", {})
            if "pose_error_mean_m" in ctrl:
                loc.append((ctrl["pose_error_mean_m"], ctrl["pose_error_max_m"]))
            d = _distance(xy, segs)
            track.append((float(d.mean()), float(d.max())))
        lo = (
            f"{np.mean([m for m, _ in loc]):.3f} / {max(x for _, x in loc):.3f}"
            if loc
            else "n/a (no pose estimate)"
        )
        tr = f"{np.mean([m for m, _ in track]):.3f} / {max(x for _, x in track):.3f}"
        print(f"| `{stem}.yaml` | {lo} | {tr} | {_infrastructure(stem)} |")
    print(f"\n(mean of the per-run means, max of the maxima, over seeds 0..{args.seeds - 1})")


if __name__ == "__main__":
    main()
