"""Random reachable twists for :func:`agvsim.kinematics.contract.check_model`, and the helpers
and tolerances its properties share.

:func:`reachable_twists` draws a batch of twists a model can execute (see
:func:`make_reachable`), and :func:`_evaluate` runs the model and ``actuation`` on them once, so
that every property looks at the same batch. Parameter helpers read a model of one robot
(scalar parameters) or a stack of N robots (``(N,)`` arrays) alike.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from agvsim.kinematics.actuation import from_twist, from_wheels

RTOL = 1e-9  # forward/inverse round trips, directions
BATCH_TOL = 1e-12  # batch vs one robot at a time; saturation arithmetic
LIMIT_SLACK = 1e-12  # rad/s above a wheel limit that still counts as within it
DT = 0.05  # control period used for the actuation checks

_SPECIAL_TWISTS = np.array(
    [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [1.0, 0.0, 1.0],
        [-1.0, 0.0, 1.0],
        [1.0, 1.0, -1.0],
    ]
)


# ----------------------------------------------------------------------------- parameters


def _params(model: Any) -> dict[str, Any]:
    if dataclasses.is_dataclass(model):
        return {f.name: getattr(model, f.name) for f in dataclasses.fields(model)}
    return dict(vars(model))


def _stack_size(model: Any) -> int | None:
    """N for a model whose parameters are ``(N,)`` arrays, None when every one is a scalar."""
    shapes = {
        np.shape(v) for v in _params(model).values() if isinstance(v, np.ndarray) and v.ndim > 0
    }
    if not shapes:
        return None
    if len(shapes) > 1 or len(next(iter(shapes))) != 1:
        raise AssertionError(
            f"check_model({type(model).__name__}): parameters must be scalars or (N,) arrays of "
            f"one length N, got shapes {sorted(shapes)}"
        )
    return next(iter(shapes))[0]


def _robot(model: Any, i: int) -> Any:
    """Robot ``i`` of a stacked model as a model of one robot (parameters of shape (1,))."""
    arrays = {
        k: v[i : i + 1]
        for k, v in _params(model).items()
        if isinstance(v, np.ndarray) and v.ndim > 0
    }
    return dataclasses.replace(model, **arrays) if arrays else model


def _per_robot(value: Any, m: int) -> np.ndarray:
    """A scalar or ``(N,)`` parameter as an ``(m,)`` array (m == N for stacks)."""
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (m,)).copy()


def _steer_limits(model: Any, m: int) -> tuple[np.ndarray, np.ndarray]:
    if not model.has_steering:
        return np.zeros(m), np.zeros(m)
    angle, rate = model.steering_limits()
    return _per_robot(angle, m), _per_robot(rate, m)


def _driven_peak(model: Any, speeds: np.ndarray) -> np.ndarray:
    return np.max(np.abs(speeds[:, list(model.driven_wheels)]), axis=-1)


# ----------------------------------------------------------------------------- sampling


def make_reachable(model: Any, twists: np.ndarray, fraction: np.ndarray | float) -> np.ndarray:
    """Project body twists ``(m, 3)`` onto what ``model`` can do, then scale each so that its
    fastest wheel turns at ``fraction`` of the wheel limit (a zero twist stays zero).

    vy is zeroed for non-holonomic models. For car-like models omega is zeroed where vx == 0
    and max_steer < pi/2, and reduced where the bicycle angle ``inverse(t).steering`` is beyond
    ``max_steer`` (to 0.98 max_steer: the angle is atan(L omega / vx), so tan scales with omega).
    """
    t = np.array(twists, dtype=np.float64)
    m = t.shape[0]
    if not model.holonomic:
        t[:, 1] = 0.0
    if model.has_steering:
        max_angle, _ = _steer_limits(model, m)
        t[(t[:, 0] == 0.0) & (max_angle < np.pi / 2), 2] = 0.0
        delta = np.abs(model.inverse(t).steering)
        over = delta > max_angle
        t[over, 2] *= np.tan(0.98 * max_angle[over]) / np.tan(delta[over])
    speeds = model.inverse(t).speeds
    peak = np.max(np.abs(speeds), axis=-1)
    limit = _per_robot(model.max_wheel_speed_rad_s, m)
    frac = np.broadcast_to(np.asarray(fraction, dtype=np.float64), (m,))
    scale = np.where(peak > 0, frac * limit / np.where(peak > 0, peak, 1.0), 1.0)
    return t * scale[:, None]


def reachable_twists(model: Any, rng: np.random.Generator, m: int) -> np.ndarray:
    """``m`` random reachable twists, about a quarter of them special cases (zero, pure
    translation, turning on the spot, ...), each using 5 to 95 % of the wheel limit."""
    t = rng.uniform(-1.0, 1.0, (m, 3))
    special = rng.random(m) < 0.25
    t[special] = _SPECIAL_TWISTS[rng.integers(0, len(_SPECIAL_TWISTS), int(special.sum()))]
    return make_reachable(model, t, rng.uniform(0.05, 0.95, m))


def _evaluate(model: Any, t: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    """Everything the properties look at, for twists ``t`` (m, 3); rows are robots."""
    m = t.shape[0]
    driven = list(model.driven_wheels)
    ws = model.inverse(t)
    drive = ws.speeds[:, driven]
    limit = _per_robot(model.max_wheel_speed_rad_s, m)
    max_angle, max_rate = _steer_limits(model, m)

    # a twist beyond the limits, with the wheels already steered for it
    peak = _driven_peak(model, ws.speeds)
    factor = np.where(peak > 0, limit * rng.uniform(1.5, 10.0, m) / np.where(peak > 0, peak, 1), 0)
    big = t * factor[:, None]
    steer_now = ws.steering.copy() if model.has_steering else np.zeros(m)
    cmd = big.copy()
    if not model.holonomic:  # an unreachable sideways part, to be dropped
        cmd[:, 1] += rng.normal(size=m)

    # wheel commands, two thirds of them beyond the limit, and steering targets beyond +-max
    wheel_cmd = rng.uniform(-3.0, 3.0, (m, len(driven))) * limit[:, None]
    small = rng.random(m) < 0.3
    wpeak = np.max(np.abs(wheel_cmd), axis=-1)
    wheel_cmd[small] *= (rng.uniform(0.0, 1.0, m) * limit / np.where(wpeak > 0, wpeak, 1))[
        small, None
    ]
    steer_from = rng.uniform(-1.0, 1.0, m) * max_angle
    steer_target = rng.uniform(-2.0, 2.0, m) * np.where(model.has_steering, max_angle, 1.0)

    return {
        "twist": t,
        "inverse": ws,
        "forward": model.forward(drive, ws.steering),
        "drive_for": model.drive_for(t, ws.steering),
        "big": big,
        "cmd": cmd,
        "steer_now": steer_now,
        "act_big": from_twist(model, cmd, steer_now, DT),
        "act_within": from_twist(model, t, steer_now, DT),
        "wheel_cmd": wheel_cmd,
        "steer_from": steer_from,
        "steer_target": steer_target,
        "act_wheels": from_wheels(model, wheel_cmd, steer_target, steer_from, DT),
        "limit": limit,
        "max_angle": max_angle,
        "max_rate": max_rate,
    }
