"""What every map reader and writer shares: :class:`MapFormatError` and its messages, the
checks of a map's size and geometry, and grey images read and written through Pillow.

:mod:`agvsim.world.loaders` (pictures, CSV, images, :func:`~agvsim.world.loaders.load_map`) and
:mod:`agvsim.world.ros_map` (ROS ``map_server`` maps) both build on this module, which imports
neither. Pillow is imported only by the functions that need it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agvsim.world.grid import OccupancyGrid

MAX_CELLS = 25_000_000  # default limit on rows x cols of a map read from a file (5000 x 5000)
OCCUPIED_PIXEL = 0  # walls in saved images, as ROS map_saver writes them
_A_FRACTION = "a number in [0, 1]"


class MapFormatError(ValueError):
    """A map file or matrix that cannot be read; the message says where and what is allowed.

    ``source`` is the file path (or ``"inline matrix"``), ``where`` the line/row/field/key.
    """

    def __init__(self, message: str, *, source: str | None = None, where: str | None = None):
        super().__init__(message)
        self.source = source
        self.where = where


def map_error(source: str, where: str | None, problem: str, allowed: str = "") -> MapFormatError:
    place = f"{source}, {where}" if where else source
    msg = f"{place}: {problem}" + (f" (allowed: {allowed})" if allowed else "")
    return MapFormatError(msg, source=source, where=where)


def is_real(v: object) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool)


def make_grid(
    occupied: np.ndarray, resolution_m: float, origin_xy_m: Sequence[float] | None, source: str
) -> OccupancyGrid:
    """Validate the geometry arguments and build the grid (centred when no origin is given)."""
    if not (is_real(resolution_m) and math.isfinite(resolution_m) and resolution_m > 0):
        raise map_error(source, "resolution_m", f"{resolution_m!r} is not allowed", "metres > 0")
    if origin_xy_m is not None:
        ok = isinstance(origin_xy_m, Sequence | np.ndarray) and len(origin_xy_m) == 2
        if not (ok and all(is_real(v) and math.isfinite(v) for v in origin_xy_m)):
            allowed = "None (centred) or (x, y), two finite numbers of metres"
            raise map_error(source, "origin_xy_m", f"{origin_xy_m!r} is not allowed", allowed)
        origin_xy_m = (float(origin_xy_m[0]), float(origin_xy_m[1]))
    return OccupancyGrid.from_matrix(occupied, float(resolution_m), origin_xy_m)


def check_cells(rows: int, cols: int, max_cells: int | None, source: str) -> None:
    """MapFormatError when a ``rows x cols`` map is over ``max_cells`` (default MAX_CELLS)."""
    limit = MAX_CELLS if max_cells is None else max_cells
    if rows * cols > limit:
        problem = (
            f"{rows:,} x {cols:,} = {rows * cols:,} cells is over the limit max_grid_cells = "
            f"{limit:,} (raise it with 'limits: {{max_grid_cells: {rows * cols}}}' in the "
            f"scenario or '--limit max_grid_cells={rows * cols}')"
        )
        raise map_error(source, None, problem)


def require_file(path: str | Path) -> Path:
    p = Path(path)
    if not p.is_file():
        problem = "is not a file" if p.exists() else "file not found"
        raise map_error(str(p), None, problem, "the path of an existing map file")
    return p


def read_grey(path: Path, source: str, max_cells: int | None = None) -> np.ndarray:
    """Image as float grey levels in [0, 255]: mean of the colour channels, alpha ignored,
    16-bit images scaled down. Any Pillow failure becomes a MapFormatError; an image of more
    than ``max_cells`` pixels is refused before it is decoded."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as opened:
            width, height = opened.size
            check_cells(height, width, max_cells, source)
            opened.load()
            img: Image.Image = opened
            if img.mode == "P":
                img = img.convert("RGBA" if "transparency" in img.info else "RGB")
            elif img.mode not in ("L", "LA", "RGB", "RGBA", "I", "F") and "I;16" not in img.mode:
                img = img.convert("L" if img.mode == "1" else "RGB")
            mode, arr = img.mode, np.asarray(img)
    except UnidentifiedImageError as exc:
        raise map_error(
            source, None, "not an image Pillow can read", "PNG, PGM, BMP, JPEG..."
        ) from exc
    except (OSError, ValueError, SyntaxError, EOFError, Image.DecompressionBombError) as exc:
        raise map_error(source, None, f"cannot read the image ({exc})") from exc
    if mode == "F":
        raise map_error(source, None, "float images are not supported", "8/16-bit grey or colour")
    if mode == "I" or mode.startswith("I;16"):
        return arr.astype(np.float64) / 257.0  # 0..65535 -> 0..255
    arr = arr.astype(np.float64)
    if arr.ndim == 3:
        arr = arr[:, :, : 1 if arr.shape[2] <= 2 else 3].mean(axis=2)  # LA -> L, RGB(A) -> RGB
    return arr


def fraction(value: Any, source: str, where: str) -> float:
    if isinstance(value, str):
        try:
            value = float(value)  # yaml-cpp reads '1e-05' as a number; PyYAML as a string
        except ValueError:
            pass
    if not (is_real(value) and 0.0 <= value <= 1.0):
        raise map_error(source, where, f"{value!r} is not allowed", _A_FRACTION)
    return float(value)


def save_grey(grid: OccupancyGrid, path: Path, free_value: int, fmt: str) -> None:
    from PIL import Image

    pixels = np.where(grid.occupied, OCCUPIED_PIXEL, free_value).astype(np.uint8)
    Image.fromarray(pixels).save(path, format=fmt)  # 2-D uint8 -> 8-bit grey ("L")
