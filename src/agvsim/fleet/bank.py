"""The vehicles' hot state in arrays, and one numba kernel that ticks the quiet ones.

A thousand VDA 5050 vehicles spend most control ticks doing nothing that needs the protocol:
a parked vehicle waits for an order, a driving one follows its leg between two nodes. Calling
each vehicle's Python ``control`` for that cost ~15 us a vehicle a tick, far more than the
simulation step itself. So the numbers such a tick reads and writes live here, one row per
vehicle (``VehicleBank``): the last control time and pose, the held twist, the distance since
the last node, the battery charge, the leg being followed (its polyline, node arc lengths and
speeds, the progress along it) and what the vehicle can do (``Mobility``) and needs of its
protective field. ``Vehicle`` reads and writes the same rows through properties, so there is one
copy of every value.

``tick`` (numba) runs each step over all vehicles. A vehicle whose control tick is due is
handled there only when its Python side declared it *quiet* (no message waiting, nothing to
publish but the periodic messages, no action running, not paused, charging, broken or stopped
by its field: ``Vehicle._settle``) and the tick changes nothing the protocol sees: no node
passed, the leg's end not reached, ``driving`` unchanged, the battery not empty, no lidar
return within the protective field's reach. Anything else flags the vehicle *slow* without
touching its row, and its Python ``control`` runs the whole tick as before. A quiet vehicle
whose periodic state or visualization is due (``next_wake_s``) is flagged *publish*: Python
only builds those messages. The kernel follows the leg with the
same arithmetic as ``agvsim.fleet.motion.Leg.twist`` (tested against it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from agvsim.angles import wrap_scalar

MAX_TURN_RATE_RAD_S = 1.5  # as agvsim.fleet.motion
SPIN_ABOVE_RAD = 1.0  # pursuit_twist's defaults
CURVE_SLOWDOWN_M = 0.5


class VehicleBank:
    """Rows of vehicle state (see the module docstring); ``n`` vehicles, fixed."""

    def __init__(self, n: int, points: int = 64):
        self.n = n
        z = np.zeros
        self.t_s = z(n)
        self.pose = z((n, 3))
        self.twist = z((n, 3))
        self.dist_node_m = z(n)
        self.charge_pct = z(n)
        self.idle_pct_s = z(n)
        self.drive_pct_m = z(n)
        self.pct_per_j = z(n)  # battery drained by motor energy (robots with dynamics)
        self.energy_j = z(n)  # motor energy delivered since the vehicle's last tick
        self.next_control_s = z(n)
        self.period_s = z(n)
        self.next_wake_s = z(n)  # the next publish due (state / visualization)
        self.quiet = z(n, dtype=np.bool_)
        self.mail = z(n, dtype=np.bool_)  # a message waits in the inbox (set by ``receive``)
        self.driving = z(n, dtype=np.bool_)
        # the leg
        self.has_leg = z(n, dtype=np.bool_)
        self.reached = z(n, dtype=np.bool_)
        self.s = z(n)
        self.look_m = z(n)
        self.tol_m = z(n)
        self.next_node_s = np.full(n, np.inf)
        self.pstart = z(n, dtype=np.int64)
        self.npts = z(n, dtype=np.int64)
        self.nstart = z(n, dtype=np.int64)
        self.nnodes = z(n, dtype=np.int64)
        self.px, self.py, self.cum = z(points), z(points), z(points)
        self.node_s, self.speed = z(points), z(points)
        self._pend = self._nend = 0
        # mobility
        self.holonomic = z(n, dtype=np.bool_)
        self.can_spin = z(n, dtype=np.bool_)
        self.kmax = z(n)
        self.min_r_m = z(n)
        # protective field along the path (fleet.safety)
        self.use_field = z(n, dtype=np.bool_)
        self.front_m = z(n)
        self.reaction_s = z(n)
        self.decel_m_s2 = np.ones(n)
        self.margin_m = z(n)
        self.half_width_m = z(n)
        self.mount_m = z(n)

    # ------------------------------------------------------------------ legs
    def _room(self, pts: int, nodes: int) -> None:
        """Make room for a leg of ``pts`` points and ``nodes`` nodes: compact the flat buffers
        (drop legs no row refers to) and grow them when that is not enough."""
        if self._pend + pts <= len(self.px) and self._nend + nodes <= len(self.node_s):
            return
        live = np.flatnonzero(self.has_leg)
        used_p = int(self.npts[live].sum()) + pts
        used_n = int(self.nnodes[live].sum()) + nodes
        cap_p = max(len(self.px), 2 * used_p)
        cap_n = max(len(self.node_s), 2 * used_n)
        px, py, cum = np.zeros(cap_p), np.zeros(cap_p), np.zeros(cap_p)
        node_s, speed = np.zeros(cap_n), np.zeros(cap_n)
        p = q = 0
        for k in live:
            a, m = self.pstart[k], self.npts[k]
            px[p : p + m], py[p : p + m] = self.px[a : a + m], self.py[a : a + m]
            cum[p : p + m] = self.cum[a : a + m]
            self.pstart[k] = p
            p += m
            b, c = self.nstart[k], self.nnodes[k]
            node_s[q : q + c], speed[q : q + c] = self.node_s[b : b + c], self.speed[b : b + c]
            self.nstart[k] = q
            q += c
        self.px, self.py, self.cum, self.node_s, self.speed = px, py, cum, node_s, speed
        self._pend, self._nend = p, q

    def set_leg(
        self,
        k: int,
        pts: list[tuple[float, float]],
        cum: list[float],
        node_s: list[float],
        speeds: list[float],
        look_m: float,
        tol_m: float,
    ) -> None:
        """Row ``k`` follows this polyline (``speeds``: one per edge, i.e. per node gap)."""
        self.has_leg[k] = False  # its old leg is garbage from here
        m, c = len(pts), len(node_s)
        self._room(m, c)
        a, b = self._pend, self._nend
        arr = np.asarray(pts, dtype=np.float64).reshape(m, 2)
        self.px[a : a + m], self.py[a : a + m] = arr[:, 0], arr[:, 1]
        self.cum[a : a + m] = cum
        self.node_s[b : b + c] = node_s
        self.speed[b : b + c] = 0.0
        self.speed[b : b + len(speeds)] = speeds
        self.pstart[k], self.npts[k], self.nstart[k], self.nnodes[k] = a, m, b, c
        self._pend, self._nend = a + m, b + c
        self.look_m[k], self.tol_m[k] = look_m, tol_m
        self.has_leg[k] = True


# ---------------------------------------------------------------------------------- kernel
@njit(cache=True)
def _bisect_right(a: np.ndarray, lo: int, hi: int, x: float) -> int:
    """Python's bisect.bisect_right(a[lo:hi], x) + lo."""
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit(cache=True)
def follow(
    x: float,
    y: float,
    th: float,
    s0: float,
    a: int,
    m: int,
    px: np.ndarray,
    py: np.ndarray,
    cum: np.ndarray,
    b: int,
    c: int,
    node_s: np.ndarray,
    speed: np.ndarray,
    look_m: float,
    tol_m: float,
    holonomic: bool,
    can_spin: bool,
    kmax: float,
    min_r_m: float,
) -> tuple[float, float, float, float, bool]:
    """``Leg.twist`` for one leg: (new progress s, vx, vy, omega, reached now)."""
    ld = max(look_m, 1.2 * min_r_m)
    # project: the closest path point within ld + 0.5 ahead of s0
    window = ld + 0.5
    best, best_d = s0, math.inf
    i = max(_bisect_right(cum, a, a + m, s0) - 1 - a, 0)
    while i < m - 1 and cum[a + i] <= s0 + window:
        ax, ay = px[a + i], py[a + i]
        dx, dy = px[a + i + 1] - ax, py[a + i + 1] - ay
        ln2 = dx * dx + dy * dy
        t = min(max(((x - ax) * dx + (y - ay) * dy) / ln2, 0.0), 1.0)
        d = math.hypot(ax + t * dx - x, ay + t * dy - y)
        if d < best_d:
            best, best_d = cum[a + i] + t * (cum[a + i + 1] - cum[a + i]), d
        i += 1
    s = max(best, s0)
    ex, ey = px[a + m - 1], py[a + m - 1]
    to_end = math.hypot(ex - x, ey - y)
    remaining = cum[a + m - 1] - s
    if remaining < ld and to_end < tol_m:
        return s, 0.0, 0.0, 0.0, True
    # the carrot ld further on, and the travel heading there
    sc = min(max(s + ld, 0.0), cum[a + m - 1])
    j = min(max(_bisect_right(cum, a, a + m, sc) - 1 - a, 0), m - 2)
    ax, ay, bx, by = px[a + j], py[a + j], px[a + j + 1], py[a + j + 1]
    ln = cum[a + j + 1] - cum[a + j]
    t = 0.0 if ln <= 0 else (sc - cum[a + j]) / ln
    tx, ty = ax + t * (bx - ax), ay + t * (by - ay)
    heading = math.atan2(by - ay, bx - ax)
    nspeeds = c - 1
    v = 0.0
    if nspeeds > 0:
        q = _bisect_right(node_s, b, b + c, s) - 1 - b
        v = speed[b + min(max(q, 0), nspeeds - 1)]
    if remaining < ld:
        tx, ty = ex, ey
        v = min(v, max(0.1, to_end) * v)
    vx, vy, w = pursuit(x, y, th, tx, ty, v, holonomic, can_spin, kmax, heading)
    return s, vx, vy, w, False


