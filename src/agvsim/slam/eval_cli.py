"""Plain functions behind the ``agvsim`` SLAM commands (no typer here, so they are testable).

Each returns the text to print and raises :class:`SlamCommandError` (a ``ValueError``) with a
one-line message for bad input: a missing file, a malformed line (file and line number), or
trajectories and relations that do not overlap.
"""

from __future__ import annotations

import time
from pathlib import Path

from agvsim.slam.evaluate import (
    EvaluationError,
    evaluate_relations,
    format_relation_errors,
    load_relations,
    load_trajectory,
)
from agvsim.slam.g2o import G2OFormatError, load_g2o, save_g2o
from agvsim.slam.posegraph import Initialisation, PoseGraph, RobustKernel, optimize

__all__ = ["SlamCommandError", "eval_command", "optimize_g2o_command"]


class SlamCommandError(ValueError):
    """Bad input to a SLAM command; the message is meant for the user as is."""


def _need_file(path: Path, what: str) -> None:
    if not path.is_file():
        raise SlamCommandError(f"{what} file not found: {path}")


def eval_command(trajectory: Path, relations: Path, tolerance_s: float = 1e-3) -> str:
    """Score a ``timestamp x y theta`` trajectory on a Kümmerle ``*.relations`` file."""
    _need_file(trajectory, "trajectory")
    _need_file(relations, "relations")
    try:
        traj = load_trajectory(trajectory)
        rel = load_relations(relations)
        result = evaluate_relations(traj, rel, tolerance_s=tolerance_s)
    except EvaluationError as exc:
        raise SlamCommandError(str(exc)) from exc
    return format_relation_errors(result, title=f"{trajectory.name} on {relations.name}")


def optimize_g2o_command(
    path: Path,
    out: Path | None = None,
    robust: RobustKernel | str = RobustKernel.NONE,
    max_iterations: int = 100,
    robust_scale: float = 1.0,
    initialisation: Initialisation | str = Initialisation.AUTO,
) -> str:
    """Load a 2-D g2o graph, optimise it (node 0 fixed) and report chi2, iterations and time;
    write the optimised graph to ``out`` when given. By default the start is the better of
    the stored guess and the guess-free chordal start (:class:`~.posegraph.Initialisation`)."""
    _need_file(path, "g2o")
    try:
        kernel = RobustKernel(robust)
    except ValueError as exc:
        choices = ", ".join(k.value for k in RobustKernel)
        raise SlamCommandError(
            f"unknown robust kernel {robust!r}; choose one of {choices}"
        ) from exc
    if max_iterations < 1:
        raise SlamCommandError(f"max_iterations must be at least 1, got {max_iterations}")
    try:
        graph = load_g2o(path)
    except G2OFormatError as exc:
        raise SlamCommandError(str(exc)) from exc
    if graph.n_nodes == 0:
        raise SlamCommandError(f"{path}: the graph has no nodes")
    t0 = time.perf_counter()
    result = optimize(
        graph,
        robust=kernel,
        robust_scale=robust_scale,
        max_iterations=max_iterations,
        initialisation=initialisation,
    )
    seconds = time.perf_counter() - t0
    lines = [
        f"{path.name}: {graph.n_nodes} nodes, {graph.n_edges} edges, robust kernel {kernel.value}",
        f"  chi2 initial  {result.chi2_initial:.6g}",
        f"  chi2 final    {result.chi2_final:.6g}",
        f"  iterations    {result.iterations} ({'converged' if result.converged else 'stopped'})",
        f"  time          {seconds:.3f} s",
    ]
    if kernel is not RobustKernel.NONE:
        lines.insert(3, f"  robust cost   {result.cost_initial:.6g} -> {result.cost_final:.6g}")
    if out is not None:
        optimised = PoseGraph.from_arrays(
            result.poses, graph.edge_i, graph.edge_j, graph.measurements, graph.information
        )
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        save_g2o(optimised, out)
        lines.append(f"  wrote         {out}")
    return "\n".join(lines)
