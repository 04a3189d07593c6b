"""Ray casting against walls and boxes, checked against hand-worked distances and against an
independent slow reference: intersect the beam with every edge of every occupied cell (and of
every box) as closed segments and keep the nearest."""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.sensors.raycast import RayCaster, cast_rays, warmup
from agvsim.world.grid import OccupancyGrid

TOL = 1e-9


# ---------------------------------------------------------------------------- reference
def _unit(angle: float) -> tuple[float, float]:
    c, s = math.cos(angle), math.sin(angle)
    if abs(c) < 1e-12:  # the kernel's snapping: beams at multiples of pi/2 are axis-parallel
        return 0.0, math.copysign(1.0, s)
    if abs(s) < 1e-12:
        return math.copysign(1.0, c), 0.0
    return c, s


def _ray_segments(x0, y0, c, s, ax, ay, bx, by, tol=1e-10) -> float:
    """Nearest t >= 0 where the ray meets any closed segment (ax, ay)-(bx, by) (arrays)."""
    ex, ey = bx - ax, by - ay
    den = c * ey - s * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((ax - x0) * ey - (ay - y0) * ex) / den
        u = ((ax - x0) * s - (ay - y0) * c) / den
    ok = (den != 0) & (t >= 0) & (u >= -tol) & (u <= 1 + tol)
    return float(t[ok].min()) if ok.any() else math.inf


def ref_walls(grid: OccupancyGrid, x0: float, y0: float, angle: float, r_max: float) -> float:
    res = grid.resolution_m
    ox, oy = grid.origin_xy_m
    iy, ix = np.nonzero(grid.cells_bu)
    x_lo, x_hi = ox + ix * res, ox + (ix + 1) * res
    y_lo, y_hi = oy + iy * res, oy + (iy + 1) * res
    tol = 1e-10  # the kernel counts a beam passing within ~1e-11 m of a wall as touching it
    if np.any((x_lo - tol <= x0) & (x0 <= x_hi + tol) & (y_lo - tol <= y0) & (y0 <= y_hi + tol)):
        return 0.0
    # only cells on the boundary of the walls can be touched first: keep their edges
    occ = np.pad(grid.cells_bu != 0, 1)
    inner = occ[:-2, 1:-1] & occ[2:, 1:-1] & occ[1:-1, :-2] & occ[1:-1, 2:]
    edge = ~inner[iy, ix]
    x_lo, x_hi, y_lo, y_hi = x_lo[edge], x_hi[edge], y_lo[edge], y_hi[edge]
    c, s = _unit(angle)
    ax = np.concatenate([x_lo, x_hi, x_lo, x_lo])
    ay = np.concatenate([y_lo, y_lo, y_lo, y_hi])
    bx = np.concatenate([x_lo, x_hi, x_hi, x_hi])
    by = np.concatenate([y_hi, y_hi, y_lo, y_hi])
    t = _ray_segments(x0, y0, c, s, ax, ay, bx, by)
    return t if t <= r_max else math.inf


def ref_boxes(boxes, x0, y0, angle, r_max, skip=-1) -> float:
    boxes = np.delete(np.asarray(boxes, dtype=float), skip, axis=0) if skip >= 0 else boxes
    if len(boxes) == 0:
        return math.inf
    cx, cy, th, hl, hw = boxes.T
    u = np.stack([np.cos(th), np.sin(th)], -1)
    v = np.stack([-u[:, 1], u[:, 0]], -1)
    d = np.array([x0, y0]) - boxes[:, :2]
    if np.any((np.abs(np.sum(d * u, 1)) <= hl) & (np.abs(np.sum(d * v, 1)) <= hw)):
        return 0.0  # inside a box
    corners = [
        boxes[:, :2] + sx * hl[:, None] * u + sy * hw[:, None] * v
        for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))
    ]
    p = np.concatenate(corners)
    q = np.concatenate(corners[1:] + corners[:1])
    c, s = math.cos(angle), math.sin(angle)
    best = _ray_segments(x0, y0, c, s, p[:, 0], p[:, 1], q[:, 0], q[:, 1], 0.0)
    return best if best <= r_max else math.inf


