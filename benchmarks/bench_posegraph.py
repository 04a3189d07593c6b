"""Pose-graph optimisation on the community benchmark graphs (plain least squares, node 0 fixed).

Run ``python benchmarks/bench_posegraph.py [names ...]``. For each of ``intel.g2o``,
``manhattan.g2o`` (M3500, no vertices: initialised from the odometry chain) and
``city10000.g2o`` prints nodes, edges, chi2 before and after, the known optimum and the relative
difference, iterations and seconds (load time apart from optimisation time). The graphs come
from ``$AGVSIM_DATASETS`` or ``<repo>/../shared/datasets/posegraphs``; skips with a message when
that folder is absent. Prints numbers; does not gate.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from agvsim.slam.datasets import datasets_dir
from agvsim.slam.g2o import load_g2o
from agvsim.slam.posegraph import optimize

KNOWN_OPTIMA = {"intel": 45.0047, "manhattan": 3549.04, "city10000": 511.985}


def bench(path: Path, known: float, max_iterations: int) -> dict[str, float]:
    t0 = time.perf_counter()
    graph = load_g2o(path)
    t1 = time.perf_counter()
    result = optimize(graph, max_iterations=max_iterations)
    t2 = time.perf_counter()
    return {
        "nodes": graph.n_nodes,
        "edges": graph.n_edges,
        "chi2_initial": result.chi2_initial,
        "chi2_final": result.chi2_final,
        "known": known,
        "rel_diff": (result.chi2_final - known) / known,
        "iterations": result.iterations,
        "converged": result.converged,
        "load_s": t1 - t0,
        "optimize_s": t2 - t1,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help=f"graphs (default: {' '.join(KNOWN_OPTIMA)})")
    parser.add_argument("--max-iterations", type=int, default=100)
    args = parser.parse_args()
    names = args.names or list(KNOWN_OPTIMA)
    unknown = sorted(set(names) - set(KNOWN_OPTIMA))
    if unknown:
        parser.error(f"unknown graph(s) {unknown}; choose from {list(KNOWN_OPTIMA)}")
    root = datasets_dir()
    if root is None or not (root / "posegraphs").is_dir():
        print("bench_posegraph: no datasets folder (set AGVSIM_DATASETS); skipped")
        return 0
    header = (
        f"{'graph':<11}{'nodes':>7}{'edges':>7}{'chi2 initial':>14}{'chi2 final':>13}"
        f"{'known':>11}{'rel diff':>10}{'iters':>6}{'load s':>8}{'opt s':>8}"
    )
    print(header)
    for name in names:
        path = root / "posegraphs" / f"{name}.g2o"
        if not path.is_file():
            print(f"{name:<11} missing ({path}); skipped")
            continue
        r = bench(path, KNOWN_OPTIMA[name], args.max_iterations)
        flag = "" if r["converged"] else "  (not converged)"
        print(
            f"{name:<11}{r['nodes']:>7d}{r['edges']:>7d}{r['chi2_initial']:>14.6g}"
            f"{r['chi2_final']:>13.6f}{r['known']:>11.6g}{r['rel_diff']:>+10.2e}"
            f"{r['iterations']:>6d}{r['load_s']:>8.3f}{r['optimize_s']:>8.3f}{flag}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
