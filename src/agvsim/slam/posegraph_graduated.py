"""Switchable loop closures from a poor start: graduated stages over the whole graph.

Switchable constraints (:attr:`~.robust.RobustKernel.DCS`) tell a false loop closure from a
true one by its error at the current poses, so they need poses near the right basin: from a
graph's odometry chain (M3500: tens of metres off) every true closure of a long loop starts
with a huge error and is switched off with the false ones (200 false closures among M3500's
1,954 true ones: chi2 118,566 against the optimum 3,549).

:func:`optimize_graduated` relaxes the switches' prior and tightens it in stages (graduated
non-convexity, as :meth:`~.graph_slam.GraphSlam.optimise` does online): the first stage's
bound keeps every closure whole at the start (plain least squares, where the true closures,
ten to one, pull the graph into their basin), each next one divides it by ``stage_factor``
in chi2, down to ``switch_scale`` standard deviations, and a last optimisation at that scale
converges. With ``nodes_per_step`` the graph is also grown in node order, the order a SLAM
run created it in, as an online SLAM meets it: the new nodes are placed after the last
optimised one by the odometry chain (or, without one, by the start's relative poses) and the
graph so far is optimised in graduated stages before more nodes come. Measured on M3500 with
200 false closures from its odometry chain, both reach the optimum (``docs/slam.md``).

The first stage is plain least squares, and where the false closures outweigh the true ones
there it can lead astray a start that one switchable optimisation would have kept (intel.g2o
with ``Phi = 9``). Both minimise the same cost at ``switch_scale``, so
:func:`optimize_switchable` runs both and keeps the lower cost: on the benchmark graphs with
200 false closures it is the one nearer the true optimum in every case measured.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from agvsim.slam.posegraph import OptimizeResult, PoseGraph, chi2, edge_chi2, optimize
from agvsim.slam.posegraph_init import odometry_chain_poses
from agvsim.slam.se2 import between, compose

__all__ = ["graduated_scales", "optimize_graduated", "optimize_switchable"]


def graduated_scales(chi2_worst: float, switch_scale: float, stage_factor: float) -> list[float]:
    """Switch scales (std) of the graduated stages: ``sqrt(chi2_worst)``, then divided by
    ``stage_factor`` in chi2 per stage while above ``switch_scale^2``, then ``switch_scale``."""
    if stage_factor <= 1.0:
        raise ValueError(f"stage_factor must be above 1, got {stage_factor}")
    final = switch_scale**2
    stages = []
    worst = chi2_worst
    while worst > final:
        stages.append(math.sqrt(worst))
        worst /= stage_factor
    return [*stages, switch_scale]


def optimize_graduated(
    graph: PoseGraph,
    switchable: ArrayLike,
    switch_scale: float,
    *,
    nodes_per_step: int | None = None,
    stage_factor: float = 10.0,
    max_iterations: int = 100,
) -> OptimizeResult:
    """Optimise ``graph`` with switchable constraints on the ``switchable`` (E,) edges in
    graduated stages, the whole graph at once or (``nodes_per_step``) grown in node order that
    many nodes at a time (module docstring); node 0 is fixed. Does not modify ``graph``;
    ``chi2_initial`` is the given poses' chi2."""
    switch = np.asarray(switchable, dtype=bool)
    if switch.shape != (graph.n_edges,):
        raise ValueError(
            f"switchable must have one flag per edge, shape ({graph.n_edges},); got {switch.shape}"
        )
    if nodes_per_step is None:
        nodes_per_step = max(graph.n_nodes, 1)
    if nodes_per_step < 1:
        raise ValueError(f"nodes_per_step must be at least 1, got {nodes_per_step}")
    start = graph.poses.copy()
    chain = odometry_chain_poses(graph.n_nodes, graph.edge_i, graph.edge_j, graph.measurements)
    guide = start if chain is None else chain  # relative poses that place the new nodes
    poses = start.copy()
    last = np.maximum(graph.edge_i, graph.edge_j)
    done = min(nodes_per_step, graph.n_nodes)
    while True:
        keep = last < done
        sub = PoseGraph.from_arrays(
            poses[:done],
            graph.edge_i[keep],
            graph.edge_j[keep],
            graph.measurements[keep],
            graph.information[keep],
        )
        mask = switch[keep]
        worst = float(edge_chi2(sub)[mask].max()) if mask.any() else 0.0
        for scale in graduated_scales(worst, switch_scale, stage_factor):
            final = scale == switch_scale
            res = optimize(
                sub,
                max_iterations=30 if final else 10,
                tolerance=1e-6 if final else 1e-4,
                switchable=mask,
                switch_scale=scale,
            )
            sub.poses = res.poses
        poses[:done] = sub.poses
        if done == graph.n_nodes:
            break
        nxt = min(done + nodes_per_step, graph.n_nodes)
        poses[done:nxt] = compose(poses[done - 1], between(guide[done - 1], guide[done:nxt]))
        done = nxt
    whole = graph.copy()
    whole.poses = poses
    res = optimize(
        whole, max_iterations=max_iterations, switchable=switch, switch_scale=switch_scale
    )
    chi2_given = chi2(graph) if graph.n_edges else 0.0
    return OptimizeResult(
        res.poses,
        chi2_given,
        res.chi2_final,
        res.iterations,
        res.converged,
        res.cost_initial,
        res.cost_final,
        res.switches,
    )


def optimize_switchable(
    graph: PoseGraph,
    switchable: ArrayLike,
    switch_scale: float,
    *,
    stage_factor: float = 10.0,
    max_iterations: int = 100,
) -> OptimizeResult:
    """The lower-cost result of one switchable optimisation from the given poses and of
    :func:`optimize_graduated` (whole graph): the same robust cost, two starts."""
    direct = optimize(
        graph, max_iterations=max_iterations, switchable=switchable, switch_scale=switch_scale
    )
    graduated = optimize_graduated(
        graph,
        switchable,
        switch_scale,
        stage_factor=stage_factor,
        max_iterations=max_iterations,
    )
    return graduated if graduated.cost_final < direct.cost_final else direct
