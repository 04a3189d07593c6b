"""The scenario file: one validated YAML document holds the world, the robots, duration and seed.

``load_scenario(path)`` parses and validates (unknown keys get "did you mean ...?", bad values a
message naming the field, the value and what is allowed); ``build(scenario)`` turns it into a
ready ``Simulation``. The schema is documented in docs/scenario.md.
"""

from __future__ import annotations

import difflib
import importlib.util
import inspect
import re
from dataclasses import fields as dc_fields
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, model_validator

from agvsim.behaviours import BEHAVIOURS
from agvsim.control.adapters import WheelsFromTwist
from agvsim.control.api import ControllerContext
from agvsim.control.avoid import ObstacleAvoidance
from agvsim.control.script import ScriptController, ScriptStep
from agvsim.kinematics import MODELS, stack_models, wrap_angle
from agvsim.metrics.capture import CaptureConfig
from agvsim.metrics.coverage import CoverageConfig
from agvsim.metrics.reach import ReachConfig
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.spec import ControlMode, OdometrySpec, RobotSpec, World
from agvsim.world import loaders, mazes
from agvsim.world.grid import OccupancyGrid


class ScenarioError(ValueError):
    """A scenario that cannot run; ``problems`` lists one clear line per fault."""

    def __init__(self, source: str, problems: list[str]):
        self.source, self.problems = source, problems
        super().__init__(f"{source}: " + "; ".join(problems))

    def __str__(self) -> str:
        lines = "\n".join(f"  - {p}" for p in self.problems)
        return f"{self.source} is not a valid scenario:\n{lines}"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# ---------------------------------------------------------------------------------- world
class RandomMaze(_Strict):
    rows: int = Field(8, ge=1, le=500, description="rooms north-south")
    cols: int = Field(8, ge=1, le=500, description="rooms west-east")
    seed: int = 0
    corridor_cells: int = Field(2, ge=1, le=50)
    wall_cells: int = Field(1, ge=1, le=50)
    loop_fraction: float = Field(0.0, ge=0.0, le=1.0)


class BoxObstacle(_Strict):
    x_m: float
    y_m: float
    theta_deg: float = 0.0
    length_m: float = Field(gt=0)
    width_m: float = Field(gt=0)


class WorldConfig(_Strict):
    maze: Literal["thesis_fig16", "thesis_c1"] | None = None
    matrix: list[list[int]] | None = None
    picture: str | None = Field(None, description="text picture: '#' wall, '.' free")
    file: str | None = Field(None, description=".txt .csv .png .pgm or ROS map .yaml")
    random: RandomMaze | None = None
    cell_size_m: float = Field(1.0, gt=0, le=100)
    origin_xy_m: tuple[float, float] | None = None
    boxes: list[BoxObstacle] = []

    @model_validator(mode="after")
    def _one_source(self) -> WorldConfig:
        given = [k for k in ("maze", "matrix", "picture", "file", "random") if getattr(self, k)]
        if len(given) != 1:
            raise ValueError(
                "give exactly one map source out of maze, matrix, picture, file, random "
                f"(got {given or 'none'})"
            )
        return self


# ---------------------------------------------------------------------------------- robots
class Pose(_Strict):
    x_m: float = 0.0
    y_m: float = 0.0
    theta_deg: float = 0.0


class Body(_Strict):
    length_m: float = Field(0.6, gt=0, le=20)
    width_m: float = Field(0.45, gt=0, le=20)
    offset_x_m: float | None = Field(None, description="footprint centre ahead of P")


class SensorCommon(_Strict):
    name: str | None = None
    rate_hz: float | None = Field(None, gt=0, le=10000)
    range_min_m: float = Field(0.0, ge=0)
    noise_std_m: float = Field(0.0, ge=0)
    dropout_prob: float = Field(0.0, ge=0, le=1)
    mount_x_m: float | None = None
    mount_y_m: float = 0.0
    mount_yaw_deg: float = 0.0


class RangersConfig(SensorCommon):
    type: Literal["rangers"]
    range_max_m: float = Field(1.0, gt=0, le=1000)


class LidarConfig(SensorCommon):
    type: Literal["lidar"]
    beams: int = Field(240, ge=1, le=100000)
    fov_deg: float = Field(360.0, gt=0, le=360)
    angle_min_deg: float | None = None
    range_max_m: float = Field(10.0, gt=0, le=1000)


