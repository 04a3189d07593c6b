"""A sweep's table: rows -> a typed Arrow table written as Parquet and CSV; comparison plots.

Column types follow the values: bool, int64, float64 (ints and floats mixed), string; a
column whose values are lists or mappings (a varied controller, a pose) holds their JSON text.
A missing value (a metric a run did not have, a time to goal never reached) is null.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pyarrow as pa


def to_arrow(rows: Sequence[dict], columns: Sequence[str]) -> pa.Table:
    """The rows as a table with ``columns`` first (in order), then any others they hold."""
    names = list(columns) + sorted({k for r in rows for k in r} - set(columns))
    arrays = [_array([r.get(n) for r in rows]) for n in names]
    return pa.table(arrays, names=names)


def _array(values: list[Any]) -> pa.Array:
    present = [v for v in values if v is not None]
    if all(isinstance(v, bool) for v in present):
        return pa.array(values, type=pa.bool_())
    if all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        if all(-(2**63) <= v < 2**63 for v in present):
            return pa.array(values, type=pa.int64())
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return pa.array([None if v is None else float(v) for v in values], type=pa.float64())
    if all(isinstance(v, str) for v in present):
        return pa.array(values, type=pa.string())
    return pa.array(
        [None if v is None else json.dumps(v, sort_keys=True, default=str) for v in values],
        type=pa.string(),
    )


def write_table(table: pa.Table, parquet_path: Path, csv_path: Path) -> None:
    """Write both files atomically (a reader never sees half a file)."""
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    for path, write in (
        (parquet_path, lambda p: pq.write_table(table, p)),
        (csv_path, lambda p: pcsv.write_csv(table, p)),
    ):
        tmp = path.with_name(path.name + ".tmp")
        write(str(tmp))
        os.replace(tmp, path)


def read_table(path: str | Path) -> pa.Table:
    import pyarrow.parquet as pq

    return pq.read_table(str(path))


def plot_columns(
    table: pa.Table, columns: Sequence[str], labels: dict[int, str], out_dir: Path, title: str
) -> list[Path]:
    """One PNG per column: a box plot of the column's values over the seeds, per variation
    (each run a dot on it); for a true/false column the fraction of true per variation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variations = sorted(labels)
    var_col = table.column("variation").to_pylist()
    written = []
    for col in columns:
        if col not in table.column_names:
            continue
        values = table.column(col).to_pylist()
        per = [[v for var, v in zip(var_col, values, strict=True) if var == k] for k in variations]
        kind = table.schema.field(col).type
        fig_w = min(16.0, max(6.0, 1.1 * len(variations) + 2.0))
        fig, ax = plt.subplots(figsize=(fig_w, 4.8), layout="constrained")
        xs = list(range(1, len(variations) + 1))
        if pa.types.is_boolean(kind):
            rates = [
                sum(bool(v) for v in vs if v is not None) / max(1, sum(v is not None for v in vs))
                for vs in per
            ]
            ax.bar(xs, rates, color="#4c72b0")
            ax.set_ylim(0, 1.05)
            ax.set_ylabel(f"{col}: fraction true")
            for x, r, vs in zip(xs, rates, per, strict=True):
                ax.text(x, r + 0.02, f"{r:.2f} (n={len(vs)})", ha="center", fontsize=8)
        elif pa.types.is_integer(kind) or pa.types.is_floating(kind):
            data = [[float(v) for v in vs if v is not None and math.isfinite(v)] for vs in per]
            ax.boxplot(
                [d if d else [math.nan] for d in data], positions=xs, widths=0.5, showmeans=True
            )
            for x, d in zip(xs, data, strict=True):
                n = len(d)
                jitter = [x + 0.18 * ((j + 0.5) / n - 0.5) for j in range(n)] if n else []
                ax.plot(jitter, d, "o", color="#dd8452", alpha=0.7, markersize=4)
            missing = [len(vs) - len(d) for vs, d in zip(per, data, strict=True)]
            if any(missing):
                for x, m in zip(xs, missing, strict=True):
                    if m:
                        ax.annotate(
                            f"{m} without a value",
                            (x, 0),
                            xycoords=("data", "axes fraction"),
                            ha="center",
                            va="bottom",
                            fontsize=8,
                            color="grey",
                        )
            ax.set_ylabel(col)
        else:
            plt.close(fig)
            continue
        ax.set_xticks(xs, [_wrap(labels[k]) for k in variations], fontsize=8)
        ax.set_xlabel("variation")
        ax.set_title(f"{title}: {col} (over seeds)")
        ax.grid(axis="y", alpha=0.3)
        path = out_dir / f"plot_{_file_name(col)}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def _wrap(label: str) -> str:
    return label.replace(", ", "\n")


def _file_name(col: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in col)
