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

Layout: this module holds :func:`check_model` and the model and integration properties; the
twist sampling, shared helpers and tolerances are in ``_contract_twists``, the actuation
properties in ``_contract_actuation``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from agvsim.kinematics._contract_actuation import (
    _check_from_twist,
    _check_from_wheels,
    _check_no_side_slip,
    _check_steering_sequence,
)
from agvsim.kinematics._contract_twists import (
    BATCH_TOL,
    DT,
    LIMIT_SLACK,  # noqa: F401 - re-exported, like the other tolerances
    RTOL,
    _evaluate,
    _robot,
    _stack_size,
    _steer_limits,
    make_reachable,
    reachable_twists,
)
from agvsim.kinematics.actuation import from_twist, from_wheels
from agvsim.kinematics.base import integrate_se2, wrap_angle

__all__ = ["check_model", "make_reachable", "reachable_twists"]

CIRCLE_TOL_M = 1e-9

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
    c.require(bool(np.all(np.isfinite(pos))), "wheel_positions_m", "wheel positions are not finite")
    if model.has_steering:
        angle, rate = _steer_limits(model, 1 if stack is None else stack)
        c.require(
            bool(np.all((angle > 0) & (angle <= np.pi / 2)) and np.all(rate > 0)),
            prop,
            f"steering_limits() must give 0 < max_steer <= pi/2 and a positive rate, "
            f"got {model.steering_limits()!r}",
        )


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
