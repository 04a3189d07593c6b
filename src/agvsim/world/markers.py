"""What the onboard camera sees of the world besides its shape: wall, floor, sky and box
colours, painted wall cells, and markers on wall faces (ArUco and AprilTag fiducials, QR codes,
colour patches).

A marker hangs on one *face* of a wall cell: ``north`` (the face whose outward normal is +y),
``east`` (+x), ``south`` (-y) or ``west`` (-x); the cell's neighbour on that side must be free
floor. ``size_m`` is the side of the code itself (the black square of an ArUco/AprilTag marker,
the QR symbol without its quiet zone, or the whole patch); a white quiet zone is printed around
codes (1 module for ArUco/AprilTag, 2 for QR). Seen from the front, texture column 0 is on the
left and row 0 at the top. Textures are made once, at build time, with OpenCV (``cv2``, imported
only here and only when a scenario has codes).

Layouts follow docs/CONVENTIONS.md: ``row`` 0 is north, ``col`` 0 west; world x east, y north,
z up, metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from agvsim.world.grid import OccupancyGrid

RGB = tuple[int, int, int]


class Face(StrEnum):
    """A wall cell's face, named by the direction its outward normal points."""

    NORTH = "north"
    EAST = "east"
    SOUTH = "south"
    WEST = "west"

    @property
    def code(self) -> int:
        """0 north, 1 east, 2 south, 3 west (the renderer's face codes)."""
        return _FACE_ORDER.index(self)

    @property
    def normal(self) -> tuple[float, float]:
        return _NORMALS[self.code]


_FACE_ORDER = (Face.NORTH, Face.EAST, Face.SOUTH, Face.WEST)
_NORMALS = ((0.0, 1.0), (1.0, 0.0), (0.0, -1.0), (-1.0, 0.0))
_STEP = ((-1, 0), (0, 1), (1, 0), (0, -1))  # (d_row, d_col) to the neighbour a face looks at


class MarkerKind(StrEnum):
    ARUCO = "aruco"
    APRILTAG = "apriltag"
    QR = "qr"
    PATCH = "patch"


# OpenCV's predefined dictionaries by the names scenarios use
ARUCO_DICTIONARIES = {
    **{f"{n}x{n}_{k}": f"DICT_{n}X{n}_{k}" for n in (4, 5, 6, 7) for k in (50, 100, 250, 1000)},
    "original": "DICT_ARUCO_ORIGINAL",
    "mip_36h12": "DICT_ARUCO_MIP_36h12",
}
APRILTAG_FAMILIES = {f: f"DICT_APRILTAG_{f}" for f in ("16h5", "25h9", "36h10", "36h11")}
QUIET_MODULES = {MarkerKind.ARUCO: 1, MarkerKind.APRILTAG: 1, MarkerKind.QR: 2, MarkerKind.PATCH: 0}


@dataclass(frozen=True)
class MarkerSpec:
    """Where and what a marker is, as a scenario gives it (plain values, validated on placing).

    Place it by ``cell`` (row, col) of a wall cell, its centre ``offset_m`` along the face from
    the face's middle (to the right as seen from the front), or by a world point ``xy_m`` in or
    on the wall cell, whose position along the face is kept."""

    kind: MarkerKind
    face: Face
    size_m: float
    center_z_m: float
    cell: tuple[int, int] | None = None
    xy_m: tuple[float, float] | None = None
    offset_m: float = 0.0
    marker_id: int = 0
    dictionary: str = "4x4_50"  # ArUco dictionary, or AprilTag family for kind apriltag
    text: str = ""  # QR payload
    rgb: RGB = (255, 0, 0)  # patch colour
    name: str = ""  # label in ground truth; default from kind and id


