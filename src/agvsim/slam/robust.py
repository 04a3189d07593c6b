"""Robust kernels for pose-graph optimisation, applied as iteratively reweighted information.

An edge with ``s = e^T Omega e`` costs ``rho(s)`` instead of ``s``; at each linearisation its
information is scaled by the weight ``w = rho'(s)`` (IRLS), so an outlier with a large ``s``
pulls less. ``k`` is the kernel's scale in units of ``sqrt(chi2)`` (standard deviations).
"""

from __future__ import annotations

import enum

import numpy as np
from numpy.typing import NDArray

__all__ = ["RobustKernel", "robust_cost_and_weights"]

F64 = NDArray[np.float64]


class RobustKernel(enum.StrEnum):
    """Robust cost ``rho(s)`` of an edge's ``s = e^T Omega e`` (scale ``k``) and IRLS weight.

    * ``none``:   ``rho = s``,                                         ``w = 1``
    * ``huber``:  ``rho = s`` if ``s <= k^2`` else ``2 k sqrt(s) - k^2``, ``w = min(1, k/sqrt(s))``
    * ``cauchy``: ``rho = k^2 log(1 + s / k^2)``,                       ``w = 1 / (1 + s / k^2)``
    """

    NONE = "none"
    HUBER = "huber"
    CAUCHY = "cauchy"


def robust_cost_and_weights(s: F64, kernel: RobustKernel, scale: float) -> tuple[F64, F64]:
    """``(rho(s), rho'(s))`` per edge for the kernel (see :class:`RobustKernel`)."""
    if kernel is RobustKernel.NONE:
        return s, np.ones_like(s)
    k2 = scale * scale
    if kernel is RobustKernel.HUBER:
        r = np.sqrt(s)
        inlier = s <= k2
        cost = np.where(inlier, s, 2.0 * scale * r - k2)
        w = np.where(inlier, 1.0, scale / np.maximum(r, 1e-300))
        return cost, w
    if kernel is RobustKernel.CAUCHY:
        return k2 * np.log1p(s / k2), 1.0 / (1.0 + s / k2)
    raise ValueError(f"unknown robust kernel {kernel!r}")
