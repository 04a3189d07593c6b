"""The scenario file: one validated YAML document holds the world, the robots, duration and seed.

``load_scenario(path)`` parses and validates (unknown keys get "did you mean ...?", bad values a
message naming the field, the value and what is allowed); ``build(scenario)`` turns it into a
ready ``Simulation``. The schema is documented in docs/scenario.md.
"""

from __future__ import annotations

import math
import re
from dataclasses import fields as dc_fields
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from agvsim.behaviours import BEHAVIOURS
from agvsim.control.api import ControllerContext
from agvsim.control.traffic import KeepClear, RobotSight, StaticMap, sight_sensor
from agvsim.dynamics.vehicle import Dynamics, check_dynamics
from agvsim.kinematics import wrap_angle
from agvsim.safe_yaml import YamlInputError, load_yaml, load_yaml_file, measure_data
from agvsim.scenario_controllers import cone_beams as cone_beams  # re-exported
from agvsim.scenario_dynamics import dynamics_spec, floor_spec
from agvsim.scenario_guidance import (
    FloorCameraConfig,
    LineSensorConfig,
    build_floor_codes,
    build_reflectors,
    build_tape,
    floor_camera_spec,
    line_sensor_spec,
    safety_problems,
    safety_spec,
    top_speed_m_s,
)
from agvsim.scenario_limits import (
    MAX_MAGNITUDE,
    Limits,
    check_grid_cells,
    check_robot_count,
    check_scenario,
)
from agvsim.scenario_params import build_model
from agvsim.scenario_schema import (
    CameraConfig,
    LidarConfig,
    RangersConfig,
    RobotConfig,
    Scenario,
    WorldConfig,
    _format_errors,
    _loc,
)
from agvsim.scenario_schema import _models_in as _models_in  # re-exported
from agvsim.scenario_schema import parse_robot as parse_robot  # re-exported
from agvsim.sensors.camera import CameraSpec
from agvsim.sensors.floor_codes import FloorCameraSpec
from agvsim.sensors.line_sensor import LineSensorSpec
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.engine import S_MAX, W_MAX, Binding, Simulation
from agvsim.sim.spec import (
    BODY_HEIGHT_M,
    WALL_HEIGHT_M,
    ControlMode,
    OdometrySpec,
    RobotSpec,
    World,
)
from agvsim.world import loaders, mazes
from agvsim.world.grid import OccupancyGrid
from agvsim.world.markers import Appearance, Face, MarkerKind, MarkerSpec, Paint, place_markers


class ScenarioError(ValueError):
    """A scenario that cannot run; ``problems`` lists one clear line per fault."""

    def __init__(self, source: str, problems: list[str]):
        self.source, self.problems = source, problems
        super().__init__(f"{source}: " + "; ".join(problems))

    def __str__(self) -> str:
        lines = "\n".join(f"  - {p}" for p in self.problems)
        return f"{self.source} is not a valid scenario:\n{lines}"


def parse_scenario(
    data: Any,
    source: str = "scenario",
    limits: Limits | None = None,
    *,
    limits_from_file: bool = True,
) -> Scenario:
    """Validate a scenario's data (a dict, as from YAML) and check it against ``limits``
    (default: :class:`~agvsim.scenario_limits.Limits()`), which the scenario's own ``limits:``
    block raises unless ``limits_from_file`` is False (data from an untrusted place)."""
    if not isinstance(data, dict):
        raise ScenarioError(
            source, [f"the file must hold a mapping of keys, got {type(data).__name__}"]
        )
    limits = limits or Limits()
    try:  # data from anywhere (the app, a sweep): an alias bomb is refused before it is walked
        measure_data(data, source, limits.yaml)
    except YamlInputError as err:
        raise ScenarioError(source, [_yaml_problem(err)]) from None
    _count_robots_first(data, limits, limits_from_file, source)
    huge = _huge_floats(data)
    if huge:  # every block (controllers, dynamics, fleet, metrics) alike, before validation
        raise ScenarioError(source, huge)
    try:
        sc = Scenario.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(source, _format_errors(err)) from None
    except RecursionError:  # data built in Python, nested past what any reader allows
        raise ScenarioError(source, ["the data is nested too deeply"]) from None
    effective = limits.with_block(sc.limits, limits_from_file, source)
    problems = check_scenario(sc, effective)
    if problems:
        raise ScenarioError(source, problems)
    sc._limits = effective
    return sc


