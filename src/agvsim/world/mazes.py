"""Ready-made and generated mazes.

``THESIS_MAZES`` holds the two 20x20 binary matrices of the thesis the simulator reimplements
(the matrices of Fig. 16 and App. C.1), stored as text pictures in ``agvsim/data/mazes``.
Every function returns an :class:`~agvsim.world.grid.OccupancyGrid` (row 0 = north) centred on
the world origin unless it says otherwise; sizes are in cells, lengths in metres.
"""

from __future__ import annotations

from importlib import resources

import numpy as np
from scipy import ndimage

from agvsim.world.grid import OccupancyGrid
from agvsim.world.loaders import MAX_CELLS, parse_text_picture

__all__ = [
    "THESIS_MAZES",
    "thesis_maze",
    "upsample",
    "random_maze",
    "free_cells_connected",
    "tile",
]


def _load_packaged(name: str) -> OccupancyGrid:
    ref = resources.files("agvsim") / "data" / "mazes" / f"{name}.txt"
    return parse_text_picture(ref.read_text(encoding="utf-8"), 1.0, None, source=str(ref))


#: name -> 20x20 maze at 1 m per cell, centred (spans x, y in [-10, 10] m). Read-only grids.
THESIS_MAZES: dict[str, OccupancyGrid] = {
    name: _load_packaged(name) for name in ("thesis_fig16", "thesis_c1")
}


