"""A line sensor: a bar of N hall-effect (magnetic tape) or optical (painted line) elements
across the vehicle, and a spot reader (magnets / RFID tags at the nodes).

Element j of a bar ``span_m`` wide sits at lateral position ``y_j = -span/2 + j span/(N-1)``
(robot frame, left positive) at ``mount_x_m`` ahead of the reference point; it is on when its
centre lies over the tape (within half the tape's width of the centre line). The reading is
what a real guidance sensor outputs: the elements' states, and the lateral offset of the line
from the bar's middle as the mean position of the lit elements (plus Gaussian noise), for each
separate run of lit elements (two runs: a fork or a crossing under the bar).

Batch-first: one kernel call reads every robot's bar against every tape segment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np


@dataclass(frozen=True)
class LineSensorSpec:
    name: str = "line"
    elements: int = 16
    span_m: float = 0.16  # a common 16-element magnetic guide sensor: 10 mm pitch
    mount_x_m: float = 0.3
    noise_std_m: float = 0.0
    spot_radius_m: float = 0.05  # how close a spot must pass under the reader

    def __post_init__(self) -> None:
        if not (2 <= self.elements <= 256):
            raise ValueError(f"line sensor {self.name!r}: elements must be 2..256")
        if not (0.0 < self.span_m <= 5.0):
            raise ValueError(f"line sensor {self.name!r}: span_m must be in (0, 5] m")
        if self.noise_std_m < 0 or self.spot_radius_m <= 0:
            raise ValueError(
                f"line sensor {self.name!r}: noise_std_m >= 0 and spot_radius_m > 0 needed"
            )

    @property
    def positions_m(self) -> np.ndarray:
        return np.linspace(-self.span_m / 2.0, self.span_m / 2.0, self.elements)


@dataclass(frozen=True)
class LineReading:
    """What a line sensor reads at ``stamp_s``: its elements' states ``(E,)``, the lateral
    offset (m, left positive, noise included) of each run of lit elements, right to left
    (empty: no line under the bar), and the code of the spot under the reader (-1: none)."""

    stamp_s: float
    active: np.ndarray
    offsets_m: tuple[float, ...]
    spot_code: int = -1


@nb.njit(cache=True)
def _seg_distance(px: float, py: float, s: np.ndarray) -> float:
    ax, ay, bx, by = s[0], s[1], s[2], s[3]
    ux, uy = bx - ax, by - ay
    den = ux * ux + uy * uy
    t = 0.0
    if den > 0.0:
        t = ((px - ax) * ux + (py - ay) * uy) / den
        t = min(1.0, max(0.0, t))
    dx, dy = px - (ax + t * ux), py - (ay + t * uy)
    return math.sqrt(dx * dx + dy * dy)


@nb.njit(cache=True)
def read_elements(
    poses: np.ndarray,
    mount_x: np.ndarray,
    positions: np.ndarray,
    segments: np.ndarray,
    half_width: float,
) -> np.ndarray:
    """Which elements are over the tape: ``poses`` (N, 3), ``mount_x`` (N,), element lateral
    positions ``(N, E)`` (NaN pads a shorter bar), tape ``segments`` (M, 4). Returns (N, E)."""
    n, e = positions.shape
    out = np.zeros((n, e), dtype=np.bool_)
    for i in range(n):
        c, s = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        for j in range(e):
            y = positions[i, j]
            if math.isnan(y):
                continue
            px = poses[i, 0] + c * mount_x[i] - s * y
            py = poses[i, 1] + s * mount_x[i] + c * y
            for m in range(segments.shape[0]):
                if _seg_distance(px, py, segments[m]) <= half_width:
                    out[i, j] = True
                    break
    return out


def line_offsets(active: np.ndarray, positions: np.ndarray) -> list[list[float]]:
    """For each robot, the lateral offset (m, left positive) of each separate run of lit
    elements: the mean position of the run's elements, runs ordered right to left (by y)."""
    out: list[list[float]] = []
    for on, y in zip(active, positions, strict=True):
        runs: list[float] = []
        j = 0
        while j < len(on):
            if on[j]:
                k = j
                while k + 1 < len(on) and on[k + 1]:
                    k += 1
                runs.append(float(y[j : k + 1].mean()))
                j = k + 1
            else:
                j += 1
        out.append(runs)
    return out


def spots_under(
    poses: np.ndarray, mount_x: np.ndarray, spot_xy: np.ndarray, radius_m: np.ndarray
) -> np.ndarray:
    """(N,) index of the spot under each robot's reader (at the bar's middle), -1 for none."""
    n = len(poses)
    if len(spot_xy) == 0:
        return np.full(n, -1, dtype=np.int64)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    reader = np.column_stack([poses[:, 0] + c * mount_x, poses[:, 1] + s * mount_x])
    d = np.hypot(*(reader[:, None, :] - spot_xy[None, :, :]).transpose(2, 0, 1))
    k = d.argmin(axis=1)
    return np.where(d[np.arange(n), k] <= radius_m, k, -1).astype(np.int64)