# ---------------------------------------------------------------------------- worlds
def maze(cell_m: float) -> OccupancyGrid:
    """20 m maze (border and interior walls drawn on 1 m cells) at ``cell_m`` resolution."""
    m = np.zeros((20, 20), dtype=bool)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = True
    m[4, 2:12] = m[8, 5:13] = m[12, 9:18] = True
    m[4:12, 15] = m[12:18, 5] = m[15:19, 12] = True
    m[16, 2] = m[10, 3] = True
    k = round(1.0 / cell_m)
    return OccupancyGrid.from_matrix(np.kron(m, np.ones((k, k), dtype=bool)), cell_m)


def empty(n: int = 10) -> OccupancyGrid:
    """n x n free 1 m cells, lower-left corner at the world origin."""
    return OccupancyGrid(np.zeros((n, n), dtype=bool), 1.0, (0.0, 0.0))


def with_walls(grid: OccupancyGrid, cells_xy: list[tuple[int, int]]) -> OccupancyGrid:
    """Occupy the cells given as (ix, iy), iy counted from the south edge."""
    occ = grid.occupied.copy()
    for ix, iy in cells_xy:
        occ[grid.rows - 1 - iy, ix] = True
    return OccupancyGrid(occ, grid.resolution_m, grid.origin_xy_m)


def free_points(grid: OccupancyGrid, n: int, rng: np.random.Generator) -> np.ndarray:
    xmin, xmax, ymin, ymax = grid.extent_m
    p = np.column_stack([rng.uniform(xmin, xmax, 8 * n), rng.uniform(ymin, ymax, 8 * n)])
    return p[~grid.is_occupied_at(p[:, 0], p[:, 1])][:n]


# ---------------------------------------------------------------------------- walls
@pytest.mark.parametrize("cell_m", [1.0, 0.05])
def test_walls_match_reference_on_maze(cell_m):
    grid = maze(cell_m)
    rng = np.random.default_rng(7)
    pts = free_points(grid, 30, rng)
    ang = rng.uniform(-np.pi, np.pi, (30, 6))
    r_max = rng.uniform(0.5, 25.0, 30)
    got = RayCaster(grid).cast(pts, ang, r_max)
    for i in range(30):
        for k in range(6):
            want = ref_walls(grid, *pts[i], ang[i, k], r_max[i])
            assert got[i, k] == pytest.approx(want, abs=TOL), (pts[i], ang[i, k])


def test_walls_match_reference_from_vertices_faces_and_outside():
    """Origins on cell vertices and faces, on the map border and off the map; beams along the
    axes and the diagonals, where the DDA's tie handling matters."""
    rng = np.random.default_rng(3)
    occ = rng.random((12, 12)) < 0.2
    grid = OccupancyGrid(occ, 0.5, (-2.0, 1.0))
    caster = RayCaster(grid)
    ang = np.array([0, 0.5, 1, 1.5, 2, -0.5, -1, -1.5, 1 / 3, -2 / 3]) * np.pi
    ang = np.append(ang, [math.atan2(1, 2), math.atan2(-2, 1)])
    for _ in range(150):
        x = -2.0 + rng.integers(-3, 28) * 0.25
        y = 1.0 + rng.integers(-3, 28) * 0.25
        got = caster.cast_single(x, y, ang, 9.0)
        want = [ref_walls(grid, x, y, a, 9.0) for a in ang]
        np.testing.assert_allclose(got, want, atol=TOL, rtol=0, err_msg=f"origin {(x, y)}")