@njit(cache=True)
def pursuit(
    x: float,
    y: float,
    th: float,
    tx: float,
    ty: float,
    v: float,
    holonomic: bool,
    can_spin: bool,
    kmax: float,
    heading: float,
) -> tuple[float, float, float]:
    """``agvsim.control.mobility.pursuit_twist`` with the leg follower's arguments."""
    dx, dy = tx - x, ty - y
    co, si = math.cos(th), math.sin(th)
    bx, by = co * dx + si * dy, -si * dx + co * dy
    dist = math.hypot(bx, by)
    if dist < 1e-9:
        return 0.0, 0.0, 0.0
    r = MAX_TURN_RATE_RAD_S
    if holonomic:
        w = max(-r, min(r, 2.0 * wrap_scalar(heading - th)))
        return v * bx / dist, v * by / dist, w
    alpha = math.atan2(by, bx)
    k = 2.0 * math.sin(alpha) / dist
    if can_spin:
        if abs(alpha) > SPIN_ABOVE_RAD:
            return 0.0, 0.0, math.copysign(r, alpha)
        u = v / (1.0 + CURVE_SLOWDOWN_M * abs(k))
        if abs(u * k) > r:
            u = r / abs(k)
        return u, 0.0, u * k
    if abs(alpha) > math.pi / 2:
        k = math.copysign(kmax, alpha)
    k = max(-kmax, min(kmax, k))
    u = v / (1.0 + CURVE_SLOWDOWN_M * abs(k))
    return u, 0.0, u * k


