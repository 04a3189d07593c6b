"""Fleet scenarios in ``agvsim sweep``: a scenario with a ``master:`` block runs in-process
(master plus vehicles, no broker) and gives one row of the master's figures; a sweep that
varies ``master.fleet_size`` also gets ``throughput.png``: orders per hour against the number
of vehicles, with where it saturates marked (the smallest fleet within 95 % of the best)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from agvsim.master.run import InProcessRun
from agvsim.scenario import Scenario

SATURATION = 0.95
FLEET_SIZE = "master.fleet_size"
THROUGHPUT = "master.orders_per_hour"


def is_fleet(sc: Scenario) -> bool:
    return sc.master is not None and sc.vda5050 is not None and sc.layout is not None


def _row(run: InProcessRun, summary: dict[str, Any], wall_s: float) -> dict[str, Any]:
    t = run.t_s
    row: dict[str, Any] = {
        "status": "completed",
        "error": None,
        "simulated_time_s": t,
        "steps": int(run.fleet.sim.state.step),
        "controller_errors": 0,
        "wall_time_s": wall_s,
        "real_time_factor": t / wall_s if wall_s > 0 else 0.0,
        "vehicles": len(run.fleet.vehicles),
    }
    for k, v in summary.items():
        if k == "waiting_s_by_node":
            continue
        if isinstance(v, dict):
            row.update({f"master.{k}.{kk}": vv for kk, vv in v.items()})
        else:
            row[f"master.{k}"] = v
    return row


def fleet_row(sc: Scenario, seed: int) -> dict[str, Any]:
    run = InProcessRun(sc, seed=seed, master_period_s=0.25)
    t0 = time.perf_counter()
    run.run()
    return _row(run, run.summary(), time.perf_counter() - t0)


def fleet_dry_row(sc: Scenario, seed: int) -> dict[str, Any]:
    """The row's columns, from a built (not run) fleet: checks the scenario too."""
    run = InProcessRun(sc, seed=seed, duration_s=0.0)
    return _row(run, run.summary(), 0.0)


def saturation(sizes: list[int], rates: list[float]) -> int | None:
    """The smallest fleet size whose throughput is within 95 % of the best."""
    if not rates or max(rates) <= 0:
        return None
    best = max(rates)
    return min(n for n, r in zip(sizes, rates, strict=True) if r >= SATURATION * best)


def throughput_plot(rows: list[dict[str, Any]], out_dir: Path, title: str) -> Path | None:
    """Mean orders per hour (and each seed's) against the fleet size."""
    if not rows or FLEET_SIZE not in rows[0]:
        return None
    pts = [
        (int(r[FLEET_SIZE]), float(r[THROUGHPUT])) for r in rows if r.get(THROUGHPUT) is not None
    ]
    if not pts:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = sorted({n for n, _ in pts})
    means = [sum(r for n, r in pts if n == s) / sum(1 for n, _ in pts if n == s) for s in sizes]
    fig, ax = plt.subplots(figsize=(7, 4.5), layout="constrained")
    ax.scatter([n for n, _ in pts], [r for _, r in pts], s=14, color="0.6", label="one seed")
    ax.plot(sizes, means, "o-", color="#1f77b4", label="mean over seeds")
    sat = saturation(sizes, means)
    if sat is not None:
        ax.axvline(sat, color="#d62728", ls="--", lw=1)
        ax.annotate(
            f"saturates at {sat} vehicles\n({SATURATION:.0%} of the best {max(means):.0f}/h)",
            (sat, max(means)),
            xytext=(8, -30),
            textcoords="offset points",
            fontsize=9,
            color="#d62728",
        )
    ax.set_xlabel("vehicles")
    ax.set_ylabel("orders completed per hour")
    ax.set_ylim(bottom=0)
    ax.set_title(title, fontsize=10)
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(alpha=0.3)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "throughput.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
