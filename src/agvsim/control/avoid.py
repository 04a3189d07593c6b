"""The thesis's obstacle avoidance (Fig. 22), for every model, as one batch controller.

Drive straight on; when the front range reads below ``trigger_m``, turn 90 deg to the right
(measured with the wheel-odometry heading, with a tolerance rather than the float equality that
tripped the thesis; the target is rounded to a multiple of 90 deg so errors do not pile up),
then drive on. Models that can turn on the spot do so; car-like models
(tricycle with limited steering, Ackermann) turn on full right lock and, when the front gets
too close, back up on full left lock (a K-turn). A bump makes every model back away from the nearer obstacle, then turn.
"""

from __future__ import annotations

import numpy as np

from agvsim.control.api import BatchObservation
from agvsim.kinematics.base import wrap_angle

DRIVE, TURN, REVERSE, BACKOFF = 0, 1, 2, 3
STATE_NAMES = ("drive", "turn_right", "reverse", "back_off")


class ObstacleAvoidance:
    """Batch controller; outputs body twists ``(k, 3)``."""

    def __init__(
        self,
        sensor: str = "rangers",
        front_beams: tuple[int, ...] = (0,),
        back_beams: tuple[int, ...] = (2,),
        trigger_m: float = 0.8,
        speed_m_s: float = 0.5,
        turn_rate_rad_s: float = 1.0,
        turn_angle_rad: float = np.pi / 2,
        can_spin: np.ndarray | bool = True,
        tolerance_rad: float = 0.01,
        backoff_s: float = 0.6,
        snap: bool = True,
    ):
        self.sensor = sensor
        self.front = np.asarray(front_beams, dtype=np.int64)
        self.back = np.asarray(back_beams, dtype=np.int64)
        self.trigger_m, self.speed, self.rate = trigger_m, speed_m_s, turn_rate_rad_s
        self.turn_angle, self.tol, self.backoff_s = turn_angle_rad, tolerance_rad, backoff_s
        self.can_spin = np.asarray(can_spin, dtype=bool)
        self.snap = snap

    def reset(self, k: int, rng: np.random.Generator) -> None:
        self.state = np.full(k, DRIVE, dtype=np.int64)
        self.target = np.zeros(k)
        self.until = np.zeros(k)
        self.spin = np.broadcast_to(self.can_spin, (k,)).copy()
        self.back_dir = -np.ones(k)
        self._started = False

    def _snap(self, heading: np.ndarray) -> np.ndarray:
        """Round a target heading to the nearest multiple of the turn angle (walls of a maze
        are axis aligned: the robot keeps driving square instead of accumulating errors)."""
        if not self.snap:
            return wrap_angle(heading)
        q = self.turn_angle
        return wrap_angle(np.round(heading / q) * q)

    def _min_range(self, ranges: np.ndarray, beams: np.ndarray) -> np.ndarray:
        r = ranges[:, beams]
        r = np.where(r == -np.inf, 0.0, r)  # closer than range_min: as close as it gets
        return r.min(axis=1)

    def step(self, obs: BatchObservation) -> np.ndarray:
        if self.sensor not in obs.ranges:
            raise KeyError(
                f"obstacle avoidance reads sensor {self.sensor!r}, but the robots have "
                f"{sorted(obs.ranges)}"
            )
        ranges = obs.ranges[self.sensor]
        front = self._min_range(ranges, self.front)
        back = self._min_range(ranges, self.back) if self.back.size else np.full(len(front), 9e9)
        heading = obs.odom_pose[:, 2]
        t = obs.t_s
        s = self.state
        car = ~self.spin
        if not self._started:  # hold the initial heading (rounded to the maze's axes)
            self.target[:] = self._snap(heading)
            self._started = True
        close = self.trigger_m * 0.45

        # transitions, each guarded on the current state (first match wins)
        in_back = s == BACKOFF
        bumped = obs.bump & ~in_back
        s[bumped] = BACKOFF
        self.until[bumped] = t + self.backoff_s
        # back off away from the nearer obstacle: reverse if the front is nearer, else forward
        self.back_dir[bumped] = np.where(front[bumped] <= back[bumped], -1.0, 1.0)
        # done backing off, or bumped again while doing it: turn
        done_back = in_back & ((t >= self.until) | obs.bump)
        s[done_back] = TURN
        self.target[done_back] = self._snap(heading[done_back] - self.turn_angle)
        start_turn = (s == DRIVE) & (front < self.trigger_m)
        s[start_turn] = TURN
        self.target[start_turn] = self._snap(heading[start_turn] - self.turn_angle)
        err = wrap_angle(self.target - heading)
        turned = ((s == TURN) | (s == REVERSE)) & (np.abs(err) < self.tol)
        s[turned] = DRIVE
        go_back = (s == TURN) & car & (front < close)
        s[go_back] = REVERSE
        go_fwd = (s == REVERSE) & ((back < close) | (front > self.trigger_m))
        s[go_fwd] = TURN

        cmd = np.zeros((len(s), 3))
        drive = s == DRIVE
        cmd[drive, 0] = self.speed
        # hold the target heading while driving (P control): no drift after turns
        cmd[drive, 2] = np.clip(2.0 * err[drive], -self.rate, self.rate)
        turn = s == TURN
        # in place: rotate right, slowing near the target; car-like: creep on full right lock
        cmd[turn & ~car, 2] = -np.clip(np.abs(err[turn & ~car]) * 3.0, 0.2, 1.0) * self.rate
        cmd[turn & car, 0] = 0.5 * self.speed
        cmd[turn & car, 2] = -10.0 * self.rate
        rev = s == REVERSE
        cmd[rev, 0] = -0.5 * self.speed
        cmd[rev, 2] = -10.0 * self.rate
        back_off = s == BACKOFF
        cmd[back_off, 0] = 0.5 * self.speed * self.back_dir[back_off]
        return cmd

    def state_names(self) -> list[str]:
        return [STATE_NAMES[k] for k in self.state]
