"""Coarse fields and the coarse-to-fine global relocalisation search (agvsim.slam.relocalise)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_scan_matching import RES, WALLS, cast, points, room_field

from agvsim.slam import scan_matching as sm
from agvsim.slam.frontend import Submap
from agvsim.slam.mapping import coarse_field
from agvsim.slam.relocalise import coarse_pyramid, covering, global_search
from agvsim.slam.se2 import between


def test_coarse_field_by_hand() -> None:
    # 6 x 5 field, factor 2: blocks (3 x 3 of them, the last row and column half outside)
    f = np.zeros((6, 5), np.float32)
    f[0, 1] = 0.25  # block (0, 0)
    f[3, 0] = 0.125  # block (1, 0)
    f[5, 4] = 0.5  # block (2, 2), the last column's block half outside the field
    f[4, 2] = 0.0625  # block (2, 1)
    f[5, 3] = 0.375  # block (2, 1): its maximum
    c = coarse_field(f, 2)
    assert c.shape == (3, 3) and c.dtype == np.uint8
    # block maxima as 255 v rounded up: 63.75 -> 64, 31.875 -> 32, 127.5 -> 128, 95.625 -> 96
    expect = np.array([[64, 0, 0], [32, 0, 0], [0, 96, 128]], np.uint8)
    np.testing.assert_array_equal(c, expect)
    with pytest.raises(ValueError, match="factor"):
        coarse_field(f, 0)


def _cell_score(grid: np.ndarray, res: float, pts: np.ndarray, pose: np.ndarray) -> float:
    """Mean of the cells the points fall in (0 outside): the score branch and bound uses."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    x = pose[0] + c * pts[:, 0] - s * pts[:, 1]
    y = pose[1] + s * pts[:, 0] + c * pts[:, 1]
    ix, iy = np.floor(x / res).astype(int), np.floor(y / res).astype(int)
    ok = (ix >= 0) & (iy >= 0) & (ix < grid.shape[1]) & (iy < grid.shape[0])
    inside = grid[iy.clip(0, grid.shape[0] - 1), ix.clip(0, grid.shape[1] - 1)]
    return float(np.where(ok, inside, 0.0).mean())


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), factor=st.integers(1, 6))
def test_coarse_score_bounds_the_fine_score_at_the_same_pose(seed: int, factor: int) -> None:
    """Each point's fine cell lies in its coarse block, so the coarse score at a pose is at
    least the fine score there (up to the rounding up to 1/255), and equal for factor 1."""
    rng = np.random.default_rng(seed)
    grid = (rng.random((60, 70)) ** 6).astype(np.float32)
    coarse = coarse_field(grid, factor).astype(np.float64) / 255.0
    r, a = rng.uniform(0.1, 1.5, 30), rng.uniform(-math.pi, math.pi, 30)
    pts = np.column_stack([r * np.cos(a), r * np.sin(a)])
    pose = np.array([rng.uniform(0.0, 3.5), rng.uniform(0.0, 3.0), rng.uniform(-3.0, 3.0)])
    fine_score = _cell_score(grid, RES, pts, pose)
    coarse_score = _cell_score(coarse, factor * RES, pts, pose)
    assert fine_score <= coarse_score + 1e-9
    if factor == 1:
        assert coarse_score == pytest.approx(fine_score, abs=1 / 255)


def _submap(index: int, walls: np.ndarray, factor: int = 4) -> Submap:
    field, ox, oy = room_field(walls)
    empty = np.zeros((0, 0), np.float32)
    s = Submap(index, np.zeros(3), ox, oy, empty, field, empty, [0], True)
    s.coarse, s.coarse_factor = coarse_field(field, factor), factor
    return s


def test_global_search_finds_the_scan_in_the_right_submap() -> None:
    """A scan of the room is found among the room and a look-alike with the pillar and the
    cupboard moved, at the pose it was taken from, and refines to the score that the
    exhaustive search over the room's full pyramid refines to."""
    other = WALLS.copy()
    other[4:8] += [3.0, 1.0, 3.0, 1.0]  # the pillar
    other[8:10, [0, 2]] -= 5.0  # the cupboard
    submaps = [_submap(0, other), _submap(1, WALLS)]
    true = np.array([2.2, 1.7, math.radians(35.0)])
    pts = points(cast(true))[::2]
    pyramids = {s.index: sm.max_pyramid(s.likelihood, 6) for s in submaps}
    found = global_search(submaps, pts, RES, 9.0, 0.3, lambda s: pyramids[s.index])
    assert found is not None and found.submap == 1
    d = between(true, found.pose)
    assert math.hypot(d[0], d[1]) < 2 * RES and abs(d[2]) < math.radians(2.0)
    assert found.bound >= found.score
    s = submaps[1]
    h, w = s.likelihood.shape
    step = 2.0 * sm.angular_step(RES, 9.0)
    centre = np.array([s.ox + 0.5 * w * RES, s.oy + 0.5 * h * RES, 0.0])
    exact, _ = sm.branch_and_bound(
        pyramids[1], s.ox, s.oy, RES, pts, centre, 0.5 * max(h, w) * RES, math.pi, step, 0.3
    )
    # on different angle grids: compared once both are refined (as GraphSlam.relocalise does)
    refined = [
        sm.gauss_newton(s.likelihood, s.ox, s.oy, RES, pts, p, 15, 0.0)[1]
        for p in (found.pose, exact)
    ]
    assert refined[0] == pytest.approx(refined[1], abs=0.005)


def test_global_search_without_coarse_fields_or_points_finds_nothing() -> None:
    s = _submap(0, WALLS)
    pts = points(cast(np.array([2.0, 2.0, 0.0])))
    s.coarse = None
    assert global_search([s], pts, RES, 9.0, 0.3, lambda _: None) is None  # type: ignore[arg-type,return-value]
    assert global_search([_submap(0, WALLS)], pts[:0], RES, 9.0, 0.3, lambda _: None) is None  # type: ignore[arg-type,return-value]


def test_coarse_pyramid_levels_are_block_maxima_of_the_coarse_field() -> None:
    c = coarse_field(room_field()[0], 4)
    pyr = coarse_pyramid(c)
    np.testing.assert_array_equal(pyr[0], c.astype(np.float32) / np.float32(255.0))
    assert pyr[3, 10, 12] == pyr[0, 10:18, 12:20].max()


def test_covering_keeps_every_keyframe_in_about_half_the_submaps() -> None:
    # the tracker's pattern: 40 keyframes a submap, a new one every 20, plus one cut short
    # by a relocalisation (keyframes 100-109) and one without a coarse field
    spans = [(0, 40), (20, 60), (40, 80), (60, 100), (80, 110), (100, 110), (110, 150)]
    subs = []
    for k, (a, b) in enumerate(spans):
        s = _submap(k, WALLS)
        s.nodes = list(range(a, b))
        subs.append(s)
    subs[-1].coarse = None
    kept = covering(subs)
    assert [s.index for s in kept] == [0, 2, 4]
    assert set().union(*(s.nodes for s in kept)) == set(range(110))