def _count_robots_first(data: dict, limits: Limits, from_file: bool, source: str) -> None:
    """Refuse a huge robot list before validating it (validation costs ~50 us a robot)."""
    robots, block = data.get("robots"), data.get("limits")
    if not isinstance(robots, list):
        return
    raised = block.get("max_robots") if from_file and isinstance(block, dict) else None
    if isinstance(raised, int) and not isinstance(raised, bool) and raised > limits.max_robots:
        limits = replace(limits, max_robots=raised)
    try:
        check_robot_count(len(robots), limits)
    except ValueError as err:
        raise ScenarioError(source, [str(err)]) from None


def _huge_floats(data: Any) -> list[str]:
    """One line per float of magnitude above MAX_MAGNITUDE in the raw data (at most 30)."""
    out: list[str] = []
    stack: list[tuple[Any, tuple]] = [(data, ())]
    while stack and len(out) < 30:
        node, where = stack.pop()
        if isinstance(node, float):
            if abs(node) > MAX_MAGNITUDE and math.isfinite(node):  # NaN / inf: the schema's
                out.append(
                    f"{_loc(where)}: too large (allowed: magnitude <= {MAX_MAGNITUDE:g}) "
                    f"(got {node!r})"
                )
        elif isinstance(node, dict):
            stack.extend(reversed([(v, (*where, str(k))) for k, v in node.items()]))
        elif isinstance(node, list | tuple):
            stack.extend(reversed([(v, (*where, i)) for i, v in enumerate(node)]))
    return out


def load_scenario(
    path: str | Path, limits: Limits | None = None, *, limits_from_file: bool = True
) -> Scenario:
    """Read and validate a scenario YAML file (UTF-8, within ``limits``; see
    :mod:`agvsim.scenario_limits`). A file from an untrusted place (a browser upload) is
    read with ``limits_from_file=False``: its ``limits:`` block may lower limits, not raise
    them."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(
            str(path),
            [
                "the file is a directory or a device, not a regular file"
                if path.exists()
                else "no such file"
            ],
        )
    limits = limits or Limits()
    try:
        data = load_yaml_file(path, limits.yaml)
    except YamlInputError as err:
        raise ScenarioError(str(path), [_yaml_problem(err)]) from None
    scenario = parse_scenario(data, str(path), limits, limits_from_file=limits_from_file)
    scenario._base_dir = path.parent
    scenario._source = str(path)
    return scenario


def scenario_from_text(
    text: str | bytes,
    source: str,
    limits: Limits | None = None,
    *,
    limits_from_file: bool = False,
) -> Scenario:
    """A scenario from YAML text (an upload): the same checks as :func:`load_scenario`; by
    default the text's ``limits:`` block may lower the limits but not raise them."""
    limits = limits or Limits()
    try:
        data = load_yaml(text, source, limits.yaml)
    except YamlInputError as err:
        raise ScenarioError(source, [_yaml_problem(err)]) from None
    return parse_scenario(data, source, limits, limits_from_file=limits_from_file)


def _yaml_problem(err: YamlInputError) -> str:
    hint = "; put a large map in a map file (world.file)" if "yaml_max_" in err.problem else ""
    return (f"line {err.line}: " if err.line is not None else "") + err.problem + hint


# ---------------------------------------------------------------------------------- building
def build_grid(cfg: WorldConfig, base_dir: Path, limits: Limits | None = None) -> OccupancyGrid:
    res, origin = cfg.cell_size_m, cfg.origin_xy_m
    limits = limits or Limits()
    if cfg.maze:
        grid = mazes.thesis_maze(cfg.maze, resolution_m=res)
    elif cfg.matrix is not None:
        return loaders.grid_from_matrix(cfg.matrix, res, origin, source="world.matrix")
    elif cfg.picture is not None:
        return loaders.parse_text_picture(cfg.picture, res, origin, source="world.picture")
    elif cfg.random is not None:
        r = cfg.random
        pitch = r.corridor_cells + r.wall_cells
        rows, cols = r.rows * pitch + r.wall_cells, r.cols * pitch + r.wall_cells
        check_grid_cells(rows, cols, limits, "world.random")
        grid = mazes.random_maze(
            r.rows,
            r.cols,
            r.seed,
            corridor_cells=r.corridor_cells,
            wall_cells=r.wall_cells,
            resolution_m=res,
            loop_fraction=r.loop_fraction,
            max_cells=limits.max_grid_cells,
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
            max_cells=limits.max_grid_cells,
        )
    if origin is not None:
        grid = OccupancyGrid(grid.occupied, grid.resolution_m, origin)
    return grid


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
        spec = replace(spec, name=sc.name)
    return spec