def test_hand_worked_wall_west_face_and_max_range():
    grid = with_walls(empty(), [(5, 0)])  # wall cell x in [5, 6], y in [0, 1]
    caster = RayCaster(grid)
    assert caster.cast_single(0.5, 0.5, [0.0], 10.0)[0] == 4.5  # exactly its west face
    assert caster.cast_single(0.5, 0.5, [0.0], 4.5)[0] == 4.5  # a hit at max range counts
    assert caster.cast_single(0.5, 0.5, [0.0], 4.4999)[0] == math.inf
    assert caster.cast_single(9.5, 0.5, [math.pi], 10.0)[0] == 3.5  # its east face
    # 3-4-5 triangle: from (2, 0.25) towards (5, 0.25 + 3 * 0.25) hits x = 5 at y = 1.0,
    # the wall's north-west corner (closed cells: touching counts)
    a = math.atan2(0.75, 3.0)
    got = caster.cast_single(2.0, 0.25, [a], 10.0)[0]
    assert got == pytest.approx(math.hypot(3, 0.75), abs=TOL)


def test_axis_parallel_beams_and_grazing_a_face():
    grid = with_walls(empty(), [(7, 3), (2, 3), (4, 8), (4, 0)])
    caster = RayCaster(grid)
    got = caster.cast_single(4.5, 3.5, [0.0, np.pi / 2, np.pi, -np.pi / 2, 2 * np.pi], 20.0)
    np.testing.assert_array_equal(got, [2.5, 4.5, 1.5, 2.5, 2.5])
    # the beam runs along the line y = 4, the top face of row 3: it grazes the wall cell (7, 3)
    # at its corner (7, 4) and stops there; one along y = 4.5 passes free
    assert caster.cast_single(4.5, 4.0, [0.0], 20.0)[0] == 2.5
    assert caster.cast_single(4.5, 4.5, [0.0], 20.0)[0] == math.inf
    # along x = 5 (east face of column 4): grazes (4, 8) at y = 8
    assert caster.cast_single(5.0, 5.5, [np.pi / 2], 20.0)[0] == 2.5


def test_origin_on_cell_boundaries():
    grid = with_walls(empty(), [(7, 3), (2, 3)])
    caster = RayCaster(grid)
    # on the vertical face x = 5 and on the vertex (5, 3): distances still exact
    np.testing.assert_array_equal(caster.cast_single(5.0, 3.5, [0.0, np.pi], 20.0), [2.0, 2.0])
    assert caster.cast_single(5.0, 3.0, [0.0], 20.0)[0] == 2.0  # grazes (7, 3) at its corner
    # on the wall's own face: touching a wall cell reads 0 on every beam
    np.testing.assert_array_equal(caster.cast_single(7.0, 3.5, [0.0, np.pi, 1.0], 5.0), 0.0)
    np.testing.assert_array_equal(caster.cast_single(7.5, 3.5, [0.0, 2.0], 5.0), 0.0)  # inside


@pytest.mark.parametrize("side", [-1.0, 1.0])
@pytest.mark.parametrize("drift", [-1.86e-12, 1.86e-12])
def test_origin_a_hair_off_a_face_with_a_beam_a_hair_off_along_it(side, drift):
    """A 40 m x 40 m room of 5 cm cells, walls one cell thick. An origin 3e-11 m beside the
    face x = 1 (within the corner tolerance, so taken as on it) casts a beam a hair off due
    north and south, and one beside the face y = 1 a beam a hair off due east: the walls are
    15.45, 24.45 and 38.95 m away whichever way the beams drift. Before the fix a beam that
    started a hair before the face and drifted across it read the distance to where it
    crossed (16.1 m north): past the wall and out of the map. A simulated scanner driven
    exactly along x = 50 in a warehouse put its centre beam's returns 2 to 10 m outside the
    walls."""
    cells = np.zeros((800, 800), dtype=bool)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = True
    caster = RayCaster(OccupancyGrid(cells, 0.05, (0.0, 0.0)))
    near = 1.0 + side * 3e-11
    north = caster.cast_single(near, 24.5, [math.pi / 2 + drift], 30.0)[0]
    south = caster.cast_single(near, 24.5, [-math.pi / 2 + drift], 30.0)[0]
    east = caster.cast_single(1.0, near, [drift], 40.0)[0]
    assert north == pytest.approx(39.95 - 24.5, abs=1e-9)
    assert south == pytest.approx(24.5 - 0.05, abs=1e-9)
    assert east == pytest.approx(39.95 - 1.0, abs=1e-9)