def _positive_int(value: int, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _resolution(value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        raise ValueError(f"resolution_m must be a number of metres > 0, got {value!r}")
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"resolution_m must be a finite number of metres > 0, got {value!r}")
    return float(value)


def thesis_maze(name: str, resolution_m: float = 1.0) -> OccupancyGrid:
    """A thesis maze with ``resolution_m``-metre cells, centred on the world origin.

    At the default 1 m the 20x20 maze spans x, y in [-10, 10] m. For a fine grid of the same
    walls use ``upsample(thesis_maze(name), 20)`` (0.05 m cells).

    Raises:
        ValueError: unknown name (the message lists the known ones).
    """
    if name not in THESIS_MAZES:
        raise ValueError(f"unknown thesis maze {name!r}; known: {', '.join(THESIS_MAZES)}")
    return OccupancyGrid.from_matrix(THESIS_MAZES[name].occupied, _resolution(resolution_m))


def upsample(grid: OccupancyGrid, factor: int) -> OccupancyGrid:
    """The same walls on a finer grid: each cell becomes ``factor x factor`` cells.

    The resolution is divided by ``factor``; origin and extent (metres) stay the same.
    """
    factor = _positive_int(factor, "factor")
    occ = np.repeat(np.repeat(grid.occupied, factor, axis=0), factor, axis=1)
    return OccupancyGrid(occ, grid.resolution_m / factor, grid.origin_xy_m)


def tile(grid: OccupancyGrid, nx: int, ny: int) -> OccupancyGrid:
    """Repeat ``grid`` ``nx`` times east and ``ny`` times north, centred on the world origin.

    Each copy keeps its own border, so copies of a closed maze are separate regions.
    """
    nx, ny = _positive_int(nx, "nx"), _positive_int(ny, "ny")
    return OccupancyGrid.from_matrix(np.tile(grid.occupied, (ny, nx)), grid.resolution_m)


def free_cells_connected(grid: OccupancyGrid) -> bool:
    """True when the free cells form exactly one 4-connected region (False if none are free)."""
    _, n_regions = ndimage.label(~grid.occupied)  # default structure: 4-connectivity
    return n_regions == 1


def random_maze(
    rows: int,
    cols: int,
    rng_or_seed: int | np.random.Generator,
    corridor_cells: int = 2,
    wall_cells: int = 1,
    resolution_m: float = 1.0,
    loop_fraction: float = 0.0,
    max_cells: int = MAX_CELLS,
) -> OccupancyGrid:
    """A random maze over a ``rows x cols`` lattice of rooms, centred on the world origin.

    Randomized depth-first search (iterative) makes a perfect maze: exactly one path between
    any two rooms. Then ``loop_fraction`` (in [0, 1]) of the interior walls still standing
    between neighbouring rooms are removed, which makes loops. Rooms are ``corridor_cells``
    cells wide, walls ``wall_cells`` thick, and a solid border of ``wall_cells`` surrounds the
    maze, so the grid is ``rows * (corridor_cells + wall_cells) + wall_cells`` cells tall (and
    likewise wide), each cell ``resolution_m`` metres.

    ``rng_or_seed``: an int seed (``numpy.random.default_rng(seed)``) or a Generator, which is
    advanced. The same seed always gives the same maze. A grid of more than ``max_cells``
    cells is refused (ValueError) before anything is generated.
    """
    rows, cols = _positive_int(rows, "rows"), _positive_int(cols, "cols")
    c = _positive_int(corridor_cells, "corridor_cells")
    w = _positive_int(wall_cells, "wall_cells")
    if not 0.0 <= loop_fraction <= 1.0:
        raise ValueError(f"loop_fraction must be in [0, 1], got {loop_fraction!r}")
    resolution_m = _resolution(resolution_m)
    height, width = rows * (c + w) + w, cols * (c + w) + w
    if height * width > max_cells:
        raise ValueError(
            f"a random maze of {height:,} x {width:,} = {height * width:,} cells is over the "
            f"limit max_grid_cells = {max_cells:,}"
        )
    if isinstance(rng_or_seed, np.random.Generator):
        rng = rng_or_seed
    elif isinstance(rng_or_seed, int | np.integer) and not isinstance(rng_or_seed, bool):
        rng = np.random.default_rng(int(rng_or_seed))
    else:
        raise ValueError(
            f"rng_or_seed must be an int seed or a numpy Generator, got {rng_or_seed!r}"
        )

    pitch = c + w
    occ = np.ones((rows * pitch + w, cols * pitch + w), dtype=bool)

    def top_left(i: int, j: int) -> tuple[int, int]:
        return w + i * pitch, w + j * pitch

    def open_wall(i: int, j: int, di: int, dj: int) -> None:
        """Remove the wall between room (i, j) and its neighbour (i + di, j + dj), di, dj >= 0."""
        r0, c0 = top_left(i, j)
        if di:
            occ[r0 + c : r0 + pitch, c0 : c0 + c] = False
        else:
            occ[r0 : r0 + c, c0 + c : c0 + pitch] = False

    for i in range(rows):
        for j in range(cols):
            r0, c0 = top_left(i, j)
            occ[r0 : r0 + c, c0 : c0 + c] = False

    visited = np.zeros((rows, cols), dtype=bool)
    opened: set[tuple[int, int, int, int]] = set()  # (i, j, di, dj) with di + dj == 1
    start = (int(rng.integers(rows)), int(rng.integers(cols)))
    visited[start] = True
    stack = [start]
    while stack:
        i, j = stack[-1]
        nbrs = [
            (i + di, j + dj)
            for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1))
            if 0 <= i + di < rows and 0 <= j + dj < cols and not visited[i + di, j + dj]
        ]
        if not nbrs:
            stack.pop()
            continue
        ni, nj = nbrs[int(rng.integers(len(nbrs)))]
        a, b = min((i, j), (ni, nj)), max((i, j), (ni, nj))
        opened.add((a[0], a[1], b[0] - a[0], b[1] - a[1]))
        open_wall(a[0], a[1], b[0] - a[0], b[1] - a[1])
        visited[ni, nj] = True
        stack.append((ni, nj))

    if loop_fraction > 0.0:
        standing = [
            (i, j, di, dj)
            for i in range(rows)
            for j in range(cols)
            for di, dj in ((1, 0), (0, 1))
            if i + di < rows and j + dj < cols and (i, j, di, dj) not in opened
        ]
        n_remove = int(round(loop_fraction * len(standing)))
        for k in rng.choice(len(standing), size=n_remove, replace=False):
            open_wall(*standing[int(k)])
    return OccupancyGrid.from_matrix(occ, resolution_m)