SensorConfig = Annotated[RangersConfig | LidarConfig, Field(discriminator="type")]


class OdometryConfig(_Strict):
    wheel_noise_rel: float = Field(0.01, ge=0, le=1)
    wheel_noise_abs_rad_s: float = Field(0.0, ge=0)
    steering_noise_deg: float = Field(0.0, ge=0)


class ScriptStepConfig(_Strict):
    duration_s: float = Field(gt=0)
    twist: list[float] | None = Field(None, description="[vx, omega] or [vx, vy, omega]")
    wheels: list[float] | None = Field(None, description="driven wheel speeds, rad/s")
    steering_deg: float = 0.0

    @model_validator(mode="after")
    def _one_kind(self) -> ScriptStepConfig:
        if (self.twist is None) == (self.wheels is None):
            raise ValueError("each script step needs exactly one of 'twist' or 'wheels'")
        if self.twist is not None and len(self.twist) not in (2, 3):
            raise ValueError(f"twist must be [vx, omega] or [vx, vy, omega], got {self.twist}")
        return self


class ScriptConfig(_Strict):
    type: Literal["script"]
    steps: list[ScriptStepConfig] = Field(min_length=1)
    loop: bool = False


class AvoidConfig(_Strict):
    type: Literal["avoid"]
    sensor: str = "rangers"
    trigger_m: float = Field(0.8, gt=0)
    speed_m_s: float = Field(0.5, gt=0)
    turn_rate_rad_s: float = Field(1.0, gt=0)
    heading_source: Literal["true_pose", "odometry"] = "true_pose"
    side_clearance_m: float | None = Field(
        None, gt=0, description="kept off side walls while driving; default 0.8 x trigger_m"
    )


class PythonControllerConfig(_Strict):
    type: Literal["python"]
    file: str = Field(description="a .py file next to the scenario (or an absolute path)")
    name: str = Field("controller", description="function or class defined in the file")


class IdleConfig(_Strict):
    type: Literal["idle"]


# Behaviours that bring their own config and builder (agvsim.behaviours.BEHAVIOURS) join the
# built-in controller types here
ControllerConfig = Annotated[
    Union[(ScriptConfig, AvoidConfig, PythonControllerConfig, IdleConfig, *BEHAVIOURS)],  # noqa: UP007
    Field(discriminator="type"),
]


class MetricsConfig(_Strict):
    capture: CaptureConfig | None = None
    reach: ReachConfig | None = None
    coverage: CoverageConfig | None = None


class RobotConfig(_Strict):
    name: str = Field(min_length=1)
    model: Literal["differential", "tricycle", "ackermann", "mecanum", "omni3"]
    mode: ControlMode = ControlMode.INVERSE
    params: dict[str, float | str] = Field({}, description="model parameters, see `agvsim models`")
    body: Body = Body()
    pose: Pose = Pose()
    color: str = "#d62728"
    sensors: list[SensorConfig] = []
    odometry: OdometryConfig = OdometryConfig()
    controller: ControllerConfig = IdleConfig(type="idle")
    knows: list[str] = Field(
        [], description="robots whose true pose this robot's controller sees (obs.others)"
    )


class Scenario(_Strict):
    name: str = "unnamed scenario"
    description: str = ""
    seed: int = 0
    duration_s: float = Field(60.0, gt=0, le=1e7)
    dt_s: float = Field(0.02, gt=0, le=1.0)
    world: WorldConfig
    robots: list[RobotConfig] = Field(min_length=1)
    metrics: MetricsConfig = MetricsConfig()
    on_controller_error: Literal["stop_run", "stop_robot"] = Field(
        "stop_run", description="a failing controller ends the run, or only stops its robot"
    )
    _base_dir: Path = PrivateAttr(default=Path("."))
    _source: str = PrivateAttr(default="scenario")

    @model_validator(mode="after")
    def _unique_names(self) -> Scenario:
        names = [r.name for r in self.robots]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"robot names must be unique; repeated: {dup}")
        for k, r in enumerate(self.robots):
            for other in r.knows:
                if other not in names or other == r.name:
                    raise ValueError(
                        f"robots[{k}].knows: {other!r} is not another robot"
                        + _did_you_mean(other, [n for n in names if n != r.name])
                    )
        return self


