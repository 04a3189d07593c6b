"""Loop closure: candidates within a search radius, branch-and-bound matching, verification.

For a new keyframe ``i`` with global estimate ``g_i``, every finished submap ``s`` holding a
keyframe ``k`` within ``search_radius_m + b_k`` of ``g_i`` (and none of the last
``min_node_gap`` keyframes) is a candidate. ``b_k`` bounds how far the graph's estimate of
``k`` relative to ``i`` may be off: ``drift_sigmas`` standard deviations of the relative pose's
covariance, propagated along the most certain route from ``k`` to ``i``: over the keyframe
chain and across the accepted loop closures, each of which holds its keyframe to the submap it
matched (:func:`drift_bounds`). Each step adds a random walk in translation and heading that
grows with the distance driven and the angle turned, and a heading error at step ``j`` swings
the rest of the route by the lever arm ``|p_i - p_j|``: the search grows fast on long loops
and not on a robot turning on the spot, with no fixed radius.
The match's windows grow the same way, in translation and in heading.

The scan is placed in the submap's frame at the graph's guess ``x_0 = o_s * (G_s^-1 * g_i)``
(``o_s``: submap origin in the local frame it was built in, ``G_s``: its global pose) and
matched with :func:`~.scan_matching.branch_and_bound` over a ``+-(window_m + b_k)``,
``+-(window_rad + b_k,theta)`` window (``b_k,theta`` the heading bound), then refined by
Gauss-Newton.

A closure is *verified* when

1. its score (mean likelihood of the scan's points in the submap) is at least ``min_score``, and
2. the matched global pose ``g_i'`` agrees with the graph (``D = g_i^-1 g_i'`` within
   ``agree_m`` and ``agree_rad``), or a recent pending closure ``j`` is consistent with it
   and one of the two scores at least ``jump_min_score``: the two matched poses are placed as
   local tracking placed the two keyframes, ``(g_j'^-1 g_i')^-1 (l_j^-1 l_i)`` within the
   same bounds (pairwise consistency), ``j`` lies ``confirm_gap`` keyframes or more back and
   was matched in another submap (neighbouring keyframes in one submap see the same walls and
   repeat the same wrong fit). A single strong match in a place that merely looks alike
   cannot bend the graph on its own; in a maze of 1 m cells a fit one cell off, half the scan
   on walls, is common.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components, dijkstra

from agvsim.slam import scan_matching as sm
from agvsim.slam.frontend import Submap
from agvsim.slam.memory import HeapReleaser
from agvsim.slam.se2 import between, compose

__all__ = [
    "LoopClosure",
    "LoopConfig",
    "LoopDetector",
    "TiePlaces",
    "drift_bounds",
    "step_variances",
    "tie_places",
]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class LoopConfig:
    """Knobs of loop closing (metres, radians)."""

    search_radius_m: float = 3.0  # the thesis's search radius
    window_m: float = 1.5  # branch-and-bound window around the graph's guess, +-
    window_rad: float = math.radians(15.0)
    # local SLAM's drift as random walks (std): translation per sqrt(metre driven), heading per
    # sqrt(metre driven) and per sqrt(radian turned); see drift_bounds
    drift_m_per_sqrt_m: float = 0.02
    drift_rad_per_sqrt_m: float = math.radians(0.1)
    drift_rad_per_sqrt_rad: float = 0.01
    drift_sigmas: float = 3.0  # search bounds: this many standard deviations
    max_drift_m: float = 8.0  # caps of the bounds (the matching cost grows with the window)
    max_drift_rad: float = math.radians(45.0)
    min_score: float = 0.55  # the thesis's loop-closure threshold, as a mean likelihood
    min_node_gap: int = 80  # keyframes between a node and the submaps it may close on
    max_candidates: int = 2  # submaps matched per keyframe, nearest first
    agree_m: float = 0.3
    agree_rad: float = math.radians(3.0)
    pending_nodes: int = 20  # how long an unconfirmed closure waits for a second one
    jump_min_score: float = 0.7  # a closure that moves the graph needs at least this score
    confirm_gap: int = 5  # ... from a keyframe at least this many keyframes later (new geometry)
    sigma_m: float = 0.05  # std of a match along its best-constrained direction
    min_eigen_ratio: float = 0.02  # floor of the information along weak directions (corridors)
    pyramid_levels: int = 6
    gn_iterations: int = 15
    jump_drift_factor: float = 2.0  # a match may move a node agree_m + this x drift bound
    pyramid_cache_mib: float = 256.0  # submap pyramids kept for matching (LRU)


@dataclass(frozen=True)
class LoopClosure:
    """Node ``node`` seen in submap ``submap``: ``measurement`` = T_submap_node (3,)."""

    node: int
    submap: int
    measurement: F64
    score: float
    matched: F64  # g_i': the node's global pose implied by the match (3,)
    estimate: F64  # g_i: the graph's global estimate of the node when matched (3,)
    local: F64  # l_i: the node's local tracking pose (3,)
    information: F64  # (3, 3) in the submap frame's node coordinates, see _shape_information


class LoopDetector:
    """Finds, matches and verifies loop closures; caches the submaps' max pyramids (LRU)."""

    def __init__(self, cfg: LoopConfig, resolution_m: float) -> None:
        self.cfg = cfg
        self.res = resolution_m
        self._pyramids: OrderedDict[int, np.ndarray] = OrderedDict()
        self._cached_bytes = 0
        # evicted pyramids (and the fields they were built from) free large blocks: give the
        # heap's free pages back after every quarter of the cache's budget evicted
        self._releaser = HeapReleaser(max(int(cfg.pyramid_cache_mib * 2**20) // 4, 1 << 20))
        self._pending: list[LoopClosure] = []

    def candidates(
        self,
        node: int,
        node_xy: F64,
        node_submap: NDArray[np.int64],
        drift_m: F64,
        submaps: list[Submap],
        drift_rad: F64 | None = None,
    ) -> list[tuple[int, float, float]]:
        """Finished submaps with a keyframe ``k`` within ``search_radius_m + drift_m[k]`` of
        ``node``, nearest first, with that keyframe's drift bounds (m, rad); ``node_xy (N, 2)``
        global positions, ``node_submap (N,)`` each node's submap, ``drift_m (N,)`` and
        ``drift_rad (N,)`` how far the graph's estimate of each node relative to ``node`` may
        be off (:func:`drift_bounds`; capped at ``max_drift_m``, ``max_drift_rad``)."""
        last = node - self.cfg.min_node_gap
        if last <= 0:
            return []
        d = np.hypot(*(node_xy[:last] - node_xy[node]).T)
        drift = np.minimum(drift_m[:last], self.cfg.max_drift_m)
        turn = np.zeros(last) if drift_rad is None else drift_rad[:last]
        turn = np.minimum(turn, self.cfg.max_drift_rad)
        near = np.nonzero(d <= self.cfg.search_radius_m + drift)[0]
        if near.size == 0:
            return []
        out: list[tuple[int, float, float]] = []
        for k in near[np.argsort(d[near])]:
            s = int(node_submap[k])
            if all(s != o[0] for o in out) and submaps[s].finished and max(submaps[s].nodes) < last:
                out.append((s, float(drift[k]), float(turn[k])))
                if len(out) == self.cfg.max_candidates:
                    break
        return out

    def pyramid(self, s: Submap) -> np.ndarray:
        """The submap's max pyramid (level 0: its likelihood field), from a cache of at most
        ``pyramid_cache_mib`` (least recently used first out): memory bounded by the map, not
        by the log."""
        pyr = self._pyramids.get(s.index)
        if pyr is None:
            pyr = sm.max_pyramid(s.field(), self.cfg.pyramid_levels)
            self._pyramids[s.index] = pyr
            self._cached_bytes += pyr.nbytes
            budget = self.cfg.pyramid_cache_mib * 2**20
            while self._cached_bytes > budget and len(self._pyramids) > 1:
                nbytes = self._pyramids.popitem(last=False)[1].nbytes  # freed here
                self._cached_bytes -= nbytes
                self._releaser.freed(nbytes)
        else:
            self._pyramids.move_to_end(s.index)
        return pyr

    def match(
        self,
        node: int,
        points: F64,
        ang_step: float,
        g_node: F64,
        l_node: F64,
        s: Submap,
        g_submap: F64,
        drift_m: float = 0.0,
        drift_rad: float = 0.0,
    ) -> LoopClosure | None:
        """Branch-and-bound + Gauss-Newton of ``points`` (robot frame) in submap ``s``, the
        windows widened by the drift bounds (m, rad); None when the score stays under
        ``min_score``."""
        cfg = self.cfg
        win_m = cfg.window_m + drift_m
        win_rad = cfg.window_rad + drift_rad
        guess = compose(s.origin, between(g_submap, g_node))
        pyramid = self.pyramid(s)
        field = pyramid[0]
        pose, score = sm.branch_and_bound(
            pyramid,
            s.ox,
            s.oy,
            self.res,
            points,
            guess,
            win_m,
            win_rad,
            ang_step,
            cfg.min_score,
        )
        if score < cfg.min_score:
            return None
        refined, score2, hess = sm.gauss_newton(
            field, s.ox, s.oy, self.res, points, pose, cfg.gn_iterations, 1e-4
        )
        score = sm.score_pose(field, s.ox, s.oy, self.res, points, pose)
        if score2 >= score and np.all(np.abs(refined[:2] - pose[:2]) < 2 * self.res):
            pose, score = refined, score2
        jump = between(guess, pose)
        if math.hypot(jump[0], jump[1]) > cfg.agree_m + cfg.jump_drift_factor * drift_m:
            # farther from the graph's estimate than local SLAM can have drifted: in a maze or
            # a row of equal rooms the same walls fit one period off
            return None
        meas = between(s.origin, pose)
        return LoopClosure(
            node,
            s.index,
            meas,
            float(score),
            compose(g_submap, meas),
            # copies: a row of the caller's (N, 3) pose array would keep all of it alive, one
            # whole copy of the graph per loop closure (memory quadratic in the log's length)
            np.array(g_node, dtype=np.float64),
            np.array(l_node, dtype=np.float64),
            _shape_information(hess, -pose[2], cfg.sigma_m, cfg.min_eigen_ratio),
        )

    def verify(self, closure: LoopClosure) -> list[LoopClosure]:
        """The closures that become accepted now (this one, and a pending one it confirms)."""
        cfg = self.cfg
        self._pending = [p for p in self._pending if closure.node - p.node <= cfg.pending_nodes]
        if self.agrees(between(closure.estimate, closure.matched)):
            return [closure]
        # a weak fit far from the graph's estimate is most likely a look-alike: it waits, and
        # is taken only with a consistent strong one (sparse scans build thinner submaps, where
        # right closures score lower; their drifted graph needs them most)
        strong = closure.score >= cfg.jump_min_score
        for p in self._pending:
            err = between(between(p.matched, closure.matched), between(p.local, closure.local))
            if (
                closure.node - p.node >= cfg.confirm_gap
                and closure.submap != p.submap
                and (strong or p.score >= cfg.jump_min_score)
                and self.agrees(err)
            ):
                self._pending.remove(p)
                return [p, closure]
        self._pending.append(closure)
        return []

    def clear_pending(self) -> None:
        """Forget unconfirmed closures (their estimates are stale after an optimisation)."""
        self._pending = []

    def agrees(self, d: F64) -> bool:
        """``d`` (3,) within ``agree_m`` and ``agree_rad``."""
        return bool(math.hypot(d[0], d[1]) <= self.cfg.agree_m and abs(d[2]) <= self.cfg.agree_rad)


def _shape_information(hess: F64, rot_rad: float, sigma_m: float, floor: float) -> F64:
    """Information of a match from the Gauss-Newton ``J^T J`` (computed for submap-frame
    increments): rotated into the node's frame (the edge error's frame), scaled so that the
    best-constrained translation direction has std ``sigma_m``, eigenvalues floored at
    ``floor`` times the largest (a corridor constrains little along itself, so the edge pulls
    little that way)."""
    c, s = math.cos(rot_rad), math.sin(rot_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    h = rot @ hess @ rot.T  # R(theta)^T H R(theta), theta the heading in the grid frame
    lam_t = float(np.linalg.eigvalsh(h[:2, :2])[-1])
    if not lam_t > 0:
        return np.diag([sigma_m**-2, sigma_m**-2, (sigma_m / 5.0) ** -2])
    h = h / (lam_t * sigma_m**2)
    w, v = np.linalg.eigh(h)
    w = np.maximum(w, floor * w[-1])
    return (v * w) @ v.T


def step_variances(cfg: LoopConfig, step: F64) -> tuple[float, float]:
    """Variances (translation per axis m^2, heading rad^2) that local SLAM's drift adds over
    one keyframe step ``step`` (3,): random walks in the distance driven and the angle turned
    (:class:`LoopConfig` ``drift_*``)."""
    dist, turn = math.hypot(step[0], step[1]), abs(step[2])
    var_t = cfg.drift_m_per_sqrt_m**2 * dist
    var_r = cfg.drift_rad_per_sqrt_m**2 * dist + cfg.drift_rad_per_sqrt_rad**2 * turn
    return var_t, var_r


def tie_places(ties: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """(n,) the place of each of ``n`` keyframes: keyframes that ``ties (M, 2)`` hold together
    (directly or through others) share a label, their lowest keyframe's index; a keyframe no
    tie holds is -1. See :func:`drift_bounds` and :class:`TiePlaces`."""
    ties = np.asarray(ties, dtype=np.int64).reshape(-1, 2)
    if np.any((ties < 0) | (ties >= n)):
        raise ValueError(f"ties must name keyframes 0..{n - 1}")
    graph = sp.coo_matrix((np.ones(len(ties)), (ties[:, 0], ties[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    lowest = np.full(n, n, dtype=np.int64)
    np.minimum.at(lowest, comp, np.arange(n))
    place = lowest[comp]
    tied = np.zeros(n, dtype=bool)
    tied[ties.ravel()] = True
    place[~tied] = -1
    return place


class TiePlaces:
    """:func:`tie_places` kept up to date as ties come in, one at a time (a tie that joins two
    places, or brings in a keyframe lower than its place's, relabels: one pass over the
    keyframes)."""

    def __init__(self) -> None:
        self.place = np.zeros(0, dtype=np.int64)

    def grow(self, n: int) -> None:
        """Room for ``n`` keyframes (new ones untied)."""
        if n > len(self.place):
            extra = np.full(max(n, 2 * len(self.place)) - len(self.place), -1, dtype=np.int64)
            self.place = np.concatenate([self.place, extra])

    def tie(self, a: int, b: int) -> None:
        """Hold keyframes ``a`` and ``b`` together."""
        self.grow(max(a, b) + 1)
        p = self.place
        labels = [int(x) for x in (p[a], p[b]) if x >= 0]
        low = min(a, b, *labels)  # a place is labelled by its lowest keyframe
        for x in set(labels) - {low}:
            p[p == x] = low
        p[a] = p[b] = low

    def reset(self, ties: NDArray[np.int64], n: int) -> None:
        """Start again from ``ties`` alone (after some were dropped)."""
        self.place = tie_places(ties, max(n, 1))


def drift_bounds(
    xy: F64,
    var_t: F64,
    var_r: F64,
    node: int,
    sigmas: float,
    place: NDArray[np.int64] | None = None,
) -> tuple[F64, F64]:
    """How far the graph's estimate of each keyframe ``k <= node`` relative to ``node`` may be
    off: ``sigmas`` standard deviations of the relative pose along the most certain route
    between them, ``(bound_m (node+1,), bound_rad (node+1,))``.

    Along the keyframe chain, first-order propagation: ``xy (N, 2)`` keyframe positions (the
    graph's estimate), ``var_t (N,)`` and ``var_r (N,)`` the variances each step ``j - 1 ->
    j`` adds (:func:`step_variances`). Step ``j``'s heading error swings the rest of the route
    about ``p_j``, moving ``node`` by the lever arm ``|p_node - p_j|``, so a stretch of chain
    ``(a, b]`` costs::

        var_xy = sum_{j in (a, b]} 2 var_t[j] + var_r[j] |p_node - p_j|^2
        var_th = sum_{j in (a, b]} var_r[j]

    (``var_xy`` is the trace of the 2x2 position covariance: the bound is ``sigmas *
    sqrt(var_xy)``). Accepted loop closures tie keyframes together (a closure's keyframe and
    the first and last keyframes of the submap it matched): ``place (>= node+1,)`` labels the
    keyframes held together (:func:`tie_places`; -1: untied; None: no ties), and crossing
    between keyframes of one place costs nothing. Only the keyframes a closure's route reaches
    cheaply get small bounds, not everything before the last closure: a closure onto a pass
    that slipped holds ``node`` to that pass and leaves older passes as uncertain as the chain
    between them. The cheapest routes come from a shortest-path search over the places alone,
    joined by the stretches of chain between neighbouring tied keyframes (summed from prefix
    sums); every other keyframe is reached along the chain from the nearest tied keyframe (or
    ``node``, or keyframe 0) on either side."""
    dx = xy[1 : node + 1, 0] - xy[node, 0]
    dy = xy[1 : node + 1, 1] - xy[node, 1]
    vr = var_r[1 : node + 1]
    # cost of the chain from keyframe 0 to keyframe k: prefix sums over the steps j <= k
    chain = (np.zeros(node + 1), np.zeros(node + 1))
    np.cumsum(2.0 * var_t[1 : node + 1] + vr * (dx * dx + dy * dy), out=chain[0][1:])
    np.cumsum(vr, out=chain[1][1:])
    labels = np.full(node + 1, -1, dtype=np.int64) if place is None else place[: node + 1]
    is_vert = labels >= 0
    is_vert[0] = is_vert[node] = True
    verts = np.flatnonzero(is_vert)
    # places numbered 0..P-1; keyframe 0 and the node, untied, are places of their own
    ids = np.where(labels[verts] >= 0, labels[verts], verts)
    seen = np.zeros(node + 1, dtype=np.int64)
    seen[ids] = 1
    number = np.cumsum(seen) - 1
    n_places = int(number[-1]) + 1
    pl = number[ids]
    i = np.flatnonzero(pl[:-1] != pl[1:])  # stretches between neighbours in different places
    lo, hi = np.minimum(pl[i], pl[i + 1]), np.maximum(pl[i], pl[i + 1])
    left = np.cumsum(is_vert) - 1  # for each keyframe: the nearest vertex at or before it
    right = left + ~is_vert  # ... at or after it
    out = []
    for c in chain:  # c[k]: the chain's cost from keyframe 0 to k
        w = c[verts[i + 1]] - c[verts[i]]
        # two places joined by several stretches: the cheapest (a sparse matrix would sum)
        order = np.lexsort((w, hi, lo))
        lo_o, hi_o = lo[order], hi[order]
        first = np.ones(len(order), dtype=bool)
        first[1:] = (lo_o[1:] != lo_o[:-1]) | (hi_o[1:] != hi_o[:-1])
        pick = order[first]
        # a tiny cost keeps a free stretch an edge (zero means no edge)
        graph = sp.csr_matrix((w[pick] + 1e-18, (lo[pick], hi[pick])), shape=(n_places,) * 2)
        dist = dijkstra(graph, directed=False, indices=pl[-1])[pl]  # verts[-1] == node
        var = np.minimum(dist[left] + c - c[verts[left]], dist[right] + c[verts[right]] - c)
        out.append(sigmas * np.sqrt(np.maximum(var, 0.0)))
    return out[0], out[1]
