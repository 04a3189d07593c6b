"""g2o files: round trip, clear errors for malformed lines, graphs without vertices, the CLI."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from agvsim.slam.datasets import datasets_dir
from agvsim.slam.eval_cli import SlamCommandError, optimize_g2o_command
from agvsim.slam.g2o import G2OFormatError, load_g2o, save_g2o
from agvsim.slam.posegraph import PoseGraph, chi2

SMALL = """# a triangle
VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1.1 0.1 1.5
FIX 0
VERTEX_SE2 2 0.9 1.2 3.0

EDGE_SE2 0 1 1 0 1.5707963267948966 10 0.5 0 20 0 30
EDGE_SE2 1 2 1 0 1.5707963267948966 10 0 0 10 0 10
EDGE_SE2 2 0 1.4142135623730951 0 2.356194490192345 5 0 0 5 0 50
"""


def write(tmp_path: Path, text: str, name: str = "g.g2o") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_load_small(tmp_path: Path) -> None:
    g = load_g2o(write(tmp_path, SMALL))
    assert g.n_nodes == 3 and g.n_edges == 3
    np.testing.assert_array_equal(g.poses[1], [1.1, 0.1, 1.5])
    np.testing.assert_array_equal(g.edge_i, [0, 1, 2])
    np.testing.assert_array_equal(g.edge_j, [1, 2, 0])
    np.testing.assert_array_equal(g.information[0], [[10, 0.5, 0], [0.5, 20, 0], [0, 0, 30]])


def test_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    n, e = 30, 50
    info = rng.normal(size=(e, 3, 3))
    info = info @ np.swapaxes(info, 1, 2) + np.eye(3)
    g = PoseGraph.from_arrays(
        rng.normal(size=(n, 3)) * [100, 100, 1],
        rng.integers(0, n // 2, e),
        rng.integers(n // 2, n, e),
        rng.normal(size=(e, 3)),
        info,
    )
    path = tmp_path / "out.g2o"
    save_g2o(g, path)
    back = load_g2o(path)
    for name in ("poses", "edge_i", "edge_j", "measurements", "information"):
        np.testing.assert_array_equal(getattr(back, name), getattr(g, name), err_msg=name)


def test_vertex_ids_are_renumbered(tmp_path: Path) -> None:
    text = "VERTEX_SE2 20 2 0 0\nVERTEX_SE2 10 1 0 0\nEDGE_SE2 10 20 1 0 0 1 0 0 1 0 1\n"
    g = load_g2o(write(tmp_path, text))
    np.testing.assert_array_equal(g.poses[:, 0], [1, 2])
    assert (g.edge_i[0], g.edge_j[0]) == (0, 1)
    assert chi2(g) == pytest.approx(0.0)


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0", "EDGE_SE2 i j dx dy dtheta"),
        ("EDGE_SE2 0 1 1 0 x 1 0 0 1 0 1", "11 numbers"),
        ("VERTEX_SE2 1 1 0", "VERTEX_SE2 id x y theta"),
        ("VERTEX_SE2 1.5 1 0 0", "VERTEX_SE2 id x y theta"),
        ("VERTEX_SE2 0 1 0 0", "vertex 0 already defined on line 2"),
        ("VERTEX_SE3:QUAT 1 0 0 0 0 0 0 1", "VERTEX_SE2, EDGE_SE2 or FIX"),
        ("EDGE_SE2 1 1 1 0 0 1 0 0 1 0 1", "two different vertices"),
        ("EDGE_SE2 0 7 1 0 0 1 0 0 1 0 1", "7 has no VERTEX_SE2"),
        ("FIX zero", "FIX id"),
        ("VERTEX_SE2 3 nan 0 0", "VERTEX_SE2 id x y theta"),
    ],
)
def test_malformed_line_names_file_line_and_text(tmp_path: Path, line: str, expected: str) -> None:
    path = write(tmp_path, f"# header\nVERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n{line}\n", "bad.g2o")
    with pytest.raises(G2OFormatError) as info:
        load_g2o(path)
    err = info.value
    assert isinstance(err, ValueError)
    assert err.line_no == 4 and err.line == line
    assert "bad.g2o:4: " in str(err) and expected in str(err) and line in str(err)


def test_graph_without_vertices_starts_from_odometry(tmp_path: Path) -> None:
    quarter = f"1 0 {math.pi / 2} 1 0 0 1 0 1"
    text = "".join(f"EDGE_SE2 {k} {k + 1} {quarter}\n" for k in range(3))
    text += f"EDGE_SE2 3 0 {quarter}\n"
    g = load_g2o(write(tmp_path, text))
    assert g.n_nodes == 4
    np.testing.assert_allclose(g.poses[:, :2], [[0, 0], [1, 0], [1, 1], [0, 1]], atol=1e-12)
    assert chi2(g) == pytest.approx(0.0, abs=1e-20)


def test_graph_without_vertices_and_broken_chain_uses_tree(tmp_path: Path) -> None:
    # no edge 1 -> 2: node 2 is reached through 0 -> 2
    text = "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 0 2 0 2 0 1 0 0 1 0 1\n"
    g = load_g2o(write(tmp_path, text))
    np.testing.assert_allclose(g.poses, [[0, 0, 0], [1, 0, 0], [0, 2, 0]])


def test_optimize_g2o_command(tmp_path: Path) -> None:
    src = write(tmp_path, SMALL)
    out = tmp_path / "opt.g2o"
    text = optimize_g2o_command(src, out=out, robust="none", max_iterations=50)
    assert "3 nodes, 3 edges" in text and "converged" in text and str(out) in text
    optimised = load_g2o(out)
    assert chi2(optimised) < chi2(load_g2o(src))
    assert "robust cost" in optimize_g2o_command(src, None, "huber", 50)
    with pytest.raises(SlamCommandError, match="choose one of none, huber, cauchy"):
        optimize_g2o_command(src, None, "tukey", 10)
    with pytest.raises(SlamCommandError, match="not found"):
        optimize_g2o_command(tmp_path / "missing.g2o", None, "none", 10)
    with pytest.raises(SlamCommandError, match=r"bad\.g2o:1: "):
        optimize_g2o_command(write(tmp_path, "EDGE_SE2 0 1\n", "bad.g2o"), None, "none", 10)


@pytest.mark.skipif(datasets_dir() is None, reason="datasets folder absent")
def test_manhattan_loads_from_odometry_chain() -> None:
    root = datasets_dir()
    assert root is not None
    g = load_g2o(root / "posegraphs" / "manhattan.g2o")
    assert (g.n_nodes, g.n_edges) == (3500, 5453)
    odo = g.edge_j == g.edge_i + 1
    # the chain reproduces every odometry edge exactly
    from agvsim.slam.posegraph import edge_errors

    assert np.abs(edge_errors(g)[odo]).max() < 1e-9
