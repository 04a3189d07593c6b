"""Robust kernels for pose-graph optimisation, applied as iteratively reweighted information.

An edge with ``s = e^T Omega e`` costs ``rho(s)`` instead of ``s``; at each linearisation its
information is scaled by the weight ``w = rho'(s)`` (IRLS), so an outlier with a large ``s``
pulls less. ``k`` is the kernel's scale in units of ``sqrt(chi2)`` (standard deviations).

``dcs`` is dynamic covariance scaling (Agarwal et al., ICRA 2013): the switchable constraints
of Suenderhauf and Protzel (IROS 2012) with each edge's switch variable solved in closed form.
A switchable edge costs ``s_w^2 chi2 + Phi (1 - s_w)^2`` with a switch ``s_w`` in [0, 1] and a
prior ``Phi`` that holds it at 1; the switch that fits best is ``s_w = min(1, 2 Phi / (Phi +
chi2))`` (DCS's form, exactly 1 for an edge within ``Phi``), so the edge's information is
scaled by ``s_w^2``. Here ``rho`` is the integral of that weight, ``chi2`` up to ``Phi`` and
``3 Phi - 4 Phi^2 / (Phi + chi2)`` beyond (bounded by ``3 Phi``): Levenberg-Marquardt's gain
ratio then sees the same cost the weights minimise. A wrong loop closure, however strongly
it claims to be right, costs at most ``3 Phi`` and stops pulling: its switch goes to 0.
"""

from __future__ import annotations

import enum

import numpy as np
from numpy.typing import NDArray

__all__ = ["RobustKernel", "robust_cost_and_weights", "switch_values"]

F64 = NDArray[np.float64]


class RobustKernel(enum.StrEnum):
    """Robust cost ``rho(s)`` of an edge's ``s = e^T Omega e`` (scale ``k``) and IRLS weight.

    * ``none``:   ``rho = s``,                                         ``w = 1``
    * ``huber``:  ``rho = s`` if ``s <= k^2`` else ``2 k sqrt(s) - k^2``, ``w = min(1, k/sqrt(s))``
    * ``cauchy``: ``rho = k^2 log(1 + s / k^2)``,                       ``w = 1 / (1 + s / k^2)``
    * ``dcs``:    ``rho = s`` if ``s <= Phi`` else ``3 Phi - 4 Phi^2 / (Phi + s)``,
      ``w = min(1, 2 Phi / (Phi + s))^2`` with ``Phi = k^2`` (module docstring)
    """

    NONE = "none"
    HUBER = "huber"
    CAUCHY = "cauchy"
    DCS = "dcs"


def robust_cost_and_weights(s: F64, kernel: RobustKernel, scale: float | F64) -> tuple[F64, F64]:
    """``(rho(s), rho'(s))`` per edge for the kernel (see :class:`RobustKernel`); ``scale``
    one number or one per edge."""
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
    if kernel is RobustKernel.DCS:
        inlier = s <= k2
        cost = np.where(inlier, s, 3.0 * k2 - 4.0 * k2 * k2 / (k2 + s))
        return cost, switch_values(s, scale) ** 2
    raise ValueError(f"unknown robust kernel {kernel!r}")


def switch_values(s: F64, scale: float | F64) -> F64:
    """The switches ``min(1, 2 Phi / (Phi + s))`` (``Phi = scale^2``) of switchable edges with
    ``s = e^T Omega e``: 1 keeps an edge whole, 0 switches it off (:class:`RobustKernel`)."""
    k2 = scale * scale
    return np.minimum(1.0, 2.0 * k2 / (k2 + s))
