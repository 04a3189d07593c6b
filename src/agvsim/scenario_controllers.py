"""The controller registry's entry type, and the scenario's four basic controller types.

A :class:`Behaviour` says how one ``controller: {type: ...}`` of a scenario becomes a core
controller: its config class (validated at the edge) and its builder. ``agvsim.behaviours``
holds the registry ``BEHAVIOURS`` (type tag -> ``Behaviour``), which the scenario schema turns
into its union of controller configs and ``agvsim.scenario`` uses to build every robot's
controller the same way. The four types here are the scenario's own:

=======  ==========================  =================================================
type     config                      controller
=======  ==========================  =================================================
script   ``ScriptConfig``            :class:`agvsim.control.script.ScriptController`
avoid    ``AvoidConfig``             :class:`agvsim.control.avoid.ObstacleAvoidance`,
                                     one batched controller for the robots sharing a config
python   ``PythonControllerConfig``  the user's function or class, from a file (user code:
                                     each call is timed by the engine's watchdog)
idle     ``IdleConfig``              none: the robot stands still
=======  ==========================  =================================================
"""

from __future__ import annotations

import importlib.util
import inspect
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, model_validator

from agvsim.config_base import StrictConfig, construct, did_you_mean
from agvsim.control.adapters import WheelsFromTwist
from agvsim.control.api import ControllerContext
from agvsim.control.avoid import SIDE_PER_TRIGGER, ObstacleAvoidance
from agvsim.control.script import ScriptController, ScriptStep
from agvsim.control.traffic import RobotSight, sight_sensor
from agvsim.kinematics import stack_models
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.spec import ControlMode, RobotSpec

PathText = Annotated[str, Field(min_length=1, max_length=4096)]


class ControllerConfigBase(StrictConfig):
    """Every controller config: a strict block tagged by its ``type``."""

    type: str


@dataclass(frozen=True)
class Behaviour:
    """One controller type of a scenario file.

    ``build(config, ctx)`` makes one robot's controller (None: no controller, the robot
    idles). A batched type gives ``build_group(configs, ctxs)`` instead: one controller for
    all the robots whose ``group_key(config, spec)`` is equal (default: the config itself,
    and the model's kind), in one control mode (and of one model kind in forward mode); its
    ``check(config, ctx)`` refuses a robot it cannot drive before any is built. Builders
    raise ValueError starting with the config field at fault (``"sensor: ..."``).
    ``keep_clear``: slowed to stop short of robots its lidar sees (agvsim.control.traffic);
    ``user_code``: the user's own code, each call timed by the engine's watchdog.
    """

    config: type[ControllerConfigBase]
    build: Callable[[Any, ControllerContext], Any] | None = None
    build_group: Callable[[Sequence[Any], Sequence[ControllerContext]], Any] | None = None
    group_key: Callable[[Any, RobotSpec], Hashable] | None = None
    check: Callable[[Any, ControllerContext], None] | None = None
    keep_clear: bool = False
    user_code: bool = False


def _spec(ctx: ControllerContext) -> RobotSpec:
    assert isinstance(ctx.spec, RobotSpec)
    return ctx.spec


# ---------------------------------------------------------------------------------- script
class ScriptStepConfig(StrictConfig):
    duration_s: float = Field(gt=0)
    twist: list[float] | None = Field(default=None, description="[vx, omega] or [vx, vy, omega]")
    wheels: list[float] | None = Field(default=None, description="driven wheel speeds, rad/s")
    steering_deg: float = 0.0

    @model_validator(mode="after")
    def _one_kind(self) -> ScriptStepConfig:
        if (self.twist is None) == (self.wheels is None):
            raise ValueError("each script step needs exactly one of 'twist' or 'wheels'")
        if self.twist is not None and len(self.twist) not in (2, 3):
            raise ValueError(f"twist must be [vx, omega] or [vx, vy, omega], got {self.twist}")
        return self


class ScriptConfig(ControllerConfigBase):
    type: Literal["script"]
    steps: list[ScriptStepConfig] = Field(min_length=1)
    loop: bool = False


