"""Relative-pose error metric of Kümmerle et al. (2009), "On measuring the accuracy of SLAM
algorithms".

A relation ``(t1, t2, d*)`` gives the true pose at time ``t2`` in the robot frame at ``t1``.
From an estimated trajectory ``X(t)``::

    d_est = X(t1)^-1 X(t2)                                    (se2.between)
    e_trans_m   = || t(d_est) - t(d*) ||_2                    metres
    e_rot_deg   = | wrap(theta(d_est) - theta(d*)) | * 180/pi  degrees

and the score is the mean and standard deviation (population, ddof = 0) of each over all
relations whose two timestamps are in the trajectory (exactly, or to within ``tolerance_s``,
1 ms by default; the others are counted as unmatched and left out).

Files (blank lines and ``#`` comments skipped, whitespace separated):

* relations: ``t1 t2 x y z roll pitch yaw`` (z, roll, pitch ignored);
* trajectory: ``timestamp x y theta`` (what the SLAM writes), or TUM ``timestamp x y z qx qy qz
  qw`` (the yaw of the quaternion is used).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from agvsim.slam.se2 import between, wrap_angle

__all__ = [
    "EvaluationError",
    "EvaluationFormatError",
    "RelationErrors",
    "Relations",
    "Trajectory",
    "evaluate_relations",
    "format_relation_errors",
    "load_relations",
    "load_trajectory",
    "match_timestamps",
]

F64 = NDArray[np.float64]


class EvaluationError(ValueError):
    """Inputs that cannot be evaluated (e.g. no relation matches the trajectory)."""


class EvaluationFormatError(EvaluationError):
    """A malformed line of a relations or trajectory file."""

    def __init__(self, path: Path | str, line_no: int, line: str, expected: str) -> None:
        self.path, self.line_no, self.line, self.expected = Path(path), line_no, line, expected
        text = line if len(line) <= 200 else line[:200] + "..."
        super().__init__(f"{path}:{line_no}: {expected}; got {text!r}")


@dataclass(frozen=True)
class Relations:
    """Ground-truth relations: times ``t1_s, t2_s (K,)`` and ``d_true (K, 3)`` [x m, y m, yaw rad]
    (pose at t2 in the robot frame at t1)."""

    t1_s: F64
    t2_s: F64
    d_true: F64


@dataclass(frozen=True)
class Trajectory:
    """Estimated poses ``(N, 3)`` [x m, y m, theta rad] at ``timestamps_s (N,)`` (increasing)."""

    timestamps_s: F64
    poses: F64


@dataclass(frozen=True)
class RelationErrors:
    """Per-relation errors of the matched relations and how many could not be matched."""

    translation_error_m: F64  # (K,)
    rotation_error_deg: F64  # (K,)
    matched: NDArray[np.bool_]  # (R,) True where both timestamps of relation r were found
    tolerance_s: float

    @property
    def count(self) -> int:
        """Relations used (matched)."""
        return int(self.translation_error_m.shape[0])

    @property
    def n_relations(self) -> int:
        return int(self.matched.shape[0])

    @property
    def n_unmatched(self) -> int:
        return self.n_relations - self.count

    @property
    def translation_mean_m(self) -> float:
        return float(np.mean(self.translation_error_m))

    @property
    def translation_std_m(self) -> float:
        return float(np.std(self.translation_error_m))

    @property
    def rotation_mean_deg(self) -> float:
        return float(np.mean(self.rotation_error_deg))

    @property
    def rotation_std_deg(self) -> float:
        return float(np.std(self.rotation_error_deg))


def _read_table(
    path: Path, widths: tuple[int, ...], expected: str
) -> tuple[F64, list[tuple[int, str]]]:
    """Rows of floats (each row one of ``widths`` long, all rows the same width) and the
    (line number, text) of each."""
    rows: list[list[float]] = []
    line_nos: list[tuple[int, str]] = []
    width = 0
    with path.open("r", encoding="utf-8") as f:
        for line_no, raw in enumerate(f, start=1):
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            fields = line.split()
            try:
                values = [float(v) for v in fields]
            except ValueError:
                values = []
            ok = len(fields) in widths and (width == 0 or len(fields) == width)
            if not ok or not values or not all(math.isfinite(v) for v in values):
                raise EvaluationFormatError(path, line_no, line, expected)
            width = len(fields)
            rows.append(values)
            line_nos.append((line_no, line))
    if not rows:
        raise EvaluationError(f"{path}: no data lines (expected {expected})")
    return np.asarray(rows, dtype=np.float64), line_nos


def load_relations(path: Path | str) -> Relations:
    """Read a ``*.relations`` file: ``t1 t2 x y z roll pitch yaw`` per line."""
    path = Path(path)
    data, _ = _read_table(path, (8,), "expected 8 numbers 't1 t2 x y z roll pitch yaw'")
    return Relations(data[:, 0], data[:, 1], np.stack([data[:, 2], data[:, 3], data[:, 7]], 1))


def load_trajectory(path: Path | str) -> Trajectory:
    """Read ``timestamp x y theta`` lines (or TUM ``timestamp x y z qx qy qz qw``), sorted by
    time; a repeated timestamp is an error."""
    path = Path(path)
    data, line_nos = _read_table(
        path,
        (4, 8),
        "expected 'timestamp x y theta' (4 numbers) or TUM 'timestamp x y z qx qy "
        "qz qw' (8 numbers)",
    )
    if data.shape[1] == 8:
        qx, qy, qz, qw = data[:, 4], data[:, 5], data[:, 6], data[:, 7]
        yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        poses = np.stack([data[:, 1], data[:, 2], yaw], axis=1)
    else:
        poses = data[:, 1:4].copy()
    order = np.argsort(data[:, 0], kind="stable")
    t = data[order, 0]
    dup = np.flatnonzero(np.diff(t) == 0.0)
    if dup.size:
        k = int(order[dup[0] + 1])
        raise EvaluationFormatError(
            path, *line_nos[k], "expected each timestamp once (repeated timestamp)"
        )
    return Trajectory(t, poses[order])


def match_timestamps(query_s: F64, timestamps_s: F64, tolerance_s: float) -> NDArray[np.int64]:
    """Index of the nearest trajectory timestamp to each query time, or -1 when the nearest is
    farther than ``tolerance_s``. ``timestamps_s`` must be increasing."""
    n = timestamps_s.shape[0]
    hi = np.clip(np.searchsorted(timestamps_s, query_s), 0, n - 1)
    lo = np.clip(hi - 1, 0, n - 1)
    near = np.where(
        np.abs(timestamps_s[lo] - query_s) <= np.abs(timestamps_s[hi] - query_s), lo, hi
    )
    return np.where(np.abs(timestamps_s[near] - query_s) <= tolerance_s, near, -1)


def evaluate_relations(
    trajectory: Trajectory, relations: Relations, tolerance_s: float = 1e-3
) -> RelationErrors:
    """Kümmerle et al. errors of ``trajectory`` on ``relations`` (module docstring). Raises
    :class:`EvaluationError` when no relation has both its timestamps in the trajectory."""
    if tolerance_s < 0.0:
        raise ValueError(f"tolerance_s must be >= 0, got {tolerance_s}")
    k1 = match_timestamps(relations.t1_s, trajectory.timestamps_s, tolerance_s)
    k2 = match_timestamps(relations.t2_s, trajectory.timestamps_s, tolerance_s)
    matched = (k1 >= 0) & (k2 >= 0)
    if not np.any(matched):
        t = trajectory.timestamps_s
        raise EvaluationError(
            f"none of the {relations.t1_s.shape[0]} relations has both timestamps in the "
            f"trajectory (within {tolerance_s} s); trajectory spans [{t[0]:.6f}, {t[-1]:.6f}] s, "
            f"relations [{min(relations.t1_s.min(), relations.t2_s.min()):.6f}, "
            f"{max(relations.t1_s.max(), relations.t2_s.max()):.6f}] s"
        )
    p = trajectory.poses
    d_est = between(p[k1[matched]], p[k2[matched]])
    d_true = relations.d_true[matched]
    e_t = np.hypot(d_est[:, 0] - d_true[:, 0], d_est[:, 1] - d_true[:, 1])
    e_r = np.degrees(np.abs(wrap_angle(d_est[:, 2] - d_true[:, 2])))
    return RelationErrors(e_t, e_r, matched, tolerance_s)


def format_relation_errors(result: RelationErrors, title: str = "relative pose error") -> str:
    """A short text table of the means, standard deviations and counts."""
    lines = [
        f"{title} (Kümmerle et al. 2009)",
        f"  relations used     {result.count} of {result.n_relations}"
        + (
            f"  ({result.n_unmatched} unmatched: a timestamp not in the trajectory within "
            f"{result.tolerance_s * 1e3:g} ms)"
            if result.n_unmatched
            else ""
        ),
        "                     mean        std        max",
        f"  translation  m   {result.translation_mean_m:9.4f}  {result.translation_std_m:9.4f}"
        f"  {float(np.max(result.translation_error_m)):9.4f}",
        f"  rotation   deg   {result.rotation_mean_deg:9.4f}  {result.rotation_std_deg:9.4f}"
        f"  {float(np.max(result.rotation_error_deg)):9.4f}",
    ]
    return "\n".join(lines)
