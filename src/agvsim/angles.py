"""Angle wrapping, written once: every heading and angle difference in agvsim is wrapped to
(-pi, pi] by these two functions (docs/CONVENTIONS.md).

``wrap_angle`` takes arrays (or a number) and returns an array; ``wrap_scalar`` takes one
float and is a numba function, so kernels call it and plain Python may too. Both compute
``pi - mod(pi - a, 2 pi)``, then turn the -pi that rounding can leave into pi; as numpy's and
Python's float modulo round alike, the two give the same bits for the same angle.

This module imports numpy and numba only; every layer (SLAM included) may use it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

__all__ = ["TWO_PI", "wrap_angle", "wrap_scalar"]

TWO_PI = 2.0 * np.pi


def wrap_angle(angle_rad: ArrayLike) -> NDArray[np.float64]:
    """Angle(s) in rad wrapped to (-pi, pi]: ``pi - mod(pi - a, 2 pi)``."""
    out = np.pi - np.mod(np.pi - np.asarray(angle_rad, dtype=np.float64), TWO_PI)
    # np.mod may round a tiny negative remainder up to exactly 2 pi, giving -pi
    return np.asarray(np.where(out <= -np.pi, np.pi, out), dtype=np.float64)


@njit(cache=True, error_model="numpy")
def wrap_scalar(angle_rad: float) -> float:
    """One angle in rad wrapped to (-pi, pi]: the scalar twin of :func:`wrap_angle`."""
    t = math.pi - ((math.pi - angle_rad) % TWO_PI)
    return math.pi if t <= -math.pi else t