def default_camera_height(wheel_radius_m: float) -> float:
    """Where a camera without ``mount_z_m`` sits: 5 cm above the robot's body (m)."""
    return float(wheel_radius_m) + BODY_HEIGHT_M + 0.05


def default_rate_hz(sensor_type: str, dt_s: float) -> float:
    """The rate of a range sensor without ``rate_hz``: the thesis's rangers every step, a
    lidar 10 Hz."""
    return 10.0 if sensor_type == "lidar" else 1.0 / dt_s


def _camera(sc: CameraConfig, rc: RobotConfig, model: Any, offset: float) -> CameraSpec:
    """A camera spec; by default on the front of the body, 5 cm above its top."""
    wheel_r = float(np.asarray(getattr(model, "wheel_radius_m", 0.1)).reshape(-1)[0])
    mount_z = sc.mount_z_m if sc.mount_z_m is not None else default_camera_height(wheel_r)
    if not mount_z < WALL_HEIGHT_M:
        raise ValueError(
            f"mount_z_m: the camera at {mount_z:g} m must be below the wall tops "
            f"({WALL_HEIGHT_M:g} m)"
        )
    return CameraSpec(
        name=sc.name or "camera",
        width_px=sc.width_px,
        height_px=sc.height_px,
        hfov_rad=float(np.deg2rad(sc.hfov_deg)),
        rate_hz=sc.rate_hz,
        mount_xy_m=(
            offset + rc.body.length_m / 2.0 if sc.mount_x_m is None else sc.mount_x_m,
            sc.mount_y_m,
        ),
        mount_z_m=round(float(mount_z), 9),
        mount_yaw_rad=float(np.deg2rad(sc.mount_yaw_deg)),
        pitch_rad=float(np.deg2rad(sc.pitch_deg)),
        range_max_m=sc.range_max_m,
        noise_std=sc.noise_std,
    )


def build_appearance(cfg: WorldConfig, grid: OccupancyGrid) -> Appearance:
    """Colours and markers of the world (marker textures are made here, with OpenCV)."""
    col = cfg.colors
    for k, p in enumerate(col.paint):
        for key, (a, b), n in (("rows", p.rows, grid.rows), ("cols", p.cols, grid.cols)):
            if not (0 <= a < n and 0 <= b < n):
                raise ValueError(
                    f"colors.paint[{k}].{key}: {[a, b]} is outside the map (allowed: 0..{n - 1})"
                )
    specs = []
    for m in cfg.markers:
        kind = MarkerKind(m.kind)
        specs.append(
            MarkerSpec(
                kind=kind,
                face=Face(m.face),
                size_m=m.size_m,
                center_z_m=WALL_HEIGHT_M / 2 if m.center_z_m is None else m.center_z_m,
                cell=None if m.cell is None else (int(m.cell[0]), int(m.cell[1])),
                xy_m=None if m.x_m is None else (float(m.x_m), float(m.y_m)),  # type: ignore[arg-type]
                offset_m=m.offset_m,
                marker_id=int(getattr(m, "id", 0)),
                dictionary=str(getattr(m, "dictionary", getattr(m, "family", "4x4_50"))),
                text=str(getattr(m, "text", "")),
                rgb=tuple(getattr(m, "rgb", (255, 0, 0))),  # type: ignore[arg-type]
                name=m.name or "",
            )
        )
    return Appearance(
        wall_rgb=col.wall_rgb,
        floor_rgb=col.floor_rgb,
        sky_rgb=col.sky_rgb,
        box_rgb=col.box_rgb,
        shade_faces=col.shade_faces,
        floor_checker=col.floor_checker,
        paint=tuple(Paint(p.rows, p.cols, p.rgb) for p in col.paint),
        markers=place_markers(specs, grid, WALL_HEIGHT_M),
    )


def robot_spec(rc: RobotConfig, where: str, dt_s: float) -> RobotSpec:
    try:
        return _robot_spec(rc, where, dt_s)
    except ScenarioError:
        raise
    except ValueError as err:
        raise ScenarioError("", [f"{where}: {err}"]) from None