# ---------------------------------------------------------------------------------- loading
def _loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def _models_in(ann: Any) -> list[type[BaseModel]]:
    """Every schema class an annotation can hold (through list, Optional, Union, Annotated)."""
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return [ann]
    out: list[type[BaseModel]] = []
    for arg in getattr(ann, "__args__", ()) or ():
        out += _models_in(arg)
    origin = getattr(ann, "__origin__", None)
    if origin is not None and not out:
        out += _models_in(origin)
    return out


def _tag_of(model: type[BaseModel]) -> str | None:
    f = model.model_fields.get("type")
    args = getattr(f.annotation, "__args__", ()) if f is not None else ()
    return str(args[0]) if args else None


def _fields_at(model: type[BaseModel], loc: tuple) -> list[str]:
    """Field names of the schema object that ``loc`` (without its last key) points into;
    pydantic puts a discriminated union's tag (e.g. 'lidar') into the location."""
    cands: list[type[BaseModel]] = [model]
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        tagged = [m for m in cands if _tag_of(m) == part]
        if tagged:
            cands = tagged
            continue
        nxt: list[type[BaseModel]] = []
        for m in cands:
            if part in m.model_fields:
                nxt += _models_in(m.model_fields[part].annotation)
        cands = nxt or cands
    names: list[str] = []
    for m in cands:
        names += [n for n in m.model_fields if n not in names]
    return names


def _did_you_mean(word: str, options: list[str]) -> str:
    close = difflib.get_close_matches(word, options, n=1, cutoff=0.6)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return f"{hint} (allowed: {', '.join(sorted(options))})"


