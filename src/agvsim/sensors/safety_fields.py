"""Safety laser scanner field sets, as industrial scanners (SICK, Pilz, ...) are configured.

A *field set* is a pair of polygons in the robot frame (x forward, y left, metres): the
**protective** field (a return inside it stops the vehicle) and an optional **warning** field
(a return inside it slows the vehicle). A scanner holds several field sets and switches between
them by the vehicle's signed forward speed (and, for car-like models, by the steering angle),
the way a scanner's inputs select a "field case" on a real vehicle: a longer field at higher
speed, one bent to the inside of a curve when steering.

Stopping: from the moment a return enters the protective field the vehicle goes on as
commanded for ``response_time_s`` (the scanner's response time plus the brake's), then brakes
at ``decel_m_s2`` until it stands. Its reference point therefore travels

    d_stop(v) = v * response_time_s + v^2 / (2 * decel_m_s2)

and a protective field is long enough for a speed v when its reach along the direction of
travel is at least the body's front (or rear) plus d_stop(v) (:func:`check_fields`).

The kernels are batch-first: one call tests every robot's scan against its active field set.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from agvsim.world.points import xy_points

CLEAR, WARNING, PROTECTIVE = 0, 1, 2
STATUS_NAMES = ("clear", "warning", "protective")


def _polygon(points: Sequence[Sequence[float]], where: str) -> np.ndarray:
    """An (n, 2) float array checked to be a simple polygon with n >= 3 and a non-zero area."""
    p = xy_points(points, where, 3)
    n = len(p)
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue  # neighbours share a vertex
            if _segments_cross(p[i], p[(i + 1) % n], p[j], p[(j + 1) % n]):
                raise ValueError(
                    f"{where}: the polygon's edges {i}-{i + 1} and {j}-{(j + 1) % n} cross "
                    "(list the points in order around the field)"
                )
    if abs(polygon_area(p)) < 1e-9:
        raise ValueError(f"{where}: the polygon has no area (its points are on one line)")
    return p


def polygon_area(p: np.ndarray) -> float:
    """Signed area (shoelace formula; positive counter-clockwise)."""
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _segments_cross(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> bool:
    def orient(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> float:
        return float((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))

    o1, o2, o3, o4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
    return o1 * o2 < 0 and o3 * o4 < 0


@dataclass(frozen=True)
class FieldSet:
    """One field case: active while ``speed_min_m_s <= v < speed_max_m_s`` (signed forward
    speed; negative is reversing) and ``steer_min_rad <= steering < steer_max_rad``."""

    name: str
    protective: tuple[tuple[float, float], ...]
    warning: tuple[tuple[float, float], ...] | None = None
    speed_min_m_s: float = -math.inf
    speed_max_m_s: float = math.inf
    steer_min_rad: float = -math.inf
    steer_max_rad: float = math.inf

    def __post_init__(self) -> None:
        where = f"field set {self.name!r}"
        object.__setattr__(
            self, "protective", _as_tuple(_polygon(self.protective, f"{where}: protective"))
        )
        if self.warning is not None:
            object.__setattr__(
                self, "warning", _as_tuple(_polygon(self.warning, f"{where}: warning"))
            )
        for lo, hi, what in (
            (self.speed_min_m_s, self.speed_max_m_s, "speed"),
            (self.steer_min_rad, self.steer_max_rad, "steering"),
        ):
            if math.isnan(lo) or math.isnan(hi) or not lo < hi:
                raise ValueError(f"{where}: {what} range needs min < max, got [{lo}, {hi})")

    def applies(self, speed_m_s: float, steering_rad: float = 0.0) -> bool:
        return (
            self.speed_min_m_s <= speed_m_s < self.speed_max_m_s
            and self.steer_min_rad <= steering_rad < self.steer_max_rad
        )


def _as_tuple(p: np.ndarray) -> tuple[tuple[float, float], ...]:
    return tuple((float(x), float(y)) for x, y in p)


@dataclass(frozen=True)
class SafetyScannerSpec:
    """A safety scanner on a robot: which range sensor it reads (``sensor``), its field sets,
    and the braking it triggers."""

    sensor: str
    field_sets: tuple[FieldSet, ...]
    response_time_s: float = 0.1
    decel_m_s2: float = 1.0
    warning_speed_m_s: float = 0.3
    _index: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.field_sets:
            raise ValueError(f"safety scanner on {self.sensor!r}: give at least one field set")
        names = [f.name for f in self.field_sets]
        if len(set(names)) != len(names):
            raise ValueError(f"safety scanner on {self.sensor!r}: field set names repeat: {names}")
        if not (0.0 <= self.response_time_s <= 10.0):
            raise ValueError(f"response_time_s must be in [0, 10] s, got {self.response_time_s}")
        if not (0.0 < self.decel_m_s2 <= 100.0):
            raise ValueError(f"decel_m_s2 must be in (0, 100] m/s^2, got {self.decel_m_s2}")
        if not (0.0 <= self.warning_speed_m_s <= 100.0):
            raise ValueError(f"warning_speed_m_s must be in [0, 100], got {self.warning_speed_m_s}")
        for i, a in enumerate(self.field_sets):
            for b in self.field_sets[i + 1 :]:
                if _overlap(a, b):
                    raise ValueError(
                        f"field sets {a.name!r} and {b.name!r} are both active at some speed "
                        f"and steering: [{a.speed_min_m_s}, {a.speed_max_m_s}) m/s x "
                        f"[{a.steer_min_rad}, {a.steer_max_rad}) rad overlaps "
                        f"[{b.speed_min_m_s}, {b.speed_max_m_s}) x "
                        f"[{b.steer_min_rad}, {b.steer_max_rad})"
                    )

    def select(self, speed_m_s: float, steering_rad: float = 0.0) -> int:
        """The index of the active field set, or -1 when none covers this speed and steering
        (the vehicle must then stop: no field case is a fault on a real scanner)."""
        for i, f in enumerate(self.field_sets):
            if f.applies(speed_m_s, steering_rad):
                return i
        return -1

    def stopping_distance_m(self, speed_m_s: float) -> float:
        """How far the reference point travels from a violation at ``speed_m_s`` until it
        stands: the response time at full speed, then braking."""
        v = abs(speed_m_s)
        return v * self.response_time_s + v * v / (2.0 * self.decel_m_s2)


def _overlap(a: FieldSet, b: FieldSet) -> bool:
    return max(a.speed_min_m_s, b.speed_min_m_s) < min(a.speed_max_m_s, b.speed_max_m_s) and max(
        a.steer_min_rad, b.steer_min_rad
    ) < min(a.steer_max_rad, b.steer_max_rad)


def reach_m(polygon: Sequence[Sequence[float]], direction_rad: float) -> float:
    """How far along the ray from the robot's reference point in ``direction_rad`` (robot
    frame) the polygon reaches: the farthest crossing of the ray with the polygon's boundary
    (0 when the ray misses it)."""
    p = np.asarray(polygon, dtype=np.float64)
    d = np.array([math.cos(direction_rad), math.sin(direction_rad)])
    best = 0.0
    n = len(p)
    for i in range(n):
        a, b = p[i], p[(i + 1) % n]
        e = b - a
        den = d[0] * (-e[1]) - d[1] * (-e[0])
        if abs(den) < 1e-15:
            continue
        # t d = a + s e  ->  [d, -e] [t, s]^T = a
        t = (a[0] * (-e[1]) - a[1] * (-e[0])) / den
        s = (d[0] * a[1] - d[1] * a[0]) / den
        if t >= 0.0 and -1e-12 <= s <= 1.0 + 1e-12:
            best = max(best, t)
    return best


def check_fields(
    spec: SafetyScannerSpec,
    front_m: float,
    rear_m: float,
    max_speed_m_s: float,
    max_reverse_m_s: float = 0.0,
    margin_m: float = 0.0,
) -> list[str]:
    """Problems with the fields' lengths, one sentence each (empty when all are long enough).

    For every field set, at the fastest speed it is active for (capped by the vehicle's
    ``max_speed_m_s`` forward and ``max_reverse_m_s`` backward), the protective field must
    reach, straight ahead (or behind, when reversing), the body's front ``front_m`` (rear
    ``rear_m``) plus the stopping distance and ``margin_m``. Also: every speed the vehicle can
    drive at must have a field set (for straight steering)."""
    problems: list[str] = []
    for f in spec.field_sets:
        for sign, top, body, way in (
            (1.0, max_speed_m_s, front_m, "ahead"),
            (-1.0, max_reverse_m_s, rear_m, "behind"),
        ):
            lo, hi = (
                (f.speed_min_m_s, f.speed_max_m_s)
                if sign > 0
                else (
                    -f.speed_max_m_s,
                    -f.speed_min_m_s,
                )
            )
            # the fastest speed in this direction the set is active for
            v = min(max(hi, 0.0), top)
            if v <= 0.0 or max(lo, 0.0) > top:
                continue
            need = body + spec.stopping_distance_m(v) + margin_m
            have = reach_m(f.protective, 0.0 if sign > 0 else math.pi)
            if have + 1e-9 < need:
                problems.append(
                    f"field set {f.name!r}: the protective field reaches {have:.3f} m {way} but "
                    f"at {v:.3f} m/s the vehicle needs {need:.3f} m (body {body:.3f} m + "
                    f"{v:.3f} m/s x {spec.response_time_s:g} s response + v^2/(2 x "
                    f"{spec.decel_m_s2:g} m/s^2) braking"
                    + (f" + {margin_m:g} m margin" if margin_m else "")
                    + "): lengthen the field or lower the set's speed_max_m_s"
                )
    gaps = speed_gaps(spec, -max_reverse_m_s, max_speed_m_s)
    for lo, hi in gaps:
        where = f"at {lo:.3f} m/s" if hi == lo else f"between {lo:.3f} and {hi:.3f} m/s"
        problems.append(
            f"no field set is active {where} (straight ahead): the vehicle would drive there "
            "with no protective field (a set is active for speed_min_m_s <= v < speed_max_m_s)"
        )
    return problems


def speed_gaps(spec: SafetyScannerSpec, v_lo: float, v_hi: float) -> list[tuple[float, float]]:
    """Speed intervals within [v_lo, v_hi] (both ends driven) that no field set covers at zero
    steering; (v, v) when only the speed v itself is left out (a set's maximum is exclusive)."""
    covered = sorted(
        (f.speed_min_m_s, f.speed_max_m_s)
        for f in spec.field_sets
        if f.steer_min_rad <= 0.0 < f.steer_max_rad
    )
    gaps: list[tuple[float, float]] = []
    at = v_lo  # everything below ``at`` is covered
    for lo, hi in covered:
        if hi <= at:
            continue
        if lo > at:
            gaps.append((at, min(lo, v_hi)))
        at = hi
        if at > v_hi:
            break
    if at <= v_hi:
        gaps.append((at, v_hi))
    return [g for g in gaps if g[0] <= v_hi]


# ---------------------------------------------------------------------- packed, batch kernels
@dataclass(frozen=True)
class PackedFields:
    """Every polygon of every scanner in flat arrays, for the kernels: polygon k has vertices
    ``verts[start[k] : start[k] + count[k]]``; field set j of scanner s has protective polygon
    ``prot[first[s] + j]`` and warning polygon ``warn[first[s] + j]`` (-1: none)."""

    verts: np.ndarray  # (V, 2)
    start: np.ndarray  # (K,) int64
    count: np.ndarray  # (K,) int64
    prot: np.ndarray  # (F,) int64, polygon index
    warn: np.ndarray  # (F,) int64, polygon index or -1
    first: np.ndarray  # (S,) int64, index of each scanner's first field set

    @classmethod
    def of(cls, scanners: Sequence[SafetyScannerSpec]) -> PackedFields:
        verts: list[tuple[float, float]] = []
        start: list[int] = []
        count: list[int] = []
        prot: list[int] = []
        warn: list[int] = []
        first: list[int] = []

        def add(poly: tuple[tuple[float, float], ...]) -> int:
            start.append(len(verts))
            count.append(len(poly))
            verts.extend(poly)
            return len(start) - 1

        for s in scanners:
            first.append(len(prot))
            for f in s.field_sets:
                prot.append(add(f.protective))
                warn.append(-1 if f.warning is None else add(f.warning))
        i64 = np.int64
        return cls(
            np.asarray(verts, dtype=np.float64).reshape(-1, 2),
            np.asarray(start, dtype=i64),
            np.asarray(count, dtype=i64),
            np.asarray(prot, dtype=i64),
            np.asarray(warn, dtype=i64),
            np.asarray(first, dtype=i64),
        )


@nb.njit(cache=True)
def _inside(x: float, y: float, verts: np.ndarray, start: int, count: int) -> bool:
    """Crossing-number test (a point on an edge may count either way)."""
    inside = False
    j = start + count - 1
    for i in range(start, start + count):
        xi, yi = verts[i, 0], verts[i, 1]
        xj, yj = verts[j, 0], verts[j, 1]
        if (yi > y) != (yj > y):
            xc = xi + (y - yi) * (xj - xi) / (yj - yi)
            if x < xc:
                inside = not inside
        j = i
    return inside


@nb.njit(cache=True)
def field_status(
    points: np.ndarray,
    valid: np.ndarray,
    active: np.ndarray,
    verts: np.ndarray,
    start: np.ndarray,
    count: np.ndarray,
    prot: np.ndarray,
    warn: np.ndarray,
) -> np.ndarray:
    """Status of each scanner (CLEAR, WARNING or PROTECTIVE): ``points`` (S, B, 2) are the scan
    returns in the robot frame, ``valid`` (S, B) which are returns, ``active`` (S,) the global
    index of each scanner's active field set (-1: none, which counts as PROTECTIVE)."""
    n = points.shape[0]
    out = np.zeros(n, dtype=np.int8)
    for s in range(n):
        f = active[s]
        if f < 0:
            out[s] = PROTECTIVE
            continue
        p, w = prot[f], warn[f]
        status = CLEAR
        for b in range(points.shape[1]):
            if not valid[s, b]:
                continue
            x, y = points[s, b, 0], points[s, b, 1]
            if _inside(x, y, verts, start[p], count[p]):
                status = PROTECTIVE
                break
            if w >= 0 and status == CLEAR and _inside(x, y, verts, start[w], count[w]):
                status = WARNING
        out[s] = status
    return out


def scan_points_robot_frame(
    ranges: np.ndarray,
    beam_angles_rad: np.ndarray,
    mount_xy_m: tuple[float, float],
    mount_yaw_rad: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Robot-frame points (B, 2) of one scan and which beams are returns: +inf (no return) and
    NaN are not, -inf (closer than the sensor's minimum) is a return at the sensor."""
    r = np.asarray(ranges, dtype=np.float64)
    valid = ~np.isnan(r) & ~np.isposinf(r)
    rr = np.where(valid, np.maximum(r, 0.0), 0.0)
    a = np.asarray(beam_angles_rad, dtype=np.float64) + mount_yaw_rad
    pts = np.column_stack([mount_xy_m[0] + rr * np.cos(a), mount_xy_m[1] + rr * np.sin(a)])
    return pts, valid


@nb.njit(cache=True)
def brake(
    cmd: np.ndarray,
    prev: np.ndarray,
    status: np.ndarray,
    since_s: np.ndarray,
    t_s: float,
    dt_s: float,
    response_s: np.ndarray,
    decel: np.ndarray,
    warn_speed: np.ndarray,
) -> np.ndarray:
    """The body twists (N, 3) the robots get: ``cmd`` as commanded, ``prev`` as driven in the
    last step. PROTECTIVE: for ``response_s`` after the violation began (``since_s``, NaN when
    none; updated here) the previous twist goes on, then the speed falls by ``decel`` per
    second to zero (turn rate in proportion). WARNING: the speed is capped at ``warn_speed``.
    A twist that is not faster than the previous one in a protective violation passes."""
    out = cmd.copy()
    for i in range(cmd.shape[0]):
        if status[i] == PROTECTIVE:
            if np.isnan(since_s[i]):
                since_s[i] = t_s
            v_prev = math.hypot(prev[i, 0], prev[i, 1])
            if t_s - since_s[i] < response_s[i] - 1e-12:
                for k in range(3):
                    out[i, k] = prev[i, k]
            else:
                v_new = max(0.0, v_prev - decel[i] * dt_s)
                if v_prev > 1e-12:
                    scale = v_new / v_prev
                    for k in range(3):
                        out[i, k] = prev[i, k] * scale
                else:
                    for k in range(3):
                        out[i, k] = 0.0
        else:
            since_s[i] = np.nan
            if status[i] == WARNING:
                v = math.hypot(cmd[i, 0], cmd[i, 1])
                if v > warn_speed[i]:
                    scale = warn_speed[i] / v
                    for k in range(3):
                        out[i, k] = cmd[i, k] * scale
    return out
