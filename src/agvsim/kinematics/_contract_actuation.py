"""The actuation properties of :func:`agvsim.kinematics.contract.check_model`: wheels roll
without side slip, ``actuation.from_twist`` saturation keeps the commanded direction (and a twist
within the limits is executed as is), ``actuation.from_wheels`` saturates the drive by one factor
per robot and moves the steering within its angle and rate limits.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from agvsim.kinematics._contract_twists import (
    BATCH_TOL,
    DT,
    LIMIT_SLACK,
    RTOL,
    _driven_peak,
    _per_robot,
    _steer_limits,
)
from agvsim.kinematics.actuation import Actuation, from_wheels

if TYPE_CHECKING:
    from agvsim.kinematics.contract import _Checker


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
