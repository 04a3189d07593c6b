"""Map pictures are computed in log-odds (no float64 grid for a large map) and agree with the
probability definition p = 1 - 1 / (1 + exp(l)) cell for cell."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np

from agvsim.slam.mapping import OccupancyMap, save_map_png


def test_picture_and_png_match_the_probability_thresholds(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    # log-odds as the renderer makes them (sums of +-0.4), over more rows than one band
    grid = OccupancyMap((rng.integers(-10, 11, (1300, 70)) * 0.4).astype(np.float32), 0.05, (0, 0))
    p = grid.probability[::-1]
    trinary = np.full(p.shape, 205, np.uint8)
    trinary[p < 0.196] = 254
    trinary[p > 0.65] = 0
    np.testing.assert_array_equal(grid.picture(), trinary)
    shade = np.clip(255.0 * (1.0 - p), 0, 255).astype(np.uint8)
    shade[grid.logodds[::-1] == 0] = 205
    np.testing.assert_array_equal(iio.imread(save_map_png(grid, tmp_path / "m.png")), shade)
    assert {0, 205, 254} == set(np.unique(grid.picture()).tolist())
