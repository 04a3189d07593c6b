"""Guidance tape on the floor: magnetic tape or a painted line, and magnetic spots / RFID tags.

Tape is given as polylines and circular arcs in the world frame (metres); arcs are cut into
chords so fine that a chord is never more than ``chord_error_m`` from the true arc, so one
segment list serves both. Spots are points with an id (a magnet's code or an RFID tag's
number) that a reader under the vehicle detects within its radius.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agvsim.world.points import xy_points


@dataclass(frozen=True)
class Arc:
    """A circular arc: centre, radius, from ``start_deg`` turning by ``sweep_deg`` (positive
    counter-clockwise)."""

    cx_m: float
    cy_m: float
    radius_m: float
    start_deg: float
    sweep_deg: float

    def points(self, chord_error_m: float) -> np.ndarray:
        """(n, 2) points along the arc, every chord within ``chord_error_m`` of it."""
        r = self.radius_m
        # the sagitta of a chord subtending angle a is r (1 - cos(a / 2))
        a_max = 2.0 * math.acos(max(-1.0, 1.0 - chord_error_m / r)) if r > chord_error_m else 1.0
        sweep = math.radians(self.sweep_deg)
        n = max(1, math.ceil(abs(sweep) / max(a_max, 1e-6)))
        a = math.radians(self.start_deg) + np.linspace(0.0, sweep, n + 1)
        return np.column_stack([self.cx_m + r * np.cos(a), self.cy_m + r * np.sin(a)])


@dataclass(frozen=True)
class Spot:
    x_m: float
    y_m: float
    code: int


class Tape:
    """All tape of a world as segments ``(M, 4)`` = (x0, y0, x1, y1), its width, and spots."""

    def __init__(
        self,
        lines: Sequence[Sequence[Sequence[float]] | Arc] = (),
        width_m: float = 0.05,
        spots: Sequence[Spot] = (),
        chord_error_m: float = 0.001,
    ):
        if not (0.0 < width_m <= 1.0):
            raise ValueError(f"tape width_m must be in (0, 1] m, got {width_m}")
        segs: list[np.ndarray] = []
        for k, line in enumerate(lines):
            pts = (
                line.points(chord_error_m)
                if isinstance(line, Arc)
                else xy_points(line, f"tape line {k}", 2)
            )
            segs.append(np.column_stack([pts[:-1], pts[1:]]))
        self.segments = np.concatenate(segs) if segs else np.zeros((0, 4))
        self.width_m = float(width_m)
        self.spots = tuple(spots)
        self.spot_xy = np.array([(s.x_m, s.y_m) for s in spots], dtype=np.float64).reshape(-1, 2)
        self.spot_code = np.array([s.code for s in spots], dtype=np.int64)

    @property
    def length_m(self) -> float:
        d = self.segments[:, 2:] - self.segments[:, :2]
        return float(np.hypot(d[:, 0], d[:, 1]).sum())

    def distance_m(self, xy: np.ndarray) -> np.ndarray:
        """Distance of points ``(..., 2)`` to the tape's centre line (inf without tape)."""
        p = np.asarray(xy, dtype=np.float64)
        if len(self.segments) == 0:
            return np.full(p.shape[:-1], np.inf)
        a, b = self.segments[:, :2], self.segments[:, 2:]
        ab = b - a
        den = np.maximum((ab * ab).sum(-1), 1e-300)
        q = p[..., None, :]
        t = np.clip(((q - a) * ab).sum(-1) / den, 0.0, 1.0)
        d = q - (a + t[..., None] * ab)
        return np.sqrt((d * d).sum(-1)).min(axis=-1)
