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
The error type and the checks both share are in :mod:`agvsim.world.map_io` (imported by both;
neither imports the other's way up).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from agvsim.world.grid import OccupancyGrid
from agvsim.world.map_io import (
    MAX_CELLS,
    MapFormatError,
    check_cells,
    fraction,
    is_real,
    make_grid,
    map_error,
    read_grey,
    require_file,
    save_grey,
)
from agvsim.world.ros_map import (
    ROS_EXTENSIONS,
    ROS_MODES,
    ROS_REQUIRED_KEYS,
    load_ros_map,
    save_ros_map,
)

__all__ = [
    "CSV_EXTENSIONS",
    "IMAGE_EXTENSIONS",
    "MAX_CELLS",
    "ROS_EXTENSIONS",
    "ROS_MODES",
    "ROS_REQUIRED_KEYS",
    "TEXT_EXTENSIONS",
    "MapFormatError",
    "format_text_picture",
    "grid_from_matrix",
    "load_csv",
    "load_image",
    "load_map",
    "load_ros_map",
    "load_text",
    "parse_text_picture",
    "save_csv",
    "save_png",
    "save_ros_map",
    "save_text",
]

WALL_CHAR, FREE_CHAR = "#", "."
TEXT_EXTENSIONS = (".txt", ".map")
CSV_EXTENSIONS = (".csv",)
IMAGE_EXTENSIONS = (".png", ".pgm", ".ppm", ".pbm", ".bmp", ".jpg", ".jpeg", ".tif", ".tiff")

_A_MATRIX = "a non-empty list of equal-length rows of 0/1"
_A_PICTURE = f"lines of '{WALL_CHAR}' (wall) and '{FREE_CHAR}' (free), all the same width"
_A_CSV = "lines of 0/1 separated by commas, all with the same number of fields"


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
            raise map_error(source, None, "the matrix is empty or not a list of rows", _A_MATRIX)
        for r, row in enumerate(matrix, start=1):
            if isinstance(row, str | bytes) or not isinstance(row, Sequence | np.ndarray):
                raise map_error(source, f"row {r}", f"{row!r} is not a list of values", _A_MATRIX)
            if len(row) != len(matrix[0]) or not len(row):
                problem = f"has {len(row)} values but row 1 has {len(matrix[0])}"
                problem = problem if len(row) else "the row is empty"
                raise map_error(source, f"row {r}", problem, _A_MATRIX)
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
        raise map_error(source, None, f"shape {arr.shape} is not allowed", _A_MATRIX)
    if arr.dtype.kind in "biuf":
        good = (arr == 0) | (arr == 1)
    else:
        good = np.vectorize(_is_zero_one, otypes=[bool])(arr)
    if not good.all():
        r, c = (int(i) for i in np.argwhere(~good)[0])
        bad = arr[r, c].item() if isinstance(arr[r, c], np.generic) else arr[r, c]
        where, problem = f"row {r + 1}, column {c + 1}", f"value {bad!r} is not allowed"
        raise map_error(source, where, problem, "0 or 1 (or False/True)")
    return make_grid(arr.astype(float) != 0, resolution_m, origin_xy_m, source)


def _is_zero_one(v: object) -> bool:
    return isinstance(v, bool | np.bool_) or (is_real(v) and v in (0, 1))


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
        raise map_error(source, None, "no map lines found", allowed)
    for n, line in numbered:
        if not line:
            raise map_error(source, f"line {n}", "blank line inside the map", allowed)
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
            raise map_error(source, f"line {n}, column {bad + 1}", problem, _A_PICTURE)
        if len(line) != len(first):
            problem = f"has {len(line)} cells but line {first_no} has {len(first)}"
            raise map_error(source, f"line {n}", problem, _A_PICTURE)
    flat = np.frombuffer("".join(line for _, line in numbered).encode("ascii"), dtype=np.uint8)
    occ = flat.reshape(len(numbered), len(first)) == ord(WALL_CHAR)
    return make_grid(occ, resolution_m, origin_xy_m, source)


def format_text_picture(grid: OccupancyGrid) -> str:
    """The text picture of ``grid`` (``#`` wall, ``.`` free, row 0 first, trailing newline)."""
    chars = np.where(grid.occupied, WALL_CHAR, FREE_CHAR)
    return "".join("".join(row) + "\n" for row in chars)


def _check_text_size(path: Path, max_cells: int | None) -> None:
    """Refuse a text map file too large to hold a map within the cell limit (before reading)."""
    limit = MAX_CELLS if max_cells is None else max_cells
    size = path.stat().st_size
    if size > 4 * limit + (1 << 20):  # a cell takes 1 (picture) or 2 (CSV) bytes; room for spaces
        problem = f"{size:,} bytes is too large for a map of at most max_grid_cells = {limit:,}"
        raise map_error(
            str(path), None, problem, "raise max_grid_cells (docs/scenario.md, 'Limits')"
        )


def _read_text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise map_error(str(path), None, f"cannot read the file ({exc.strerror})") from exc
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line_no = data[: exc.start].count(b"\n") + 1
        where = f"line {line_no}"
        problem = f"byte {data[exc.start]:#04x} is not UTF-8 text"
        raise map_error(str(path), where, problem, "a UTF-8 text file") from exc


def load_text(
    path: str | Path,
    resolution_m: float = 1.0,
    origin_xy_m: tuple[float, float] | None = None,
    max_cells: int | None = None,
) -> OccupancyGrid:
    """Read a text picture file (see :func:`parse_text_picture`); cells ``resolution_m`` metres;
    at most ``max_cells`` cells (default :data:`MAX_CELLS`)."""
    p = require_file(path)
    _check_text_size(p, max_cells)
    grid = parse_text_picture(_read_text(p), resolution_m, origin_xy_m, source=str(p))
    check_cells(grid.rows, grid.cols, max_cells, str(p))
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
    p = require_file(path)
    _check_text_size(p, max_cells)
    src = str(p)
    numbered = _content_lines(_read_text(p), src, _A_CSV)
    rows: list[list[bool]] = []
    for n, line in numbered:
        fields = [f.strip() for f in line.split(",")]
        for k, f in enumerate(fields, start=1):
            if f not in ("0", "1"):
                raise map_error(
                    src, f"line {n}, field {k}", f"value {f!r} is not allowed", "0 or 1"
                )
        if rows and len(fields) != len(rows[0]):
            problem = f"has {len(fields)} fields but line {numbered[0][0]} has {len(rows[0])}"
            raise map_error(src, f"line {n}", problem, _A_CSV)
        rows.append([f == "1" for f in fields])
    check_cells(len(rows), len(rows[0]), max_cells, src)
    return make_grid(np.array(rows, dtype=bool), resolution_m, origin_xy_m, src)


# ---------------------------------------------------------------------------------- images
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
    p = require_file(path)
    threshold = fraction(threshold, str(p), "threshold")
    lightness = read_grey(p, str(p), max_cells) / 255.0
    if negate:
        lightness = 1.0 - lightness
    return make_grid(lightness < threshold, resolution_m, origin_xy_m, str(p))


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
    p = require_file(path)
    ext = p.suffix.lower()
    if ext in ROS_EXTENSIONS:
        if resolution_m is not None or origin_xy_m is not None:
            problem = "a ROS map sets its own resolution and origin"
            raise map_error(str(p), "resolution_m/origin_xy_m", problem, "leave both unset (None)")
        return load_ros_map(p, max_cells=max_cells)
    res = 1.0 if resolution_m is None else resolution_m
    if ext in TEXT_EXTENSIONS:
        return load_text(p, res, origin_xy_m, max_cells)
    if ext in CSV_EXTENSIONS:
        return load_csv(p, res, origin_xy_m, max_cells)
    if ext in IMAGE_EXTENSIONS:
        return load_image(p, res, origin_xy_m, max_cells=max_cells)
    allowed = " ".join(TEXT_EXTENSIONS + CSV_EXTENSIONS + IMAGE_EXTENSIONS + ROS_EXTENSIONS)
    raise map_error(str(p), "extension", f"{ext or '(none)'!r} is not a known map format", allowed)


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


def save_png(grid: OccupancyGrid, path: str | Path) -> Path:
    """Write ``grid`` as an 8-bit grey PNG, one pixel per cell, walls black, free white."""
    p = Path(path)
    save_grey(grid, p, 255, "PNG")
    return p