@dataclass(frozen=True)
class Marker:
    """A placed marker: its frame on the wall and its texture."""

    name: str
    kind: MarkerKind
    marker_id: int
    dictionary: str
    text: str
    rgb: RGB
    face: Face
    center_xyz_m: tuple[float, float, float]  # centre of the code on the face, world frame
    size_m: float  # side of the code (without quiet zone)
    extent_m: float  # side of the printed square, quiet zone included
    texture: np.ndarray = field(repr=False)  # (h, w, 3) uint8, quiet zone included

    @property
    def normal_xy(self) -> tuple[float, float]:
        return self.face.normal

    @property
    def right_xy(self) -> tuple[float, float]:
        """Unit vector along the face to the right, as seen by someone facing the marker."""
        nx, ny = self.face.normal
        return (-ny, nx)

    def corners_world(self, quiet_zone: bool = False) -> np.ndarray:
        """(4, 3) corners of the code (or of the printed square) in the order OpenCV's ArUco
        detector reports them: top-left, top-right, bottom-right, bottom-left, seen from the
        front."""
        h = 0.5 * (self.extent_m if quiet_zone else self.size_m)
        cx, cy, cz = self.center_xyz_m
        rx, ry = self.right_xy
        out = np.empty((4, 3))
        for k, (a, b) in enumerate(((-1, 1), (1, 1), (1, -1), (-1, -1))):
            out[k] = (cx + a * h * rx, cy + a * h * ry, cz + b * h)
        return out


@dataclass(frozen=True)
class Paint:
    """Wall cells ``rows[0]..rows[1]`` x ``cols[0]..cols[1]`` (inclusive) in colour ``rgb``."""

    rows: tuple[int, int]
    cols: tuple[int, int]
    rgb: RGB


@dataclass(frozen=True)
class Appearance:
    """Colours (RGB 0..255) and markers of a world. ``shade_faces`` darkens east, south and west
    faces by a different amount each so corners stay visible; ``floor_checker`` tints every
    other floor cell slightly so that motion shows."""

    wall_rgb: RGB = (175, 175, 185)
    floor_rgb: RGB = (225, 225, 215)
    sky_rgb: RGB = (200, 220, 240)
    box_rgb: RGB = (170, 125, 80)
    shade_faces: bool = True
    floor_checker: bool = True
    paint: tuple[Paint, ...] = ()
    markers: tuple[Marker, ...] = ()

    def face_shades(self) -> np.ndarray:
        """(4,) brightness of north, east, south, west faces."""
        if not self.shade_faces:
            return np.ones(4)
        return np.array([1.0, 0.85, 0.7, 0.92])

    def cell_colors(self, grid: OccupancyGrid) -> np.ndarray:
        """Wall colour per cell, ``(ny * nx, 3)`` uint8 in the kernels' bottom-up order (row
        ``iy`` = 0 south), or ``(1, 3)`` when every wall has ``wall_rgb``."""
        if not self.paint:
            return np.array([self.wall_rgb], dtype=np.uint8)
        cols = np.empty((grid.rows, grid.cols, 3), dtype=np.uint8)
        cols[:] = self.wall_rgb
        for p in self.paint:
            r0, r1 = sorted(p.rows)
            c0, c1 = sorted(p.cols)
            cols[max(r0, 0) : r1 + 1, max(c0, 0) : c1 + 1] = p.rgb
        return np.ascontiguousarray(cols[::-1].reshape(-1, 3))

    def marker_tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The renderer's view of the markers: ``geom (M, 7)`` float64 rows ``face, line, lo,
        hi, z_lo, z_hi, u_from_hi`` (face code, the face's x or y line, the printed square's
        span along the face and in height, 1.0 where texture column 0 is at ``hi``),
        ``tex_index (M, 3)`` int64 ``offset, width, height`` into ``texels (T, 3)`` uint8."""
        m = len(self.markers)
        geom = np.zeros((m, 7))
        idx = np.zeros((m, 3), dtype=np.int64)
        texels = [np.zeros((0, 3), dtype=np.uint8)]
        off = 0
        for k, mk in enumerate(self.markers):
            f = mk.face.code
            cx, cy, cz = mk.center_xyz_m
            e = 0.5 * mk.extent_m
            along = cx if f in (0, 2) else cy
            line = cy if f in (0, 2) else cx
            rx, ry = mk.right_xy
            geom[k] = (f, line, along - e, along + e, cz - e, cz + e, 1.0 if rx + ry < 0 else 0.0)
            th, tw = mk.texture.shape[:2]
            idx[k] = (off, tw, th)
            texels.append(mk.texture.reshape(-1, 3))
            off += tw * th
        return geom, idx, np.ascontiguousarray(np.concatenate(texels))


# ---------------------------------------------------------------------------------- textures
def _cv2():
    try:
        import cv2
    except ImportError as err:  # pragma: no cover - a dependency of the package
        raise ValueError(
            "markers need OpenCV: pip install 'opencv-python-headless>=4.8,<5'"
        ) from err
    return cv2


def dictionary_size(kind: MarkerKind, dictionary: str) -> int:
    """How many ids an ArUco dictionary or AprilTag family holds."""
    cv2 = _cv2()
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, _cv2_dict_name(kind, dictionary)))
    return int(d.bytesList.shape[0])


def _cv2_dict_name(kind: MarkerKind, dictionary: str) -> str:
    table = APRILTAG_FAMILIES if kind == MarkerKind.APRILTAG else ARUCO_DICTIONARIES
    if dictionary not in table:
        what = "family" if kind == MarkerKind.APRILTAG else "dictionary"
        raise ValueError(
            f"{what}: {dictionary!r} is not one of OpenCV's (allowed: {', '.join(table)})"
        )
    return table[dictionary]


def aruco_dictionary(kind: MarkerKind | str, dictionary: str):
    """OpenCV's ``cv2.aruco.Dictionary`` for an ArUco dictionary or an AprilTag family name."""
    cv2 = _cv2()
    return cv2.aruco.getPredefinedDictionary(
        getattr(cv2.aruco, _cv2_dict_name(MarkerKind(kind), dictionary))
    )