def build_script(cfg: ScriptConfig, ctx: ControllerContext) -> ScriptController:
    """Timed steps of twists (``[vx, omega]`` or ``[vx, vy, omega]``) or wheel speeds."""
    model = _spec(ctx).model
    steps = []
    for st in cfg.steps:
        twist = None
        if st.twist is not None:
            tw = st.twist
            twist = (tw[0], 0.0, tw[1]) if len(tw) == 2 else (tw[0], tw[1], tw[2])
        if st.wheels is not None and len(st.wheels) != len(model.driven_wheels):
            driven = [model.wheel_names[k] for k in model.driven_wheels]
            raise ValueError(
                f"steps: a {model.kind} robot has {len(driven)} driven wheel(s) {driven}, "
                f"got {len(st.wheels)} speeds {st.wheels}"
            )
        wheels = None if st.wheels is None else tuple(st.wheels)
        steps.append(ScriptStep(st.duration_s, twist, wheels, float(np.deg2rad(st.steering_deg))))
    return construct(ScriptController, cfg, steps=steps)


# ---------------------------------------------------------------------------------- avoid
class AvoidConfig(ControllerConfigBase):
    type: Literal["avoid"]
    sensor: str = "rangers"
    trigger_m: float = Field(default=0.8, gt=0)
    speed_m_s: float = Field(default=0.5, gt=0)
    turn_rate_rad_s: float = Field(default=1.0, gt=0)
    heading_source: Literal["true_pose", "odometry"] = "true_pose"
    side_clearance_m: float | None = Field(
        default=None, gt=0, description="kept off side walls while driving; default 0.8 x trigger_m"
    )


def check_avoid(cfg: AvoidConfig, ctx: ControllerContext) -> None:
    names = [s.name for s in _spec(ctx).sensors]
    if cfg.sensor not in names:
        raise ValueError(
            f"sensor: the robot has no sensor {cfg.sensor!r}" + did_you_mean(cfg.sensor, names)
        )


def avoid_group_key(cfg: AvoidConfig, spec: RobotSpec) -> Hashable:
    """Robots batched in one avoidance controller: the sensor it reads and the heading source
    alike, and the beams of that sensor and of the lidar that sees other robots (the cone
    beams and the robots' sight are worked out once a group). Speeds, trigger, turn rate and
    side clearance are each robot's own, and so is the model's kind in inverse mode."""
    seen = sight_sensor(spec)
    beams = tuple(
        (s.name, s.num_beams, s.beam_angles_rad.tobytes(), tuple(s.mount_xy_m), s.mount_yaw_rad)
        for s in spec.sensors
        if s.name in (cfg.sensor, seen)
    )
    return (cfg.type, cfg.sensor, cfg.heading_source, seen, beams)


def build_avoid(cfgs: Sequence[AvoidConfig], ctxs: Sequence[ControllerContext]) -> Any:
    """The thesis's obstacle avoidance for a group of robots, batched (wrapped to command
    wheel speeds when the group is in forward mode); each robot keeps its own speed, trigger,
    turn rate and side clearance."""
    specs = [_spec(c) for c in ctxs]
    spec0, cfg = specs[0], cfgs[0]
    sensor = next(s for s in spec0.sensors if s.name == cfg.sensor)
    front, back = cone_beams(sensor)
    static = ctxs[0].static
    trigger = np.array([c.trigger_m for c in cfgs])
    side = [c.side_clearance_m for c in cfgs]
    ctrl: Any = construct(
        ObstacleAvoidance,
        cfg,
        front_beams=front,
        back_beams=back,
        trigger_m=trigger,
        speed_m_s=np.array([c.speed_m_s for c in cfgs]),
        turn_rate_rad_s=np.array([c.turn_rate_rad_s for c in cfgs]),
        side_clearance_m=np.array(
            [SIDE_PER_TRIGGER * t if v is None else v for t, v in zip(trigger, side, strict=True)]
        ),
        can_spin=np.array([_can_spin(s.model) for s in specs]),
        sight=RobotSight.for_robots(specs, static, sight_sensor(spec0) or ""),  # type: ignore[arg-type]
    )
    if spec0.mode == ControlMode.FORWARD:
        ctrl = WheelsFromTwist(ctrl, stack_models([s.model for s in specs]))
    return ctrl


