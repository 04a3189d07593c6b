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

With ``--false-closures N`` it then adds N false loop closures to each graph (random pairs of
nodes more than one apart, random relative poses up to 5 m and any heading, the information
of a random true closure; seed 1) and, from the stored guess and from the odometry chain,
prints the chi2 *of the clean graph* at the result of one switchable optimisation
(``optimize(..., switchable=..., switch_scale=S)``), of
:func:`~agvsim.slam.posegraph_graduated.optimize_graduated` (graduated stages, whole graph)
and of ``optimize_switchable`` (the lower cost of the two), beside the known optimum, the
largest switch of a false closure and the smallest of a true one.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from agvsim.slam.datasets import datasets_dir
from agvsim.slam.g2o import load_g2o
from agvsim.slam.perturb import with_false_closures
from agvsim.slam.posegraph import PoseGraph, chi2, optimize
from agvsim.slam.posegraph_graduated import optimize_graduated, optimize_switchable
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


def bench_false_closures(name: str, graph: PoseGraph, n: int, known: float) -> None:
    # the switch scale follows the graph's information: M3500's true closures reach chi2 13 at
    # its optimum, intel's stay under 0.7 (docs/slam.md)
    scale = 5.0 if name == "manhattan" else 1.0
    bad, switchable = with_false_closures(graph, n, seed=1)
    n_true = graph.n_edges
    chain = odometry_chain_poses(bad.n_nodes, bad.edge_i, bad.edge_j, bad.measurements)
    for start, poses in (("stored", graph.poses.copy()), ("chain", chain)):
        if poses is None:
            continue
        bad.poses = poses
        for how in ("one", "graduated", "lower"):
            t0 = time.perf_counter()
            if how == "one":
                r = optimize(bad, max_iterations=100, switchable=switchable, switch_scale=scale)
            elif how == "graduated":
                r = optimize_graduated(bad, switchable, scale)
            else:
                r = optimize_switchable(bad, switchable, scale)
            dt = time.perf_counter() - t0
            c = chi2(graph, r.poses)
            print(
                f"{name:<11}{start:<8}{how:<11}{n:>6d}{scale:>6.1f}{c:>14.4f}{known:>11.6g}"
                f"{(c - known) / known:>+10.2e}{r.switches[n_true:].max():>9.3f}"
                f"{r.switches[:n_true][switchable[:n_true]].min():>9.3f}{dt:>8.1f}",
                flush=True,
            )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help=f"graphs (default: {' '.join(KNOWN_OPTIMA)})")
    parser.add_argument("--max-iterations", type=int, default=100)
    parser.add_argument(
        "--false-closures", type=int, default=0, help="then add this many false closures"
    )
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
    if args.false_closures > 0:
        print(
            f"\n{'graph':<11}{'start':<8}{'switches':<11}{'false':>6}{'scale':>6}"
            f"{'chi2 clean':>14}{'known':>11}{'rel diff':>10}{'max off':>9}{'min on':>9}{'s':>8}"
        )
        for name in names:
            path = root / "posegraphs" / f"{name}.g2o"
            if path.is_file():
                bench_false_closures(name, load_g2o(path), args.false_closures, KNOWN_OPTIMA[name])
    return 0


if __name__ == "__main__":
    sys.exit(main())