def code_modules(spec: MarkerSpec) -> np.ndarray:
    """The code as a (n, n) uint8 image, one pixel per module (0 black, 255 white), without its
    quiet zone; a patch is one pixel. Raises ValueError for an id outside the dictionary or a
    text too long for a QR code."""
    if spec.kind == MarkerKind.PATCH:
        return np.full((1, 1), 255, dtype=np.uint8)
    cv2 = _cv2()
    if spec.kind == MarkerKind.QR:
        try:
            img = cv2.QRCodeEncoder.create().encode(spec.text)
        except cv2.error as err:
            raise ValueError(
                f"text: {spec.text!r} cannot be encoded as a QR code ({err})"
            ) from None
        dark = np.argwhere(img < 128)
        (r0, c0), (r1, c1) = dark.min(axis=0), dark.max(axis=0)
        return np.ascontiguousarray(img[r0 : r1 + 1, c0 : c1 + 1])
    d = aruco_dictionary(spec.kind, spec.dictionary)
    n = int(d.bytesList.shape[0])
    if not 0 <= spec.marker_id < n:
        raise ValueError(
            f"id: {spec.marker_id} is not in {spec.kind.value} {spec.dictionary!r} "
            f"(allowed: 0..{n - 1})"
        )
    side = int(d.markerSize) + 2
    return np.asarray(cv2.aruco.generateImageMarker(d, spec.marker_id, side, borderBits=1))


def marker_texture(spec: MarkerSpec) -> tuple[np.ndarray, int, int]:
    """(texture (h, w, 3) uint8 with the white quiet zone, code modules, quiet modules)."""
    code = code_modules(spec)
    q = QUIET_MODULES[spec.kind]
    n = code.shape[0]
    grey = np.pad(code, q, constant_values=255)
    tex = np.repeat(grey[:, :, None], 3, axis=2)
    if spec.kind == MarkerKind.PATCH:
        tex[:] = spec.rgb
    return np.ascontiguousarray(tex), n, q


# ---------------------------------------------------------------------------------- placing
def default_name(spec: MarkerSpec, k: int) -> str:
    if spec.name:
        return spec.name
    if spec.kind in (MarkerKind.ARUCO, MarkerKind.APRILTAG):
        return f"{spec.kind.value}:{spec.marker_id}"
    if spec.kind == MarkerKind.QR:
        return f"qr:{spec.text}"
    return f"patch{k}"


def _open_face(grid: OccupancyGrid, row: int, col: int, face: Face) -> str | None:
    """Why the face of cell (row, col) cannot hold a marker, or None."""
    if not (0 <= row < grid.rows and 0 <= col < grid.cols):
        return f"cell ({row}, {col}) is outside the map ({grid.rows} rows x {grid.cols} cols)"
    if not grid.occupied[row, col]:
        return f"cell ({row}, {col}) is free floor, not a wall"
    dr, dc = _STEP[face.code]
    r, c = row + dr, col + dc
    if not (0 <= r < grid.rows and 0 <= c < grid.cols):
        return f"the {face.value} face of cell ({row}, {col}) is on the map's edge"
    if grid.occupied[r, c]:
        return f"the {face.value} face of cell ({row}, {col}) touches the wall cell ({r}, {c})"
    return None


