"""The route search of the master (Safe Interval Path Planning) as one numba kernel over
index arrays: node and arc indices, the free intervals of every node in two 2-D arrays, and a
binary heap of search states in parallel arrays.

``agvsim.master.traffic.plan_route`` prepares the arrays and turns the result into steps; this
module only searches. The search is the one its docstring describes: A* (weighted: f = g +
``weight`` h) over states (node, the arc it arrived by (car-like vehicles only), free interval
of the node, stops done). Ties of f (quantised to the microsecond, so that sums taken in
another order tie too) go to the state furthest along (-g), then by node index, interval,
stops done and push order: the order is total, so the routes found are the same on every
machine and the same as the Python reference search the tests keep.

Arrays (n nodes, m arcs, in ``RoadGraph.out_k`` order):

- ``out_off`` (n + 1), ``out_end`` (m), ``out_time_s`` (m): arcs out of each node (CSR);
- ``exit_off`` (m + 1), ``exit_arc`` (...): car-like, the arcs it may take after each arc;
  ``start_exits``: the arcs it may take standing on the start (facing its heading);
- ``va_s``, ``vb_s``, ``v_serial`` (n, capacity), ``v_count`` (n): the reservation table, each
  node's pending visits in planned order: from when (-inf once granted) until when (inf: parks)
  it is held, margins included, and by which vehicle. The free intervals of a node are worked
  out from its row the first time the search reaches it (the planning vehicle's own visits
  left out), so nothing is kept between searches but the table;
- ``h_s`` (stops, n): shortest time from each node to each stop; ``rest_s`` (stops): from
  each stop to the end; ``stop_node``, ``dwell_s`` (stops); ``avoid`` (n): never entered.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.typed import Dict

INF = np.inf
QUANTUM = 1e6  # f is compared in microseconds


@njit(cache=True)
def quantise(f: float) -> float:
    """f in whole microseconds (inf stays inf): equal sums taken in another order tie."""
    return np.floor(f * QUANTUM + 0.5)


@njit(cache=True)
def _before(hf, hg, hn, hj, hk, hp, a, b) -> bool:  # noqa: ANN001 - numba arrays
    """Heap entry ``a`` pops before ``b``: by (f, -g, node, interval, stops done, push)."""
    if hf[a] != hf[b]:
        return hf[a] < hf[b]
    if hg[a] != hg[b]:
        return hg[a] > hg[b]
    if hn[a] != hn[b]:
        return hn[a] < hn[b]
    if hj[a] != hj[b]:
        return hj[a] < hj[b]
    if hk[a] != hk[b]:
        return hk[a] < hk[b]
    return hp[a] < hp[b]


@njit(cache=True)
def _first_open(lo_row, hi_row, count, t) -> int:  # noqa: ANN001
    """The first interval of a row that ends after ``t`` (intervals are sorted, disjoint)."""
    a, b = 0, count
    while a < b:
        mid = (a + b) // 2
        if hi_row[mid] <= t:
            a = mid + 1
        else:
            b = mid
    return a


@njit(cache=True)
def _push(hf, hg, hn, hj, hk, hp, heap, size, e) -> int:  # noqa: ANN001
    """Add entry ``e`` to the heap of ``size`` entries; returns the new size."""
    i = size
    while i > 0:
        parent = (i - 1) // 2
        if _before(hf, hg, hn, hj, hk, hp, e, heap[parent]):
            heap[i] = heap[parent]
            i = parent
        else:
            break
    heap[i] = e
    return size + 1


@njit(cache=True)
def _pop(hf, hg, hn, hj, hk, hp, heap, size) -> int:  # noqa: ANN001
    """Remove the first entry (``heap[0]``, read it before); returns the new size."""
    size -= 1
    if size > 0:
        x = heap[size]
        i = 0
        while True:
            c = 2 * i + 1
            if c >= size:
                break
            if c + 1 < size and _before(hf, hg, hn, hj, hk, hp, heap[c + 1], heap[c]):
                c += 1
            if _before(hf, hg, hn, hj, hk, hp, heap[c], x):
                heap[i] = heap[c]
                i = c
            else:
                break
        heap[i] = x
    return size


@njit(cache=True)
def _grown(a):  # noqa: ANN001, ANN202
    out = np.empty(2 * a.shape[0], a.dtype)
    out[: a.shape[0]] = a
    return out


@njit(cache=True)
def _gaps_of(v, me, va_s, vb_s, v_serial, v_count, g_off, g_n, g_lo, g_hi, used):  # noqa: ANN001
    """Work out node ``v``'s free intervals for vehicle ``me`` into the search's buffers
    (``g_off[v]``, ``g_n[v]``: where and how many); returns the buffers (grown if needed)
    and how much of them is used."""
    need = used + v_count[v] + 1
    if need > g_lo.shape[0]:
        size = g_lo.shape[0]
        while size < need:
            size *= 2
        lo_, hi_ = np.empty(size, np.float64), np.empty(size, np.float64)
        lo_[:used], hi_[:used] = g_lo[:used], g_hi[:used]
        g_lo, g_hi = lo_, hi_
    g_off[v] = used
    lo = -INF
    for q in range(v_count[v]):
        if v_serial[v, q] == me:
            continue
        a, b = va_s[v, q], vb_s[v, q]
        if a > lo:
            g_lo[used], g_hi[used] = lo, a
            used += 1
        if b > lo:
            lo = b
    if lo < INF:
        g_lo[used], g_hi[used] = lo, INF
        used += 1
    g_n[v] = used - g_off[v]
    return g_lo, g_hi, used


@njit(cache=True)
def search(
    out_off,  # noqa: ANN001 - numba arrays, see the module docstring
    out_end,  # noqa: ANN001
    out_time_s,  # noqa: ANN001
    car_like: bool,
    exit_off,  # noqa: ANN001
    exit_arc,  # noqa: ANN001
    start_exits,  # noqa: ANN001
    start_arc: int,
    va_s,  # noqa: ANN001
    vb_s,  # noqa: ANN001
    v_serial,  # noqa: ANN001
    v_count,  # noqa: ANN001
    me: int,
    h_s,  # noqa: ANN001
    rest_s,  # noqa: ANN001
    stop_node,  # noqa: ANN001
    dwell_s,  # noqa: ANN001
    avoid,  # noqa: ANN001
    start: int,
    held_s: float,
    t0_s: float,
    stop_at_start: bool,
    weight: float,
    max_expansions: int,
):  # noqa: ANN201
    """The search for vehicle ``me`` (its code in ``v_serial``) from ``start`` at ``t0_s``,
    having held it since ``held_s``; ``start_arc``: the arc it arrived by (car-like; -1: it
    stands there, use ``start_exits``). Returns the states from the start to the goal as
    (node, arrive_s, depart_s, stops done) arrays (depart -1: a stop done there, the next
    state is on the same node; inf on the goal), empty when no route fits, and the number of
    states expanded (-1: the start is not free from ``held_s`` to ``t0_s``)."""
    n = v_count.shape[0]
    last = stop_node.shape[0] - 1
    arcs = out_end.shape[0] + 1
    # the free intervals of the nodes reached so far
    g_off = np.full(n, -1, np.int64)
    g_n = np.zeros(n, np.int64)
    g_lo = np.empty(4096, np.float64)
    g_hi = np.empty(4096, np.float64)
    used = 0
    g_lo, g_hi, used = _gaps_of(
        start, me, va_s, vb_s, v_serial, v_count, g_off, g_n, g_lo, g_hi, used
    )
    start_gap = -1
    for i in range(g_n[start]):
        if g_lo[g_off[start] + i] <= held_s and t0_s < g_hi[g_off[start] + i]:
            start_gap = i
            break
    nothing = np.empty(0, np.int64)
    if start_gap < 0:
        return nothing, np.empty(0, np.float64), np.empty(0, np.float64), nothing, -1
    cap = 1 << 20  # intervals per node, in the state keys
    # the states: (node, arc, interval, stops done) -> row of the state arrays
    rows = Dict.empty(key_type=types.int64, value_type=types.int64)
    s_node = np.empty(1024, np.int64)
    s_arc = np.empty(1024, np.int64)
    s_gap = np.empty(1024, np.int64)
    s_k = np.empty(1024, np.int64)
    s_g = np.empty(1024, np.float64)  # the best arrival found
    s_parent = np.empty(1024, np.int64)
    s_dep = np.empty(1024, np.float64)  # departure from the parent's node (-1: a stop)
    # the heap entries (f, g, node, interval, stops done, push order, state) and the heap
    hf = np.empty(1024, np.float64)
    hg = np.empty(1024, np.float64)
    hn = np.empty(1024, np.int64)
    hj = np.empty(1024, np.int64)
    hk = np.empty(1024, np.int64)
    hp = np.empty(1024, np.int64)
    hs = np.empty(1024, np.int64)
    heap = np.empty(1024, np.int64)

    rows[((start_arc + 1) * n + start) * cap + start_gap] = 0
    s_node[0], s_arc[0], s_gap[0], s_k[0] = start, start_arc, start_gap, 0
    s_g[0], s_parent[0], s_dep[0] = t0_s, -1, INF
    n_s = 1
    hf[0] = quantise(t0_s + weight * (h_s[0, start] + rest_s[0]))
    hg[0], hn[0], hj[0], hk[0], hp[0], hs[0] = t0_s, start, start_gap, 0, 0, 0
    heap[0] = 0
    size, pushed, expansions = 1, 1, 0
    goal = -1
    while size > 0:
        top = heap[0]
        size = _pop(hf, hg, hn, hj, hk, hp, heap, size)
        cur = hs[top]
        a = hg[top]
        if a > s_g[cur]:
            continue  # a quicker way here was found since (and expanded, or is queued)
        expansions += 1
        if expansions > max_expansions:
            break
        u, came, i_gap, k = s_node[cur], s_arc[cur], s_gap[cur], s_k[cur]
        hi = g_hi[g_off[u] + i_gap]
        if car_like and came >= 0:
            e0, e1 = exit_off[came], exit_off[came + 1]
        elif car_like:
            e0, e1 = 0, start_exits.shape[0]
        else:
            e0, e1 = out_off[u], out_off[u + 1]
        # candidate successors: (row or -1 for a new state, node, arc, interval, stops, g,
        # departure, f) pushed below in the order the Python reference pushes them
        if u == stop_node[k] and (stop_at_start or s_parent[cur] >= 0):
            if k == last:
                if hi == INF and (e1 > e0 or out_off[u + 1] == out_off[u]):
                    goal = cur
                    break
            else:
                a2 = a + dwell_s[k]
                key = (((k + 1) * arcs + came + 1) * n + u) * cap + i_gap
                known = rows[key] if key in rows else -1
                if a2 < hi and (known < 0 or a2 < s_g[known]):
                    row = known
                    if row < 0:
                        row = n_s
                        if row == s_node.shape[0]:
                            s_node, s_arc, s_gap = _grown(s_node), _grown(s_arc), _grown(s_gap)
                            s_k, s_g = _grown(s_k), _grown(s_g)
                            s_parent, s_dep = _grown(s_parent), _grown(s_dep)
                        rows[key] = row
                        n_s += 1
                        s_node[row], s_arc[row], s_gap[row], s_k[row] = u, came, i_gap, k + 1
                    s_g[row], s_parent[row], s_dep[row] = a2, cur, -1.0
                    if pushed == hf.shape[0]:
                        hf, hg, hn, hj = _grown(hf), _grown(hg), _grown(hn), _grown(hj)
                        hk, hp, hs, heap = _grown(hk), _grown(hp), _grown(hs), _grown(heap)
                    e = pushed
                    hf[e] = quantise(a2 + weight * (h_s[k + 1, u] + rest_s[k + 1]))
                    hg[e], hn[e], hj[e], hk[e], hp[e], hs[e] = a2, u, i_gap, k + 1, e, row
                    size = _push(hf, hg, hn, hj, hk, hp, heap, size, e)
                    pushed += 1
        for x in range(e0, e1):
            if car_like and came >= 0:
                arc = exit_arc[x]
            elif car_like:
                arc = start_exits[x]
            else:
                arc = x
            v = out_end[arc]
            h = h_s[k, v]
            if h == INF or avoid[v]:
                continue
            dt = out_time_s[arc]
            if g_off[v] < 0:
                g_lo, g_hi, used = _gaps_of(
                    v, me, va_s, vb_s, v_serial, v_count, g_off, g_n, g_lo, g_hi, used
                )
            o, cnt = g_off[v], g_n[v]
            j = _first_open(g_lo[o : o + cnt], g_hi[o : o + cnt], cnt, a)
            while j < cnt:
                lo, hi2 = g_lo[o + j], g_hi[o + j]
                d = a if a > lo else lo
                arrive = d + dt
                if arrive >= hi:
                    break  # cannot hold u until then (later gaps start later still)
                if arrive < hi2:
                    c_arc = arc if car_like else -1
                    key = ((k * arcs + c_arc + 1) * n + v) * cap + j
                    known = rows[key] if key in rows else -1
                    if known < 0 or arrive < s_g[known]:
                        row = known
                        if row < 0:
                            row = n_s
                            if row == s_node.shape[0]:
                                s_node, s_arc = _grown(s_node), _grown(s_arc)
                                s_gap, s_k, s_g = _grown(s_gap), _grown(s_k), _grown(s_g)
                                s_parent, s_dep = _grown(s_parent), _grown(s_dep)
                            rows[key] = row
                            n_s += 1
                            s_node[row], s_arc[row], s_gap[row], s_k[row] = v, c_arc, j, k
                        s_g[row], s_parent[row], s_dep[row] = arrive, cur, d
                        if pushed == hf.shape[0]:
                            hf, hg, hn, hj = _grown(hf), _grown(hg), _grown(hn), _grown(hj)
                            hk, hp, hs, heap = _grown(hk), _grown(hp), _grown(hs), _grown(heap)
                        e = pushed
                        hf[e] = quantise(arrive + weight * (h + rest_s[k]))
                        hg[e], hn[e], hj[e], hk[e], hp[e], hs[e] = arrive, v, j, k, e, row
                        size = _push(hf, hg, hn, hj, hk, hp, heap, size, e)
                        pushed += 1
                j += 1
    if goal < 0:
        return (
            np.empty(0, np.int64),
            np.empty(0, np.float64),
            np.empty(0, np.float64),
            np.empty(0, np.int64),
            expansions,
        )
    length = 0
    s = goal
    while s >= 0:
        length += 1
        s = s_parent[s]
    nodes = np.empty(length, np.int64)
    arrive_s = np.empty(length, np.float64)
    depart_s = np.empty(length, np.float64)
    done = np.empty(length, np.int64)
    s, dep = goal, INF
    for i in range(length - 1, -1, -1):
        nodes[i], arrive_s[i], depart_s[i], done[i] = s_node[s], s_g[s], dep, s_k[s]
        dep = s_dep[s]
        s = s_parent[s]
    return nodes, arrive_s, depart_s, done, expansions