@njit(cache=True)
def tick(
    t: float,
    poses: np.ndarray,
    range_min: np.ndarray,
    mail: np.ndarray,
    out: np.ndarray,
    slow: np.ndarray,
    publish: np.ndarray,
    t_s: np.ndarray,
    pose: np.ndarray,
    twist: np.ndarray,
    dist_node_m: np.ndarray,
    charge_pct: np.ndarray,
    idle_pct_s: np.ndarray,
    drive_pct_m: np.ndarray,
    pct_per_j: np.ndarray,
    energy_j: np.ndarray,
    next_control_s: np.ndarray,
    period_s: np.ndarray,
    next_wake_s: np.ndarray,
    quiet: np.ndarray,
    driving: np.ndarray,
    has_leg: np.ndarray,
    reached: np.ndarray,
    s: np.ndarray,
    look_m: np.ndarray,
    tol_m: np.ndarray,
    next_node_s: np.ndarray,
    pstart: np.ndarray,
    npts: np.ndarray,
    nstart: np.ndarray,
    nnodes: np.ndarray,
    px: np.ndarray,
    py: np.ndarray,
    cum: np.ndarray,
    node_s: np.ndarray,
    speed: np.ndarray,
    holonomic: np.ndarray,
    can_spin: np.ndarray,
    kmax: np.ndarray,
    min_r_m: np.ndarray,
    use_field: np.ndarray,
    front_m: np.ndarray,
    reaction_s: np.ndarray,
    decel_m_s2: np.ndarray,
    margin_m: np.ndarray,
    half_width_m: np.ndarray,
    mount_m: np.ndarray,
) -> None:
    """One step for every vehicle: ``out`` the twist to command; ``slow[k]`` True where the
    vehicle's Python ``control`` must run this step (its row then untouched); ``publish[k]``
    where the tick was done here and a periodic message is due (Python publishes it)."""
    for k in range(len(out)):
        slow[k] = False
        publish[k] = False
        if mail[k]:
            slow[k] = True
            continue
        if t < next_control_s[k] - 1e-9:  # held between control ticks
            out[k, 0], out[k, 1], out[k, 2] = twist[k, 0], twist[k, 1], twist[k, 2]
            continue
        if not quiet[k]:
            slow[k] = True
            continue
        x, y, th = poses[k, 0], poses[k, 1], poses[k, 2]
        moved = math.hypot(x - pose[k, 0], y - pose[k, 1])
        dt = max(0.0, t - t_s[k])
        used = idle_pct_s[k] * dt + drive_pct_m[k] * moved
        if pct_per_j[k] > 0.0:
            used += pct_per_j[k] * energy_j[k]
        c = max(0.0, charge_pct[k] - used)
        if c <= 0.0:
            slow[k] = True
            continue
        s_new, vx, vy, w = s[k], 0.0, 0.0, 0.0
        if has_leg[k]:
            if reached[k]:
                slow[k] = True
                continue
            s_new, vx, vy, w, done = follow(
                x,
                y,
                th,
                s[k],
                pstart[k],
                npts[k],
                px,
                py,
                cum,
                nstart[k],
                nnodes[k],
                node_s,
                speed,
                look_m[k],
                tol_m[k],
                holonomic[k],
                can_spin[k],
                kmax[k],
                min_r_m[k],
            )
            if done or s_new >= next_node_s[k] - 1e-6:
                slow[k] = True
                continue
        moving = math.hypot(vx, vy) > 1e-6 or abs(w) > 1e-6
        if moving != driving[k]:
            slow[k] = True
            continue
        if use_field[k] and (vx != 0.0 or vy != 0.0 or w != 0.0):
            v = max(math.hypot(vx, vy), math.hypot(twist[k, 0], twist[k, 1]))
            length = front_m[k] + v * reaction_s[k] + v * v / (2.0 * decel_m_s2[k]) + margin_m[k]
            if not range_min[k] > length + half_width_m[k] + mount_m[k] + 0.5:
                slow[k] = True
                continue
        t_s[k] = t
        pose[k, 0], pose[k, 1], pose[k, 2] = x, y, th
        dist_node_m[k] += moved
        charge_pct[k] = c
        energy_j[k] = 0.0
        s[k] = s_new
        twist[k, 0], twist[k, 1], twist[k, 2] = vx, vy, w
        next_control_s[k] = t + period_s[k]
        out[k, 0], out[k, 1], out[k, 2] = vx, vy, w
        publish[k] = t >= next_wake_s[k] - 1e-9


def run_tick(
    bank: VehicleBank,
    t: float,
    poses: np.ndarray,
    range_min: np.ndarray,
    mail: np.ndarray,
    out: np.ndarray,
    slow: np.ndarray,
    publish: np.ndarray,
) -> None:
    b = bank
    tick(
        t,
        poses,
        range_min,
        mail,
        out,
        slow,
        publish,
        b.t_s,
        b.pose,
        b.twist,
        b.dist_node_m,
        b.charge_pct,
        b.idle_pct_s,
        b.drive_pct_m,
        b.pct_per_j,
        b.energy_j,
        b.next_control_s,
        b.period_s,
        b.next_wake_s,
        b.quiet,
        b.driving,
        b.has_leg,
        b.reached,
        b.s,
        b.look_m,
        b.tol_m,
        b.next_node_s,
        b.pstart,
        b.npts,
        b.nstart,
        b.nnodes,
        b.px,
        b.py,
        b.cum,
        b.node_s,
        b.speed,
        b.holonomic,
        b.can_spin,
        b.kmax,
        b.min_r_m,
        b.use_field,
        b.front_m,
        b.reaction_s,
        b.decel_m_s2,
        b.margin_m,
        b.half_width_m,
        b.mount_m,
    )
