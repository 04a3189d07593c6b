"""The work behind ``agvsim sweep`` and ``agvsim grade``: progress bars, tables, exit codes.
(cli.py declares the options and calls these; each returns the command's exit code.)"""

from __future__ import annotations

import csv
import json
import math
import statistics
from pathlib import Path

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table

from agvsim.signals import exit_code


def _fail(console: Console, label: str, message: object, style: str = "red") -> None:
    console.print(f"{label}:", style=style, end=" ")
    console.print(str(message), markup=False, highlight=False)


# ---------------------------------------------------------------------------------- sweep
def sweep_command(
    sweep_file: Path,
    out_dir: Path | None,
    workers: int | None,
    ray: bool,
    ray_address: str | None,
    limit: int | None,
    plots: bool,
    quiet: bool,
    dry_run: bool,
    out: Console,
    err: Console,
) -> int:
    from agvsim.experiments.executors import ray_available
    from agvsim.experiments.spec import SweepError, plan_sweep
    from agvsim.experiments.sweep import run_sweep

    if workers is not None and workers < 1:
        _fail(err, "error", f"--workers must be >= 1, got {workers}")
        return 2
    if limit is not None and limit < 0:
        _fail(err, "error", f"--limit must be >= 0, got {limit}")
        return 2
    use_ray = ray or bool(ray_address)
    if use_ray and not ray_available():
        _fail(err, "error", "--ray needs Ray: pip install 'agvsim[ray]' (ray>=2.9,<3)")
        return 2
    try:
        plan = plan_sweep(sweep_file, out_dir)
    except SweepError as e:
        _fail(err, "error", e)
        return 2
    where = "Ray" + (f" at {ray_address}" if ray_address else "") if use_ray else "local"
    out.print(
        f"{plan.name}: {len(plan.variations)} variation(s) x {len(plan.seeds)} seed(s) = "
        f"{len(plan.tasks)} runs, on {where}; output {plan.out_dir}",
        markup=False,
        highlight=False,
    )
    if dry_run:
        for v in plan.variations:
            out.print(f"  {v.index:4d}  {v.label}", markup=False, highlight=False)
        out.print(f"  seeds {plan.seeds}; columns: {', '.join(plan.columns)}", markup=False)
        return 0
    bar = Progress(
        TextColumn("[bold]sweep"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[note]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err,
        disable=quiet,
    )
    job = bar.add_task("sweep", total=len(plan.tasks), note="preparing")

    def tick(done: int, total: int, task, row) -> None:
        if row is None:
            note = f"{done} already finished" if done else ""
        else:
            note = f"variation {task.variation} seed {task.seed}: {row.get('status')}"
        bar.update(job, completed=done, note=note)

    try:
        with bar:
            result = run_sweep(
                plan,
                workers=workers,
                ray=use_ray,
                ray_address=ray_address,
                progress=tick,
                limit=limit,
                plots=plots,
            )
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM (agvsim.signals.Terminated)
        _fail(
            err,
            "interrupted",
            f"finished runs are kept in {plan.out_dir / 'runs'}; run the same command again "
            "to go on where it stopped",
            "yellow",
        )
        return exit_code(e)
    except (RuntimeError, ConnectionError) as e:  # Ray could not start or connect
        _fail(err, "error", e)
        return 1
    _print_sweep_summary(result, out)
    for task, message in result.failed:
        _fail(err, "run failed", f"variation {task.variation} seed {task.seed}: {message}")
    return 1 if result.failed else 0


def _print_sweep_summary(result, out: Console) -> None:
    plan, table = result.plan, result.table
    shown = [c for c in plan.plots if c in table.column_names][:3]
    t = Table(
        title=f"{plan.name}: mean (std) over seeds; true/false columns: how many true",
        title_justify="left",
    )
    t.add_column("#", justify="right")
    t.add_column("variation", overflow="fold")
    t.add_column("runs", justify="right")
    t.add_column("status", overflow="fold")
    for c in shown:
        t.add_column(c.replace(".", ".\n", 1), justify="right", overflow="fold")
    var_col = table.column("variation").to_pylist()
    status = table.column("status").to_pylist()
    cols = {c: table.column(c).to_pylist() for c in shown}
    for v in plan.variations:
        idx = [i for i, k in enumerate(var_col) if k == v.index]
        counts: dict[str, int] = {}
        for i in idx:
            counts[status[i]] = counts.get(status[i], 0) + 1
        cells = []
        for c in shown:
            if all(isinstance(cols[c][i], bool | None) for i in idx):
                cells.append(f"{sum(bool(cols[c][i]) for i in idx)}/{len(idx)}")
                continue
            vals = [float(cols[c][i]) for i in idx if cols[c][i] is not None]
            vals = [x for x in vals if math.isfinite(x)]
            if not vals:
                cells.append("-")
            elif len(vals) == 1:
                cells.append(f"{vals[0]:.3g}")
            else:
                cells.append(f"{statistics.fmean(vals):.3g} ({statistics.stdev(vals):.2g})")
        st = ", ".join(f"{k} {n}" for k, n in sorted(counts.items()))
        t.add_row(str(v.index), v.label, str(len(idx)), st, *cells)
    out.print(t)
    done = "" if result.complete else f" (incomplete: {table.num_rows} of {len(plan.tasks)})"
    out.print(
        f"{result.executed} run(s) done now, {result.skipped} already finished{done}\n"
        f"table: {result.parquet_path}, {result.csv_path}"
        + (f"\nplots: {', '.join(p.name for p in result.plots)}" if result.plots else ""),
        markup=False,
        highlight=False,
    )


# ---------------------------------------------------------------------------------- grade
def grade_command(
    controllers: list[Path],
    suite_file: Path,
    out_dir: Path | None,
    name: str | None,
    quiet: bool,
    out: Console,
    err: Console,
) -> int:
    from agvsim.grade import SuiteError, grade, grades_to_records, load_suite

    try:
        suite = load_suite(suite_file)
    except SuiteError as e:
        _fail(err, "error", e)
        return 2
    missing = [str(c) for c in controllers if not c.is_file()]
    if missing:
        _fail(err, "error", f"no such controller file: {', '.join(missing)}")
        return 2
    bad = [str(c) for c in controllers if c.suffix != ".py"]
    if bad:
        _fail(err, "error", f"a controller must be a Python file ending in .py: {', '.join(bad)}")
        return 2
    cfg, tasks = suite
    students = _student_names(controllers)
    out_dir = out_dir or Path("runs/grades") / suite_file.stem
    out_dir.mkdir(parents=True, exist_ok=True)
    everything = []
    bar = Progress(
        TextColumn("[bold]grading[/bold] {task.fields[who]}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[note]}"),
        TimeElapsedColumn(),
        console=err,
        disable=quiet,
    )
    try:
        with bar:
            job = bar.add_task("grade", total=len(tasks) * len(controllers), who="", note="")
            for c, who in zip(controllers, students, strict=True):
                bar.update(job, who=who, note="")

                def done(g) -> None:
                    bar.update(job, advance=1, note=f"{g.task}: {g.status}")

                everything += grade(c, suite, out_dir, on_task=done, name=name, student=who)
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM (agvsim.signals.Terminated)
        _fail(err, "interrupted", "grading stopped; no grades written", "yellow")
        return exit_code(e)
    for who in students:
        _print_grades([g for g in everything if g.student == who], cfg.name, out)
    if len(controllers) > 1:
        _print_totals(everything, out)
    records = grades_to_records(everything)
    (out_dir / "grades.json").write_text(
        json.dumps({"suite": cfg.name, "grades": records}, indent=2) + "\n", encoding="utf-8"
    )
    with (out_dir / "grades.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=list(records[0]))
        w.writeheader()
        w.writerows(records)
    out.print(
        f"grades: {out_dir / 'grades.csv'}, {out_dir / 'grades.json'}; "
        f"printed output of each task: {out_dir / 'logs'}",
        markup=False,
        highlight=False,
    )
    return 0


def _student_names(files: list[Path]) -> list[str]:
    """Each file's stem, or folder/stem where two stems are the same (alice/ctrl, bob/ctrl)."""
    stems = [f.stem for f in files]
    return [
        f.stem if stems.count(f.stem) == 1 else f"{f.resolve().parent.name}/{f.stem}" for f in files
    ]


def _fmt(v: float | None, unit: str = "") -> str:
    return "-" if v is None else f"{v:.2f}{unit}"


def _print_grades(grades, suite: str, out: Console) -> None:
    if not grades:
        return
    t = Table(title=f"{grades[0].student} on {suite}", title_justify="left")
    for col, just in (
        ("task", "left"),
        ("result", "left"),
        ("time s", "right"),
        ("collisions", "right"),
        ("path m", "right"),
        ("score", "right"),
        ("note", "left"),
    ):
        t.add_column(col, justify=just)  # type: ignore[arg-type]
    style = {"success": "green", "fail": "yellow"}
    for g in grades:
        t.add_row(
            g.task,
            f"[{style.get(g.status, 'red')}]{g.status}[/]",
            _fmt(g.time_s),
            "-" if g.collisions is None else str(g.collisions),
            _fmt(g.path_length_m),
            f"{g.score:g} / {g.points:g}",
            _escape(g.message[:120]),
        )
    total, best = sum(g.score for g in grades), sum(g.points for g in grades)
    t.add_section()
    t.add_row(
        "total",
        f"{sum(g.success for g in grades)}/{len(grades)} passed",
        "",
        "",
        "",
        f"[bold]{total:g} / {best:g}[/]",
        "",
    )
    out.print(t)


def _print_totals(grades, out: Console) -> None:
    t = Table(title="all students", title_justify="left")
    t.add_column("student")
    t.add_column("passed", justify="right")
    t.add_column("score", justify="right")
    for s in dict.fromkeys(g.student for g in grades):
        mine = [g for g in grades if g.student == s]
        t.add_row(
            s,
            f"{sum(g.success for g in mine)}/{len(mine)}",
            f"{sum(g.score for g in mine):g} / {sum(g.points for g in mine):g}",
        )
    out.print(t)


def _escape(text: str) -> str:
    from rich.markup import escape

    return escape(text)
