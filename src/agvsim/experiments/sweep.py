"""``run_sweep``: validate a sweep, skip the runs already finished, run the others on local
processes or Ray, and assemble the table and the plots.

Output folder::

    runs/<run id>.json   one finished run each, written atomically as it finishes
    results.parquet      the table: one row per (variation, seed), sorted by them
    results.csv          the same table as CSV
    plot_<column>.png    comparison plots over the seeds, per variation
    sweep.json           the plan: variations, their values and labels, seeds, run ids

After an interruption, running the sweep again runs only what is missing; the table is
assembled from ``runs/`` so it is the same as a sweep that ran in one go.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa

from agvsim.experiments import executors
from agvsim.experiments.runs import FINISHED, RunTask
from agvsim.experiments.spec import SweepConfig, SweepPlan, plan_sweep
from agvsim.experiments.table import plot_columns, to_arrow, write_table

# progress(done, total, task, row): after each run is kept (task None: the first call, with
# the runs found finished); may raise KeyboardInterrupt to stop the sweep
Progress = Callable[[int, int, RunTask | None, dict | None], None]


@dataclass
class SweepResult:
    plan: SweepPlan
    table: pa.Table  # the finished runs (all of them unless ``complete`` is False)
    parquet_path: Path
    csv_path: Path
    plots: list[Path]
    executed: int  # runs done by this call
    skipped: int  # runs found finished in runs/
    failed: list[tuple[RunTask, str]] = field(default_factory=list)  # broke; redone next time

    @property
    def complete(self) -> bool:
        return self.table.num_rows == len(self.plan.tasks)


def run_sweep(
    sweep: str | Path | SweepConfig | SweepPlan,
    out_dir: str | Path | None = None,
    workers: int | None = None,
    ray: bool = False,
    ray_address: str | None = None,
    progress: Progress | None = None,
    limit: int | None = None,
    plots: bool = True,
) -> SweepResult:
    """Run a sweep (a file, a config or a plan from ``plan_sweep``) and write its outputs.

    ``workers``: local processes (default: one per CPU; 1 runs in this process), or Ray's CPUs
    when ``ray`` starts a local Ray. ``ray_address``: an existing Ray cluster (implies
    ``ray``). ``limit``: run at most this many new runs, then assemble what is finished.
    Raises SweepError (bad sweep, before anything runs); on KeyboardInterrupt the finished
    runs are kept and the exception re-raised."""
    plan = sweep if isinstance(sweep, SweepPlan) else plan_sweep(sweep, out_dir)
    out = Path(out_dir) if out_dir is not None else plan.out_dir
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    _write_json(out / "sweep.json", _plan_json(plan))

    done: dict[str, dict] = {}
    todo: list[RunTask] = []
    queued: set[str] = set()
    for task in plan.tasks:  # two variations may give the same run: it runs once
        if task.run_id in done or task.run_id in queued:
            continue
        row = _load_row(runs_dir / f"{task.run_id}.json")
        if row is not None:
            done[task.run_id] = row
        else:
            todo.append(task)
            queued.add(task.run_id)
    skipped = len(done)
    if limit is not None:
        todo = todo[: max(0, limit)]
    total = len(plan.tasks)
    if progress is not None:
        progress(len(done), total, None, None)

    workers = workers or executors.default_workers()
    runner: Iterator[tuple[RunTask, dict]]
    if ray or ray_address:
        runner = executors.run_ray(todo, ray_address, workers) if todo else iter(())
    else:
        runner = executors.run_local(todo, workers)
    failed: list[tuple[RunTask, str]] = []
    executed = 0
    try:
        for task, row in runner:
            executed += 1
            if row.get("status") in FINISHED:
                record = {"run_id": task.run_id, "variation": task.variation, "seed": task.seed}
                _write_json(runs_dir / f"{task.run_id}.json", {**record, "row": row})
                done[task.run_id] = row
            else:
                failed.append((task, str(row.get("error"))))
            if progress is not None:
                progress(len(done), total, task, row)
    finally:
        close = getattr(runner, "close", None)
        if close is not None:
            close()

    table = assemble(plan, done)
    out.mkdir(parents=True, exist_ok=True)
    parquet, csv = out / "results.parquet", out / "results.csv"
    write_table(table, parquet, csv)
    images: list[Path] = []
    if plots and table.num_rows:
        labels = {v.index: v.label for v in plan.variations}
        images = plot_columns(table, plan.plots, labels, out, plan.name)
        if "master.fleet_size" in plan.config.vary:  # how many vehicles? (docs/master.md)
            from agvsim.master.sweep import throughput_plot

            tp = throughput_plot(table.to_pylist(), out, plan.name)
            images += [tp] if tp is not None else []
    return SweepResult(plan, table, parquet, csv, images, executed, skipped, failed)


def assemble(plan: SweepPlan, rows: dict[str, dict]) -> pa.Table:
    """The table of the finished runs, sorted by (variation, seed)."""
    variations = {v.index: v for v in plan.variations}
    out: list[dict[str, Any]] = []
    for task in sorted(plan.tasks, key=lambda t: (t.variation, t.seed)):
        row = rows.get(task.run_id)
        if row is None:
            continue
        var = variations[task.variation]
        lead: dict[str, Any] = {"variation": task.variation}
        if plan.config.cases:
            lead["case"] = var.case
        lead.update(var.values)
        lead.update({"seed": task.seed, "run_id": task.run_id})
        out.append({**lead, **row})
    columns = [*plan.columns[: plan.columns.index("seed") + 1], "run_id"]
    columns += [c for c in plan.columns if c not in columns]
    return to_arrow(out, columns)


def _load_row(path: Path) -> dict | None:
    """A finished run's row, or None (no file, a half-written or foreign one)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        row = data["row"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return row if isinstance(row, dict) and row.get("status") in FINISHED else None


def _write_json(path: Path, data: Any) -> None:
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=1, default=str) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _plan_json(plan: SweepPlan) -> dict:
    return {
        "name": plan.name,
        "source": plan.source,
        "seeds": plan.seeds,
        "duration_s": plan.duration_s,
        "vary": list(plan.config.vary),
        "cases": list(plan.config.cases),
        "variations": [
            {"index": v.index, "label": v.label, "case": v.case, "values": v.values}
            for v in plan.variations
        ],
        "runs": [
            {"run_id": t.run_id, "variation": t.variation, "seed": t.seed} for t in plan.tasks
        ],
        "columns": plan.columns,
        "plots": plan.plots,
    }