def test_diagonal_through_corner_of_two_walls_is_a_hit():
    # walls (3, 2) and (2, 3) share the corner (3, 3); the free cells (2, 2) and (3, 3) meet there
    grid = with_walls(empty(), [(3, 2), (2, 3)])
    caster = RayCaster(grid)
    d = math.hypot(0.5, 0.5)
    for a in (math.pi / 4, math.atan2(1.0, 1.0 + 1e-15), math.atan2(1.0 + 1e-15, 1.0)):
        assert caster.cast_single(2.5, 2.5, [a], 10.0)[0] == pytest.approx(d, abs=TOL)
    # and back through the same corner from the other side
    assert caster.cast_single(3.5, 3.5, [-3 * math.pi / 4], 10.0)[0] == pytest.approx(d, abs=TOL)
    # a single wall's corner on the diagonal is touched as well
    grid1 = with_walls(empty(), [(3, 2)])
    assert RayCaster(grid1).cast_single(2.5, 2.5, [math.pi / 4], 10.0)[0] == pytest.approx(d)


def test_no_return_reads_inf_and_map_border_is_open():
    caster = RayCaster(empty())
    got = caster.cast_single(5.0, 5.0, np.linspace(-np.pi, np.pi, 16, endpoint=False), 30.0)
    assert np.all(got == math.inf)
    # from off the map: the wall is seen, and nothing beyond the map border
    grid = with_walls(empty(), [(0, 5)])
    caster = RayCaster(grid)
    assert caster.cast_single(-3.0, 5.5, [0.0], 10.0)[0] == 3.0
    assert caster.cast_single(-3.0, 5.5, [np.pi], 10.0)[0] == math.inf
    assert caster.cast_single(-3.0, 5.5, [0.0], 2.9)[0] == math.inf


def test_nan_padding_reads_inf():
    caster = RayCaster(with_walls(empty(), [(5, 0)]))
    got = caster.cast(
        np.array([[0.5, 0.5], [0.5, 0.5]]),
        np.array([[0.0, np.nan, np.nan], [0.0, np.pi / 2, np.nan]]),
        20.0,
    )
    np.testing.assert_array_equal(got, [[4.5, np.inf, np.inf], [4.5, np.inf, np.inf]])


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-12, 12),
    y=st.floats(-12, 12),
    theta=st.floats(-10, 10),
    r_max=st.floats(0.01, 40),
    beams=st.integers(1, 40),
)
def test_ranges_never_exceed_max_range(x, y, theta, r_max, beams):
    caster = _maze_caster()
    ang = theta + np.linspace(0, 2 * np.pi, beams, endpoint=False)
    got = caster.cast_single(x, y, ang, r_max)
    assert np.all((got >= 0) & ((got <= r_max) | (got == np.inf)))
    k = int(np.argmin(got))
    assert got[k] == pytest.approx(ref_walls(caster.grid, x, y, ang[k], r_max), abs=TOL)


@functools.cache
def _maze_caster() -> RayCaster:
    return RayCaster(maze(1.0))


@pytest.mark.slow
def test_empty_space_skipping_gives_identical_results():
    rng = np.random.default_rng(11)
    occ = np.kron(rng.random((16, 16)) < 0.12, np.ones((12, 12), dtype=bool))
    occ |= rng.random(occ.shape) < 0.002  # scattered single cells
    grid = OccupancyGrid(occ, 0.05, (-3.0, 2.0))
    pts = np.vstack([free_points(grid, 200, rng), rng.uniform(-5, 10, (20, 2))])
    ang = rng.uniform(-4, 4, (len(pts), 1)) + np.linspace(0, 2 * np.pi, 90, endpoint=False)
    fast = RayCaster(grid).cast(pts, ang, 12.0)
    plain = RayCaster(grid, skip_empty=False).cast(pts, ang, 12.0)
    np.testing.assert_array_equal(fast, plain)
    assert np.isfinite(fast).mean() > 0.5


