"""The thesis's obstacle avoidance (Fig. 22), for every model, as one batch controller.

Drive straight on; when the front range reads below ``trigger_m``, turn 90 deg to the right,
then drive on. Angles are compared with a tolerance (the thesis's float equality failed on
discrete steps) and the target heading is rounded to a multiple of 90 deg, so errors do not
pile up. The heading comes from the ground-truth pose, as the thesis's charts read the
simulator's pose feedback, or from wheel odometry (``heading_source="odometry"``). Models that
turn on the spot do so; car-like models (tricycle with limited steering, Ackermann) turn on
full right lock and, when the front gets too close, back up on full left lock (a K-turn). A
bump makes every model back away from the nearer obstacle, then turn.

While driving, the robot keeps ``side_clearance_m`` off the walls beside it (it veers away from
a side reading closer than that; between two close walls it centres). The thesis's robots
turned on the spot about their body centre, but a tricycle spins about its rear axle and an
Ackermann car turns on an arc: their noses swing out by more than half their width, and a
right turn started next to a wall on the right hits it (found by 10-minute endurance runs in
the App. C.1 maze). The default clearance is ``0.8 * trigger_m``: the room the designer gives
the turn ahead, asked for at the side the robot turns to as well.

Other robots (``sight``, a :class:`agvsim.control.traffic.RobotSight` on the robots' lidar): a
robot in the body's path ahead counts as an obstacle ahead (the robot turns right as it would
for a wall), one in the path behind as one behind (a car's K-turn stops reversing), and every
command is slowed to stop ``sight.stop_gap_m`` short of a robot in the way
(``RobotSight.limit``). The single front ranger of the thesis misses a robot coming in at an
angle; the lidar does not. Two robots can hold each other still (one turning on the spot next
to a car that has no room either way): a robot held for ``hold_s`` backs away, forwards or
backwards, whichever way has more room, then turns again.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from agvsim.angles import wrap_angle, wrap_scalar
from agvsim.control.api import BatchObservation
from agvsim.control.traffic import RobotSight

DRIVE, TURN, REVERSE, BACKOFF = 0, 1, 2, 3
SIDE_PER_TRIGGER = 0.8  # the default side clearance, in units of the trigger distance
STATE_NAMES = ("drive", "turn_right", "reverse", "back_off")


class ObstacleAvoidance:
    """Batch controller; outputs body twists ``(k, 3)``."""

    def __init__(
        self,
        sensor: str = "rangers",
        front_beams: tuple[int, ...] = (0,),
        back_beams: tuple[int, ...] = (2,),
        trigger_m: float | np.ndarray = 0.8,
        side_beams: tuple[tuple[int, ...], tuple[int, ...]] | None = None,
        side_clearance_m: float | np.ndarray | None = None,
        speed_m_s: float | np.ndarray = 0.5,
        turn_rate_rad_s: float | np.ndarray = 1.0,
        turn_angle_rad: float = np.pi / 2,
        can_spin: np.ndarray | bool = True,
        tolerance_rad: float = 0.01,
        backoff_s: float = 0.6,
        snap: bool = True,
        heading_source: str = "true_pose",
        sight: RobotSight | None = None,
        hold_s: float = 1.5,
    ):
        self.sensor = sensor
        self.front = np.asarray(front_beams, dtype=np.int64)
        self.back = np.asarray(back_beams, dtype=np.int64)
        self.trigger_m, self.speed, self.rate = trigger_m, speed_m_s, turn_rate_rad_s
        self.turn_angle, self.tol, self.backoff_s = turn_angle_rad, tolerance_rad, backoff_s
        self.can_spin = np.asarray(can_spin, dtype=bool)
        self.snap = snap
        # (left, right) beams; None: a quarter turn either side of the front beams (found on the
        # first step, when the number of beams is known)
        self.side_beams = side_beams
        self.side_clear = (
            SIDE_PER_TRIGGER * np.asarray(trigger_m)
            if side_clearance_m is None
            else side_clearance_m
        )
        if heading_source not in ("true_pose", "odometry"):
            raise ValueError(
                f"heading_source must be 'true_pose' or 'odometry', got {heading_source!r}"
            )
        self.heading_source = heading_source
        self.sight = sight
        self.hold_s = hold_s

    def reset(self, k: int, rng: np.random.Generator) -> None:
        self.state = np.full(k, DRIVE, dtype=np.int64)
        self.target = np.zeros(k)
        self.until = np.zeros(k)
        self.spin = np.broadcast_to(self.can_spin, (k,)).copy()
        self.back_dir = -np.ones(k)
        self.held_since = np.full(k, np.nan)  # since when another robot holds it still
        self._started = False
        self._left = self._right = np.zeros(0, dtype=np.int64)
        # (k, 8) settings of each robot: a number is every robot's, an array one each
        values = (
            self.trigger_m,
            self.speed,
            self.rate,
            self.turn_angle,
            self.tol,
            self.backoff_s,
            float(self.snap),
            self.side_clear,
        )
        self._params = np.empty((k, len(values)))
        for c, v in enumerate(values):
            self._params[:, c] = np.asarray(v, dtype=np.float64)

    def _snap(self, heading: np.ndarray) -> np.ndarray:
        """Round a target heading to the nearest multiple of the turn angle (walls of a maze
        are axis aligned: the robot keeps driving square instead of accumulating errors)."""
        if not self.snap:
            return wrap_angle(heading)
        q = self.turn_angle
        return wrap_angle(np.round(heading / q) * q)

    def step(self, obs: BatchObservation) -> np.ndarray:
        if self.sensor not in obs.ranges:
            raise KeyError(
                f"obstacle avoidance reads sensor {self.sensor!r}, but the robots have "
                f"{sorted(obs.ranges)}"
            )
        # the thesis's charts read the simulator's pose feedback; 'odometry' is what a real
        # robot has (its heading drifts with encoder noise, and so does the robot's path)
        pose = obs.true_pose if self.heading_source == "true_pose" else obs.odom_pose
        heading = pose[:, 2]
        ranges = np.ascontiguousarray(obs.ranges[self.sensor])
        if not self._started:  # hold the initial heading (rounded to the maze's axes)
            self.target[:] = self._snap(heading)
            left, right = self.side_beams or side_beams_of(self.front, self.back, ranges.shape[1])
            self._left = np.asarray(left, dtype=np.int64)
            self._right = np.asarray(right, dtype=np.int64)
            self._started = True
        params = self._params
        k = len(heading)
        robot_front, robot_back = np.full(k, np.inf), np.full(k, np.inf)
        walls_back = np.full(k, np.inf)
        blocked = np.zeros(k, dtype=bool)
        sight = self.sight if self.sight is not None and self.sight.sensor in obs.ranges else None
        if sight is not None:  # other robots on the lidar, as distances from the reference point
            scan = sight.robot_points(obs.true_pose, obs.ranges[sight.sensor])
            fp = sight.body
            ahead, walls, behind, walls_behind = sight.free_m_many(
                obs.true_pose, scan, [(0.0, None), (0.0, 0.03), (np.pi, None), (np.pi, 0.03)]
            )
            robot_front = np.minimum(ahead, walls) + fp.half_length_m + fp.offset_x_m
            tail = fp.half_length_m - fp.offset_x_m
            robot_back = behind + tail
            walls_back = walls_behind + tail
            blocked = ahead < sight.stop_gap_m + 0.1
        cmd = np.zeros((k, 3))
        _avoid_step(
            self.state,
            self.target,
            self.until,
            self.back_dir,
            self.spin,
            ranges,
            self.front,
            self.back,
            self._left,
            self._right,
            np.ascontiguousarray(heading),
            np.ascontiguousarray(obs.bump),
            robot_front,
            robot_back,
            blocked,
            obs.t_s,
            params,
            cmd,
        )
        if sight is not None:
            f = sight.factor(cmd, obs.true_pose, scan)
            if self._give_way(cmd, f, obs.t_s, ranges, robot_front, robot_back, walls_back):
                f = sight.factor(cmd, obs.true_pose, scan)  # for the commands it changed
            cmd = cmd * f[:, None]
        return cmd

    def _give_way(
        self,
        cmd: np.ndarray,
        factor: np.ndarray,
        t_s: float,
        ranges: np.ndarray,
        robot_front: np.ndarray,
        robot_back: np.ndarray,
        walls_back: np.ndarray,
    ) -> bool:
        """Robots that another one has held still for ``hold_s`` (two robots that block each
        other's turns) back away, forwards or backwards, whichever way has more room, for
        ``backoff_s``; then they turn again. Writes their new commands into ``cmd``; True if
        there were any."""
        wants = np.abs(cmd).max(axis=1) > 1e-6
        held = wants & (factor < 0.05)
        self.held_since[~held] = np.nan
        self.held_since[held & np.isnan(self.held_since)] = t_s
        due = held & (t_s - self.held_since >= self.hold_s)
        if not due.any():
            return False
        r = np.where(ranges == -np.inf, 0.0, ranges)
        front = np.minimum(r[:, self.front].min(axis=1), robot_front)
        back = np.minimum(robot_back, walls_back)
        if self.back.size:
            back = np.minimum(back, r[:, self.back].min(axis=1))
        for i in np.flatnonzero(due):
            self.state[i] = BACKOFF
            self.until[i] = t_s + self.backoff_s
            self.back_dir[i] = 1.0 if front[i] > back[i] else -1.0
            self.held_since[i] = np.nan
            cmd[i] = (0.5 * self._params[i, 1] * self.back_dir[i], 0.0, 0.0)
        return True

    def state_names(self) -> list[str]:
        return [STATE_NAMES[k] for k in self.state]


def side_beams_of(
    front: np.ndarray, back: np.ndarray, n_beams: int
) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(left, right) beams a quarter turn either side of the front beams, for a sensor whose
    beams go once round evenly (the thesis rangers 0/90/180/270 deg, a 360 deg lidar): there
    the back beams sit half a turn from the front ones. Other fans get none (no side keeping)."""
    if n_beams % 4 or front.size == 0 or back.size == 0:
        return (), ()
    a = 2.0 * np.pi * front / n_beams  # the middle of the front beams (they may wrap round)
    f = int(round(np.arctan2(np.sin(a).mean(), np.cos(a).mean()) * n_beams / (2.0 * np.pi)))
    f %= n_beams
    if (f + n_beams // 2) % n_beams not in set(back.tolist()):
        return (), ()
    q = n_beams // 4
    return ((f + q) % n_beams,), ((f - q) % n_beams,)


@njit(cache=True, error_model="numpy")
def _nearest(ranges, i, beams) -> float:
    """Smallest reading among ``beams`` of robot i (-inf, too close, counts as 0)."""
    m = np.inf
    for b in beams:
        r = ranges[i, b]
        if r == -np.inf:
            r = 0.0
        m = min(m, r)
    return m


@njit(cache=True, error_model="numpy")
def _snap(h: float, q: float, snap: bool) -> float:
    return wrap_scalar(round(h / q) * q) if snap else wrap_scalar(h)


@njit(cache=True, error_model="numpy")
def _avoid_step(
    state,
    target,
    until,
    back_dir,
    spin,
    ranges,
    front_beams,
    back_beams,
    left_beams,
    right_beams,
    heading,
    bump,
    robot_front,
    robot_back,
    blocked,
    t,
    params,
    cmd,
):
    """One step of the state machine for every robot; writes twists into ``cmd (k, 3)``.
    ``params (k, 8)``: each robot's trigger, speed, turn rate, turn angle, tolerance, back-off
    time, snap (1.0 or 0.0) and side clearance."""
    for i in range(state.shape[0]):
        trigger, speed, rate, turn, tol, backoff_s = params[i, :6]
        snap = params[i, 6] > 0.5
        side_clear = params[i, 7]
        close = 0.45 * trigger
        front = min(_nearest(ranges, i, front_beams), robot_front[i])
        back = min(_nearest(ranges, i, back_beams) if back_beams.size else np.inf, robot_back[i])
        h = heading[i]
        s = state[i]
        was_back = s == BACKOFF
        # transitions, in priority order
        if bump[i] and not was_back:  # back away from the nearer obstacle
            s = BACKOFF
            until[i] = t + backoff_s
            back_dir[i] = -1.0 if front <= back else 1.0
        if was_back and bump[i]:  # blocked that way too: try the other way
            back_dir[i] = -back_dir[i]
        if was_back and t >= until[i]:
            s = TURN
            target[i] = _snap(h - turn, turn, snap)
        if s == DRIVE and front < trigger:  # the thesis: obstacle ahead -> turn 90 deg right
            s = TURN
            target[i] = _snap(h - turn, turn, snap)
        err = wrap_scalar(target[i] - h)
        if (s == TURN or s == REVERSE) and abs(err) < tol:
            s = DRIVE
        if s == TURN and not spin[i] and (front < close or blocked[i]):  # car-like: K-turn
            s = REVERSE
        if s == REVERSE and (back < close or front > trigger):
            s = TURN
        state[i] = s
        # outputs of the active state
        vx, w = 0.0, 0.0
        if s == DRIVE:  # straight on, holding the target heading, clear of the side walls
            veer = 0.0  # > 0: away from a wall on the right
            if right_beams.size:
                veer += max(side_clear - _nearest(ranges, i, right_beams), 0.0)
            if left_beams.size:
                veer -= max(side_clear - _nearest(ranges, i, left_beams), 0.0)
            veer = min(max(2.0 * veer, -0.35), 0.35)  # rad off the target heading
            vx, w = speed, min(max(2.0 * (err + veer), -rate), rate)
        elif s == TURN and spin[i]:  # on the spot, slowing near the target
            w = -min(max(abs(err) * 3.0, 0.2), 1.0) * rate
        elif s == TURN:  # creep on full right lock
            vx, w = 0.5 * speed, -10.0 * rate
        elif s == REVERSE:  # back on full left lock: still turning right
            vx, w = -0.5 * speed, -10.0 * rate
        else:  # BACKOFF
            vx = 0.5 * speed * back_dir[i]
        cmd[i, 0], cmd[i, 2] = vx, w
