"""Load and save 2-D pose graphs in the g2o text format.

Lines (one record each; blank lines and ``#`` comments are skipped)::

    VERTEX_SE2 id x y theta                          initial guess, m m rad
    EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33   pose j in frame i; upper triangle of
                                                     the 3x3 information matrix, row by row
    FIX id                                           accepted and ignored (node 0 is the gauge)

Vertex ids are renumbered 0..N-1 in increasing id order (files whose ids are already 0..N-1,
the usual case, keep them). A file without vertices (``manhattan.g2o``) gets ``N = max id + 1``
nodes initialised from the odometry chain (:mod:`.posegraph_init`). A malformed line, bytes
that are not UTF-8 text, or an information matrix that is not positive definite raise
:class:`G2OFormatError` naming the file, the line number, the line and what was expected.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from agvsim.slam.posegraph import PoseGraph
from agvsim.slam.posegraph_init import initial_poses

__all__ = ["G2OFormatError", "load_g2o", "save_g2o"]

_VERTEX_FIELDS = "VERTEX_SE2 id x y theta"
_EDGE_FIELDS = "EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33"


class G2OFormatError(ValueError):
    """A line of a g2o file that cannot be read."""

    def __init__(self, path: Path | str, line_no: int, line: str, expected: str) -> None:
        self.path, self.line_no, self.line, self.expected = Path(path), line_no, line, expected
        text = line if len(line) <= 200 else line[:200] + "..."
        super().__init__(f"{path}:{line_no}: {expected}" + (f"; got {text!r}" if text else ""))


def _numbers(fields: list[str], n_int: int, n_float: int) -> tuple[list[int], list[float]] | None:
    """``n_int`` ints then ``n_float`` finite floats from ``fields[1:]``; None if malformed."""
    if len(fields) != 1 + n_int + n_float:
        return None
    try:
        ints = [int(f) for f in fields[1 : 1 + n_int]]
        floats = [float(f) for f in fields[1 + n_int :]]
    except ValueError:
        return None
    if not all(math.isfinite(v) for v in floats):
        return None
    return ints, floats


def load_g2o(path: Path | str) -> PoseGraph:
    """Read a 2-D g2o file (``VERTEX_SE2``, ``EDGE_SE2``, ``FIX``) into a :class:`PoseGraph`."""
    path = Path(path)
    vertex_ids: list[int] = []
    vertex_poses: list[list[float]] = []
    vertex_lines: dict[int, int] = {}
    edge_ids: list[list[int]] = []
    edge_vals: list[list[float]] = []
    edge_lines: list[int] = []
    with path.open("rb") as f:
        for line_no, raw_bytes in enumerate(f, start=1):
            try:
                raw = raw_bytes.decode("utf-8")
            except UnicodeDecodeError as exc:
                bad = raw_bytes[exc.start : exc.start + 1]
                raise G2OFormatError(
                    path,
                    line_no,
                    "",
                    f"expected a text file; byte {bad!r} at column {exc.start + 1} is not UTF-8 "
                    "(a binary file?)",
                ) from None
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            fields = line.split()
            tag = fields[0]
            if tag == "VERTEX_SE2":
                got = _numbers(fields, 1, 3)
                if got is None:
                    raise G2OFormatError(path, line_no, line, f"expected '{_VERTEX_FIELDS}'")
                vid = got[0][0]
                if vid in vertex_lines:
                    raise G2OFormatError(
                        path,
                        line_no,
                        line,
                        f"vertex {vid} already defined on line {vertex_lines[vid]}",
                    )
                vertex_lines[vid] = line_no
                vertex_ids.append(vid)
                vertex_poses.append(got[1])
            elif tag == "EDGE_SE2":
                got = _numbers(fields, 2, 9)
                if got is None:
                    raise G2OFormatError(
                        path, line_no, line, f"expected '{_EDGE_FIELDS}' (11 numbers)"
                    )
                if got[0][0] == got[0][1]:
                    raise G2OFormatError(
                        path, line_no, line, "expected an edge between two different vertices"
                    )
                edge_ids.append(got[0])
                edge_vals.append(got[1])
                edge_lines.append(line_no)
            elif tag == "FIX":
                if _numbers(fields, len(fields) - 1, 0) is None or len(fields) < 2:
                    raise G2OFormatError(path, line_no, line, "expected 'FIX id [id ...]'")
            else:
                raise G2OFormatError(
                    path,
                    line_no,
                    line,
                    "expected a VERTEX_SE2, EDGE_SE2 or FIX line "
                    "(only 2-D SE(2) graphs are supported)",
                )
    ij = np.asarray(edge_ids, dtype=np.int64).reshape(-1, 2)
    vals = np.asarray(edge_vals, dtype=np.float64).reshape(-1, 9)
    if vertex_ids:
        ids = np.asarray(vertex_ids, dtype=np.int64)
        order = np.argsort(ids, kind="stable")
        sorted_ids = ids[order]
        pos = np.searchsorted(sorted_ids, ij)
        pos_c = np.minimum(pos, sorted_ids.shape[0] - 1)
        unknown = sorted_ids[pos_c] != ij
        if np.any(unknown):
            e = int(np.argmax(unknown.any(axis=1)))
            vid = int(ij[e][np.argmax(unknown[e])])
            raise G2OFormatError(
                path,
                edge_lines[e],
                _line_text(path, edge_lines[e]),
                f"expected an edge between defined vertices; {vid} has no VERTEX_SE2 line",
            )
        poses = np.asarray(vertex_poses, dtype=np.float64)[order]
        ij = pos
    else:
        if np.any(ij < 0):
            e = int(np.argmax((ij < 0).any(axis=1)))
            raise G2OFormatError(
                path,
                edge_lines[e],
                _line_text(path, edge_lines[e]),
                "expected non-negative vertex ids",
            )
        n = int(ij.max()) + 1 if ij.size else 0
        poses = initial_poses(n, ij[:, 0], ij[:, 1], vals[:, :3])
    info = np.empty((vals.shape[0], 3, 3))
    iu = np.triu_indices(3)
    info[:, iu[0], iu[1]] = vals[:, 3:]
    info[:, iu[1], iu[0]] = vals[:, 3:]
    _check_information(path, info, edge_lines)
    return PoseGraph.from_arrays(poses, ij[:, 0], ij[:, 1], vals[:, :3], info)


def _check_information(path: Path, info: np.ndarray, edge_lines: list[int]) -> None:
    """Every information matrix must be positive definite: a zero (or indefinite) one makes
    its edge weightless (or rewards error), and a graph of such edges "converges" at any
    poses. Raises :class:`G2OFormatError` naming the first offending line."""
    if info.shape[0] == 0:
        return
    eig = np.linalg.eigvalsh(info)  # ascending, (E, 3)
    scale = np.maximum(np.abs(eig).max(axis=1), np.finfo(float).tiny)
    bad = eig[:, 0] <= 1e-12 * scale
    if np.any(bad):
        e = int(np.argmax(bad))
        raise G2OFormatError(
            path,
            edge_lines[e],
            _line_text(path, edge_lines[e]),
            "expected a positive-definite information matrix (I11 I12 I13 I22 I23 I33); "
            f"its eigenvalues are {', '.join(f'{v:.6g}' for v in eig[e])}",
        )


def _line_text(path: Path, line_no: int) -> str:
    with path.open("r", encoding="utf-8", errors="replace") as f:
        for k, raw in enumerate(f, start=1):
            if k == line_no:
                return raw.strip()
    return ""


def save_g2o(graph: PoseGraph, path: Path | str) -> None:
    """Write ``graph`` as ``VERTEX_SE2`` and ``EDGE_SE2`` lines (vertex ids = node indices).

    Numbers are written with 17 significant digits, so :func:`load_g2o` reads back the same
    float64 values (the information matrix is symmetrised from its upper triangle).
    """
    iu = np.triu_indices(3)
    upper = graph.information[:, iu[0], iu[1]]
    with Path(path).open("w", encoding="utf-8") as f:
        for k, (x, y, th) in enumerate(graph.poses.tolist()):
            f.write(f"VERTEX_SE2 {k} {x:.17g} {y:.17g} {th:.17g}\n")
        for i, j, z, u in zip(
            graph.edge_i.tolist(),
            graph.edge_j.tolist(),
            graph.measurements.tolist(),
            upper.tolist(),
            strict=True,
        ):
            nums = " ".join(f"{v:.17g}" for v in (*z, *u))
            f.write(f"EDGE_SE2 {i} {j} {nums}\n")
