"""Planar dynamics of the robots that have a ``DynamicsSpec``, batched: tables built once, a
handful of state arrays, one kernel call a step (``agvsim.dynamics.kernel``).

The engine hands over the kinematic targets (driven-wheel speeds and the steering angle after
the kinematic model's limits) and gets back, for the dynamic robots only, the twist that
moves each body from its start to its end pose, the wheels' mean speeds over the step (what
the encoders count, so odometry drifts with slip), the steering, and torque, slip and power
per wheel.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from agvsim.dynamics import kernel as K
from agvsim.dynamics.braking import (
    BrakeMonitor,
    braking_deceleration_m_s2,
    stopping_distance_m,
)
from agvsim.dynamics.spec import G_M_S2, FloorFriction, FrictionModel, LoadSpec

if TYPE_CHECKING:
    from agvsim.sim.spec import RobotSpec


@dataclass(frozen=True)
class MassProperties:
    mass_kg: float
    com_xy_m: tuple[float, float]  # robot frame, from P
    yaw_inertia_kg_m2: float  # about the centre of mass


def mass_properties(robot: RobotSpec, load: LoadSpec | None = None) -> MassProperties:
    """Body plus load (a point mass): total mass, centre of mass and yaw inertia about it."""
    spec = robot.dynamics
    if spec is None:
        raise ValueError(f"robot {robot.name!r} has no dynamics")
    load = spec.load if load is None else load
    mb = spec.mass_kg
    cb = np.array(spec.com_xy_m if spec.com_xy_m is not None else (robot.body_offset_x_m, 0.0))
    ib = spec.yaw_inertia_kg_m2
    if ib is None:
        ib = mb * (robot.body_length_m**2 + robot.body_width_m**2) / 12.0
    ml, cl = load.mass_kg, np.asarray(load.offset_xy_m, dtype=np.float64)
    m = mb + ml
    c = (mb * cb + ml * cl) / m
    inertia = ib + mb * float(np.sum((cb - c) ** 2)) + ml * float(np.sum((cl - c) ** 2))
    return MassProperties(m, (float(c[0]), float(c[1])), float(inertia))


def wheel_layout(model: Any) -> np.ndarray:
    """(W, NWC) wheel table of a kinematic model: position, rolling direction, contact kind,
    driven, steering; normal load and inertia are filled in later."""
    pos = np.asarray(model.wheel_positions_m(), dtype=np.float64).reshape(-1, 2)
    w = len(model.wheel_names)
    tab = np.zeros((w, K.NWC))
    tab[:, K.W_PX], tab[:, K.W_PY] = pos[:, 0], pos[:, 1]
    driven = np.zeros(w, dtype=bool)
    driven[list(model.driven_wheels)] = True
    tab[:, K.W_DRIVEN] = driven
    kind = model.kind
    if kind in ("differential", "tricycle", "ackermann"):
        # driven standard wheels: friction circle; passive ones roll freely (side force only)
        tab[:, K.W_KIND] = np.where(driven, K.KIND_2D, K.KIND_1D)
        tab[:, K.W_GAMMA] = np.where(driven, 0.0, np.pi / 2)
        steer = K.STEER_BICYCLE
        if kind == "ackermann" and model.steering_geometry == "ackermann":
            steer = K.STEER_ACKERMANN
        tab[list(model.steered_wheels), K.W_STEER] = steer
    elif kind == "mecanum":
        # 45 deg rollers: force only along the roller axis (front-left (1, -1)/sqrt 2, ...)
        tab[:, K.W_KIND] = K.KIND_1D
        tab[:, K.W_GAMMA] = np.array([-1.0, 1.0, 1.0, -1.0]) * np.pi / 4
    elif kind == "omni3":
        # rollers along the rim: force only along the rolling direction (tangent)
        tab[:, K.W_KIND] = K.KIND_1D
        tab[:, K.W_BETA] = np.arctan2(pos[:, 1], pos[:, 0]) + np.pi / 2
    else:
        raise ValueError(f"no dynamics for kinematic model {kind!r}")
    return tab


def normal_loads(pos_m: np.ndarray, mass_kg: float, com_xy_m: tuple[float, float]) -> np.ndarray:
    """Static wheel loads (N): the least-norm loads that hold the weight and its moments (a
    differential drive's casters carry nothing). Raises when the centre of mass lies outside
    the wheels' support (a load would be negative)."""
    a = np.vstack([np.ones(len(pos_m)), pos_m[:, 0], pos_m[:, 1]])
    wgt = mass_kg * G_M_S2
    rhs = np.array([wgt, wgt * com_xy_m[0], wgt * com_xy_m[1]])
    loads = np.linalg.lstsq(a, rhs, rcond=None)[0]
    if np.any(loads < -1e-9 * wgt):
        raise ValueError(
            f"the centre of mass ({com_xy_m[0]:.3f}, {com_xy_m[1]:.3f}) m lies outside the "
            f"wheels' support: the loads would be {np.round(loads, 1).tolist()} N; move the "
            "load or the centre of mass between the wheels"
        )
    return np.maximum(loads, 0.0)


def check_dynamics(robot: RobotSpec) -> None:
    """Raise ValueError (with a clear message) when a robot's dynamics cannot be built: a
    centre of mass outside the wheels' support."""
    mp = mass_properties(robot)
    normal_loads(wheel_layout(robot.model)[:, :2], mp.mass_kg, mp.com_xy_m)


@dataclass(frozen=True)
class DynamicsStep:
    """What one step gives, rows over the dynamic robots (``Dynamics.idx``)."""

    twist: np.ndarray  # (D, 3) constant twist from start to end pose
    wheel_speeds: np.ndarray  # (D, W) mean spin over the step (encoders), rad/s
    steering: np.ndarray  # (D,) bicycle steering angle at the end, rad
    steer_angles: np.ndarray  # (D, S) steered wheels' angles (model order), rad
    torque_nm: np.ndarray  # (D, W) wheel torque at the end, N m
    slip_m_s: np.ndarray  # (D, W) slip speed of each contact at the end, m/s
    power_w: np.ndarray  # (D, W) mean mechanical power of each motor, W (< 0: braking)
    substeps: np.ndarray  # (D,) sub-steps taken


class Dynamics:
    """The dynamic robots of a simulation: their tables and state (see the module docstring).
    ``idx`` are their indices among all robots; rows of every array follow it."""

    def __init__(self, robots: Sequence[RobotSpec], floor: FloorFriction, width: int, steer: int):
        self.idx = np.array([i for i, r in enumerate(robots) if r.dynamics is not None], np.int64)
        self.robots = [robots[i] for i in self.idx]
        self.floor = floor
        self._regions = floor.table()
        n = len(self.idx)
        self.body = np.zeros((n, K.NB))
        self.wheel = np.zeros((n, width, K.NWC))
        self.steer_cols = np.full((n, steer), -1, dtype=np.int64)
        for d, r in enumerate(self.robots):
            self._fill(d, r, None)
            cols = list(r.model.steered_wheels)
            self.steer_cols[d, : len(cols)] = cols
        self.loads = [r.dynamics.load for r in self.robots]  # type: ignore[union-attr]
        self.brakes = BrakeMonitor(n)
        # at most this many Newton iterations per implicit stage (a diagnostic knob: fewer
        # make non-convergence, reported per robot, happen)
        self.newton_iterations = K.NEWTON_ITERATIONS
        self.reset(np.zeros(n))

    def _fill(self, d: int, robot: RobotSpec, load: LoadSpec | None) -> None:
        spec, model = robot.dynamics, robot.model
        assert spec is not None
        mp = mass_properties(robot, load)
        tab = wheel_layout(model)
        nw = len(tab)
        try:
            tab[:, K.W_NORMAL] = normal_loads(tab[:, :2], mp.mass_kg, mp.com_xy_m)
        except ValueError as err:
            raise ValueError(f"robot {robot.name!r}: {err}") from None
        mot = spec.motor
        j_driven = spec.wheel_inertia_kg_m2 + mot.rotor_inertia_kg_m2 * mot.gear_ratio**2
        tab[:, K.W_J] = np.where(tab[:, K.W_DRIVEN] > 0, j_driven, spec.wheel_inertia_kg_m2)
        ang = tab[:, K.W_BETA]
        tab[:, K.W_DIRS], tab[:, K.W_DIRS + 1] = np.cos(ang), np.sin(ang)
        ang = ang + tab[:, K.W_GAMMA]
        tab[:, K.W_DIRS + 2], tab[:, K.W_DIRS + 3] = np.cos(ang), np.sin(ang)
        self.wheel[d] = 0.0
        self.wheel[d, :nw] = tab
        r = float(np.asarray(model.wheel_radius_m))
        n_drive = len(model.driven_wheels)
        b = self.body[d]
        b[K.B_MASS], b[K.B_INERTIA] = mp.mass_kg, mp.yaw_inertia_kg_m2
        b[K.B_CX], b[K.B_CY] = mp.com_xy_m
        b[K.B_LEVER] = float(np.hypot(tab[:, 0] - mp.com_xy_m[0], tab[:, 1] - mp.com_xy_m[1]).max())
        b[K.B_RADIUS] = r
        b[K.B_WHEELBASE] = float(np.asarray(getattr(model, "wheelbase_m", 1.0)))
        # the speed controller is tuned for the empty robot: a load makes it slower
        b[K.B_GAIN] = (j_driven + spec.mass_kg * r * r / n_drive) / mot.time_constant_s
        b[K.B_GEAR], b[K.B_TMAX] = mot.gear_ratio, mot.torque_max_nm
        b[K.B_MTAU] = mot.time_constant_s
        b[K.B_TSTALL] = (
            3.0 * mot.torque_max_nm if mot.stall_torque_nm is None else mot.stall_torque_nm
        )
        b[K.B_W0] = np.inf if mot.no_load_speed_rad_s is None else mot.no_load_speed_rad_s
        b[K.B_VSLIP] = spec.slip_speed_m_s
        b[K.B_MAXSUB] = np.inf if spec.max_substep_s is None else spec.max_substep_s
        b[K.B_TYRE] = spec.friction_model == FrictionModel.TYRE
        b[K.B_STEER] = model.has_steering
        if model.has_steering:
            max_angle, max_rate = model.steering_limits()
            b[K.B_DMAX], b[K.B_RATE] = float(np.asarray(max_angle)), float(np.asarray(max_rate))
            st = spec.steering
            b[K.B_SACC], b[K.B_STAU] = st.torque_max_nm / st.inertia_kg_m2, st.time_constant_s
        b[K.B_NW] = nw

    # ------------------------------------------------------------------ API
    def row(self, robot_index: int) -> int:
        """The row of robot ``robot_index`` (index among all robots) in these arrays."""
        hit = np.flatnonzero(self.idx == robot_index)
        if hit.size == 0:
            raise KeyError(f"robot {robot_index} has no dynamics")
        return int(hit[0])

    def set_load(self, robot_index: int, load: LoadSpec) -> None:
        """Pick (or drop) a load at run time: mass, centre of mass, inertia and wheel loads
        change from the next step; the velocity at P is kept."""
        d = self.row(robot_index)
        self._fill(d, self.robots[d], load)
        self.loads[d] = load

    def set_floor(self, floor: FloorFriction) -> None:
        """A new floor (friction and its regions) from the next step."""
        self.floor = floor
        self._regions = floor.table()

    def mass_kg(self) -> np.ndarray:
        return self.body[:, K.B_MASS].copy()

    def braking_deceleration_m_s2(
        self, robot_index: int, mu: float | None = None, direction_rad: float = 0.0
    ) -> float:
        """Straight-line braking limit of a robot as loaded now, moving in ``direction_rad``
        (robot frame; see ``braking``); ``mu`` defaults to the floor's."""
        d = self.row(robot_index)
        mu_w = np.full(int(self.body[d, K.B_NW]), self.floor.mu if mu is None else mu)
        return braking_deceleration_m_s2(self.body[d], self.wheel[d], mu_w, direction_rad)

    def stopping_distance_m(
        self, robot_index: int, speed_m_s: float, mu: float | None = None,
        reaction_time_s: float = 0.0, direction_rad: float = 0.0,
    ) -> float:  # fmt: skip
        """Closed-form stopping distance of a robot as loaded now (the safety-field hook):
        ``speed_m_s`` t_react + v^2 / (2 a_max)."""
        a = self.braking_deceleration_m_s2(robot_index, mu, direction_rad)
        return stopping_distance_m(speed_m_s, a, reaction_time_s)

    def reset(self, steering: np.ndarray) -> None:
        n, w = self.wheel.shape[:2]
        self.vel = np.zeros((n, 3))  # instantaneous twist at P
        self.phi = np.zeros((n, w))
        self.last_targets = np.zeros((n, w))  # wheel-speed targets of the last step
        self.delta = np.asarray(steering, dtype=np.float64).copy()
        self.delta_rate = np.zeros(n)
        self.energy_j = np.zeros((n, w))  # motor work since reset
        self.brakes = BrakeMonitor(n)
        self.last_substeps = np.zeros(n, dtype=np.int64)
        # implicit stages whose Newton iteration stopped unconverged, since reset: how many,
        # the first (step start time, residual in m/s) and the largest residual, per robot
        self.newton_unconverged = np.zeros(n, dtype=np.int64)
        self.newton_first: list[tuple[float, float] | None] = [None] * n
        self.newton_max_residual_m_s = np.zeros(n)
        for d, r in enumerate(self.robots):
            if self.loads[d] != r.dynamics.load:  # type: ignore[union-attr]
                self._fill(d, r, None)
                self.loads[d] = r.dynamics.load  # type: ignore[union-attr]

    def step(
        self,
        poses: np.ndarray,
        targets: np.ndarray,
        delta_target: np.ndarray,
        freeze: np.ndarray,
        dt: float,
        t_s: float,
    ) -> DynamicsStep:
        """Advance the dynamic robots by ``dt``: ``poses`` (D, 3) at the start, ``targets``
        (D, W) driven-wheel speeds, ``delta_target`` (D,), ``freeze`` (D,) robots that bumped
        or stopped (their velocities drop to zero first)."""
        n, w = self.wheel.shape[:2]
        twist = np.empty((n, 3))
        angle = np.empty((n, w))
        steer_angles = np.empty(self.steer_cols.shape)
        torque = np.empty((n, w))
        slip = np.empty((n, w))
        work = np.empty((n, w))
        nsub = np.empty(n, dtype=np.int64)
        speed = np.empty((n, 2))
        braking = np.empty(n, dtype=np.bool_)
        unconverged = np.empty(n, dtype=np.int64)
        residual = np.empty(n)
        vel0 = self.vel.copy()
        K.step_robots(
            float(dt),
            np.ascontiguousarray(poses),
            self._regions,
            self.floor.mu,
            self.body,
            self.wheel,
            np.ascontiguousarray(targets, dtype=np.float64),
            np.ascontiguousarray(delta_target, dtype=np.float64),
            np.ascontiguousarray(freeze, dtype=np.bool_),
            self.last_targets,
            self.vel,
            self.phi,
            self.delta,
            self.delta_rate,
            twist,
            angle,
            self.steer_cols,
            steer_angles,
            torque,
            slip,
            work,
            nsub,
            speed,
            braking,
            unconverged,
            residual,
            self.newton_iterations,
        )
        self.energy_j += work
        self.last_substeps = nsub
        self._count_unconverged(unconverged, residual, t_s)
        self.brakes.update(t_s, poses, twist, dt, speed[:, 0], speed[:, 1], braking, vel0)
        for d in self.brakes.started:  # the closed form as loaded and on the floor now
            # a stop may begin and end in one step: it is then the last event
            stop = self.brakes.active[d] or self.brakes.events[d][-1]
            mu_w = self._mu_under(d, stop.pose)
            stop.mu = float(mu_w.min())
            stop.deceleration_m_s2 = braking_deceleration_m_s2(
                self.body[d], self.wheel[d], mu_w, stop.direction_rad
            )
        angle /= dt
        work /= dt
        return DynamicsStep(twist, angle, self.delta.copy(), steer_angles, torque, slip, work, nsub)

    def _count_unconverged(self, count: np.ndarray, residual: np.ndarray, t_s: float) -> None:
        """Add one step's unconverged stages (per robot, with their largest residual)."""
        if not count.any():
            return
        self.newton_unconverged += count
        np.maximum(self.newton_max_residual_m_s, residual, out=self.newton_max_residual_m_s)
        for d in np.flatnonzero(count):
            if self.newton_first[d] is None:
                self.newton_first[d] = (float(t_s), float(residual[d]))

    def _mu_under(self, d: int, pose: np.ndarray) -> np.ndarray:
        """Friction under each wheel of row d at a world pose."""
        nw = int(self.body[d, K.B_NW])
        px, py = self.wheel[d, :nw, K.W_PX], self.wheel[d, :nw, K.W_PY]
        c, s = np.cos(pose[2]), np.sin(pose[2])
        return self.floor.mu_at(pose[0] + c * px - s * py, pose[1] + s * px + c * py)

    def _newton_summary(self, d: int) -> dict:
        first = self.newton_first[d]
        return {
            "stages": int(self.newton_unconverged[d]),
            "first_t_s": None if first is None else round(first[0], 6),
            "first_residual_m_s": None if first is None else first[1],
            "max_residual_m_s": float(self.newton_max_residual_m_s[d]),
        }

    def summary(self) -> list[dict]:
        """Per dynamic robot: mass, energy per wheel, the braking events measured against
        the closed form v^2 / (2 a_max) and the implicit stages whose Newton iteration did
        not converge (docs/dynamics.md)."""
        out = []
        for d, r in enumerate(self.robots):
            events = []
            for ev in self.brakes.events[d]:
                predicted = ev.speed_m_s**2 / (2.0 * ev.deceleration_m_s2)
                events.append(
                    {
                        "t_start_s": round(ev.t_s, 6),
                        "speed_m_s": round(ev.speed_m_s, 6),
                        "direction_deg": round(math.degrees(ev.direction_rad), 3),
                        "distance_m": round(ev.distance_m, 6),
                        "closed_form_m": round(float(predicted), 6),
                        "deceleration_limit_m_s2": round(ev.deceleration_m_s2, 6),
                        "mu": round(ev.mu, 6),
                    }
                )
            out.append(
                {
                    "name": r.name,
                    "mass_kg": round(float(self.body[d, K.B_MASS]), 6),
                    "load_kg": round(self.loads[d].mass_kg, 6),
                    "motor_energy_j": [round(float(e), 3) for e in self.energy_j[d]],
                    "stops": events,
                    "newton_unconverged": self._newton_summary(d),
                }
            )
        return out


def newton_warning(summary: list[dict]) -> str | None:
    """The one warning line of a run whose Newton iterations did not all converge, from
    ``Dynamics.summary()`` (or summary.json's ``dynamics``): the robot and time of the
    earliest such stage with its residual, and the totals; None when every stage converged."""
    hit = [r for r in summary if r["newton_unconverged"]["stages"] > 0]
    if not hit:
        return None
    first = min(hit, key=lambda r: r["newton_unconverged"]["first_t_s"])
    nu = first["newton_unconverged"]
    total = sum(r["newton_unconverged"]["stages"] for r in hit)
    return (
        f"dynamics: Newton's method did not converge for robot {first['name']!r} in the step "
        f"from t = {nu['first_t_s']:g} s (residual {nu['first_residual_m_s']:.3g} m/s); "
        f"{total} implicit stage(s) of {len(hit)} robot(s) in all, see summary.json "
        "dynamics[].newton_unconverged (docs/dynamics.md)"
    )
