"""A contract checker for kinematic models, in the spirit of Gymnasium's ``check_env``.

``check_model(model)`` drives a model (one set of parameters, or a stack of robots made by
``stack_models``) through batches of random *reachable* twists and raises ``AssertionError``
naming the model and the property that failed. Use it on every new model::

    from agvsim.kinematics.contract import check_model
    check_model(MyModel())

Properties checked (tolerances are relative to the size of the row being compared unless said):

- declarations: ``wheel_names``, ``driven_wheels``, ``steered_wheels`` agree with each other and
  with ``wheel_positions_m()`` (shape ``(W, 2)``, or ``(N, W, 2)`` for a stack of N robots);
- round trip: ``forward(inverse(t).speeds[:, driven_wheels], inverse(t).steering) == t`` (1e-9)
  and ``drive_for(t, inverse(t).steering)`` gives the same driven speeds;
- wheels roll without side slip: the velocity of a steered wheel's contact point is
  ``r * speed * (cos a, sin a)`` (not for Ackermann's ``steering_geometry="parallel"``, which is
  an approximation on purpose); the other wheels of a non-holonomic model are taken as fixed
  standard wheels along the robot's x axis (a = 0), in ``inverse`` and in ``from_twist``;
- batch consistency: evaluating robots one at a time gives the batch result (1e-12);
- ``actuation.from_twist``: a twist beyond the wheel limits is scaled down (driven wheels within
  ``max_wheel_speed_rad_s``, the peak on the limit), in the commanded direction (normalised
  twists equal to 1e-9, scale in (0, 1]); a twist within the limits is executed as is; vy is
  dropped for non-holonomic models. Only driven wheels are held to the limit: passive wheels
  (tricycle rear, Ackermann front) may turn faster, as ``actuation`` saturates the drive only;
- ``actuation.from_wheels``: driven wheel speeds saturated by one factor per robot (ratios kept),
  steering clamped to +-max_steer and moved at most max_steer_rate * dt per call;
- a full circle: ``integrate_se2`` with a constant reachable twist (vx, 0, omega) for N steps with
  N omega dt = 2 pi comes back to its start within 1e-9 m (dt 0.02 and 0.05, several omegas),
  every pose on the way on the exact circle; a step with a tiny omega is the straight line.

Reachable twists are built from the model's own constraints: vy = 0 unless ``holonomic``; for
car-like models (``has_steering``) the bicycle steering angle ``inverse(t).steering`` within
``+-max_steer`` (so omega = 0 when vx = 0 if max_steer < pi/2); every wheel within its limit.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from agvsim.kinematics.actuation import Actuation, from_twist, from_wheels
from agvsim.kinematics.base import integrate_se2, wrap_angle

__all__ = ["check_model", "make_reachable", "reachable_twists"]

RTOL = 1e-9  # forward/inverse round trips, directions
BATCH_TOL = 1e-12  # batch vs one robot at a time; saturation arithmetic
LIMIT_SLACK = 1e-12  # rad/s above a wheel limit that still counts as within it
CIRCLE_TOL_M = 1e-9
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


_REQUIRED = (
    "kind",
    "wheel_names",
    "driven_wheels",
    "steered_wheels",
    "has_steering",
    "holonomic",
    "wheel_radius_m",
    "max_wheel_speed_rad_s",
    "forward",
    "inverse",
    "drive_for",
    "wheel_positions_m",
    "steering_limits",
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


# ----------------------------------------------------------------------------- checker


class _Checker:
    def __init__(self, model: Any) -> None:
        self.model = model
        text = repr(model)
        self.name = text if len(text) <= 240 else text[:237] + "..."

    def fail(self, prop: str, detail: str) -> None:
        raise AssertionError(f"check_model: {self.name}: property '{prop}' failed: {detail}")

    def require(self, ok: bool, prop: str, detail: str | Callable[[], str]) -> None:
        if not ok:
            self.fail(prop, detail() if callable(detail) else detail)

    def shape(self, prop: str, what: str, value: Any, expected: tuple[int, ...]) -> None:
        got = np.shape(value)
        self.require(got == expected, prop, f"{what} has shape {got}, expected {expected}")

    def close(
        self,
        prop: str,
        what: str,
        got: Any,
        want: Any,
        *,
        rtol: float,
        atol: float = 1e-12,
        inputs: dict[str, np.ndarray] | None = None,
    ) -> None:
        """``got`` == ``want`` to ``atol + rtol * max|row of want|``; NaN never passes."""
        got = np.asarray(got, dtype=np.float64)
        want = np.asarray(want, dtype=np.float64)
        self.shape(prop, what, got, want.shape)
        if want.size == 0:
            return
        scale = np.abs(want) if want.ndim <= 1 else np.max(np.abs(want), axis=-1, keepdims=True)
        ok = np.abs(got - want) <= atol + rtol * scale
        if np.all(ok):
            return
        idx = np.unravel_index(int(np.argmin(ok)), ok.shape)
        row = idx[:-1] if want.ndim > 1 else idx
        shown = "".join(
            f", {k}={np.asarray(v)[row[:1]]!r}" for k, v in (inputs or {}).items() if row
        )
        self.fail(
            prop,
            f"{what}: got {got[row]!r}, expected {want[row]!r} at index {row} "
            f"(rtol {rtol:g}, atol {atol:g}{shown})",
        )

    def within(
        self, prop: str, what: str, values: np.ndarray, bound: np.ndarray, slack: float
    ) -> None:
        """``|values| <= bound + slack`` row by row (``bound`` per robot)."""
        v = np.abs(np.asarray(values, dtype=np.float64))
        b = np.asarray(bound, dtype=np.float64)
        b = b.reshape(b.shape + (1,) * (v.ndim - b.ndim))
        bad = ~(v <= b + slack)
        if np.any(bad):
            idx = np.unravel_index(int(np.argmax(bad)), bad.shape)
            self.fail(
                prop,
                f"{what}: |{v[idx]!r}| exceeds the limit {np.broadcast_to(b, v.shape)[idx]!r} "
                f"(+{slack:g}) at index {idx}",
            )


def check_model(model: Any, rng: np.random.Generator | int | None = None, n: int = 256) -> None:
    """Check that ``model`` keeps the kinematic-model contract; raise ``AssertionError`` naming
    the model and the failed property otherwise. ``rng`` is a Generator or a seed (default a
    fixed seed, so the check is deterministic); ``n`` is the number of random twists (a stack of
    N robots is checked over ceil(n / N) batches of N)."""
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(0 if rng is None else rng)
    c = _Checker(model)
    stack = _stack_size(model)
    _check_declarations(c, stack)
    m = n if stack is None else stack
    for _ in range(max(1, math.ceil(n / m))):
        t = reachable_twists(model, rng, m)
        batch = _evaluate(model, t, rng)
        _check_round_trip(c, t, batch)
        _check_from_twist(c, t, batch)
        _check_from_wheels(c, batch)
        _check_batch_consistency(c, stack, batch)
    _check_steering_sequence(c, rng, m)
    _check_full_circle(c, m)
    _check_tiny_omega(c, rng, m)


# ----------------------------------------------------------------------------- properties


def _check_declarations(c: _Checker, stack: int | None) -> None:
    model, prop = c.model, "declarations"
    for attr in _REQUIRED:
        c.require(hasattr(model, attr), prop, f"the model has no attribute {attr!r}")
    names = model.wheel_names
    w = len(names)
    c.require(
        isinstance(model.kind, str) and bool(model.kind), prop, "kind must be a non-empty str"
    )
    c.require(w > 0 and len(set(names)) == w, prop, f"wheel_names must be unique: {names!r}")
    for attr in ("driven_wheels", "steered_wheels"):
        idx = getattr(model, attr)
        c.require(
            len(set(idx)) == len(idx) and all(0 <= i < w for i in idx),
            prop,
            f"{attr} {idx!r} must be distinct indices into wheel_names {names!r}",
        )
    c.require(len(model.driven_wheels) > 0, prop, "driven_wheels is empty")
    c.require(
        bool(model.steered_wheels) == bool(model.has_steering),
        prop,
        f"has_steering={model.has_steering} but steered_wheels={model.steered_wheels!r}",
    )
    pos = np.asarray(model.wheel_positions_m())
    expected = (w, 2) if stack is None else (stack, w, 2)
    c.shape("wheel_positions_m", "wheel_positions_m()", pos, expected)
    c.require(np.all(np.isfinite(pos)), "wheel_positions_m", "wheel positions are not finite")
    if model.has_steering:
        angle, rate = _steer_limits(model, 1 if stack is None else stack)
        c.require(
            bool(np.all((angle > 0) & (angle <= np.pi / 2)) and np.all(rate > 0)),
            prop,
            f"steering_limits() must give 0 < max_steer <= pi/2 and a positive rate, "
            f"got {model.steering_limits()!r}",
        )


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


def _check_round_trip(c: _Checker, t: np.ndarray, b: dict[str, Any]) -> None:
    model, ws = c.model, b["inverse"]
    m, w = t.shape[0], len(model.wheel_names)
    prop = "inverse shapes"
    c.shape(prop, "inverse(t).speeds", ws.speeds, (m, w))
    c.shape(prop, "inverse(t).steer_angles", ws.steer_angles, (m, len(model.steered_wheels)))
    c.shape(prop, "inverse(t).steering", ws.steering, (m,))
    if not model.has_steering:
        c.close(
            prop,
            "inverse(t).steering of a model without steering",
            ws.steering,
            0 * t[:, 0],
            rtol=0,
            atol=0,
        )
    if model.has_steering:
        c.within(
            "reachable twists", "steering of a reachable twist", ws.steering, b["max_angle"], 1e-12
        )
    inputs = {"twist": t}
    c.close(
        "forward(inverse(t)) == t",
        "forward(drive, steering)",
        b["forward"],
        t,
        rtol=RTOL,
        inputs=inputs,
    )
    c.close(
        "drive_for(t, inverse(t).steering) == inverse(t).speeds[:, driven_wheels]",
        "drive_for",
        b["drive_for"],
        ws.speeds[:, list(model.driven_wheels)],
        rtol=RTOL,
        inputs=inputs,
    )
    _check_no_side_slip(c, t, ws.speeds, ws.steer_angles, "wheels roll (inverse)", fixed=True)


def _check_no_side_slip(
    c: _Checker,
    t: np.ndarray,
    speeds: np.ndarray,
    angles: np.ndarray,
    prop: str,
    *,
    fixed: bool = False,
) -> None:
    """Wheels roll without side slip: the contact point of a steered wheel moves at
    r * speed * (cos a, sin a) (not checked for the parallel-steering approximation); with
    ``fixed``, so does every other wheel of a non-holonomic model (a fixed standard wheel
    along the robot's x axis, a = 0)."""
    model = c.model
    m = t.shape[0]
    wheels, heading = [], []
    if model.has_steering and getattr(model, "steering_geometry", None) != "parallel":
        wheels += list(model.steered_wheels)
        heading.append(np.asarray(angles, dtype=np.float64).reshape(m, -1))
    if fixed and not model.holonomic:
        rest = [i for i in range(len(model.wheel_names)) if i not in model.steered_wheels]
        wheels += rest
        heading.append(np.zeros((m, len(rest))))
    if not wheels:
        return
    a = np.concatenate(heading, axis=-1)
    pos = np.broadcast_to(np.asarray(model.wheel_positions_m()), (m, len(model.wheel_names), 2))
    px, py = pos[:, wheels, 0], pos[:, wheels, 1]
    vx, vy, om = t[:, 0:1], t[:, 1:2], t[:, 2:3]
    point_v = np.stack([vx - om * py, vy + om * px], axis=-1)
    r = _per_robot(model.wheel_radius_m, m)[:, None]
    s = speeds[:, wheels] * r
    rolled = np.stack([s * np.cos(a), s * np.sin(a)], axis=-1)
    names = ", ".join(model.wheel_names[i] for i in wheels)
    c.close(
        prop,
        f"r * speed * (cos a, sin a) vs the contact-point velocity, wheels ({names}) as "
        "(x, y) pairs",
        rolled.reshape(m, -1),
        point_v.reshape(m, -1),
        rtol=RTOL,
        inputs={"twist": t, "steer_angles": angles},
    )


def _check_actuation_common(c: _Checker, act: Actuation, m: int, prop: str, *, fixed: bool) -> None:
    """Shapes and internal consistency of an Actuation; ``fixed``: also the rolling of fixed
    wheels (not in forward mode, where e.g. Ackermann reports the commanded rear speeds even
    when they disagree with the bicycle model)."""
    model = c.model
    c.shape(prop, "Actuation.twist", act.twist, (m, 3))
    c.shape(prop, "Actuation.drive", act.drive, (m, len(model.driven_wheels)))
    c.shape(prop, "Actuation.wheel_speeds", act.wheel_speeds, (m, len(model.wheel_names)))
    c.shape(prop, "Actuation.steer_angles", act.steer_angles, (m, len(model.steered_wheels)))
    c.shape(prop, "Actuation.steering", act.steering, (m,))
    c.close(
        prop,
        "Actuation.wheel_speeds[:, driven_wheels] vs Actuation.drive",
        act.wheel_speeds[:, list(model.driven_wheels)],
        act.drive,
        rtol=0,
        atol=0,
    )
    c.close(
        prop,
        "Actuation.twist vs forward(Actuation.drive, Actuation.steering)",
        act.twist,
        model.forward(act.drive, act.steering),
        rtol=BATCH_TOL,
    )
    if not model.has_steering:
        c.close(
            prop,
            "Actuation.steering of a model without steering",
            act.steering,
            np.zeros(m),
            rtol=0,
            atol=0,
        )
    _check_no_side_slip(
        c, act.twist, act.wheel_speeds, act.steer_angles, f"{prop}: wheels roll", fixed=fixed
    )


def _check_from_twist(c: _Checker, t: np.ndarray, b: dict[str, Any]) -> None:
    model = c.model
    m = t.shape[0]
    prop = "from_twist saturation keeps direction"
    act: Actuation = b["act_big"]
    big = b["big"]
    inputs = {"twist": big}
    _check_actuation_common(c, act, m, prop, fixed=True)
    c.within(prop, "driven wheel speed", act.drive, b["limit"], LIMIT_SLACK)
    if not model.holonomic:
        c.close(
            prop,
            "executed vy of a non-holonomic model",
            act.twist[:, 1],
            np.zeros(m),
            rtol=0,
            atol=0,
        )
    c.close(
        prop,
        "steering (already at its target)",
        act.steering,
        b["steer_now"],
        rtol=0,
        atol=BATCH_TOL,
    )
    norm_big = np.linalg.norm(big, axis=-1)
    moving = norm_big > 0
    if np.any(moving):
        ex, bg = act.twist[moving], big[moving]
        norm_ex = np.linalg.norm(ex, axis=-1)
        c.require(bool(np.all(norm_ex > 0)), prop, "a moving command was executed as a stop")
        c.close(
            prop,
            "executed twist / |executed twist| vs commanded / |commanded|",
            ex / norm_ex[:, None],
            bg / norm_big[moving, None],
            rtol=0,
            atol=RTOL,
            inputs={"twist": bg},
        )
        scale = np.sum(ex * bg, axis=-1) / norm_big[moving] ** 2
        c.require(
            bool(np.all((scale > 0) & (scale <= 1 + RTOL))),
            prop,
            lambda: (
                f"executed/commanded scale must be in (0, 1], got {scale.min()!r} .. "
                f"{scale.max()!r}"
            ),
        )
        c.close(
            prop,
            "peak driven wheel speed of a saturated twist vs the limit",
            _driven_peak(model, act.wheel_speeds)[moving],
            b["limit"][moving],
            rtol=RTOL,
        )

    prop = "from_twist within the limits executes the twist"
    act2: Actuation = b["act_within"]
    _check_actuation_common(c, act2, m, prop, fixed=True)
    c.close(prop, "executed twist", act2.twist, t, rtol=RTOL, inputs={"twist": t})
    c.close(
        prop,
        "driven wheel speeds",
        act2.drive,
        b["inverse"].speeds[:, list(model.driven_wheels)],
        rtol=RTOL,
        inputs=inputs,
    )


def _check_from_wheels(c: _Checker, b: dict[str, Any]) -> None:
    model = c.model
    prop = "from_wheels saturation and steering limits"
    act: Actuation = b["act_wheels"]
    cmd = b["wheel_cmd"]
    m = cmd.shape[0]
    inputs = {"drive": cmd}
    _check_actuation_common(c, act, m, prop, fixed=False)
    limit = b["limit"]
    peak = np.max(np.abs(cmd), axis=-1)
    scale = np.where(peak > limit, limit / np.where(peak > 0, peak, 1.0), 1.0)
    c.within(prop, "driven wheel speed", act.drive, limit, LIMIT_SLACK)
    c.close(
        prop,
        "saturated drive (one factor per robot: ratios kept)",
        act.drive,
        cmd * scale[:, None],
        rtol=BATCH_TOL,
        inputs=inputs,
    )
    sat = peak > limit
    c.close(
        prop,
        "peak of a saturated drive vs the limit",
        np.max(np.abs(act.drive), axis=-1)[sat],
        limit[sat],
        rtol=BATCH_TOL,
    )
    if model.has_steering:
        now, max_angle, step = b["steer_from"], b["max_angle"], b["max_rate"] * DT
        c.within(prop, "steering", act.steering, max_angle, 1e-12)
        c.within(prop, "steering change in one call", act.steering - now, step, 1e-12)
        goal = np.clip(b["steer_target"], -max_angle, max_angle)
        want = now + np.clip(goal - now, -step, step)
        c.close(
            prop,
            "steering after one call (towards the clamped target)",
            act.steering,
            want,
            rtol=0,
            atol=1e-12,
            inputs={"target": b["steer_target"], "now": now},
        )


def _check_steering_sequence(c: _Checker, rng: np.random.Generator, m: int) -> None:
    """Repeated from_wheels calls walk the steering to the clamped target, one rate step each."""
    model = c.model
    if not model.has_steering:
        return
    prop = "from_wheels steering rate limit"
    max_angle, rate = _steer_limits(model, m)
    now = rng.uniform(-1.0, 1.0, m) * max_angle
    target = rng.uniform(-2.0, 2.0, m) * max_angle
    goal = np.clip(target, -max_angle, max_angle)
    drive = np.zeros((m, len(model.driven_wheels)))
    steps = int(np.max(np.ceil(np.abs(goal - now) / (rate * DT)))) + 1
    for _ in range(min(steps, 10_000)):
        new = from_wheels(model, drive, target, now, DT).steering
        c.within(prop, "steering change in one call", new - now, rate * DT, 1e-12)
        c.within(prop, "steering", new, max_angle, 1e-12)
        c.require(
            bool(np.all(np.abs(goal - new) <= np.abs(goal - now) + 1e-12)),
            prop,
            "steering moved away from its target",
        )
        now = new
    c.close(
        prop,
        "steering after enough calls vs the clamped target",
        now,
        goal,
        rtol=0,
        atol=1e-12,
        inputs={"target": target},
    )


def _check_batch_consistency(c: _Checker, stack: int | None, b: dict[str, Any]) -> None:
    model = c.model
    prop = "batch consistency (one robot at a time == batch)"
    t = b["twist"]
    m = t.shape[0]
    rows = range(m) if stack is not None else range(0, m, max(1, m // 32))
    for i in rows:
        one = _robot(model, i) if stack is not None else model
        sl = slice(i, i + 1)
        ws = one.inverse(t[sl])
        drive = ws.speeds[:, list(model.driven_wheels)]
        got = {
            "inverse(t).speeds": (ws.speeds, b["inverse"].speeds),
            "inverse(t).steer_angles": (ws.steer_angles, b["inverse"].steer_angles),
            "inverse(t).steering": (ws.steering, b["inverse"].steering),
            "forward(drive, steering)": (one.forward(drive, ws.steering), b["forward"]),
            "drive_for": (one.drive_for(t[sl], ws.steering), b["drive_for"]),
        }
        a1 = from_twist(one, b["cmd"][sl], b["steer_now"][sl], DT)
        a2 = from_wheels(one, b["wheel_cmd"][sl], b["steer_target"][sl], b["steer_from"][sl], DT)
        for label, act, ref in (
            ("from_twist", a1, b["act_big"]),
            ("from_wheels", a2, b["act_wheels"]),
        ):
            for f in ("twist", "drive", "wheel_speeds", "steer_angles", "steering"):
                got[f"{label}(...).{f}"] = (getattr(act, f), getattr(ref, f))
        if stack is not None:
            got["wheel_positions_m()"] = (one.wheel_positions_m(), model.wheel_positions_m())
        for what, (single, batch) in got.items():
            c.close(
                prop,
                f"{what} of robot {i}",
                single,
                np.asarray(batch)[sl],
                rtol=BATCH_TOL,
                inputs={"twist": t[sl]},
            )


def _check_full_circle(c: _Checker, m: int) -> None:
    """Constant twist (vx, 0, omega), N steps with N omega dt = 2 pi: back to the start, every
    pose on the exact circle (radius vx / omega about the instantaneous centre of rotation,
    heading turned by omega dt per step). A closed polygon is not enough: Euler steps close too.
    """
    model = c.model
    prop = "full circle returns to its start (integrate_se2)"
    driven = list(model.driven_wheels)
    # the fastest reachable turn with vx == omega (sharper for car-like models if need be)
    base = make_reachable(model, np.tile([1.0, 0.0, 1.0], (m, 1)), 0.9)
    om_max = np.min(np.abs(base[:, 2]))
    c.require(om_max > 0, prop, "no reachable twist (1, 0, 1) direction turns")
    start = np.tile([1.5, -2.0, 0.7], (m, 1))
    for dt in (0.02, 0.05):
        for frac in (1.0, 0.45):
            steps = math.ceil(2 * np.pi / (om_max * frac * dt))
            if steps > 5000:
                continue
            omega = 2 * np.pi / (steps * dt)
            t = base * (omega / base[:, 2:3])
            ws = model.inverse(t)
            twist = model.forward(ws.speeds[:, driven], ws.steering)
            radius = twist[:, 0] / twist[:, 2]  # signed: the centre is on the left when > 0
            th0 = start[:, 2]
            centre = start[:, :2] + radius[:, None] * np.column_stack([-np.sin(th0), np.cos(th0)])
            pose = start
            worst_r = worst_th = 0.0
            for k in range(1, steps + 1):
                pose = integrate_se2(pose, twist, dt)
                off_r = np.abs(np.hypot(*(pose[:, :2] - centre).T) - np.abs(radius))
                off_th = np.abs(wrap_angle(pose[:, 2] - th0 - k * twist[:, 2] * dt))
                worst_r = max(worst_r, float(off_r.max()))
                worst_th = max(worst_th, float(off_th.max()))
            err = np.hypot(pose[:, 0] - start[:, 0], pose[:, 1] - start[:, 1])
            dth = np.abs(wrap_angle(pose[:, 2] - start[:, 2]))
            if not (
                np.all(err <= CIRCLE_TOL_M)
                and np.all(dth <= CIRCLE_TOL_M)
                and worst_r <= CIRCLE_TOL_M
                and worst_th <= CIRCLE_TOL_M
            ):
                c.fail(
                    prop,
                    f"after {steps} steps of dt={dt} with twist {twist[0]!r}: position error "
                    f"{err.max():.3g} m, heading error {dth.max():.3g} rad, largest distance "
                    f"off the circle {worst_r:.3g} m, largest heading drift {worst_th:.3g} rad "
                    f"(tolerance {CIRCLE_TOL_M:g})",
                )


def _check_tiny_omega(c: _Checker, rng: np.random.Generator, m: int) -> None:
    """An SE(2) step whose rotation omega dt is at most 1e-12 rad is the straight line."""
    prop = "integrate_se2 at tiny omega is the straight line"
    t = reachable_twists(c.model, rng, m)
    pose = np.column_stack([rng.uniform(-5, 5, (m, 2)), rng.uniform(-np.pi, np.pi, m)])
    for dt in (0.02, 0.05):
        for a in (0.0, 1e-15, -1e-13, 1e-12):
            tw = t.copy()
            tw[:, 2] = a / dt
            got = integrate_se2(pose, tw, dt)
            ct, st = np.cos(pose[:, 2]), np.sin(pose[:, 2])
            dx, dy = tw[:, 0] * dt, tw[:, 1] * dt
            line = np.column_stack(
                [pose[:, 0] + ct * dx - st * dy, pose[:, 1] + st * dx + ct * dy, pose[:, 2] + a]
            )
            c.close(
                prop,
                f"pose after one step (omega dt = {a:g}, dt = {dt})",
                got[:, :2],
                line[:, :2],
                rtol=0,
                atol=1e-12,
                inputs={"twist": tw},
            )
            c.close(
                prop,
                "heading after one step",
                wrap_angle(got[:, 2] - line[:, 2]),
                np.zeros(m),
                rtol=0,
                atol=1e-12,
            )
