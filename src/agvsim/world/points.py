"""Point lists read from a scenario (tape lines, field polygons), checked once."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def xy_points(points: Sequence[Sequence[float]], where: str, at_least: int) -> np.ndarray:
    """An ``(n, 2)`` float array of at least ``at_least`` finite points; ValueError naming
    ``where`` otherwise."""
    try:
        p = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: a list of [x_m, y_m] points") from None
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < at_least:
        raise ValueError(f"{where}: needs at least {at_least} [x_m, y_m] points, got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"{where}: points must be finite numbers")
    return p