def _can_spin(model: Any) -> bool:
    """True when the model can turn on the spot."""
    if not model.has_steering:
        return True
    return bool(np.all(np.asarray(model.max_steer_rad) >= np.pi / 2 - 1e-9))


def cone_beams(sensor: RangeSensorSpec, half_deg: float = 15.0) -> tuple[tuple, tuple]:
    """Beam indices looking ahead and behind (within +-half_deg; the nearest beam at least)."""
    ang = np.angle(np.exp(1j * (sensor.beam_angles_rad + sensor.mount_yaw_rad)))
    out = []
    for centre in (0.0, np.pi):
        d = np.abs(np.angle(np.exp(1j * (ang - centre))))
        sel = np.flatnonzero(d <= np.deg2rad(half_deg))
        out.append(tuple(int(k) for k in (sel if sel.size else [int(np.argmin(d))])))
    return out[0], out[1]


# ---------------------------------------------------------------------------------- python
class PythonControllerConfig(ControllerConfigBase):
    type: Literal["python"]
    file: PathText = Field(description="a .py file next to the scenario (or an absolute path)")
    name: str = Field(
        default="controller",
        min_length=1,
        max_length=200,
        description="function or class in the file",
    )


def build_python(cfg: PythonControllerConfig, ctx: ControllerContext) -> Any:
    """The user's controller: ``name`` from the file. A class, or a function taking no
    argument, makes the controller; anything else (a function of obs, an object with
    ``step()``) is the controller itself. Whether such a file may run at all is decided by
    who loads the scenario (the app refuses one from the browser)."""
    path = Path(cfg.file)
    if not path.is_absolute():
        path = Path(str(ctx.base_dir or ".")) / path
    if not path.is_file():
        raise ValueError(f"file: no such file {str(path)!r}")
    if path.suffix != ".py":
        raise ValueError(f"file: {path.name!r} must be a Python file ending in .py")
    spec = importlib.util.spec_from_file_location(f"agvsim_user_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    try:
        spec.loader.exec_module(module)  # type: ignore[union-attr]
    except (Exception, SystemExit) as err:  # noqa: BLE001 - the user's file: report, don't crash
        line = f" (line {err.lineno})" if isinstance(err, SyntaxError) and err.lineno else ""
        raise ValueError(
            f"file: {path.name} could not be loaded{line}: {type(err).__name__}: {err}"
        ) from None
    obj = getattr(module, cfg.name, None)
    if obj is None:
        found = [n for n in vars(module) if not n.startswith("_")]
        raise ValueError(
            f"name: {cfg.name!r} is not defined in {path.name}" + did_you_mean(cfg.name, found)
        )
    if isinstance(obj, type) or (callable(obj) and _takes_no_arguments(obj)):
        try:
            return obj()
        except (Exception, SystemExit) as err:  # noqa: BLE001 - the user's code: report
            raise ValueError(f"name: {cfg.name}() failed: {type(err).__name__}: {err}") from None
    return obj


def _takes_no_arguments(fn: Any) -> bool:
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return False
    return not any(
        p.default is inspect.Parameter.empty
        and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        for p in params
    )


# ---------------------------------------------------------------------------------- idle
class IdleConfig(ControllerConfigBase):
    type: Literal["idle"]


BASIC: dict[str, Behaviour] = {
    "script": Behaviour(ScriptConfig, build=build_script),
    "avoid": Behaviour(
        AvoidConfig, build_group=build_avoid, group_key=avoid_group_key, check=check_avoid
    ),
    "python": Behaviour(PythonControllerConfig, build=build_python, user_code=True),
    "idle": Behaviour(IdleConfig),
}
