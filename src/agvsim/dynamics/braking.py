"""Braking: the closed-form deceleration limit and stopping distance of a robot, and a monitor
that measures the stops of a run.

For a straight forward stop every driven wheel i pushes back with its friction
mu_i N_i |cos(beta_i + gamma_i)| or with its motor, whichever gives first (a roller wheel's
force lies along its roller axis at gamma_i to its rolling direction beta_i), so

    a_max = sum_i F_i / m_eff,       stopping distance = v t_react + v^2 / (2 a_max)

which is the v^2 / (2 mu g) of the textbook when every wheel is braked and friction limits.
These are the figures a safety field's length needs (``stopping_distance_m``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agvsim.dynamics import kernel as K
from agvsim.dynamics.spec import G_M_S2


def braking_deceleration_m_s2(
    body: np.ndarray, wheel: np.ndarray, mu: np.ndarray, direction_rad: float = 0.0
) -> float:
    """Deceleration limit (m/s^2) of a straight stop while moving in ``direction_rad`` (robot
    frame: 0 forward, pi/2 a strafe to the left), from one robot's rows of the dynamics
    tables (``body`` (NB,), ``wheel`` (W, NWC)) and the friction ``mu`` (W,) under each wheel.
    Passive wheels roll freely and do not brake; the side forces of a symmetric robot cancel.

    A wheel whose motor gives first still has to stop its own spin, so it pushes the body
    back with (G T_max - J a g_i / r) g_i / r, where g_i = |cos(beta_i + gamma_i - psi)| /
    |cos gamma_i| is its spin per unit of speed (times r); one whose friction gives first
    pushes back with mu_i N_i |cos(beta_i + gamma_i - psi)|. Which wheels are which is found by
    a fixed point (at most W rounds)."""
    nw = int(body[K.B_NW])
    torque = body[K.B_TMAX] * body[K.B_GEAR]
    r, m = body[K.B_RADIUS], body[K.B_MASS]
    along, ratio, fric, jw = [], [], [], []
    for i in range(nw):
        wi = wheel[i]
        if wi[K.W_DRIVEN] < 0.5:
            continue
        x = abs(math.cos(wi[K.W_BETA] + wi[K.W_GAMMA] - direction_rad))
        ea = abs(math.cos(wi[K.W_GAMMA]))
        if x < 1e-12 or ea < 1e-12:
            continue
        along.append(x)
        ratio.append(x / ea)
        fric.append(float(mu[i]) * wi[K.W_NORMAL] * x)
        jw.append(wi[K.W_J])
    slipping = [False] * len(along)
    a = 0.0
    for _ in range(len(along) + 1):
        force, mass = 0.0, m
        for k in range(len(along)):
            if slipping[k]:
                force += fric[k]
            else:
                force += torque * ratio[k] / r
                mass += jw[k] * ratio[k] ** 2 / (r * r)
        a = force / mass
        new = [
            (torque - jw[k] * a * ratio[k] / r) * ratio[k] / r > fric[k] for k in range(len(along))
        ]
        if new == slipping:
            break
        slipping = [s or n for s, n in zip(slipping, new, strict=True)]
    return a


def friction_deceleration_m_s2(mu: float) -> float:
    """mu g: the limit when every wheel brakes and friction gives first."""
    return mu * G_M_S2


def stopping_distance_m(
    speed_m_s: float, deceleration_m_s2: float, reaction_time_s: float = 0.0
) -> float:
    """Distance (m) to stop from ``speed_m_s`` at a constant ``deceleration_m_s2`` after
    ``reaction_time_s`` at full speed: v t + v^2 / (2 a)."""
    if not deceleration_m_s2 > 0:
        raise ValueError(f"deceleration_m_s2 must be > 0, got {deceleration_m_s2}")
    v = abs(speed_m_s)
    return v * reaction_time_s + v * v / (2.0 * deceleration_m_s2)


@dataclass
class Stop:
    t_s: float  # when braking began
    speed_m_s: float  # speed then
    pose: np.ndarray  # (3,) pose then
    direction_rad: float  # direction of travel then (robot frame)
    distance_m: float = 0.0
    deceleration_m_s2: float = math.nan  # closed-form limit then (as loaded, on that floor)
    mu: float = math.nan  # lowest friction under its wheels then


class BrakeMonitor:
    """Finds stops: a robot moving faster than ``min_speed_m_s`` whose driven wheels are all
    commanded to zero; the stop ends when it is slower than ``rest_speed_m_s`` (a new command
    before that abandons it). Distances are summed step by step."""

    def __init__(self, n: int, min_speed_m_s: float = 0.05, rest_speed_m_s: float = 1e-3):
        self.min_speed, self.rest_speed = min_speed_m_s, rest_speed_m_s
        self.active: list[Stop | None] = [None] * n
        self._on = np.zeros(n, dtype=bool)
        self.started: list[int] = []  # rows whose stop began in the last update
        self.events: list[list[Stop]] = [[] for _ in range(n)]

    def update(
        self,
        t_s: float,
        poses: np.ndarray,
        twist: np.ndarray,
        dt: float,
        speed_before: np.ndarray,
        speed_after: np.ndarray,
        braking: np.ndarray,
        velocity: np.ndarray,
    ) -> None:
        """One step: ``poses`` (D, 3) at its start, ``twist`` (D, 3) over it, speeds at its
        start and end, ``braking`` (D,) all driven wheels commanded to zero, ``velocity``
        (D, 3) at its start."""
        watch = (braking & (speed_before > self.min_speed)) | self._on
        self.started = []
        if not watch.any():  # the common case: nobody brakes
            return
        for d in np.flatnonzero(watch):
            stop = self.active[d]
            if not braking[d]:
                self.active[d], self._on[d] = None, False
                continue
            if stop is None:
                psi = math.atan2(velocity[d, 1], velocity[d, 0])
                stop = Stop(t_s, float(speed_before[d]), poses[d].copy(), psi)
                self.active[d], self._on[d] = stop, True
                self.started.append(int(d))
            stop.distance_m += float(math.hypot(twist[d, 0], twist[d, 1])) * dt
            if speed_after[d] < self.rest_speed:
                self.events[d].append(stop)
                self.active[d], self._on[d] = None, False