def _robot_spec(rc: RobotConfig, where: str, dt_s: float) -> RobotSpec:
    model = build_model(rc.model, rc.params)
    # car-like bodies sit ahead of the rear axle; others are centred on P
    offset = rc.body.offset_x_m
    if offset is None:
        offset = float(getattr(model, "wheelbase_m", 0.0)) / 2.0
    sensors: list[RangeSensorSpec] = []
    cameras: list[CameraSpec] = []
    lines: list[LineSensorSpec] = []
    floor_cams: list[FloorCameraSpec] = []
    for k, sc in enumerate(rc.sensors):
        try:
            if isinstance(sc, CameraConfig):
                cameras.append(_camera(sc, rc, model, offset))
            elif isinstance(sc, LineSensorConfig):
                lines.append(line_sensor_spec(sc, sc.name or ("line" if not lines else f"line{k}")))
            elif isinstance(sc, FloorCameraConfig):
                floor_cams.append(
                    floor_camera_spec(
                        sc, sc.name or ("floor_camera" if not floor_cams else f"floor_camera{k}")
                    )
                )
            else:
                sensors.append(_sensor(sc, offset, default_rate_hz(sc.type, dt_s)))
        except ValueError as err:
            raise ScenarioError("", [f"{where}.sensors[{k}]: {err}"]) from None
    names = [
        *(s.name for s in sensors),
        *(c.name for c in cameras),
        *(ln.name for ln in lines),
        *(f.name for f in floor_cams),
    ]
    if len(set(names)) != len(names):
        raise ScenarioError(
            "", [f"{where}.sensors: names must be unique (set 'name'), got {names}"]
        )
    th = float(np.deg2rad(rc.pose.theta_deg))
    spec = RobotSpec(
        name=rc.name,
        model=model,
        mode=rc.mode,
        body_length_m=rc.body.length_m,
        body_width_m=rc.body.width_m,
        body_offset_x_m=offset,
        initial_pose=(rc.pose.x_m, rc.pose.y_m, float(wrap_angle(th))),
        sensors=tuple(sensors),
        cameras=tuple(cameras),
        odometry=OdometrySpec(
            rc.odometry.wheel_noise_rel,
            rc.odometry.wheel_noise_abs_rad_s,
            float(np.deg2rad(rc.odometry.steering_noise_deg)),
        ),
        color=rc.color,
        dynamics=dynamics_spec(rc.dynamics, offset),
        line_sensors=tuple(lines),
        floor_cameras=tuple(floor_cams),
        safety=None if rc.safety is None else safety_spec(rc.safety, f"{where}.safety"),
    )
    if spec.dynamics is not None:
        try:
            check_dynamics(spec)
        except ValueError as err:
            raise ScenarioError("", [f"{where}.dynamics: {err}"]) from None
    return spec


def _bindings(
    sc: Scenario,
    specs: list[RobotSpec],
    base_dir: Path,
    grid: OccupancyGrid,
    boxes: np.ndarray,
    world: World | None = None,
) -> list[Binding]:
    """Every robot's controller, built one way through the registry (agvsim.behaviours):
    one binding a robot, then one a group for batched types (robots sharing a config)."""
    out: list[Binding] = []
    static = StaticMap.of(grid, boxes)
    names = tuple(r.name for r in sc.robots)
    groups: dict[tuple, list[ControllerContext]] = {}
    for i, rc in enumerate(sc.robots):
        cfg, kind = rc.controller, BEHAVIOURS[rc.controller.type]
        ctx = ControllerContext(i, specs[i], grid, names, base_dir, static, world)
        try:
            if kind.check is not None:
                kind.check(cfg, ctx)
            if kind.build_group is not None:
                groups.setdefault(_group_key(kind, cfg, specs[i]), []).append(ctx)
                continue
            ctrl = None if kind.build is None else kind.build(cfg, ctx)
        except ValueError as err:
            raise ScenarioError("", [_controller_problem(i, rc.name, cfg, err)]) from None
        if ctrl is None:
            continue
        if kind.keep_clear:
            ctrl = _keep_clear(ctrl, specs[i], static)
        out.append(Binding(ctrl, (i,), user_code=kind.user_code))
    for ctxs in groups.values():
        cfgs = [sc.robots[c.robot_index].controller for c in ctxs]
        build_group = BEHAVIOURS[cfgs[0].type].build_group
        assert build_group is not None  # only batched types are grouped
        out.append(Binding(build_group(cfgs, ctxs), tuple(c.robot_index for c in ctxs), batch=True))
    return out


def _group_key(kind: Any, cfg: Any, spec: RobotSpec) -> tuple:
    """Robots batched in one controller share the behaviour's ``group_key`` (default: the
    config and the model's kind) and the control mode; in forward mode also the model's kind
    and its non-numeric parameters (the wheel speeds come from ``stack_models`` of them)."""
    model: Any = spec.model
    texts = tuple(v for f in dc_fields(model) if isinstance(v := getattr(model, f.name), str))
    shared = (cfg, type(model)) if kind.group_key is None else kind.group_key(cfg, spec)
    forward = spec.mode == ControlMode.FORWARD
    return (shared, spec.mode, type(model) if forward else None, texts if forward else ())


