"""Read and write occupancy-grid maps: inline matrices, text pictures, CSV, images, ROS maps.

Every reader returns an :class:`~agvsim.world.grid.OccupancyGrid` (row 0 = north, column 0 =
west, cells ``resolution_m`` metres square, ``origin_xy_m`` = world (x, y) in metres of the
map's lower-left corner). Unless an origin is given, pictures are centred on the world origin.

Bad user input raises :class:`MapFormatError` (a ``ValueError``) whose message names the source
(file path or ``"inline matrix"``), the place (line / row / field / key), the bad value and what
is allowed. Pillow and PyYAML are imported only by the functions that need them, so the
simulation core can use :func:`grid_from_matrix` and :func:`parse_text_picture` without them.
ROS ``map_server`` maps are in :mod:`agvsim.world.ros_map`; ``load_ros_map`` and
``save_ros_map`` stay importable from here, and :func:`load_map` reads ``.yaml``/``.yml`` maps.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agvsim.world.grid import OccupancyGrid

WALL_CHAR, FREE_CHAR = "#", "."
TEXT_EXTENSIONS = (".txt", ".map")
CSV_EXTENSIONS = (".csv",)
IMAGE_EXTENSIONS = (".png", ".pgm", ".ppm", ".pbm", ".bmp", ".jpg", ".jpeg", ".tif", ".tiff")
ROS_EXTENSIONS = (".yaml", ".yml")  # read by agvsim.world.ros_map
_ROS_OCCUPIED_PIXEL = 0  # walls in saved images, as ROS map_saver writes them
MAX_CELLS = 25_000_000  # default limit on rows x cols of a map read from a file (5000 x 5000)

_A_MATRIX = "a non-empty list of equal-length rows of 0/1"
_A_PICTURE = f"lines of '{WALL_CHAR}' (wall) and '{FREE_CHAR}' (free), all the same width"
_A_CSV = "lines of 0/1 separated by commas, all with the same number of fields"
_A_FRACTION = "a number in [0, 1]"


class MapFormatError(ValueError):
    """A map file or matrix that cannot be read; the message says where and what is allowed.

    ``source`` is the file path (or ``"inline matrix"``), ``where`` the line/row/field/key.
    """

    def __init__(self, message: str, *, source: str | None = None, where: str | None = None):
        super().__init__(message)
        self.source = source
        self.where = where


def _err(source: str, where: str | None, problem: str, allowed: str = "") -> MapFormatError:
    place = f"{source}, {where}" if where else source
    msg = f"{place}: {problem}" + (f" (allowed: {allowed})" if allowed else "")
    return MapFormatError(msg, source=source, where=where)


def _is_real(v: object) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool)


def _make_grid(
    occupied: np.ndarray, resolution_m: float, origin_xy_m: Sequence[float] | None, source: str
) -> OccupancyGrid:
    """Validate the geometry arguments and build the grid (centred when no origin is given)."""
    if not (_is_real(resolution_m) and math.isfinite(resolution_m) and resolution_m > 0):
        raise _err(source, "resolution_m", f"{resolution_m!r} is not allowed", "metres > 0")
    if origin_xy_m is not None:
        ok = isinstance(origin_xy_m, Sequence | np.ndarray) and len(origin_xy_m) == 2
        if not (ok and all(_is_real(v) and math.isfinite(v) for v in origin_xy_m)):
            allowed = "None (centred) or (x, y), two finite numbers of metres"
            raise _err(source, "origin_xy_m", f"{origin_xy_m!r} is not allowed", allowed)
        origin_xy_m = (float(origin_xy_m[0]), float(origin_xy_m[1]))
    return OccupancyGrid.from_matrix(occupied, float(resolution_m), origin_xy_m)


# ---------------------------------------------------------------------------------- matrices
def grid_from_matrix(
    matrix: Sequence[Sequence[int | bool]] | np.ndarray,
    resolution_m: float = 1.0,
    origin_xy_m: tuple[float, float] | None = None,
    source: str = "inline matrix",
) -> OccupancyGrid:
    """Grid from a 0/1 (or bool) matrix, row 0 = north, 1 = wall.

    Args:
        matrix: list of equal-length rows (or a 2-D array) of 0/1 or True/False.
        resolution_m: cell side in metres.
        origin_xy_m: world (x, y) in metres of the lower-left map corner; None centres the map.
        source: name used in error messages.

    Raises:
        MapFormatError: empty matrix, ragged rows or a value other than 0/1; the message gives
            the 1-based row (and column) number.
    """
    if not isinstance(matrix, np.ndarray):
        if isinstance(matrix, str | bytes) or not isinstance(matrix, Sequence) or not matrix:
            raise _err(source, None, "the matrix is empty or not a list of rows", _A_MATRIX)
        for r, row in enumerate(matrix, start=1):
            if isinstance(row, str | bytes) or not isinstance(row, Sequence | np.ndarray):
                raise _err(source, f"row {r}", f"{row!r} is not a list of values", _A_MATRIX)
            if len(row) != len(matrix[0]) or not len(row):
                problem = f"has {len(row)} values but row 1 has {len(matrix[0])}"
                problem = problem if len(row) else "the row is empty"
                raise _err(source, f"row {r}", problem, _A_MATRIX)
        try:
            arr = np.array(matrix)
        except ValueError:  # values nested in odd shapes
            arr = np.array([], dtype=object)
        if arr.dtype.kind not in "biuf":  # strings, lists or mixed types: check one by one
            arr = np.empty((len(matrix), len(matrix[0])), dtype=object)
            for r, row in enumerate(matrix):
                for c, v in enumerate(row):
                    arr[r, c] = v
    else:
        arr = matrix
    if arr.ndim != 2 or arr.size == 0:
        raise _err(source, None, f"shape {arr.shape} is not allowed", _A_MATRIX)
    if arr.dtype.kind in "biuf":
        good = (arr == 0) | (arr == 1)
    else:
        good = np.vectorize(_is_zero_one, otypes=[bool])(arr)
    if not good.all():
        r, c = (int(i) for i in np.argwhere(~good)[0])
        bad = arr[r, c].item() if isinstance(arr[r, c], np.generic) else arr[r, c]
        where, problem = f"row {r + 1}, column {c + 1}", f"value {bad!r} is not allowed"
        raise _err(source, where, problem, "0 or 1 (or False/True)")
    return _make_grid(arr.astype(float) != 0, resolution_m, origin_xy_m, source)


def _is_zero_one(v: object) -> bool:
    return isinstance(v, bool | np.bool_) or (_is_real(v) and v in (0, 1))


# ---------------------------------------------------------------------------------- text files
def _content_lines(text: str, source: str, allowed: str) -> list[tuple[int, str]]:
    """(1-based line number, line without trailing whitespace), blank edge lines dropped.

    Raises MapFormatError when nothing is left or a blank line sits inside the content.
    """
    numbered = [(n, line.rstrip()) for n, line in enumerate(text.splitlines(), start=1)]
    while numbered and not numbered[-1][1]:
        numbered.pop()
    while numbered and not numbered[0][1]:
        numbered.pop(0)
    if not numbered:
        raise _err(source, None, "no map lines found", allowed)
    for n, line in numbered:
        if not line:
            raise _err(source, f"line {n}", "blank line inside the map", allowed)
    return numbered


def parse_text_picture(
    text: str,
    resolution_m: float = 1.0,
    origin_xy_m: tuple[float, float] | None = None,
    source: str = "<text>",
) -> OccupancyGrid:
    """Grid from a text picture: ``#`` = wall, ``.`` = free, first line = north.

    Blank lines before and after the picture and whitespace at line ends are ignored; line
    numbers in error messages count every line of ``text`` (1-based).

    Args:
        text: the picture.
        resolution_m: side of one character cell in metres.
        origin_xy_m: world (x, y) in metres of the lower-left corner; None centres the map.
        source: name used in error messages (the file path for :func:`load_text`).
    """
    numbered = _content_lines(text, source, _A_PICTURE)
    first_no, first = numbered[0]
    for n, line in numbered:
        bad = next((i for i, ch in enumerate(line) if ch not in (WALL_CHAR, FREE_CHAR)), None)
        if bad is not None:
            problem = f"character {line[bad]!r} is not allowed"
            raise _err(source, f"line {n}, column {bad + 1}", problem, _A_PICTURE)
        if len(line) != len(first):
            problem = f"has {len(line)} cells but line {first_no} has {len(first)}"
            raise _err(source, f"line {n}", problem, _A_PICTURE)
    flat = np.frombuffer("".join(line for _, line in numbered).encode("ascii"), dtype=np.uint8)
    occ = flat.reshape(len(numbered), len(first)) == ord(WALL_CHAR)
    return _make_grid(occ, resolution_m, origin_xy_m, source)


def format_text_picture(grid: OccupancyGrid) -> str:
    """The text picture of ``grid`` (``#`` wall, ``.`` free, row 0 first, trailing newline)."""
    chars = np.where(grid.occupied, WALL_CHAR, FREE_CHAR)
    return "".join("".join(row) + "\n" for row in chars)


def _check_cells(rows: int, cols: int, max_cells: int | None, source: str) -> None:
    """MapFormatError when a ``rows x cols`` map is over ``max_cells`` (default MAX_CELLS)."""
    limit = MAX_CELLS if max_cells is None else max_cells
    if rows * cols > limit:
        problem = (
            f"{rows:,} x {cols:,} = {rows * cols:,} cells is over the limit max_grid_cells = "
            f"{limit:,} (raise it with 'limits: {{max_grid_cells: {rows * cols}}}' in the "
            f"scenario or '--limit max_grid_cells={rows * cols}')"
        )
        raise _err(source, None, problem)


def _check_text_size(path: Path, max_cells: int | None) -> None:
    """Refuse a text map file too large to hold a map within the cell limit (before reading)."""
    limit = MAX_CELLS if max_cells is None else max_cells
    size = path.stat().st_size
    if size > 4 * limit + (1 << 20):  # a cell takes 1 (picture) or 2 (CSV) bytes; room for spaces
        problem = f"{size:,} bytes is too large for a map of at most max_grid_cells = {limit:,}"
        raise _err(str(path), None, problem, "raise max_grid_cells (docs/scenario.md, 'Limits')")


def _require_file(path: str | Path) -> Path:
    p = Path(path)
    if not p.is_file():
        problem = "is not a file" if p.exists() else "file not found"
        raise _err(str(p), None, problem, "the path of an existing map file")
    return p


def _read_text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise _err(str(path), None, f"cannot read the file ({exc.strerror})") from exc
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line_no = data[: exc.start].count(b"\n") + 1
        where = f"line {line_no}"
        problem = f"byte {data[exc.start]:#04x} is not UTF-8 text"
        raise _err(str(path), where, problem, "a UTF-8 text file") from exc


def load_text(
    path: str | Path,
    resolution_m: float = 1.0,
    origin_xy_m: tuple[float, float] | None = None,
    max_cells: int | None = None,
) -> OccupancyGrid:
    """Read a text picture file (see :func:`parse_text_picture`); cells ``resolution_m`` metres;
    at most ``max_cells`` cells (default :data:`MAX_CELLS`)."""
    p = _require_file(path)
    _check_text_size(p, max_cells)
    grid = parse_text_picture(_read_text(p), resolution_m, origin_xy_m, source=str(p))
    _check_cells(grid.rows, grid.cols, max_cells, str(p))
    return grid


def load_csv(
    path: str | Path,
    resolution_m: float = 1.0,
    origin_xy_m: tuple[float, float] | None = None,
    max_cells: int | None = None,
) -> OccupancyGrid:
    """Read comma-separated 0/1 rows (1 = wall, first line = north; spaces around values ok).

    Blank lines before and after the matrix are ignored; a blank line inside it is an error.
    Cells are ``resolution_m`` metres; ``origin_xy_m`` as in :func:`grid_from_matrix`; at most
    ``max_cells`` cells (default :data:`MAX_CELLS`).
    """
    p = _require_file(path)
    _check_text_size(p, max_cells)
    src = str(p)
    numbered = _content_lines(_read_text(p), src, _A_CSV)
    rows: list[list[bool]] = []
    for n, line in numbered:
        fields = [f.strip() for f in line.split(",")]
        for k, f in enumerate(fields, start=1):
            if f not in ("0", "1"):
                raise _err(src, f"line {n}, field {k}", f"value {f!r} is not allowed", "0 or 1")
        if rows and len(fields) != len(rows[0]):
            problem = f"has {len(fields)} fields but line {numbered[0][0]} has {len(rows[0])}"
            raise _err(src, f"line {n}", problem, _A_CSV)
        rows.append([f == "1" for f in fields])
    _check_cells(len(rows), len(rows[0]), max_cells, src)
    return _make_grid(np.array(rows, dtype=bool), resolution_m, origin_xy_m, src)


# ---------------------------------------------------------------------------------- images
def _read_grey(path: Path, source: str, max_cells: int | None = None) -> np.ndarray:
    """Image as float grey levels in [0, 255]: mean of the colour channels, alpha ignored,
    16-bit images scaled down. Any Pillow failure becomes a MapFormatError; an image of more
    than ``max_cells`` pixels is refused before it is decoded."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as opened:
            width, height = opened.size
            _check_cells(height, width, max_cells, source)
            opened.load()
            img: Image.Image = opened
            if img.mode == "P":
                img = img.convert("RGBA" if "transparency" in img.info else "RGB")
            elif img.mode not in ("L", "LA", "RGB", "RGBA", "I", "F") and "I;16" not in img.mode:
                img = img.convert("L" if img.mode == "1" else "RGB")
            mode, arr = img.mode, np.asarray(img)
    except UnidentifiedImageError as exc:
        raise _err(source, None, "not an image Pillow can read", "PNG, PGM, BMP, JPEG...") from exc
    except (OSError, ValueError, SyntaxError, EOFError, Image.DecompressionBombError) as exc:
        raise _err(source, None, f"cannot read the image ({exc})") from exc
    if mode == "F":
        raise _err(source, None, "float images are not supported", "8/16-bit grey or colour")
    if mode == "I" or mode.startswith("I;16"):
        return arr.astype(np.float64) / 257.0  # 0..65535 -> 0..255
    arr = arr.astype(np.float64)
    if arr.ndim == 3:
        arr = arr[:, :, : 1 if arr.shape[2] <= 2 else 3].mean(axis=2)  # LA -> L, RGB(A) -> RGB
    return arr


def _fraction(value: Any, source: str, where: str) -> float:
    if isinstance(value, str):
        try:
            value = float(value)  # yaml-cpp reads '1e-05' as a number; PyYAML as a string
        except ValueError:
            pass
    if not (_is_real(value) and 0.0 <= value <= 1.0):
        raise _err(source, where, f"{value!r} is not allowed", _A_FRACTION)
    return float(value)


def load_image(
    path: str | Path,
    resolution_m: float = 1.0,
    origin_xy_m: tuple[float, float] | None = None,
    threshold: float = 0.5,
    negate: bool = False,
    max_cells: int | None = None,
) -> OccupancyGrid:
    """Read an image (PNG, PGM, BMP, JPEG, ... anything Pillow reads): one pixel = one cell.

    Image row 0 is north. A pixel's lightness ``l = grey / 255`` (grey = mean of the colour
    channels, alpha ignored; 16-bit images scaled to 0..255) makes a wall where
    ``l < threshold``; with ``negate`` the lightness is inverted first (light pixels are walls).

    Args:
        resolution_m: side of one pixel in metres.
        origin_xy_m: world (x, y) in metres of the lower-left corner; None centres the map.
        threshold: lightness in [0, 1] below which a pixel is a wall.
        negate: treat light pixels as walls.
        max_cells: most pixels allowed (default :data:`MAX_CELLS`).
    """
    p = _require_file(path)
    threshold = _fraction(threshold, str(p), "threshold")
    lightness = _read_grey(p, str(p), max_cells) / 255.0
    if negate:
        lightness = 1.0 - lightness
    return _make_grid(lightness < threshold, resolution_m, origin_xy_m, str(p))


# ---------------------------------------------------------------------------------- dispatch
def load_map(
    path: str | Path,
    resolution_m: float | None = None,
    origin_xy_m: tuple[float, float] | None = None,
    max_cells: int | None = None,
) -> OccupancyGrid:
    """Read a map, choosing the reader by file extension (case-insensitive).

    ``.txt``/``.map``: text picture; ``.csv``: 0/1 matrix; ``.png``/``.pgm``/``.bmp``/``.jpg``
    etc.: image (dark = wall); ``.yaml``/``.yml``: ROS map. ``resolution_m`` (metres per cell,
    default 1.0) and ``origin_xy_m`` (lower-left corner in metres, default centred) apply to
    pictures only; a ROS map carries its own, and giving either for one is an error. A map of
    more than ``max_cells`` cells (default :data:`MAX_CELLS`) is refused before it is read.
    """
    p = _require_file(path)
    ext = p.suffix.lower()
    if ext in ROS_EXTENSIONS:
        if resolution_m is not None or origin_xy_m is not None:
            problem = "a ROS map sets its own resolution and origin"
            raise _err(str(p), "resolution_m/origin_xy_m", problem, "leave both unset (None)")
        from agvsim.world.ros_map import load_ros_map  # imports this module: not at the top

        return load_ros_map(p, max_cells=max_cells)
    res = 1.0 if resolution_m is None else resolution_m
    if ext in TEXT_EXTENSIONS:
        return load_text(p, res, origin_xy_m, max_cells)
    if ext in CSV_EXTENSIONS:
        return load_csv(p, res, origin_xy_m, max_cells)
    if ext in IMAGE_EXTENSIONS:
        return load_image(p, res, origin_xy_m, max_cells=max_cells)
    allowed = " ".join(TEXT_EXTENSIONS + CSV_EXTENSIONS + IMAGE_EXTENSIONS + ROS_EXTENSIONS)
    raise _err(str(p), "extension", f"{ext or '(none)'!r} is not a known map format", allowed)


# ---------------------------------------------------------------------------------- writers
def save_text(grid: OccupancyGrid, path: str | Path) -> Path:
    """Write ``grid`` as a text picture (``#`` wall, ``.`` free). Resolution/origin not stored."""
    p = Path(path)
    p.write_text(format_text_picture(grid), encoding="utf-8")
    return p


def save_csv(grid: OccupancyGrid, path: str | Path) -> Path:
    """Write ``grid`` as comma-separated 0/1 rows (1 = wall). Resolution/origin not stored."""
    p = Path(path)
    lines = (",".join("1" if v else "0" for v in row) + "\n" for row in grid.occupied)
    p.write_text("".join(lines), encoding="utf-8")
    return p


def _save_grey(grid: OccupancyGrid, path: Path, free_value: int, fmt: str) -> None:
    from PIL import Image

    pixels = np.where(grid.occupied, _ROS_OCCUPIED_PIXEL, free_value).astype(np.uint8)
    Image.fromarray(pixels).save(path, format=fmt)  # 2-D uint8 -> 8-bit grey ("L")


def save_png(grid: OccupancyGrid, path: str | Path) -> Path:
    """Write ``grid`` as an 8-bit grey PNG, one pixel per cell, walls black, free white."""
    p = Path(path)
    _save_grey(grid, p, 255, "PNG")
    return p


# ---------------------------------------------------------------------------------- ROS maps
_ROS_MAP_NAMES = ("ROS_MODES", "ROS_REQUIRED_KEYS", "load_ros_map", "save_ros_map")


def __getattr__(name: str) -> Any:
    """``loaders.load_ros_map`` and the other ROS map names, from :mod:`agvsim.world.ros_map`
    (imported on first use rather than here, because it imports this module)."""
    if name in _ROS_MAP_NAMES:
        from agvsim.world import ros_map

        return getattr(ros_map, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
