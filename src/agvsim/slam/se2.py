"""SE(2) helpers over batched pose arrays.

A pose is a row ``[x, y, theta]`` (metres, metres, rad); functions take ``(N, 3)`` arrays (a single
``(3,)`` pose also works and gives a ``(3,)`` result) and broadcast ``(N, 3)`` with ``(1, 3)`` or
``(3,)``. Angles come out wrapped to (-pi, pi], as everywhere in agvsim (docs/CONVENTIONS.md).

With ``R(theta) = [[cos, -sin], [sin, cos]]`` and ``t = (x, y)``:

* compose   ``a * b   = (t_a + R(theta_a) t_b,        wrap(theta_a + theta_b))``
* inverse   ``a^-1    = (-R(theta_a)^T t_a,           wrap(-theta_a))``
* between   ``a^-1 * b = (R(theta_a)^T (t_b - t_a),   wrap(theta_b - theta_a))``

``between(T_world_a, T_world_b)`` is ``T_a_b``: pose b expressed in the frame of a (the g2o
``EDGE_SE2`` measurement and the Kümmerle relation ``pose(t1)^-1 * pose(t2)``).

This module imports numpy and :mod:`agvsim.angles` (the one angle wrap) only, so every SLAM
stage can share it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from agvsim.angles import wrap_angle

__all__ = ["between", "compose", "inverse", "rotation_matrices", "wrap_angle"]


def _as_poses(p: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(p, dtype=np.float64)
    if arr.shape[-1:] != (3,):
        raise ValueError(f"{name} must have shape (N, 3) or (3,) [x, y, theta], got {arr.shape}")
    return arr


def compose(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """``a * b``: pose b (given in frame a) expressed in a's parent frame.

    ``x = x_a + cos(th_a) x_b - sin(th_a) y_b``, ``y = y_a + sin(th_a) x_b + cos(th_a) y_b``,
    ``th = wrap(th_a + th_b)``.
    """
    pa, pb = _as_poses(a, "a"), _as_poses(b, "b")
    c, s = np.cos(pa[..., 2]), np.sin(pa[..., 2])
    x = pa[..., 0] + c * pb[..., 0] - s * pb[..., 1]
    y = pa[..., 1] + s * pb[..., 0] + c * pb[..., 1]
    return np.stack([x, y, wrap_angle(pa[..., 2] + pb[..., 2])], axis=-1)


def inverse(a: ArrayLike) -> NDArray[np.float64]:
    """``a^-1``: ``(-cos th x - sin th y, sin th x - cos th y, wrap(-th))``."""
    pa = _as_poses(a, "a")
    c, s = np.cos(pa[..., 2]), np.sin(pa[..., 2])
    x = -c * pa[..., 0] - s * pa[..., 1]
    y = s * pa[..., 0] - c * pa[..., 1]
    return np.stack([x, y, wrap_angle(-pa[..., 2])], axis=-1)


def between(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """``a^-1 * b``: pose b in the frame of pose a (relative pose, odometry increment).

    ``(dx, dy) = R(th_a)^T (t_b - t_a)``, ``dth = wrap(th_b - th_a)``.
    """
    pa, pb = _as_poses(a, "a"), _as_poses(b, "b")
    c, s = np.cos(pa[..., 2]), np.sin(pa[..., 2])
    dx, dy = pb[..., 0] - pa[..., 0], pb[..., 1] - pa[..., 1]
    return np.stack(
        [c * dx + s * dy, -s * dx + c * dy, wrap_angle(pb[..., 2] - pa[..., 2])], axis=-1
    )


def rotation_matrices(theta_rad: ArrayLike) -> NDArray[np.float64]:
    """``R(theta)`` for each angle: shape ``theta.shape + (2, 2)``, ``[[c, -s], [s, c]]``."""
    th = np.asarray(theta_rad, dtype=np.float64)
    c, s = np.cos(th), np.sin(th)
    return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)