# ---------------------------------------------------------------------------- boxes
def test_box_occludes_with_hand_worked_distances():
    caster = RayCaster(empty())
    box = np.array([[4.0, 5.0, 0.0, 0.5, 0.25]])  # x in [3.5, 4.5], y in [4.75, 5.25]
    got = caster.cast_single(1.0, 5.0, [0.0, math.atan2(0.25, 2.5), 0.2], 10.0, boxes=box)
    assert got[0] == 2.5
    assert got[1] == pytest.approx(math.hypot(2.5, 0.25), abs=TOL)  # its north-west corner
    assert got[2] == math.inf
    # a unit square turned 45 deg: its west vertex is at x = 4 - sqrt(1/2)
    diamond = np.array([[4.0, 5.0, math.pi / 4, 0.5, 0.5]])
    got = caster.cast_single(1.0, 5.0, [0.0], 10.0, boxes=diamond)[0]
    assert got == pytest.approx(3.0 - math.sqrt(0.5), abs=TOL)
    # its south-west face lies on x + y = 9 - sqrt(1/2); a 45 deg beam from (1, 2.5) meets it
    # head-on where 3.5 + sqrt(2) t = 9 - sqrt(1/2)
    got = caster.cast_single(1.0, 2.5, [math.pi / 4], 10.0, boxes=diamond)[0]
    assert got == pytest.approx((5.5 - math.sqrt(0.5)) / math.sqrt(2), abs=TOL)
    assert got == pytest.approx(ref_boxes(diamond, 1.0, 2.5, math.pi / 4, 10.0), abs=TOL)


def test_sensor_ignores_its_own_box_and_robots_occlude_each_other():
    grid = with_walls(empty(), [(9, 5)])
    caster = RayCaster(grid)
    boxes = np.array([[2.0, 5.5, 0.0, 0.4, 0.3], [6.0, 5.5, math.pi, 0.4, 0.3]])
    origins = np.array([[2.3, 5.5], [5.7, 5.5]])  # each sensor inside its own footprint
    ang = np.array([[0.0, math.pi], [math.pi, 0.0]])
    got = caster.cast(origins, ang, 10.0, boxes, np.array([0, 1]))
    # A looks forward at B's rear face x = 5.6 and back at the open map; B looks back at A's
    # front face x = 2.4 and forward at the wall's west face x = 9
    np.testing.assert_allclose(got, [[5.6 - 2.3, np.inf], [5.7 - 2.4, 9.0 - 5.7]], atol=TOL)
    # without ignoring its own box a sensor inside it reads 0
    np.testing.assert_array_equal(caster.cast(origins, ang, 10.0, boxes), 0.0)


def _random_scene(rng, n_boxes, size):
    grid = OccupancyGrid(np.zeros((4, 4), dtype=bool), size / 4, (0.0, 0.0))
    boxes = np.column_stack(
        [
            rng.uniform(0, size, n_boxes),
            rng.uniform(0, size, n_boxes),
            rng.uniform(-np.pi, np.pi, n_boxes),
            rng.uniform(0.1, 0.6, n_boxes),
            rng.uniform(0.1, 0.4, n_boxes),
        ]
    )
    return grid, boxes


