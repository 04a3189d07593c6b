"""The route search of the master (Safe Interval Path Planning) as one numba kernel over
index arrays: node and arc indices, the reservation table as rows of arrays, an open-addressing
table of search states and a binary heap of them in parallel arrays.

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
from numba import njit

INF = np.inf
QUANTUM = 1e6  # f is compared in microseconds
HASH = 0x5851F42D4C957F2D  # spreads the state keys over the open-addressing table


@njit(cache=True)
def quantise(f: float) -> float:
    """f in whole microseconds (inf stays inf): equal sums taken in another order tie."""
    return np.floor(f * QUANTUM + 0.5)


@njit(cache=True)
def _before(f1, g1, n1, j1, k1, p1, f2, g2, n2, j2, k2, p2) -> bool:  # noqa: ANN001
    """Entry 1 pops before entry 2: by (f, -g, node, interval, stops done, push order)."""
    if f1 != f2:
        return f1 < f2
    if g1 != g2:
        return g1 > g2
    if n1 != n2:
        return n1 < n2
    if j1 != j2:
        return j1 < j2
    if k1 != k2:
        return k1 < k2
    return p1 < p2


class Workspace:
    """The search's working arrays, kept between searches (no allocation per search): the
    gaps of the nodes reached (``gaps``: lo, hi; ``gap_at``: offset, count by node), the
    state table (``slots``: key, row), the states (``s_int``: node, arc, interval, stops
    done, parent; ``s_time``: arrival, departure), the heap entries (``h_int``: node,
    interval, stops done, state; ``h_time``: f, g), the heap and one expansion's successors
    (``c_int``: node, arc, interval, stops done; ``c_time``: arrival, departure,
    heuristic). A search that runs out of room says so; ``grow`` doubles every array."""

    def __init__(self, nodes: int, room: int = 4096):
        self.gap_at = np.full((nodes, 2), -1, np.int64)
        self.room = room
        self._make()

    def _make(self) -> None:
        r = self.room
        self.gaps = np.empty((4 * r, 2), np.float64)
        self.slots = np.full((4 * r, 2), -1, np.int64)
        self.s_int = np.empty((r, 5), np.int64)
        self.s_time = np.empty((r, 2), np.float64)
        self.h_int = np.empty((2 * r, 4), np.int64)
        self.h_time = np.empty((2 * r, 2), np.float64)
        self.heap = np.empty(2 * r, np.int64)
        self.c_int = np.empty((r, 4), np.int64)
        self.c_time = np.empty((r, 3), np.float64)

    def grow(self) -> None:
        self.room *= 2
        self._make()


@njit(inline="always")
def _node_gaps(node, me, v_count, v_serial, va_s, vb_s, gaps, used):  # noqa: ANN001, ANN202
    """Append ``node``'s free gaps for vehicle ``me`` (between the others' visits, sorted) to
    ``gaps`` from row ``used``; the new end, or -1 when ``gaps`` is full. Inlined into the
    search (numba's IR inlining: no call, no reference counting of the arrays)."""
    room = gaps.shape[0]
    lo = -INF
    for q in range(v_count[node]):
        if v_serial[node, q] != me:
            va, vb = va_s[node, q], vb_s[node, q]
            if va > lo:
                if used == room:
                    return -1
                gaps[used, 0], gaps[used, 1] = lo, va
                used += 1
            if vb > lo:
                lo = vb
    if lo < INF:
        if used == room:
            return -1
        gaps[used, 0], gaps[used, 1] = lo, INF
        used += 1
    return used


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
    gap_at,  # noqa: ANN001 - the Workspace's arrays
    gaps,  # noqa: ANN001
    slots,  # noqa: ANN001
    s_int,  # noqa: ANN001
    s_time,  # noqa: ANN001
    h_int,  # noqa: ANN001
    h_time,  # noqa: ANN001
    heap,  # noqa: ANN001
    c_int,  # noqa: ANN001
    c_time,  # noqa: ANN001
):  # noqa: ANN201
    """The search for vehicle ``me`` (its code in ``v_serial``) from ``start`` at ``t0_s``,
    having held it since ``held_s``; ``start_arc``: the arc it arrived by (car-like; -1: it
    stands there, use ``start_exits``). Returns the states from the start to the goal as
    (node, arrive_s, depart_s, stops done) arrays (depart -1: a stop done there, the next
    state is on the same node; inf on the goal), empty when no route fits, and the number of
    states expanded (-1: the start is not free from ``held_s`` to ``t0_s``; -2: the
    workspace is too small, grow it and search again).

    Everything is worked on inline in arrays that are never replaced: a helper that takes
    arrays, or an array variable assigned in the loop, costs numba atomic reference counts
    on every use, which were most of the time."""
    nothing = np.empty(0, np.int64)
    n = v_count.shape[0]
    last = stop_node.shape[0] - 1
    arcs = out_end.shape[0] + 1
    cap = 1 << 20  # intervals per node, in the state keys
    mask = slots.shape[0] - 1
    slots[:, 0] = -1
    gap_at[:, 0] = -1
    used = n_s = size = pushed = n_c = 0
    room_s, room_h, room_c = s_int.shape[0], heap.shape[0], c_int.shape[0]

    # the start: its gaps, the one it stands in, and it as the first successor
    gap_at[start, 0] = 0
    used = _node_gaps(start, me, v_count, v_serial, va_s, vb_s, gaps, 0)
    if used < 0:
        return nothing, np.empty(0), np.empty(0), nothing, -2
    gap_at[start, 1] = used
    start_gap = -1
    for i in range(used):
        if gaps[i, 0] <= held_s and t0_s < gaps[i, 1]:
            start_gap = i
            break
    if start_gap < 0:
        return nothing, np.empty(0), np.empty(0), nothing, -1
    c_int[0, 0], c_int[0, 1], c_int[0, 2], c_int[0, 3] = start, start_arc, start_gap, 0
    c_time[0, 0], c_time[0, 1], c_time[0, 2] = t0_s, INF, h_s[0, start] + rest_s[0]
    n_c = 1
    cur = -1
    expansions = 0
    goal = -1
    while True:
        # the successors found: new states or quicker ways to known ones go on the heap
        for c in range(n_c):
            cn, ca, cj, ck = c_int[c, 0], c_int[c, 1], c_int[c, 2], c_int[c, 3]
            g = c_time[c, 0]
            key = ((ck * arcs + ca + 1) * n + cn) * cap + cj
            slot = ((key * HASH) >> 23) & mask
            while slots[slot, 0] != key and slots[slot, 0] != -1:
                slot = (slot + 1) & mask
            row = slots[slot, 1] if slots[slot, 0] == key else -1
            if row >= 0 and not g < s_time[row, 0]:
                continue
            if row < 0:
                if n_s == room_s or 2 * (n_s + 1) > slots.shape[0]:
                    return nothing, np.empty(0), np.empty(0), nothing, -2
                row = n_s
                n_s += 1
                s_int[row, 0], s_int[row, 1], s_int[row, 2], s_int[row, 3] = cn, ca, cj, ck
                slots[slot, 0], slots[slot, 1] = key, row
            s_int[row, 4], s_time[row, 0], s_time[row, 1] = cur, g, c_time[c, 1]
            if pushed == room_h:
                return nothing, np.empty(0), np.empty(0), nothing, -2
            e = pushed
            pushed += 1
            f = quantise(g + weight * c_time[c, 2])
            h_time[e, 0], h_time[e, 1] = f, g
            h_int[e, 0], h_int[e, 1], h_int[e, 2], h_int[e, 3] = cn, cj, ck, row
            i = size
            size += 1
            while i > 0:
                up = (i - 1) // 2
                p = heap[up]
                if _before(
                    f, g, cn, cj, ck, e,
                    h_time[p, 0], h_time[p, 1], h_int[p, 0], h_int[p, 1], h_int[p, 2], p,
                ):  # fmt: skip
                    heap[i] = p
                    i = up
                else:
                    break
            heap[i] = e
        n_c = 0
        # pop the first state that is still the quickest way to itself
        top = -1
        while size > 0:
            top = heap[0]
            size -= 1
            if size > 0:
                x = heap[size]
                i = 0
                while True:
                    ch = 2 * i + 1
                    if ch >= size:
                        break
                    y = heap[ch]
                    if ch + 1 < size:
                        z = heap[ch + 1]
                        if _before(
                            h_time[z, 0], h_time[z, 1], h_int[z, 0], h_int[z, 1], h_int[z, 2], z,
                            h_time[y, 0], h_time[y, 1], h_int[y, 0], h_int[y, 1], h_int[y, 2], y,
                        ):  # fmt: skip
                            ch, y = ch + 1, z
                    if _before(
                        h_time[y, 0], h_time[y, 1], h_int[y, 0], h_int[y, 1], h_int[y, 2], y,
                        h_time[x, 0], h_time[x, 1], h_int[x, 0], h_int[x, 1], h_int[x, 2], x,
                    ):  # fmt: skip
                        heap[i] = y
                        i = ch
                    else:
                        break
                heap[i] = x
            if h_time[top, 1] > s_time[h_int[top, 3], 0]:
                top = -1  # a quicker way there was found since (and expanded, or is queued)
                continue
            break
        if top < 0:
            break
        expansions += 1
        if expansions > max_expansions:
            break
        cur = h_int[top, 3]
        a = h_time[top, 1]
        u, came, i_gap, k = s_int[cur, 0], s_int[cur, 1], s_int[cur, 2], s_int[cur, 3]
        hi = gaps[gap_at[u, 0] + i_gap, 1]
        if car_like and came >= 0:
            e0, e1 = exit_off[came], exit_off[came + 1]
        elif car_like:
            e0, e1 = 0, start_exits.shape[0]
        else:
            e0, e1 = out_off[u], out_off[u + 1]
        # the next stop done here first, then each arc out and each of its end's gaps
        # reachable in time (the reference's order)
        if u == stop_node[k] and (stop_at_start or s_int[cur, 4] >= 0):
            if k == last:
                if hi == INF and (e1 > e0 or out_off[u + 1] == out_off[u]):
                    goal = cur
                    break
            else:
                a2 = a + dwell_s[k]
                if a2 < hi:
                    c_int[0, 0], c_int[0, 1], c_int[0, 2], c_int[0, 3] = u, came, i_gap, k + 1
                    c_time[0, 0], c_time[0, 1] = a2, -1.0
                    c_time[0, 2] = h_s[k + 1, u] + rest_s[k + 1]
                    n_c = 1
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
            if gap_at[v, 0] < 0:  # first reached: its gaps for this vehicle
                gap_at[v, 0] = used
                used = _node_gaps(v, me, v_count, v_serial, va_s, vb_s, gaps, used)
                if used < 0:
                    return nothing, np.empty(0), np.empty(0), nothing, -2
                gap_at[v, 1] = used - gap_at[v, 0]
            o, cnt = gap_at[v, 0], gap_at[v, 1]
            # the first gap that ends after a (sorted, disjoint: binary search)
            j, j1 = 0, cnt
            while j < j1:
                mid = (j + j1) // 2
                if gaps[o + mid, 1] <= a:
                    j = mid + 1
                else:
                    j1 = mid
            dt = out_time_s[arc]
            while j < cnt:
                lo, hi2 = gaps[o + j, 0], gaps[o + j, 1]
                d = a if a > lo else lo
                arrive = d + dt
                if arrive >= hi:
                    break  # cannot hold u until then (later gaps start later still)
                if arrive < hi2:
                    if n_c == room_c:
                        return nothing, np.empty(0), np.empty(0), nothing, -2
                    c_int[n_c, 0], c_int[n_c, 1] = v, arc if car_like else -1
                    c_int[n_c, 2], c_int[n_c, 3] = j, k
                    c_time[n_c, 0], c_time[n_c, 1], c_time[n_c, 2] = arrive, d, h + rest_s[k]
                    n_c += 1
                j += 1
    if goal < 0:
        return nothing, np.empty(0), np.empty(0), nothing, expansions
    length = 0
    s = goal
    while s >= 0:
        length += 1
        s = s_int[s, 4]
    nodes = np.empty(length, np.int64)
    arrive_s = np.empty(length, np.float64)
    depart_s = np.empty(length, np.float64)
    done = np.empty(length, np.int64)
    s, dep = goal, INF
    for i in range(length - 1, -1, -1):
        nodes[i], arrive_s[i], depart_s[i], done[i] = s_int[s, 0], s_time[s, 0], dep, s_int[s, 3]
        dep = s_time[s, 1]
        s = s_int[s, 4]
    return nodes, arrive_s, depart_s, done, expansions
