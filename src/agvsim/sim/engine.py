"""The simulation: a fixed-step loop over all robots at once.

Each step, for every robot together (structure of arrays, a loop over model kinds only):

    commands  = controllers(observations)
    commands  = safety(commands, scans)      # only robots with a safety scanner: brake, cap
    wheels    = actuate(commands)            # inverse or forward kinematics, limits
    wheels    = dynamics(wheels)             # only robots with dynamics: forces, slip
    poses     = move(poses, wheels.twist)    # exact SE(2) integration, swept collision checks
    odometry  = dead_reckon(wheel encoders)  # noisy encoders, apart from the ground truth
    scans     = sense(poses)                 # sensors due at this time, one ray-cast call
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from dataclasses import replace as dc_replace
from typing import Any

import numpy as np

from agvsim.control.api import (
    BatchController,
    BatchObservation,
    ControlMode,
    LaserScan,
    Observation,
    Twist,
    WheelCommand,
    command_to_array,
)
from agvsim.dynamics.spec import FloorFriction
from agvsim.dynamics.vehicle import Dynamics
from agvsim.geometry import box_tables
from agvsim.kinematics import actuation, fused
from agvsim.kinematics.base import _integrate_rows, stack_models
from agvsim.sensors.camera_rig import CameraFrame, CameraRig
from agvsim.sensors.range_sensor import apply_noise
from agvsim.sensors.raycast import RayCaster
from agvsim.sim import observe
from agvsim.sim.collide import Collider, box_pairs_overlapping
from agvsim.sim.guidance import GuidanceRig
from agvsim.sim.kernels import move_bodies, pair_faults
from agvsim.sim.safety import PROTECTIVE, SafetyTable, count_events
from agvsim.sim.spec import RobotSpec, World
from agvsim.sim.state import ROBOT_ROWS, SensorTable, SimState  # noqa: F401 - in hints
from agvsim.sim.watchdog import ControllerClock, TimeLimitExceeded, check_limit
from agvsim.world.grid import OccupancyGrid

W_MAX = 4  # most wheels of any model
S_MAX = 2  # most steered wheels of any model


class ControllerError(RuntimeError):
    """A controller raised, returned an invalid command or ran past its time limit."""

    def __init__(self, robot: str, t_s: float, cause: BaseException):
        what = (
            str(cause)
            if isinstance(cause, Exception | TimeLimitExceeded)
            else f"it raised {type(cause).__name__}({cause})"  # SystemExit: not a way to stop
        )
        super().__init__(f"controller of robot {robot!r} failed at t={t_s:.3f} s: {what}")
        self.robot, self.t_s, self.cause = robot, t_s, cause


@dataclass
class Binding:
    """A controller and the robots (indices) it drives. ``batch`` controllers get arrays;
    others are called once per robot with an ``Observation``. ``user_code``: the user's own
    code (a ``python`` controller), held to ``Simulation.controller_time_limit_s``."""

    controller: Any
    robots: tuple[int, ...]
    batch: bool = False
    user_code: bool = False


@dataclass
class _Group:
    """Robots sharing one kinematic model class (parameters stacked per robot)."""

    idx: np.ndarray
    model: Any  # the stacked KinematicModel of the group
    n_drive: int
    n_wheels: int
    n_steer: int
    cmd_width: int
    sel: slice | np.ndarray  # the robots: a slice when they are consecutive
    driven: slice | list  # driven wheel columns
    rel: np.ndarray | None = None  # (k, 1) encoder noise, None when zero for all
    abs: np.ndarray | None = None
    steer_noise: np.ndarray | None = None
    car: int | None = None  # agvsim.kinematics.fused kind: actuated in one kernel call
    car_params: np.ndarray | None = None  # (k, 6) fused.car_params of the model
    car_parallel: bool = False  # an Ackermann group with the thesis's parallel steering


class Simulation:
    def __init__(
        self,
        world: World,
        robots: Sequence[RobotSpec],
        controllers: Sequence[Binding] = (),
        dt_s: float = 0.02,
        seed: int = 0,
        knows: dict[str, Sequence[str]] | None = None,
        on_controller_error: str = "stop_run",
        controller_time_limit_s: float | None = None,
    ):
        if not robots:
            raise ValueError("a simulation needs at least one robot")
        names = [r.name for r in robots]
        if len(set(names)) != len(names):
            raise ValueError(f"robot names must be unique, got {names}")
        if not dt_s > 0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        self.world, self.robots, self.dt_s, self.seed = world, list(robots), float(dt_s), seed
        if on_controller_error not in ("stop_run", "stop_robot"):
            raise ValueError(
                "on_controller_error must be 'stop_run' or 'stop_robot', "
                f"got {on_controller_error!r}"
            )
        self.on_controller_error = on_controller_error
        self.controller_time_limit_s = controller_time_limit_s
        index = {n: k for k, n in enumerate(names)}
        #: robot index -> the robots whose true pose it is given (``knows:``)
        self.knows: list[list[int]] = [[] for _ in robots]
        for who, whom in (knows or {}).items():
            for other in whom:
                if who not in index or other not in index:
                    raise ValueError(
                        f"knows: unknown robot in {who!r} -> {other!r}; robots: {names}"
                    )
                self.knows[index[who]].append(index[other])
        self.bindings = list(controllers)
        #: the robots of each binding, as index arrays
        self.binding_robots = [np.asarray(b.robots, dtype=np.int64) for b in self.bindings]
        self.n = len(self.robots)
        self.caster = RayCaster(world.grid)
        self.collider = Collider(world.grid)
        self.sensors = SensorTable.build(self.robots)
        # cameras only where robots have them: runs without cameras pay nothing
        has_cam = any(r.cameras for r in self.robots)
        self.cameras: CameraRig | None = CameraRig(self.robots, world) if has_cam else None
        self._groups = self._build_groups()
        # guidance sensors only where robots have them or the world has reflectors
        has_guide = world.reflectors is not None or any(
            r.line_sensors or r.floor_cameras for r in self.robots
        )
        self.guidance: GuidanceRig | None = GuidanceRig(self.robots, world) if has_guide else None
        has_dyn = any(r.dynamics is not None for r in self.robots)
        self.dynamics = Dynamics(self.robots, world.floor, W_MAX, S_MAX) if has_dyn else None
        self._dyn_sel: slice | np.ndarray = np.zeros(0, dtype=np.int64)
        if self.dynamics is not None:  # the dynamic robots: a slice when they are consecutive
            di = self.dynamics.idx
            whole = np.array_equal(di, np.arange(di[0], di[0] + len(di)))
            self._dyn_sel = slice(int(di[0]), int(di[0]) + len(di)) if whole else di
        hl_hw = np.array([r.footprint_half_m for r in self.robots], dtype=np.float64)
        self._half = hl_hw  # (N, 2)
        self._offset = np.array([r.body_offset_x_m for r in self.robots], dtype=np.float64)
        self._radius = np.array([r.bounding_radius_m for r in self.robots])
        self._substep_len = 0.5 * min(world.grid.resolution_m, float(hl_hw.min()))
        self._static_tab = box_tables(world.boxes)
        self._mode_twist = np.array([r.mode == ControlMode.INVERSE for r in self.robots])
        self._batch_slots: dict[bytes, dict[str, tuple[slice | np.ndarray, int]]] = {}
        #: the safety scanners (None without any: those runs pay nothing)
        self.safety: SafetyTable | None = None
        if any(r.safety is not None for r in self.robots):
            self.safety = SafetyTable.build(self.robots, self.sensors)
        self.reset(seed)

    # ------------------------------------------------------------------ set-up
    def _build_groups(self) -> list[_Group]:
        by_kind: dict[tuple, list[int]] = {}
        for i, r in enumerate(self.robots):
            key = (type(r.model), getattr(r.model, "steering_geometry", None))
            by_kind.setdefault(key, []).append(i)
        groups = []
        odo = np.array(
            [
                (
                    r.odometry.wheel_noise_rel,
                    r.odometry.wheel_noise_abs_rad_s,
                    r.odometry.steering_noise_rad,
                )
                for r in self.robots
            ]
        )
        for idx in by_kind.values():
            model = stack_models([self.robots[i].model for i in idx])
            n_drive = len(model.driven_wheels)
            dw = list(model.driven_wheels)
            consecutive = idx == list(range(idx[0], idx[0] + len(idx)))
            o = odo[idx]
            car = fused.car_kind(model)
            groups.append(
                _Group(
                    idx=np.array(idx),
                    model=model,
                    n_drive=n_drive,
                    n_wheels=len(model.wheel_names),
                    n_steer=len(model.steered_wheels),
                    cmd_width=n_drive + int(model.has_steering),
                    sel=slice(idx[0], idx[0] + len(idx)) if consecutive else np.array(idx),
                    driven=slice(dw[0], dw[-1] + 1) if dw == list(range(dw[0], dw[-1] + 1)) else dw,
                    rel=o[:, 0:1] if np.any(o[:, 0] > 0) else None,
                    abs=o[:, 1:2] if np.any(o[:, 1] > 0) else None,
                    steer_noise=o[:, 2] if model.has_steering and np.any(o[:, 2] > 0) else None,
                    car=car,
                    car_params=None if car is None else fused.car_params(model, len(idx)),
                    car_parallel=getattr(model, "steering_geometry", "") == "parallel",
                )
            )
        return groups

    def cmd_width(self, i: int) -> int:
        """Numbers a forward-mode command of robot i holds (driven wheels + steering)."""
        m = self.robots[i].model
        return len(m.driven_wheels) + int(m.has_steering)

    @property
    def rng(self) -> np.random.Generator:
        """The simulation's generator (in the state: snapshots and restores carry it)."""
        return self.state.rng

    @property
    def errors(self) -> list[ControllerError]:
        """The controller errors of this run so far (``on_controller_error: stop_robot``)."""
        return self.state.errors

    def reset(self, seed: int | None = None, poses: np.ndarray | None = None) -> None:
        """Back to t = 0 with a fresh generator from ``seed`` (default: the last one), the
        robots at ``poses`` ``(N, 3)`` (default: their initial poses) and at rest; controllers
        are reset; senses and renders once."""
        if seed is not None:
            self.seed = seed
        n = self.n
        if poses is None:
            start = np.array([r.initial_pose for r in self.robots], dtype=np.float64)
        else:
            start = np.array(poses, dtype=np.float64)
            if start.shape != (n, 3) or not np.isfinite(start).all():
                raise ValueError(f"reset: poses must be ({n}, 3) finite numbers, got {poses!r}")
        rng = np.random.default_rng(self.seed)
        self.state = SimState.zeros(n, self.sensors, W_MAX, S_MAX, start, rng, self._mode_twist)
        st = self.state
        if self.dynamics is not None:
            self.dynamics.reset(st.steering[self.dynamics.idx])
            st.wheel_torque_nm, st.wheel_slip_m_s, st.wheel_power_w = np.zeros((3, n, W_MAX))
        if self.cameras is not None:
            c = self.cameras.count
            st.images, st.depths = self.cameras.blank_frames()
            st.image_stamp, st.image_seq = np.zeros(c), np.zeros(c, dtype=np.int64)
            st.image_pose, st.next_image_s = np.zeros((c, 3)), np.zeros(c)
        if self.guidance is not None:
            g = self.guidance
            st.line_active = np.zeros((g.line_count, g.line_pos.shape[1]), dtype=bool)
            st.line_offsets = np.full((g.line_count, g.line_offsets_width), np.nan)
            st.line_spot = np.full(g.line_count, -1, dtype=np.int64)
            st.line_stamp = np.zeros(g.line_count)
            st.fix_pose, st.fix_code = np.zeros((g.cam_count, 3)), np.full(g.cam_count, -1)
            st.fix_stamp, st.fix_seq = np.zeros(g.cam_count), np.zeros(g.cam_count, np.int64)
            st.next_fix_s = np.zeros(g.cam_count)
            if self.world.reflectors is not None:
                st.intensities = np.zeros_like(st.scans)
        for b in self.bindings:
            try:
                if b.batch:
                    b.controller.reset(len(b.robots), rng)
                elif hasattr(b.controller, "reset"):
                    b.controller.reset()
            except KeyboardInterrupt:
                raise
            except BaseException as exc:  # noqa: BLE001 - user code, SystemExit included
                who = ",".join(self.robots[i].name for i in b.robots)
                raise ControllerError(who, 0.0, exc) from exc
        self._sense(force=True)
        self._render(force=True)
        self._guide(force=True)

    # ------------------------------------------------------------------ changing the state
    def place(self, i: int, pose: Sequence[float] | np.ndarray, at_rest: bool = False) -> None:
        """Put robot ``i`` at ``pose`` (x, y, theta) now, its odometry with it (a user moving
        it, a new episode); ``at_rest``: also stopped (no twist, wheel speed or steering, no
        bump). Sensors keep their readings until they fire next (see :meth:`sense_now`)."""
        p = np.asarray(pose, dtype=np.float64)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"place: pose must be 3 finite numbers (x, y, theta), got {pose!r}")
        st = self.state
        st.poses[i] = p
        st.odom_poses[i] = p
        if at_rest:
            for rows in (st.twists, st.wheel_speeds, st.steering, st.steer_angles):
                rows[i] = 0.0
            st.bump[i] = st.bump_wall[i] = st.bump_robot[i] = False

    def show_recorded(
        self,
        t_s: float,
        poses: np.ndarray | None = None,
        twists: np.ndarray | None = None,
        scans: Sequence[tuple[int, float, np.ndarray] | tuple[int, None, None]] = (),
    ) -> None:
        """Show recorded data instead of simulating (a replay): the clock at ``t_s``, the
        robots at ``poses`` with ``twists`` ``(N, 3)`` where given, and each ``(slot, stamp,
        ranges)`` of ``scans`` as sensor ``slot``'s latest reading (``(slot, None, None)``: no
        reading yet, all inf)."""
        st = self.state
        if poses is not None:
            st.poses = np.array(poses, dtype=np.float64)
        if twists is not None:
            st.twists = np.array(twists, dtype=np.float64)
        st.t_s = float(t_s)
        for slot, stamp, ranges in scans:
            if stamp is None or ranges is None:
                st.scans[slot] = np.inf
            else:
                st.scans[slot, : len(ranges)] = ranges
                st.scan_stamp[slot] = stamp

    def sense_now(self) -> None:
        """Cast every sensor now, due or not (after :meth:`place`, an edit of the walls)."""
        self._sense(force=True)

    def carry_over(self, old: SimState, rows: dict[int, int]) -> None:
        """Continue another simulation's run (this one rebuilt from an edited scenario): its
        clock, and for each ``rows[i] = j`` robot ``i`` takes the physical state of robot ``j``
        of ``old`` (pose, motion, wheels, steering, odometry, counters: ``ROBOT_ROWS``)."""
        st = self.state
        for i, j in rows.items():
            for name in ROBOT_ROWS:
                getattr(st, name)[i] = getattr(old, name)[j]
        st.t_s, st.step = old.t_s, old.step

    def snapshot(self) -> Snapshot:
        """The whole changing state now (robots, commands, sensors, generator, dynamics and
        the controllers' memory), for :meth:`restore`. Controllers are deep-copied; one that
        cannot be copied raises ValueError naming its robots."""
        ctrls = []
        for b in self.bindings:
            try:
                ctrls.append(copy.deepcopy(b.controller))
            except Exception as err:  # noqa: BLE001 - user code may hold anything
                who = ",".join(self.robots[i].name for i in b.robots)
                raise ValueError(
                    f"snapshot: the controller of robot {who!r} cannot be copied: {err}"
                ) from None
        dyn = None if self.dynamics is None else copy.deepcopy(self.dynamics)
        return Snapshot(self.state.copy(), tuple(ctrls), dyn)

    def restore(self, snap: Snapshot) -> None:
        """Back to ``snap`` (from :meth:`snapshot` of this simulation); it can be restored
        again. The world (walls, boxes, floor) stays as it is now."""
        if len(snap.controllers) != len(self.bindings) or snap.state.poses.shape[0] != self.n:
            raise ValueError("restore: the snapshot is of another simulation")
        self.state = snap.state.copy()
        for b, ctrl in zip(self.bindings, snap.controllers, strict=True):
            b.controller = copy.deepcopy(ctrl)
        if snap.dynamics is not None:
            self.dynamics = copy.deepcopy(snap.dynamics)
            self.dynamics.set_floor(self.world.floor)

    # ------------------------------------------------------------------ the step
    def step(self) -> None:
        """Advance the simulation by one kinematics step of ``dt_s`` seconds: :meth:`control`
        then :meth:`advance`."""
        self._control()
        self.advance()

    def control(self) -> None:
        """The step's first stage: every controller decides its robot's command (the only
        stage that runs user code, so the one an interruption may cut short; the state is then
        still the last step's)."""
        self._control()

    def advance(self) -> None:
        """The rest of the step after :meth:`control`: safety, actuation, dynamics, motion,
        odometry, the clock, sensors and guidance. A caller that must never see half a step
        runs this without interruptions (agvsim.run_loop holds Ctrl-C and SIGTERM)."""
        if self.safety is not None:
            self._guard()
        act = self._actuate()
        if self.dynamics is not None:
            self._apply_dynamics(act)
        self._move(act)
        self._dead_reckon(act)
        self.state.t_s = (self.state.step + 1) * self.dt_s
        self.state.step += 1
        self._sense()
        self._render()
        self._guide()

    def run(self, duration_s: float) -> None:
        for _ in range(int(round(duration_s / self.dt_s))):
            self.step()

    # ------------------------------------------------------------------ stages
    @property
    def controller_time_limit_s(self) -> float | None:
        """Wall-clock seconds each call of a ``user_code`` controller may take (None: no
        limit), enforced inside ``with sim.enforcing_time_limit():``; a call that runs longer
        fails like a controller that raised (see agvsim.sim.watchdog)."""
        return None if self._clock is None else self._clock.limit_s

    @controller_time_limit_s.setter
    def controller_time_limit_s(self, limit_s: float | None) -> None:
        checked = check_limit(limit_s)
        self._clock = None if checked is None else ControllerClock(checked)
        self._timing: ControllerClock | None = None

    def enforcing_time_limit(self) -> AbstractContextManager[object]:
        """Enforce ``controller_time_limit_s`` on the steps taken inside (a timer signal on
        the main thread; elsewhere calls run unlimited)."""
        return self._clock if self._clock is not None else nullcontext()

    def _control(self) -> None:
        st = self.state
        clock = self._clock if self._clock is not None and self._clock.running else None
        try:
            for b, idx in zip(self.bindings, self.binding_robots, strict=True):
                live = idx[~st.stopped[idx]]
                if live.size == 0:
                    continue
                self._timing = clock if b.user_code else None
                try:
                    if b.batch:
                        self._control_batch(b.controller, idx)
                    else:
                        for i in live:
                            self._control_one(b.controller, int(i))
                except ControllerError as err:
                    self._controller_failed(err, idx if b.batch else None)
        finally:
            self._timing = None

    def _call(self, fn: Any, arg: object) -> Any:
        """``fn(arg)``, a controller's step, within the time limit when it is timed."""
        clock = self._timing
        if clock is None:
            return fn(arg)
        clock.begin()
        try:
            out = fn(arg)
        finally:
            expired = clock.end()
        if expired:  # the controller caught TimeLimitExceeded and went on
            raise TimeLimitExceeded(clock.limit_s)
        return out

    def _controller_failed(self, err: ControllerError, idx: np.ndarray | None) -> None:
        """A controller raised or gave a bad command: its robot(s) stop where they are. The
        run ends (``stop_run``, re-raised) or goes on without them (``stop_robot``)."""
        st = self.state
        robots = idx if idx is not None else np.array([self.robot_index(err.robot)])
        st.stopped[robots] = True
        st.cmd_twist[robots] = 0.0
        st.cmd_wheels[robots] = 0.0
        st.cmd_is_twist[robots] = True
        st.errors.append(err)
        if self.on_controller_error == "stop_run":
            raise err

    def _control_batch(self, ctrl: BatchController, idx: np.ndarray) -> None:
        obs = self.batch_observation(idx)
        try:
            cmd = np.asarray(self._call(ctrl.step, obs), dtype=np.float64)
        except KeyboardInterrupt:  # Ctrl-C (or SIGTERM) stops the run, not the controller
            raise
        except BaseException as exc:  # noqa: BLE001 - user code: SystemExit, the time limit too
            raise ControllerError(",".join(self.robots[i].name for i in idx), obs.t_s, exc) from exc
        self._store_batch(idx, cmd)

    def _store_batch(self, idx: np.ndarray, cmd: np.ndarray) -> None:
        """Store a batch controller's ``(k, m)`` commands, read by each robot's mode."""
        if cmd.ndim != 2 or cmd.shape[0] != len(idx):
            raise ControllerError(
                self.robots[int(idx[0])].name,
                self.state.t_s,
                ValueError(f"a batch controller for {len(idx)} robots returned shape {cmd.shape}"),
            )
        finite = np.isfinite(cmd).all(axis=1)
        if not finite.all():
            k = int(np.flatnonzero(~finite)[0])
            raise ControllerError(
                self.robots[int(idx[k])].name,
                self.state.t_s,
                ValueError(f"command {cmd[k].tolist()} is not all finite numbers"),
            )
        st = self.state
        is_tw = self._mode_twist[idx]
        st.cmd_is_twist[idx] = is_tw
        if is_tw.any():
            st.cmd_twist[idx[is_tw]] = cmd[is_tw, :3]
        if not is_tw.all():
            st.cmd_wheels[idx[~is_tw], : cmd.shape[1]] = cmd[~is_tw]

    def _control_one(self, ctrl: object, i: int) -> None:
        obs = self.observation(i)
        try:
            step = getattr(ctrl, "step", None)
            cmd = self._call(step if step is not None else ctrl, obs)
            self._store_command(i, None, cmd)
        except KeyboardInterrupt:  # Ctrl-C (or SIGTERM) stops the run, not the controller
            raise
        except BaseException as exc:  # noqa: BLE001 - user code: SystemExit, the time limit too
            raise ControllerError(self.robots[i].name, obs.t_s, exc) from exc

    def _store_command(self, i: int, arr: np.ndarray | None, cmd: object) -> None:
        robot = self.robots[i]
        is_twist = (
            (robot.mode == ControlMode.INVERSE)
            if not isinstance(cmd, Twist | WheelCommand)
            else isinstance(cmd, Twist)
        )
        width = 3 if is_twist else self.cmd_width(i)
        mode = ControlMode.INVERSE if is_twist else ControlMode.FORWARD
        if arr is None:
            arr = command_to_array(cmd, width, mode, robot.name, self.state.t_s)
        arr = arr[:width]
        if arr.shape != (width,) or not np.all(np.isfinite(arr)):
            raise ValueError(f"command {arr.tolist()} is not {width} finite numbers ({mode} mode)")
        st = self.state
        st.cmd_is_twist[i] = is_twist
        if is_twist:
            st.cmd_twist[i] = arr
        else:
            st.cmd_wheels[i, :width] = arr

    def _guard(self) -> None:
        """The safety stage (agvsim.sim.safety): the robots with a scanner get their
        commands braked on a protective-field violation and capped on a warning."""
        st, tab = self.state, self.safety
        assert tab is not None
        idx = tab.robots
        is_tw = st.cmd_is_twist[idx]
        cmd = np.zeros((len(idx), 3))
        cmd[is_tw] = st.cmd_twist[idx[is_tw]]
        if not is_tw.all():
            cmd[~is_tw] = self._wheel_twists(idx[~is_tw])
        prev = st.twists[idx]
        # the field set of the faster of the speed driven and the speed commanded: a robot
        # standing in a short field must not start at a speed the field is too short for
        speed = np.where(np.abs(cmd[:, 0]) > np.abs(prev[:, 0]), cmd[:, 0], prev[:, 0])
        active = tab.active_sets(speed, st.steering[idx])
        status = tab.status(st.scans[tab.slots], active)
        # a protective stop holds until the robot stands, even if a slower field set no
        # longer sees the obstacle on the way down
        moving = (np.hypot(prev[:, 0], prev[:, 1]) > 1e-4) | (np.abs(prev[:, 2]) > 1e-4)
        status[(st.safety_status[idx] == PROTECTIVE) & moving] = PROTECTIVE
        since = st.safety_since_s[idx]
        out = tab.brake(cmd, prev, status, since, st.t_s, self.dt_s)
        st.cmd_twist[idx[is_tw]] = out[is_tw]
        if not is_tw.all():
            fw = idx[~is_tw]
            v_cmd = np.hypot(cmd[~is_tw, 0], cmd[~is_tw, 1])
            v_out = np.hypot(out[~is_tw, 0], out[~is_tw, 1])
            still = ~np.any(out[~is_tw] != 0.0, axis=1)
            scale = np.where(v_cmd > 1e-12, np.minimum(1.0, v_out / np.maximum(v_cmd, 1e-300)), 1.0)
            scale[still] = 0.0
            for i, k in zip(fw, scale, strict=True):  # driven wheels; steering kept
                st.cmd_wheels[i, : len(self.robots[i].model.driven_wheels)] *= k
        events, first, last = st.safety_events[idx], st.safety_first_s[idx], st.safety_last_s[idx]
        count_events(st.safety_status[idx], status, st.t_s, events, first, last)
        st.safety_events[idx], st.safety_first_s[idx], st.safety_last_s[idx] = events, first, last
        st.safety_status[idx] = status
        st.safety_since_s[idx] = since
        st.safety_set[idx] = np.where(active >= 0, active - tab.packed.first, -1)

    def _wheel_twists(self, robots: np.ndarray) -> np.ndarray:
        """(k, 3) the twists the forward-mode commands of ``robots`` (ascending) ask for (wheel
        speeds and steering through the models' forward kinematics, before any limit)."""
        st = self.state
        out = np.zeros((len(robots), 3))
        for g in self._groups:
            sel = np.isin(g.idx, robots)
            if not sel.any():
                continue
            rows = g.idx[sel]
            model = g.model if sel.all() else _subset(g.model, sel)
            w = st.cmd_wheels[rows]
            steer = w[:, g.n_drive] if model.has_steering else np.zeros(len(w))
            tw = model.forward(w[:, : g.n_drive], steer)
            out[np.searchsorted(robots, rows)] = tw  # both ascending
        return out

    def _actuate(self) -> np.ndarray:
        """Commands -> executed twists (N, 3); fills wheel speeds and steering in the state."""
        st, dt = self.state, self.dt_s
        twist = np.zeros((self.n, 3))
        for g in self._groups:
            if g.car is not None:
                self._actuate_car(g, twist)
                continue
            is_tw = st.cmd_is_twist[g.idx]
            for sel, by_twist in ((is_tw, True), (~is_tw, False)):
                if not sel.any():
                    continue
                whole = sel.all()
                idx = g.sel if whole else g.idx[sel]
                model = g.model if whole else _subset(g.model, sel)
                if by_twist:
                    a = actuation.from_twist(model, st.cmd_twist[idx], st.steering[idx], dt)
                else:
                    w = st.cmd_wheels[idx]
                    steer = w[:, g.n_drive] if model.has_steering else np.zeros(len(w))
                    a = actuation.from_wheels(model, w[:, : g.n_drive], steer, st.steering[idx], dt)
                twist[idx] = a.twist
                st.wheel_speeds[idx, : g.n_wheels] = a.wheel_speeds
                st.steering[idx] = a.steering
                st.steer_angles[idx, : g.n_steer] = a.steer_angles
        if st.stopped.any():
            twist[st.stopped] = 0.0
            st.wheel_speeds[st.stopped] = 0.0
        return twist

    def _actuate_car(self, g: _Group, twist: np.ndarray) -> None:
        """A tricycle or Ackermann group's actuation in one kernel call (both modes; the same
        equations as agvsim.kinematics.actuation, agvsim.kinematics.fused)."""
        st, sel = self.state, g.sel
        assert g.car is not None and g.car_params is not None
        k = len(g.idx)
        tw, wheels = np.empty((k, 3)), np.empty((k, g.n_wheels))
        steering, angles = np.empty(k), np.empty((k, g.n_steer))
        fused.actuate_car(
            g.car,
            g.car_parallel,
            g.car_params,
            st.cmd_is_twist[sel],
            st.cmd_twist[sel],
            st.cmd_wheels[sel],
            st.steering[sel],
            self.dt_s,
            tw,
            wheels,
            steering,
            angles,
        )
        twist[sel] = tw
        st.wheel_speeds[sel, : g.n_wheels] = wheels
        st.steering[sel] = steering
        st.steer_angles[sel, : g.n_steer] = angles

    def _apply_dynamics(self, twist: np.ndarray) -> None:
        """Robots with dynamics: the actuated wheel speeds and steering become targets of
        their motors; their rows of ``twist`` (N, 3) and of the wheel state become what the
        forces made of them this step (agvsim.dynamics)."""
        st, dyn = self.state, self.dynamics
        assert dyn is not None
        i = self._dyn_sel
        out = dyn.step(
            st.poses[i],
            st.wheel_speeds[i],
            st.steering[i],
            st.bump[i] | st.stopped[i],
            self.dt_s,
            st.t_s,
        )
        twist[i] = out.twist
        st.wheel_speeds[i] = out.wheel_speeds
        st.steering[i] = out.steering
        st.steer_angles[i] = out.steer_angles
        st.wheel_torque_nm[i] = out.torque_nm
        st.wheel_slip_m_s[i] = out.slip_m_s
        st.wheel_power_w[i] = out.power_w

    def set_grid(self, grid: OccupancyGrid) -> None:
        """Change the walls of the running simulation (a maze editor). Same resolution and
        extent or not: sensors and collisions use the new grid from the next step on."""
        self.world = dc_replace(self.world, grid=grid)
        self.caster.set_grid(grid)
        if self.cameras is not None:
            self.cameras.set_world(self.world)
        self.collider.set_grid(grid)
        self._substep_len = 0.5 * min(grid.resolution_m, float(self._half.min()))

    def set_floor(self, floor: FloorFriction) -> None:
        """Change the floor's friction of the running simulation (a friction brush): robots
        with dynamics feel it from the next step."""
        self.world = dc_replace(self.world, floor=floor)
        if self.dynamics is not None:
            self.dynamics.set_floor(floor)

    def set_boxes(self, boxes: np.ndarray) -> None:
        """Change the static boxes ``(K, 5)`` of the running simulation (a box dropped on the
        floor): sensors and collisions see them from the next step on."""
        self.world = dc_replace(self.world, boxes=np.asarray(boxes, dtype=np.float64))
        self._static_tab = box_tables(self.world.boxes)
        if self.cameras is not None:
            self.cameras.set_world(self.world)

    def footprints(self, poses: np.ndarray) -> np.ndarray:
        """(N, 5) oriented boxes (cx, cy, theta, half_length, half_width) of the bodies."""
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        out = np.empty((len(poses), 5))
        out[:, 0] = poses[:, 0] + c * self._offset
        out[:, 1] = poses[:, 1] + s * self._offset
        out[:, 2] = poses[:, 2]
        out[:, 3:5] = self._half
        return out

    def _move(self, twist: np.ndarray) -> None:
        """Integrate exactly, in sub-steps short enough that no body can jump a wall cell; a
        body that would overlap a wall, a box or another robot stops at its last free pose."""
        st, dt = self.state, self.dt_s
        start = st.poses
        sweep = (np.hypot(twist[:, 0], twist[:, 1]) + np.abs(twist[:, 2]) * self._radius) * dt
        n_sub = max(1, int(np.ceil(sweep.max() / self._substep_len)))
        good, bump_wall, dist, boxes = move_bodies(
            self.world.grid,
            start,
            twist,
            dt,
            n_sub,
            self._offset,
            self._half,
            self.world.boxes,
            self._static_tab,
        )
        # robots against robots: where two new footprints overlap, undo the move of each robot
        # that ran into the other's old place (both, if neither did), until none is left
        old_boxes = None
        bump_robot = np.zeros(self.n, dtype=bool)
        for _ in range(self.n):
            pairs = box_pairs_overlapping(boxes)  # our own footprints: no input checks
            if len(pairs) == 0:
                break
            if old_boxes is None:
                old_boxes = self.footprints(start)
            fault = pair_faults(boxes, old_boxes, pairs)
            fault[~fault.any(axis=1)] = True
            culprits = np.unique(pairs[fault])
            bump_robot[np.unique(pairs)] = True
            moved = culprits[np.any(good[culprits] != start[culprits], axis=1)]
            if moved.size == 0:
                break
            good[moved] = start[moved]
            dist[moved] = 0.0
            boxes = self.footprints(good)
        bump = bump_wall | bump_robot
        st.collisions += bump & ~st.bump
        st.wall_collisions += bump_wall & ~st.bump_wall
        st.robot_collisions += bump_robot & ~st.bump_robot
        st.bump, st.bump_wall, st.bump_robot = bump, bump_wall, bump_robot
        st.distance_m += dist
        twist[bump] = 0.0
        st.wheel_speeds[bump] = 0.0
        st.poses = good
        st.twists = twist
        st.wheel_angles += st.wheel_speeds * dt

    def _dead_reckon(self, twist: np.ndarray) -> None:
        """Integrate noisy wheel-encoder readings into the odometry pose."""
        st = self.state
        rng = st.rng
        for g in self._groups:
            sel = g.sel
            drive = st.wheel_speeds[sel, g.driven]
            if g.rel is not None:
                drive = drive * (1.0 + g.rel * rng.standard_normal(drive.shape))
            if g.abs is not None:
                drive = drive + g.abs * rng.standard_normal(drive.shape)
            steer = st.steering[sel]
            if g.steer_noise is not None:
                steer = steer + g.steer_noise * rng.standard_normal(steer.shape)
            odo_twist = g.model.forward(drive, steer)
            poses = np.ascontiguousarray(st.odom_poses[sel])
            _integrate_rows(poses, odo_twist, self.dt_s, poses)  # in place, row by row
            st.odom_poses[sel] = poses

    def _sense(self, force: bool = False) -> None:
        """Cast every sensor that is due now, for all robots, in one kernel call."""
        st, tab = self.state, self.sensors
        if tab.count == 0:
            return
        due = np.ones(tab.count, dtype=bool) if force else st.t_s >= st.next_scan_s - 1e-9
        if not due.any():
            return
        # every sensor due at once (the common case) is handled with slices, not gathers
        s = slice(None) if due.all() else np.flatnonzero(due)
        owner = tab.owner[s]
        pose = st.poses[owner]
        c, sn = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        mx, my = tab.mount[s, 0], tab.mount[s, 1]
        origins = np.stack([pose[:, 0] + c * mx - sn * my, pose[:, 1] + sn * mx + c * my], -1)
        width = int(tab.num_beams[s].max())  # only as many columns as the widest due sensor
        rel = tab.rel_angles[s, :width] if width < tab.max_beams else tab.rel_angles[s]
        angles = rel + (pose[:, 2] + tab.mount[s, 2])[:, None]
        boxes = self.footprints(st.poses)
        if len(self.world.boxes):
            boxes = np.concatenate([boxes, self.world.boxes])
        post = tab.post[s].any()  # noise, dropout or a minimum range to apply
        direct = isinstance(s, slice) and width == tab.max_beams and not post
        exact = self.caster.cast(
            origins, angles, tab.range_max[s], boxes, owner, out=st.scans if direct else None
        )
        if post:
            exact = apply_noise(
                exact,
                tab.range_min[s],
                tab.range_max[s],
                tab.noise[s],
                tab.dropout[s],
                self.rng,
            )
        if self.guidance is not None and self.world.reflectors is not None:
            inten = self.guidance.scan_intensities(
                st.poses, owner, tab.mount[s], rel, tab.num_beams[s], exact
            )
            inten[~np.isfinite(exact)] = 0.0  # a dropped beam returns nothing
            st.intensities[s, :width] = inten
        if not direct:
            st.scans[s, :width] = exact
        st.scan_stamp[s] = st.t_s
        st.next_scan_s[s] = st.t_s + tab.period_s[s]

    def _render(self, force: bool = False) -> None:
        """Render the cameras that are due (see :mod:`agvsim.sensors.camera_rig`)."""
        if self.cameras is None:
            return
        st = self.state
        due = self.cameras.render_due(st, self.footprints(st.poses), force, st.rng)
        for slot, rgb, depth, pose in due:
            st.images[slot] = rgb
            st.depths[slot] = depth
            st.image_stamp[slot] = st.t_s
            st.image_seq[slot] += 1
            st.image_pose[slot] = pose
            st.next_image_s[slot] = st.t_s + self.cameras.period_s[slot]

    def _guide(self, force: bool = False) -> None:
        """Line sensors every step; floor cameras that are due (render, decode, fix)."""
        g = self.guidance
        if g is None:
            return
        st = self.state
        if g.line_count:
            read = g.read_lines(st.poses, st.rng)
            st.line_active, st.line_offsets, st.line_spot = (
                read.active,
                read.offsets_m,
                read.spot_code,
            )
            st.line_stamp[:] = st.t_s
        if g.cam_count:
            due = np.ones(g.cam_count, bool) if force else st.t_s >= st.next_fix_s - 1e-9
            for slot, code, pose in g.read_codes(st.poses, due):
                st.next_fix_s[slot] = st.t_s + g.cam_period_s[slot]
                if pose is not None:
                    st.fix_pose[slot], st.fix_code[slot] = pose, code
                    st.fix_stamp[slot] = st.t_s
                    st.fix_seq[slot] += 1

    def camera_frames(self) -> list[CameraFrame]:
        """The latest frame of every camera of every robot (empty without cameras)."""
        return [] if self.cameras is None else self.cameras.frames(self.state)

    # ------------------------------------------------------------------ observations
    def scan(self, slot: int) -> LaserScan:
        return observe.scan(self, slot)

    def observation(self, i: int) -> Observation:
        return observe.observation(self, i)

    def batch_observation(self, idx: np.ndarray) -> BatchObservation:
        return observe.batch_observation(self, idx)

    def active_states(self) -> list[str]:
        """Each robot's active controller state ("" when its controller has none): read from
        ``state_name`` (one robot) or ``state_names()`` (a batch controller)."""
        return observe.active_states(self)

    def batch_slots(self, idx: np.ndarray) -> dict[str, tuple[slice | np.ndarray, int]]:
        """Sensor name -> (rows of the sensor table, beams) for the robots ``idx`` of a batch
        controller: the sensors all of them have (worked out once per set of robots)."""
        key = idx.tobytes()
        if key not in self._batch_slots:
            self._batch_slots[key] = observe.batch_slots(self.sensors, idx)
        return self._batch_slots[key]

    def robot_index(self, name: str) -> int:
        for i, r in enumerate(self.robots):
            if r.name == name:
                return i
        raise KeyError(f"no robot named {name!r}; robots: {[r.name for r in self.robots]}")


@dataclass(frozen=True)
class Snapshot:
    """The changing state of a simulation at one moment (``Simulation.snapshot``)."""

    state: SimState
    controllers: tuple[Any, ...]  # deep copies, one per binding
    dynamics: Dynamics | None  # a copy of the motors' and bodies' memory, if any


def _subset(model: Any, sel: np.ndarray) -> Any:
    """The stacked model restricted to the robots where ``sel`` is True."""
    from dataclasses import fields, replace

    vals = {}
    for f in fields(model):  # type: ignore[arg-type]
        v = getattr(model, f.name)
        if isinstance(v, np.ndarray) and v.ndim == 1 and v.shape[0] == sel.shape[0]:
            vals[f.name] = v[sel]
    return replace(model, **vals)  # type: ignore[type-var]
