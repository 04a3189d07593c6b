"""Read and write ROS ``map_server`` maps: a YAML file naming an image, its resolution and origin.

Part of the map readers: :mod:`agvsim.world.loaders` re-exports :func:`load_ros_map` and
:func:`save_ros_map`, and its :func:`~agvsim.world.loaders.load_map` reads ``.yaml``/``.yml``
files with :func:`load_ros_map`. Bad input raises the same
:class:`~agvsim.world.map_io.MapFormatError`. This module imports :mod:`agvsim.world.map_io`
only, never the loaders. PyYAML and Pillow are imported only when called.
"""

from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Any

import numpy as np

from agvsim.world.grid import OccupancyGrid
from agvsim.world.map_io import (
    fraction,
    is_real,
    make_grid,
    map_error,
    read_grey,
    require_file,
    save_grey,
)

ROS_EXTENSIONS = (".yaml", ".yml")
ROS_REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
ROS_MODES = ("trinary", "scale", "raw")
_ROS_FREE_PIXEL = 254  # what map_saver writes (occupied 0, unknown would be 205)
_A_ROS = "a map_server YAML with keys " + ", ".join(ROS_REQUIRED_KEYS)


def _ros_key(doc: dict[str, Any], key: str, source: str) -> Any:
    if key not in doc:
        close = difflib.get_close_matches(key, [str(k) for k in doc], n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise map_error(source, f"key '{key}'", f"missing{hint}", _A_ROS)
    return doc[key]


def _ros_number(value: Any, source: str, key: str, allowed: str) -> float:
    if isinstance(value, str):
        try:
            value = float(value)  # yaml-cpp reads '1e-05' as a number; PyYAML as a string
        except ValueError:
            pass
    if not (is_real(value) and math.isfinite(value)):
        raise map_error(source, f"key '{key}'", f"{value!r} is not allowed", allowed)
    return float(value)


def _read_ros_yaml(p: Path) -> dict[str, Any]:
    from agvsim.safe_yaml import YamlInputError, YamlLimits, load_yaml_file

    try:  # a map_server YAML is a handful of keys: tight limits against alias bombs
        doc = load_yaml_file(p, YamlLimits(max_bytes=1 << 20, max_nodes=10_000, max_depth=16))
    except YamlInputError as exc:
        where = f"line {exc.line}" if exc.line is not None else None
        raise map_error(str(p), where, exc.problem, _A_ROS) from None
    if not isinstance(doc, dict):
        raise map_error(str(p), None, f"top level is a {type(doc).__name__}, not a mapping", _A_ROS)
    return doc


def load_ros_map(
    yaml_path: str | Path, unknown_is_occupied: bool = True, max_cells: int | None = None
) -> OccupancyGrid:
    """Read a ROS ``map_server`` map (YAML + image); resolution and origin come from the YAML.

    Keys: ``image`` (path, relative to the YAML file), ``resolution`` (m/pixel), ``origin``
    ([x, y, yaw]: world pose of the lower-left pixel's corner, in metres / rad; yaw must be 0),
    ``negate`` (0/1), ``occupied_thresh``, ``free_thresh`` and optional ``mode`` (trinary,
    scale, raw; default trinary). Other keys are ignored.

    Trinary/scale rule of map_server: ``p = (255 - v) / 255`` (``v / 255`` with negate), where
    v is the mean of the colour channels; ``p > occupied_thresh`` is occupied,
    ``p < free_thresh`` free, anything else unknown (scale's in-between values included).
    Raw mode reads v (after negate) as percent occupancy; ``v > 100`` is unknown.
    Unknown cells are walls when ``unknown_is_occupied`` (default), free otherwise. An image
    of more than ``max_cells`` pixels (default ``map_io.MAX_CELLS``) is refused unread.
    """
    p = require_file(yaml_path)
    src, doc = str(p), _read_ros_yaml(p)
    image = _ros_key(doc, "image", src)
    if not isinstance(image, str) or not image.strip():
        raise map_error(src, "key 'image'", f"{image!r} is not allowed", "an image file path")
    res = _ros_number(_ros_key(doc, "resolution", src), src, "resolution", "metres per pixel > 0")
    if res <= 0:
        raise map_error(src, "key 'resolution'", f"{res!r} is not allowed", "metres per pixel > 0")
    origin = _ros_key(doc, "origin", src)
    if not isinstance(origin, list) or len(origin) != 3:
        raise map_error(src, "key 'origin'", f"{origin!r} is not allowed", "[x, y, yaw]")
    ox, oy, yaw = (_ros_number(v, src, "origin", "[x, y, yaw], three numbers") for v in origin)
    if yaw != 0.0:
        problem = f"yaw {yaw!r} rad is not supported"
        raise map_error(src, "key 'origin'", problem, "yaw 0; rotate the image instead")
    negate = _ros_key(doc, "negate", src)
    if isinstance(negate, float) or negate not in (0, 1):
        raise map_error(src, "key 'negate'", f"{negate!r} is not allowed", "0 or 1")
    occ_th = fraction(_ros_key(doc, "occupied_thresh", src), src, "key 'occupied_thresh'")
    free_th = fraction(_ros_key(doc, "free_thresh", src), src, "key 'free_thresh'")
    if free_th > occ_th:
        problem = f"{free_th!r} is above occupied_thresh {occ_th!r}"
        raise map_error(src, "key 'free_thresh'", problem, "free_thresh <= occupied_thresh")
    mode = doc.get("mode", "trinary")
    if mode not in ROS_MODES:
        raise map_error(src, "key 'mode'", f"{mode!r} is not allowed", ", ".join(ROS_MODES))

    image_path = Path(image) if Path(image).is_absolute() else p.parent / image
    if not image_path.is_file():
        problem = f"image file {str(image_path)!r} not found"
        raise map_error(src, "key 'image'", problem, "an existing image, relative to the YAML file")
    grey = read_grey(image_path, f"{image_path} (image of {src})", max_cells)
    if mode == "raw":
        value = 255.0 - grey if negate else grey
        known, p_occ = value <= 100.0, value / 100.0
    else:
        known, p_occ = np.ones(grey.shape, bool), (grey if negate else 255.0 - grey) / 255.0
    occupied, free = known & (p_occ > occ_th), known & (p_occ < free_th)
    walls = ~free if unknown_is_occupied else occupied
    return make_grid(walls, res, (ox, oy), src)


def save_ros_map(grid: OccupancyGrid, yaml_path: str | Path) -> Path:
    """Write ``grid`` as a ROS map: ``<stem>.pgm`` (occupied 0, free 254) beside the YAML.

    The YAML holds ``resolution`` (m/pixel), ``origin`` [x, y, 0] = ``grid.origin_xy_m`` (the
    lower-left corner, ROS semantics), negate 0, occupied_thresh 0.65, free_thresh 0.196 and
    mode trinary, so :func:`load_ros_map` reads back the same grid exactly. Returns the YAML path.
    """
    import yaml

    yp = Path(yaml_path)
    if yp.suffix.lower() not in ROS_EXTENSIONS:
        problem = f"{yp.suffix or '(none)'!r} is not allowed"
        raise map_error(str(yp), "extension", problem, " ".join(ROS_EXTENSIONS))
    save_grey(grid, yp.with_suffix(".pgm"), _ROS_FREE_PIXEL, "PPM")
    doc = {
        "image": yp.with_suffix(".pgm").name,
        "mode": "trinary",
        "resolution": float(grid.resolution_m),
        "origin": [float(grid.origin_xy_m[0]), float(grid.origin_xy_m[1]), 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    yp.write_text(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None), encoding="utf-8")
    return yp