def test_box_broad_phase_matches_brute_force_reference():
    rng = np.random.default_rng(5)
    grid, boxes = _random_scene(rng, 150, 60.0)
    s = 40
    origins = boxes[:s, :2] + rng.normal(0, 0.05, (s, 2))
    start = rng.uniform(-7, 7, (s, 1))
    step = np.where(rng.random((s, 1)) < 0.5, 1.0, -1.0) * 2 * np.pi / 64
    ang = start + step * np.arange(64)  # evenly spaced, some clockwise, unwrapped
    ang[::4] = (ang[::4] + np.pi) % (2 * np.pi) - np.pi  # some wrapped into [-pi, pi)
    ang[1, 4:] = np.nan  # a 4-beam sensor
    ang[2] = rng.uniform(-np.pi, np.pi, 64)  # uneven beams
    r_max = rng.uniform(2.0, 9.0, s)
    own = np.arange(s)
    got = RayCaster(grid).cast(origins, ang, r_max, boxes, own)
    n_finite = 0
    for i in range(s):
        for k in range(64):
            if np.isnan(ang[i, k]):
                assert got[i, k] == math.inf
                continue
            want = min(
                ref_boxes(boxes, *origins[i], ang[i, k], r_max[i], skip=i),
                ref_walls(grid, *origins[i], ang[i, k], r_max[i]),
            )
            assert got[i, k] == pytest.approx(want, abs=TOL), (i, k)
            n_finite += math.isfinite(want)
    assert n_finite > 100


@pytest.mark.slow
def test_many_robots_threads_and_kernel_function_agree():
    rng = np.random.default_rng(9)
    grid = maze(0.5)
    pts = free_points(grid, 300, rng)
    boxes = np.column_stack([pts, rng.uniform(-3, 3, 300), np.full(300, 0.3), np.full(300, 0.2)])
    ang = rng.uniform(-3, 3, (300, 1)) + np.linspace(0, 2 * np.pi, 48, endpoint=False)
    own = np.arange(300)
    caster = RayCaster(grid)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = caster.cast(pts, ang, 6.0, boxes, own)
    finally:
        numba.set_num_threads(before)
    many = caster.cast(pts, ang, 6.0, boxes, own)
    np.testing.assert_array_equal(one, many)
    out = np.empty_like(one)
    cast_rays(
        grid.cells_bu,
        grid.resolution_m,
        *grid.origin_xy_m,
        pts,
        ang,
        np.full(300, 6.0),
        boxes,
        own,
        out,
    )
    np.testing.assert_array_equal(out, one)
    # spot-check against the references
    for i, k in zip(rng.integers(0, 300, 40), rng.integers(0, 48, 40), strict=True):
        want = min(
            ref_walls(grid, *pts[i], ang[i, k], 6.0),
            ref_boxes(boxes, *pts[i], ang[i, k], 6.0, skip=i),
        )
        assert one[i, k] == pytest.approx(want, abs=TOL)


# ---------------------------------------------------------------------------- wrapper
def test_wrapper_validates_shapes_and_values():
    caster = RayCaster(empty())
    org, ang = np.zeros((2, 2)) + 5, np.zeros((2, 3))
    with pytest.raises(ValueError, match="origins"):
        caster.cast(np.zeros((2, 3)), ang, 1.0)
    with pytest.raises(ValueError, match="beam_angles"):
        caster.cast(org, np.zeros((3, 3)), 1.0)
    with pytest.raises(ValueError, match="max_range"):
        caster.cast(org, ang, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="max_range"):
        caster.cast(org, ang, -1.0)
    with pytest.raises(ValueError, match="boxes"):
        caster.cast(org, ang, 1.0, np.zeros((2, 4)))
    with pytest.raises(ValueError, match="ignore_box"):
        caster.cast(org, ang, 1.0, np.zeros((2, 5)), np.array([0, 2]))
    with pytest.raises(ValueError, match="finite"):
        caster.cast(np.array([[np.nan, 0.0], [0.0, 0.0]]), ang, 1.0)
    assert caster.cast(np.zeros((0, 2)), np.zeros((0, 5)), 1.0).shape == (0, 5)


def test_set_grid_and_warmup():
    caster = RayCaster(empty())
    assert caster.cast_single(0.5, 0.5, [0.0], 20.0)[0] == math.inf
    caster.set_grid(with_walls(empty(), [(3, 0)]))
    assert caster.cast_single(0.5, 0.5, [0.0], 20.0)[0] == 2.5
    assert warmup() >= 0.0
