"""Occupancy grid: the static walls of a world.

Layout (see docs/CONVENTIONS.md): ``occupied[row, col]`` is read as a picture, row 0 is the top
(largest y, north) and column 0 the left (smallest x, west). Each cell is ``resolution_m`` metres
square. ``origin_xy_m`` is the world position of the grid's lower-left corner (the west edge of
column 0 and the south edge of the last row).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class OccupancyGrid:
    occupied: np.ndarray  # (rows, cols) bool, row 0 = north
    resolution_m: float = 1.0
    origin_xy_m: tuple[float, float] = (0.0, 0.0)
    # bottom-up uint8 copy for the numba kernels: cells_bu[iy, ix], iy = 0 at the south edge
    cells_bu: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        occ = np.asarray(self.occupied)
        if occ.ndim != 2 or occ.shape[0] < 1 or occ.shape[1] < 1:
            raise ValueError(
                f"occupancy grid must be a non-empty 2-D matrix, got shape {occ.shape}"
            )
        if not (self.resolution_m > 0 and np.isfinite(self.resolution_m)):
            raise ValueError(f"resolution_m must be a positive number, got {self.resolution_m}")
        occ = occ.astype(bool, copy=True)
        occ.setflags(write=False)
        object.__setattr__(self, "occupied", occ)
        ox, oy = (float(v) for v in self.origin_xy_m)
        object.__setattr__(self, "origin_xy_m", (ox, oy))
        bu = np.ascontiguousarray(occ[::-1, :].astype(np.uint8))
        bu.setflags(write=False)
        object.__setattr__(self, "cells_bu", bu)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_matrix(
        cls,
        matrix: np.ndarray | list,
        resolution_m: float = 1.0,
        origin_xy_m: tuple[float, float] | None = None,
    ) -> OccupancyGrid:
        """Grid from a 0/1 matrix (row 0 = north). Centred on the world origin by default."""
        occ = np.asarray(matrix)
        if occ.ndim != 2:
            raise ValueError(f"a maze matrix must be 2-D, got shape {occ.shape}")
        occ = occ != 0
        if origin_xy_m is None:
            origin_xy_m = (-occ.shape[1] * resolution_m / 2.0, -occ.shape[0] * resolution_m / 2.0)
        return cls(occ, float(resolution_m), origin_xy_m)

    # ------------------------------------------------------------------ geometry
    @property
    def rows(self) -> int:
        return int(self.occupied.shape[0])

    @property
    def cols(self) -> int:
        return int(self.occupied.shape[1])

    @property
    def width_m(self) -> float:
        return self.cols * self.resolution_m

    @property
    def height_m(self) -> float:
        return self.rows * self.resolution_m

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the map."""
        ox, oy = self.origin_xy_m
        return (ox, ox + self.width_m, oy, oy + self.height_m)

    def cell_of(
        self, x: np.ndarray | float, y: np.ndarray | float
    ) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) of the cell holding world point(s) (x, y); may be outside the map."""
        ox, oy = self.origin_xy_m
        col = np.floor((np.asarray(x) - ox) / self.resolution_m).astype(np.int64)
        iy = np.floor((np.asarray(y) - oy) / self.resolution_m).astype(np.int64)
        return self.rows - 1 - iy, col

    def cell_center(
        self, row: np.ndarray | int, col: np.ndarray | int
    ) -> tuple[np.ndarray, np.ndarray]:
        """World (x, y) of the centre of cell(s) (row, col)."""
        ox, oy = self.origin_xy_m
        x = ox + (np.asarray(col) + 0.5) * self.resolution_m
        y = oy + (self.rows - 1 - np.asarray(row) + 0.5) * self.resolution_m
        return x, y

    def contains(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        xmin, xmax, ymin, ymax = self.extent_m
        x, y = np.asarray(x), np.asarray(y)
        return (x >= xmin) & (x < xmax) & (y >= ymin) & (y < ymax)

    def is_occupied_at(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """True where the point is on an occupied cell or outside the map."""
        row, col = self.cell_of(x, y)
        inside = (row >= 0) & (row < self.rows) & (col >= 0) & (col < self.cols)
        out = np.ones(np.shape(row), dtype=bool)
        out[inside] = self.occupied[row[inside], col[inside]]
        return out

    def with_cell(self, row: int, col: int, occupied: bool) -> OccupancyGrid:
        """A copy with one cell set (for editors)."""
        occ = self.occupied.copy()
        occ[row, col] = occupied
        return OccupancyGrid(occ, self.resolution_m, self.origin_xy_m)

    def free_fraction(self) -> float:
        return float(1.0 - self.occupied.mean())