def _format_errors(err: ValidationError) -> list[str]:
    out = []
    for e in err.errors():
        loc = tuple(e["loc"])
        where = _loc(loc)
        if e["type"] == "extra_forbidden":
            key = str(loc[-1])
            out.append(
                f"{where}: unknown key {key!r}" + _did_you_mean(key, _fields_at(Scenario, loc))
            )
        elif e["type"] == "literal_error" and isinstance(e.get("input"), str):
            opts = re.findall(r"'([^']*)'", str(e.get("ctx", {}).get("expected", "")))
            close = difflib.get_close_matches(e["input"], opts, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            out.append(f"{where}: {e['input']!r} is not allowed{hint} (allowed: {', '.join(opts)})")
        elif e["type"] == "missing":
            out.append(f"{where}: required field is missing")
        elif e["type"] == "union_tag_invalid":
            ctx = e.get("ctx", {})
            tag = ctx.get("tag", "?")
            expected = ctx.get("expected_tags", "")
            opts = [t.strip(" '") for t in str(expected).split(",")]
            out.append(f"{where}: unknown type {tag!r}" + _did_you_mean(str(tag), opts))
        else:
            msg = e["msg"].removeprefix("Value error, ")
            value = e.get("input")
            shown = (
                repr(value) if not isinstance(value, dict | list) or len(repr(value)) < 80 else ""
            )
            out.append(f"{where}: {msg}" + (f" (got {shown})" if shown else ""))
    return out


def parse_scenario(data: Any, source: str = "scenario") -> Scenario:
    if not isinstance(data, dict):
        raise ScenarioError(
            source, [f"the file must hold a mapping of keys, got {type(data).__name__}"]
        )
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(source, _format_errors(err)) from None


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(str(path), ["no such file"])
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        line = f"line {mark.line + 1}: " if mark is not None else ""
        raise ScenarioError(
            str(path), [f"{line}not valid YAML ({getattr(err, 'problem', err)})"]
        ) from None
    scenario = parse_scenario(data, str(path))
    scenario._base_dir = path.parent
    scenario._source = str(path)
    return scenario


# ---------------------------------------------------------------------------------- building
def build_grid(cfg: WorldConfig, base_dir: Path) -> OccupancyGrid:
    res, origin = cfg.cell_size_m, cfg.origin_xy_m
    if cfg.maze:
        grid = mazes.thesis_maze(cfg.maze, resolution_m=res)
    elif cfg.matrix is not None:
        return loaders.grid_from_matrix(cfg.matrix, res, origin, source="world.matrix")
    elif cfg.picture is not None:
        return loaders.parse_text_picture(cfg.picture, res, origin, source="world.picture")
    elif cfg.random is not None:
        r = cfg.random
        grid = mazes.random_maze(
            r.rows,
            r.cols,
            r.seed,
            corridor_cells=r.corridor_cells,
            wall_cells=r.wall_cells,
            resolution_m=res,
            loop_fraction=r.loop_fraction,
        )
    else:
        path = Path(cfg.file or "")
        if not path.is_absolute():
            path = base_dir / path
        # a ROS map carries its own resolution and origin: pass only what the user wrote
        given = cfg.model_fields_set
        return loaders.load_map(
            path,
            resolution_m=res if "cell_size_m" in given else None,
            origin_xy_m=origin if "origin_xy_m" in given else None,
        )
    if origin is not None:
        grid = OccupancyGrid(grid.occupied, grid.resolution_m, origin)
    return grid


def _model(rc: RobotConfig, where: str) -> Any:
    cls = MODELS[rc.model]
    allowed = [f.name for f in dc_fields(cls)]
    kwargs: dict[str, Any] = {}
    for k, v in rc.params.items():
        if k not in allowed:
            raise ScenarioError(
                "",
                [
                    f"{where}.params: unknown parameter {k!r} for model "
                    f"{rc.model!r}" + _did_you_mean(k, allowed)
                ],
            )
        default = next(f.default for f in dc_fields(cls) if f.name == k)
        numeric = isinstance(default, int | float | np.floating)
        if numeric and (isinstance(v, str | bool) or not isinstance(v, int | float)):
            raise ScenarioError("", [f"{where}.params.{k}: must be a number, got {v!r}"])
        if not numeric and not isinstance(v, str):
            raise ScenarioError("", [f"{where}.params.{k}: must be text, got {v!r}"])
        kwargs[k] = v
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as err:
        raise ScenarioError("", [f"{where}.params: {err}"]) from None


def _sensor(
    sc: RangersConfig | LidarConfig, mount_x: float, rate_default: float
) -> RangeSensorSpec:
    common = dict(
        range_min_m=sc.range_min_m,
        rate_hz=sc.rate_hz or rate_default,
        noise_std_m=sc.noise_std_m,
        dropout_prob=sc.dropout_prob,
        mount_xy_m=(mount_x if sc.mount_x_m is None else sc.mount_x_m, sc.mount_y_m),
        mount_yaw_rad=float(np.deg2rad(sc.mount_yaw_deg)),
    )
    if isinstance(sc, RangersConfig):
        spec = RangeSensorSpec.thesis_rangers(sc.range_max_m, **common)
    else:
        amin = None if sc.angle_min_deg is None else float(np.deg2rad(sc.angle_min_deg))
        spec = RangeSensorSpec.fan(
            "lidar", sc.beams, float(np.deg2rad(sc.fov_deg)), sc.range_max_m, amin, **common
        )
    if sc.name:
        from dataclasses import replace

        spec = replace(spec, name=sc.name)
    return spec


def robot_spec(rc: RobotConfig, where: str, dt_s: float) -> RobotSpec:
    try:
        return _robot_spec(rc, where, dt_s)
    except ScenarioError:
        raise
    except ValueError as err:
        raise ScenarioError("", [f"{where}: {err}"]) from None


def _robot_spec(rc: RobotConfig, where: str, dt_s: float) -> RobotSpec:
    model = _model(rc, where)
    # car-like bodies sit ahead of the rear axle; others are centred on P
    offset = rc.body.offset_x_m
    if offset is None:
        offset = float(getattr(model, "wheelbase_m", 0.0)) / 2.0
    sensors = []
    for k, sc in enumerate(rc.sensors):
        try:
            sensors.append(_sensor(sc, offset, 10.0 if sc.type == "lidar" else 1.0 / dt_s))
        except ValueError as err:
            raise ScenarioError("", [f"{where}.sensors[{k}]: {err}"]) from None
    names = [s.name for s in sensors]
    if len(set(names)) != len(names):
        raise ScenarioError(
            "", [f"{where}.sensors: names must be unique (set 'name'), got {names}"]
        )
    th = float(np.deg2rad(rc.pose.theta_deg))
    return RobotSpec(
        name=rc.name,
        model=model,
        mode=rc.mode,
        body_length_m=rc.body.length_m,
        body_width_m=rc.body.width_m,
        body_offset_x_m=offset,
        initial_pose=(rc.pose.x_m, rc.pose.y_m, float(wrap_angle(th))),
        sensors=tuple(sensors),
        odometry=OdometrySpec(
            rc.odometry.wheel_noise_rel,
            rc.odometry.wheel_noise_abs_rad_s,
            float(np.deg2rad(rc.odometry.steering_noise_deg)),
        ),
        color=rc.color,
    )


def _load_python(cfg: PythonControllerConfig, base_dir: Path, where: str) -> Any:
    path = Path(cfg.file)
    if not path.is_absolute():
        path = base_dir / path
    if not path.is_file():
        raise ScenarioError("", [f"{where}.controller.file: no such file {str(path)!r}"])
    if path.suffix != ".py":
        raise ScenarioError(
            "", [f"{where}.controller.file: {path.name!r} must be a Python file ending in .py"]
        )
    spec = importlib.util.spec_from_file_location(f"agvsim_user_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    try:
        spec.loader.exec_module(module)  # type: ignore[union-attr]
    except Exception as err:  # noqa: BLE001 - the user's file: report, don't crash
        line = f" (line {err.lineno})" if isinstance(err, SyntaxError) and err.lineno else ""
        raise ScenarioError(
            "",
            [
                f"{where}.controller.file: {path.name} could not be loaded{line}: "
                f"{type(err).__name__}: {err}"
            ],
        ) from None
    obj = getattr(module, cfg.name, None)
    if obj is None:
        found = [n for n in vars(module) if not n.startswith("_")]
        raise ScenarioError(
            "",
            [
                f"{where}.controller.name: {cfg.name!r} is not defined in {path.name}"
                + _did_you_mean(cfg.name, found)
            ],
        )
    # a class, or a function taking no argument, makes the controller; anything else
    # (a function of obs, an object with step()) is the controller itself
    if isinstance(obj, type) or (callable(obj) and _takes_no_arguments(obj)):
        try:
            return obj()
        except Exception as err:  # noqa: BLE001 - the user's code: report, don't crash
            raise ScenarioError(
                "", [f"{where}.controller.name: {cfg.name}() failed: {type(err).__name__}: {err}"]
            ) from None
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


def _bindings(
    sc: Scenario, specs: list[RobotSpec], base_dir: Path, grid: OccupancyGrid
) -> list[Binding]:
    out: list[Binding] = []
    avoid_groups: dict[tuple, list[int]] = {}
    names = tuple(r.name for r in sc.robots)
    for i, rc in enumerate(sc.robots):
        c, where = rc.controller, f"robots[{i}] ({rc.name})"
        if type(c) in BEHAVIOURS:
            ctx = ControllerContext(i, specs[i], grid, names, base_dir)
            try:
                out.append(Binding(BEHAVIOURS[type(c)](c, ctx), (i,)))
            except ValueError as err:
                raise ScenarioError("", [f"{where}.controller: {err}"]) from None
        elif isinstance(c, ScriptConfig):
            steps = []
            for st in c.steps:
                twist = None
                if st.twist is not None:
                    tw = st.twist
                    twist = (tw[0], 0.0, tw[1]) if len(tw) == 2 else (tw[0], tw[1], tw[2])
                if st.wheels is not None:
                    want = len(specs[i].model.driven_wheels)
                    if len(st.wheels) != want:
                        raise ScenarioError(
                            "",
                            [
                                f"{where}.controller.steps: a {rc.model} robot has {want} driven "
                                f"wheel(s) {_driven_names(specs[i])}, got {len(st.wheels)} speeds "
                                f"{st.wheels}"
                            ],
                        )
                steps.append(
                    ScriptStep(
                        st.duration_s,
                        twist,
                        None if st.wheels is None else tuple(st.wheels),
                        float(np.deg2rad(st.steering_deg)),
                    )
                )
            out.append(Binding(ScriptController(steps, c.loop), (i,)))
        elif isinstance(c, AvoidConfig):
            names = [s.name for s in specs[i].sensors]
            if c.sensor not in names:
                raise ScenarioError(
                    "",
                    [
                        f"{where}.controller.sensor: the robot has no sensor "
                        f"{c.sensor!r}" + _did_you_mean(c.sensor, names)
                    ],
                )
            key = (c, rc.model, rc.mode, rc.params.get("steering_geometry"))
            avoid_groups.setdefault(key, []).append(i)
        elif isinstance(c, PythonControllerConfig):
            out.append(Binding(_load_python(c, base_dir, where), (i,)))
    for (c, _model_kind, mode, _geo), idx in avoid_groups.items():
        spec0 = specs[idx[0]]
        sensor = next(s for s in spec0.sensors if s.name == c.sensor)
        front, back = cone_beams(sensor)
        car = [not _can_spin(specs[i].model) for i in idx]
        ctrl: Any = ObstacleAvoidance(
            sensor=c.sensor,
            front_beams=front,
            back_beams=back,
            trigger_m=c.trigger_m,
            speed_m_s=c.speed_m_s,
            turn_rate_rad_s=c.turn_rate_rad_s,
            heading_source=c.heading_source,
            side_clearance_m=c.side_clearance_m,
            can_spin=~np.array(car),
        )
        if mode == ControlMode.FORWARD:
            ctrl = WheelsFromTwist(ctrl, stack_models([specs[i].model for i in idx]))
        out.append(Binding(ctrl, tuple(idx), batch=True))
    return out


def _driven_names(spec: RobotSpec) -> list[str]:
    return [spec.model.wheel_names[k] for k in spec.model.driven_wheels]


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


def build(sc: Scenario, seed: int | None = None, base_dir: Path | None = None) -> Simulation:
    """A ready ``Simulation`` from a validated scenario; refuses robots inside walls."""
    try:
        return _build(sc, seed, base_dir)
    except ScenarioError as err:
        raise ScenarioError(err.source or sc._source, err.problems) from None


def _build(sc: Scenario, seed: int | None, base_dir: Path | None) -> Simulation:
    base = base_dir or sc._base_dir
    try:
        grid = build_grid(sc.world, base)
    except (loaders.MapFormatError, ValueError) as err:
        raise ScenarioError("", [f"world: {err}"]) from None
    boxes = np.array(
        [
            (b.x_m, b.y_m, np.deg2rad(b.theta_deg), b.length_m / 2, b.width_m / 2)
            for b in sc.world.boxes
        ],
        dtype=np.float64,
    ).reshape(-1, 5)
    specs = [robot_spec(rc, f"robots[{i}] ({rc.name})", sc.dt_s) for i, rc in enumerate(sc.robots)]
    world = World(grid, boxes)
    bindings = _bindings(sc, specs, base, grid)
    sim = Simulation(
        world,
        specs,
        bindings,
        dt_s=sc.dt_s,
        seed=sc.seed if seed is None else seed,
        knows={r.name: r.knows for r in sc.robots if r.knows},
        on_controller_error=sc.on_controller_error,
    )
    _check_placement(sim)
    return sim


def _check_placement(sim: Simulation) -> None:
    fp = sim.footprints(sim.state.poses)
    xmin, xmax, ymin, ymax = sim.world.grid.extent_m
    problems = []
    walls = sim.collider.hit_walls(fp)
    static = sim.collider.hit_static(fp, sim.world.boxes) if len(sim.world.boxes) else walls & False
    for i, r in enumerate(sim.robots):
        x, y, _ = r.initial_pose
        where = f"robots[{i}] ({r.name}).pose"
        if not (xmin <= x < xmax and ymin <= y < ymax):
            problems.append(
                f"{where}: ({x:g}, {y:g}) is outside the map, which spans x in "
                f"[{xmin:g}, {xmax:g}) and y in [{ymin:g}, {ymax:g}) m"
            )
        elif walls[i]:
            problems.append(
                f"{where}: the robot's body at ({x:g}, {y:g}) overlaps a wall "
                "or sticks out of the map; move it to free floor"
            )
        elif static[i]:
            problems.append(f"{where}: the robot's body at ({x:g}, {y:g}) overlaps a box obstacle")
    for i, j in sim.collider.overlapping_pairs(fp):
        problems.append(
            f"robots {sim.robots[i].name!r} and {sim.robots[j].name!r} start overlapping each other"
        )
    if problems:
        raise ScenarioError("", problems)
