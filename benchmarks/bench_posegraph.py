"""Pose-graph optimisation on the community benchmark graphs (plain least squares, node 0 fixed).

Run ``python benchmarks/bench_posegraph.py [names ...]``. For each of ``intel.g2o``,
``manhattan.g2o`` (M3500, no vertices: initialised from the odometry chain) and
``city10000.g2o``, from three starts (the stored guess, the odometry chain, and the stored
guess with a random heading per pose, seed 7) and two initialisations (``given``: LM from that
start; ``auto``: the better of it and the guess-free chordal start) prints nodes, edges, chi2
before and after, the known optimum and the relative difference, iterations and seconds (load
time apart from optimisation time). The graphs come
from ``$AGVSIM_DATASETS`` or ``<repo>/../shared/datasets/posegraphs``; skips with a message when
that folder is absent. Prints numbers; does not gate.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from agvsim.slam.datasets import datasets_dir
from agvsim.slam.g2o import load_g2o
from agvsim.slam.posegraph import PoseGraph, optimize
from agvsim.slam.posegraph_init import odometry_chain_poses

KNOWN_OPTIMA = {"intel": 45.0047, "manhattan": 3549.04, "city10000": 511.985}


def starts(graph: PoseGraph) -> dict[str, np.ndarray]:
    """The three starting guesses: stored, odometry chain, random heading per pose."""
    chain = odometry_chain_poses(graph.n_nodes, graph.edge_i, graph.edge_j, graph.measurements)
    rotated = graph.poses.copy()
    rotated[1:, 2] = np.random.default_rng(7).uniform(-np.pi, np.pi, graph.n_nodes - 1)
    out = {"stored": graph.poses.copy(), "random-rot": rotated}
    if chain is not None:
        out["chain"] = chain
    return out


def bench(
    graph: PoseGraph, load_s: float, known: float, max_iterations: int, init: str
) -> dict[str, float]:
    t1 = time.perf_counter()
    result = optimize(graph, max_iterations=max_iterations, initialisation=init)
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
        "load_s": load_s,
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
        f"{'graph':<11}{'start':<11}{'init':<7}{'nodes':>7}{'edges':>7}{'chi2 initial':>14}"
        f"{'chi2 final':>14}"
        f"{'known':>11}{'rel diff':>10}{'iters':>6}{'load s':>8}{'opt s':>8}"
    )
    print(header)
    for name in names:
        path = root / "posegraphs" / f"{name}.g2o"
        if not path.is_file():
            print(f"{name:<11} missing ({path}); skipped")
            continue
        t0 = time.perf_counter()
        graph = load_g2o(path)
        load_s = time.perf_counter() - t0
        for start, poses in starts(graph).items():
            graph.poses = poses
            for init in ("given", "auto"):
                r = bench(graph, load_s, KNOWN_OPTIMA[name], args.max_iterations, init)
                flag = "" if r["converged"] else "  (not converged)"
                print(
                    f"{name:<11}{start:<11}{init:<7}{r['nodes']:>7d}{r['edges']:>7d}{r['chi2_initial']:>14.6g}"
                    f"{r['chi2_final']:>14.6f}{r['known']:>11.6g}{r['rel_diff']:>+10.2e}"
                    f"{r['iterations']:>6d}{r['load_s']:>8.3f}{r['optimize_s']:>8.3f}{flag}",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