def _controller_problem(i: int, name: str, cfg: Any, err: ValueError) -> str:
    """A builder's message under the robot's controller, at the config field it names."""
    where, msg = f"robots[{i}] ({name}).controller", str(err)
    head = re.match(r"(\w+)(\[\d+\])?(\.\w+)*: ", msg)
    if head and head.group(1) in type(cfg).model_fields:
        return f"{where}.{msg}"
    return f"{where}: {msg}"


def _keep_clear(ctrl: Any, spec: RobotSpec, static: StaticMap) -> Any:
    """A behaviour, slowed to stop before other robots its lidar sees."""
    sensor = sight_sensor(spec)
    sight = None if sensor is None else RobotSight.for_robots([spec], static, sensor)
    return ctrl if sight is None else KeepClear(ctrl, sight)


def build(sc: Scenario, seed: int | None = None, base_dir: Path | None = None) -> Simulation:
    """A ready ``Simulation`` from a validated scenario; refuses robots inside walls."""
    try:
        return _build(sc, seed, base_dir)
    except ScenarioError as err:
        raise ScenarioError(err.source or sc._source, err.problems) from None


def _build(sc: Scenario, seed: int | None, base_dir: Path | None) -> Simulation:
    base = base_dir or sc._base_dir
    if seed is not None and (
        isinstance(seed, bool) or not isinstance(seed, int | np.integer) or not 0 <= seed < 2**63
    ):
        raise ScenarioError("", [f"seed: {seed!r} is not allowed (an integer 0 .. 2^63 - 1)"])
    try:
        grid = build_grid(sc.world, base, sc._limits)
    except (loaders.MapFormatError, ValueError) as err:
        msg = str(err)
        raise ScenarioError("", [msg if msg.startswith("world.") else f"world: {msg}"]) from None
    boxes = np.array(
        [
            (b.x_m, b.y_m, np.deg2rad(b.theta_deg), b.length_m / 2, b.width_m / 2)
            for b in sc.world.boxes
        ],
        dtype=np.float64,
    ).reshape(-1, 5)
    specs = [robot_spec(rc, f"robots[{i}] ({rc.name})", sc.dt_s) for i, rc in enumerate(sc.robots)]
    try:
        look = build_appearance(sc.world, grid)
    except ValueError as err:
        raise ScenarioError("", [f"world.{err}"]) from None
    world = World(grid, boxes, look, floor=floor_spec(sc.world.floor), **_guidance_world(sc))
    _check_safety(sc, specs, world)
    bindings = _bindings(sc, specs, base, grid, boxes, world)
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


def _guidance_world(sc: Scenario) -> dict:
    """The world's tape, floor codes and reflectors (docs/guidance.md), where given."""
    w, out = sc.world, {}
    makers: tuple[tuple[str, Any, Any], ...] = (
        ("tape", w.tape, build_tape),
        ("floor_codes", w.floor_codes, build_floor_codes),
        ("reflectors", w.reflectors, build_reflectors),
    )
    for key, cfg, make in makers:
        if cfg is None:
            continue
        try:
            out[key] = make(cfg)
        except ValueError as err:
            raise ScenarioError("", [f"world.{key}: {err}"]) from None
    return out


def _check_safety(sc: Scenario, specs: list[RobotSpec], world: World) -> None:
    """Every robot's safety scanner reads one of its range sensors and has fields long enough
    to stop in from its top speed (with dynamics: at what its wheels can brake on the floor)."""
    problems: list[str] = []
    for i, (rc, spec) in enumerate(zip(sc.robots, specs, strict=True)):
        if rc.safety is None or spec.safety is None:
            continue
        hl = spec.body_length_m / 2.0
        limit = None
        if spec.dynamics is not None:
            dyn = Dynamics([spec], world.floor, W_MAX, S_MAX)
            ahead, behind = (dyn.braking_deceleration_m_s2(0, None, a) for a in (0.0, np.pi))
            limit = min(ahead, behind)
        problems += safety_problems(
            rc.safety,
            spec.safety,
            f"robots[{i}] ({rc.name}).safety",
            [s.name for s in spec.sensors],
            spec.body_offset_x_m + hl,
            hl - spec.body_offset_x_m,
            top_speed_m_s(spec.model),
            limit,
            next((1.0 / s.rate_hz for s in spec.sensors if s.name == spec.safety.sensor), 0.0),
        )
    if problems:
        raise ScenarioError("", problems)


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