def place_marker(spec: MarkerSpec, grid: OccupancyGrid, wall_height_m: float, k: int = 0) -> Marker:
    """Put ``spec`` on its wall face. Raises ValueError naming the field at fault (``cell``,
    ``x_m``, ``size_m``, ``center_z_m``, ``id``, ``text``) and the allowed values."""
    res = grid.resolution_m
    ox, oy = grid.origin_xy_m
    f = spec.face
    nx_, ny_ = f.normal
    if spec.cell is not None:
        row, col = spec.cell
        where = "cell"
    elif spec.xy_m is not None:
        x, y = spec.xy_m
        # the wall is behind the face: nudge the point against the normal
        rr, cc = grid.cell_of(x - 1e-9 * res * nx_, y - 1e-9 * res * ny_)
        row, col = int(rr), int(cc)
        where = "x_m, y_m"
    else:
        raise ValueError("give the marker's 'cell' [row, col] or its 'x_m' and 'y_m'")
    why = _open_face(grid, row, col, f)
    if why is not None:
        at = f" ({spec.xy_m[0]:g}, {spec.xy_m[1]:g})" if spec.xy_m is not None else ""
        raise ValueError(f"{where}{at}: {why}; a marker needs a wall cell with free floor {f}")
    cx, cy = (float(v) for v in grid.cell_center(row, col))
    rx, ry = -ny_, nx_  # to the right, seen from the front
    # centre on the face line; along the face: the cell's middle + offset, or the given point
    line_x, line_y = cx + 0.5 * res * nx_, cy + 0.5 * res * ny_
    if spec.xy_m is not None and spec.cell is None:
        mx = spec.xy_m[0] if abs(rx) > 0 else line_x
        my = spec.xy_m[1] if abs(ry) > 0 else line_y
        mx, my = mx + spec.offset_m * rx, my + spec.offset_m * ry
    else:
        mx, my = line_x + spec.offset_m * rx, line_y + spec.offset_m * ry
    tex, n, q = marker_texture(spec)
    extent = spec.size_m * (n + 2 * q) / n
    e = 0.5 * extent
    z = spec.center_z_m
    if extent > wall_height_m:
        n_all = (n + 2 * q) / n
        raise ValueError(
            f"size_m: {spec.size_m:g} m makes a printed square of {extent:.3g} m with its quiet "
            f"zone, taller than the wall ({wall_height_m:g} m); allowed: size_m <= "
            f"{wall_height_m / n_all:.3g}"
        )
    if z - e < 0.0 or z + e > wall_height_m:
        raise ValueError(
            f"center_z_m: {z:g} m puts the printed square ({extent:.3g} m with its quiet zone) "
            f"outside the wall's height 0..{wall_height_m:g} m; allowed: {e:.3g}.."
            f"{wall_height_m - e:.3g} m (or a smaller size_m)"
        )
    # every cell the printed square spans along the face must be a wall with this face open
    a = mx * abs(rx) + my * abs(ry)
    o = ox if abs(rx) > 0 else oy
    tol = 1e-9 * res
    first = int(np.floor((a - e + tol - o) / res))
    last = int(np.floor((a + e - tol - o) / res))
    for j in range(first, last + 1):
        if abs(rx) > 0:  # north / south face: cells along a row
            r, c = row, j
        else:  # east / west: cells along a column (row 0 is north)
            r, c = grid.rows - 1 - j, col
        why = _open_face(grid, r, c, f)
        if why is not None:
            raise ValueError(
                f"size_m: the printed square ({extent:.3g} m wide) overhangs its wall face: "
                f"{why}; make it smaller or move it (offset_m)"
            )
    return Marker(
        name=default_name(spec, k),
        kind=spec.kind,
        marker_id=spec.marker_id,
        dictionary=spec.dictionary,
        text=spec.text,
        rgb=spec.rgb,
        face=f,
        center_xyz_m=(float(mx), float(my), float(z)),
        size_m=float(spec.size_m),
        extent_m=float(extent),
        texture=tex,
    )


def place_markers(
    specs: Sequence[MarkerSpec], grid: OccupancyGrid, wall_height_m: float
) -> tuple[Marker, ...]:
    """Place every marker; a ValueError message starts with ``markers[k].`` and the field."""
    out = []
    for k, s in enumerate(specs):
        try:
            out.append(place_marker(s, grid, wall_height_m, k))
        except ValueError as err:
            raise ValueError(f"markers[{k}].{err}") from None
    names = [m.name for m in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"markers: names must be unique (set 'name'); repeated: {dup}")
    return tuple(out)
