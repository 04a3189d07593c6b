"""The scenario's behaviours: each controller ``type`` with its typed config and its builder.

A config class validates the scenario file's ``controller:`` section (unknown keys and bad
values are refused there, at the edge); its builder turns it into a plain core controller from
:mod:`agvsim.control`, which never sees pydantic, handing the config's fields to it by name
(``config_base.construct``). ``BEHAVIOURS`` is the one registry of controller types: type tag
-> :class:`~agvsim.scenario_controllers.Behaviour` (config class, builder, flags). It holds
the scenario's basic types (script, avoid, python, idle: ``agvsim.scenario_controllers``) and
these:

=============  ====================  ======================================================
type           config                controller
=============  ====================  ======================================================
goto_goal      ``GoalConfig``        :class:`agvsim.control.goal.GoToGoal`
waypoints      ``WaypointsConfig``   :class:`agvsim.control.pure_pursuit.PurePursuit`
maze_solver    ``MazeSolverConfig``  :class:`agvsim.control.maze_solver.AStarMazeSolver`,
                                     :class:`agvsim.control.explorer.TremauxExplorer`
pursue         ``PursueConfig``      :class:`agvsim.control.pursuit.Pursuer`
evade          ``EvadeConfig``       :class:`agvsim.control.pursuit.Evader`
teleop         ``TeleopConfig``      :class:`agvsim.control.teleop.Teleop`
wall_follow    ``WallFollowConfig``  :class:`agvsim.control.wall_follow.WallFollower`
marker_search  ``MarkerSearchConfig``  :class:`agvsim.control.marker_search.MarkerSearch`
line_follow    ``LineFollowConfig``  :class:`agvsim.control.line_follow.LineFollower`
route          ``RouteConfig``       :class:`agvsim.control.route_follow.RouteFollower`
=============  ====================  ======================================================
"""

from __future__ import annotations

import math
import time
from typing import Annotated, Any, Literal

from pydantic import ConfigDict, Field, model_validator

from agvsim.config_base import construct
from agvsim.control.api import ControllerContext
from agvsim.control.explorer import TremauxExplorer
from agvsim.control.goal import GoToGoal
from agvsim.control.marker_search import MarkerSearch
from agvsim.control.maze_solver import AStarMazeSolver
from agvsim.control.mobility import Mobility, PoseSource
from agvsim.control.pure_pursuit import PurePursuit
from agvsim.control.pursuit import Evader, Pursuer, WallGuard
from agvsim.control.teleop import Teleop
from agvsim.control.wall_follow import WallFollower
from agvsim.scenario_controllers import BASIC, Behaviour, ControllerConfigBase
from agvsim.scenario_guidance import LineFollowConfig, RouteConfig, build_line_follow, build_route
from agvsim.world.loaders import MAX_CELLS

_Cell = Annotated[int, Field(ge=0, le=10_000_000)]  # numba takes 64-bit integers only


class _Config(ControllerConfigBase):
    """Every behaviour config: a strict block whose texts (names of sensors, robots) are short."""

    model_config = ConfigDict(str_max_length=200)


# ---------------------------------------------------------------------------------- goal
class GoalConfig(_Config):
    """``controller: {type: goto_goal, goal_x_m: 3, goal_y_m: -2}``"""

    type: Literal["goto_goal"]
    goal_x_m: float
    goal_y_m: float
    tolerance_m: float = Field(default=0.1, gt=0, le=100)
    max_speed_m_s: float = Field(default=0.8, gt=0, le=100)
    max_turn_rate_rad_s: float = Field(default=1.5, gt=0, le=100)
    heading_kp: float = Field(default=2.5, ge=0)
    heading_ki: float = Field(default=0.2, ge=0)
    heading_kd: float = Field(default=0.05, ge=0)
    speed_kp: float = Field(default=0.8, ge=0)
    speed_ki: float = Field(default=0.05, ge=0)
    speed_kd: float = Field(default=0.0, ge=0)
    goal_heading_deg: float | None = Field(
        default=None, description="holonomic models turn to this"
    )
    pose_source: PoseSource = "true_pose"


class WaypointsConfig(_Config):
    """``controller: {type: waypoints, points: [[0, 0], [3, 0], [3, 3]], loop: true}``"""

    type: Literal["waypoints"]
    points: list[tuple[float, float]] = Field(min_length=1, description="[x_m, y_m] each")
    loop: bool = False
    lookahead_m: float = Field(default=0.8, gt=0, le=100)
    speed_m_s: float = Field(default=0.5, gt=0, le=100)
    tolerance_m: float = Field(default=0.15, gt=0, le=100)
    max_turn_rate_rad_s: float = Field(default=1.5, gt=0, le=100)
    face_travel: bool = True
    pose_source: PoseSource = "true_pose"


def build_goal(cfg: GoalConfig, ctx: ControllerContext) -> GoToGoal:
    """The controller a ``goto_goal`` config describes."""
    heading = None if cfg.goal_heading_deg is None else math.radians(cfg.goal_heading_deg)
    return construct(
        GoToGoal,
        cfg,
        goal_xy=(cfg.goal_x_m, cfg.goal_y_m),
        heading_gains=(cfg.heading_kp, cfg.heading_ki, cfg.heading_kd),
        speed_gains=(cfg.speed_kp, cfg.speed_ki, cfg.speed_kd),
        goal_heading_rad=heading,
    )


def build_waypoints(cfg: WaypointsConfig, ctx: ControllerContext) -> PurePursuit:
    """The controller a ``waypoints`` config describes."""
    return construct(PurePursuit, cfg, waypoints=cfg.points)


# ---------------------------------------------------------------------------------- maze
class MazeSolverConfig(_Config):
    """``controller: {type: maze_solver, goal_cell: [17, 17], method: astar}``"""

    type: Literal["maze_solver"]
    method: Literal["astar", "tremaux"] = "astar"
    goal_cell: tuple[_Cell, _Cell] | None = Field(
        default=None, description="[row, col] of the map grid"
    )
    goal_x_m: float | None = None
    goal_y_m: float | None = None
    speed_m_s: float = Field(default=0.8, gt=0, le=100)
    goal_tolerance_m: float = Field(default=0.3, gt=0, le=100)
    # astar
    lookahead_m: float = Field(default=0.8, gt=0, le=100)
    connectivity: Literal[4, 8] = 8
    clearance_m: float = Field(
        default=0.05, ge=0, le=10, description="extra margin beyond half width"
    )
    preferred_clearance_m: float = Field(default=1.0, gt=0, le=100)
    plan_resolution_m: float = Field(default=0.25, gt=0, le=10)
    pose_source: PoseSource = "true_pose"
    # tremaux
    sensor: str = "lidar"
    hand: Literal["right", "left"] = "right"
    wall_distance_m: float = Field(default=0.8, gt=0, le=100)

    @model_validator(mode="after")
    def _one_goal(self) -> MazeSolverConfig:
        xy = (self.goal_x_m is None, self.goal_y_m is None)
        if xy[0] != xy[1]:
            raise ValueError("give both goal_x_m and goal_y_m, or goal_cell")
        if (self.goal_cell is None) == (self.goal_x_m is None):
            raise ValueError("give exactly one goal: goal_cell [row, col] or goal_x_m + goal_y_m")
        return self


def _check_goal_on_map(cfg: MazeSolverConfig, grid: Any) -> None:
    """A goal off the map could never be reached: refuse it rather than search forever."""
    if cfg.goal_cell is not None:
        row, col = cfg.goal_cell
        if not (row < grid.rows and col < grid.cols):
            raise ValueError(
                f"goal_cell: {[row, col]} is outside the {grid.rows} x {grid.cols} map "
                f"(allowed: rows 0..{grid.rows - 1}, cols 0..{grid.cols - 1})"
            )
        return
    xmin, xmax, ymin, ymax = grid.extent_m
    x, y = cfg.goal_x_m, cfg.goal_y_m
    if not (xmin <= x < xmax and ymin <= y < ymax):  # type: ignore[operator]
        raise ValueError(
            f"goal_x_m, goal_y_m: ({x:g}, {y:g}) is outside the map, which spans x in "
            f"[{xmin:g}, {xmax:g}) and y in [{ymin:g}, {ymax:g}) m"
        )


def build_maze_solver(
    cfg: MazeSolverConfig, ctx: ControllerContext
) -> AStarMazeSolver | TremauxExplorer:
    """The controller a ``maze_solver`` config describes, for robot ``ctx.robot_index``."""
    spec: Any = ctx.spec
    grid: Any = ctx.grid
    length = float(getattr(spec, "body_length_m", 0.6))
    width = float(getattr(spec, "body_width_m", 0.45))
    offset = float(getattr(spec, "body_offset_x_m", 0.0))
    goal_xy = None if cfg.goal_x_m is None else (cfg.goal_x_m, cfg.goal_y_m)
    _check_goal_on_map(cfg, grid)
    if cfg.method == "tremaux":
        if goal_xy is None:
            assert cfg.goal_cell is not None  # the config holds one goal or the other
            x, y = grid.cell_center(*cfg.goal_cell)
            goal_xy = (float(x), float(y))
        names = [s.name for s in getattr(spec, "sensors", ())]
        if cfg.sensor not in names:
            raise ValueError(f"maze_solver (tremaux) needs the sensor {cfg.sensor!r}; has {names}")
        return construct(TremauxExplorer, cfg, goal_xy_m=goal_xy, body_width_m=width)
    # A* plans on a raster of <= 5 cm cells (agvsim.control.planning.ClearanceMap): bound it
    up = max(1, math.ceil(grid.resolution_m / 0.05 - 1e-9))
    cells = grid.rows * up * grid.cols * up
    if cells > MAX_CELLS:
        raise ValueError(
            f"maze_solver (astar) would plan on {grid.rows * up:,} x {grid.cols * up:,} = "
            f"{cells:,} cells of 5 cm, over the limit {MAX_CELLS:,}; use a smaller map "
            "(world.cell_size_m, fewer cells) or method: tremaux"
        )
    return construct(
        AStarMazeSolver,
        cfg,
        grid=grid,
        goal_xy_m=goal_xy,
        body_length_m=length,
        body_width_m=width,
        body_offset_x_m=offset,
    )


# ---------------------------------------------------------------------------------- pursuit
class PursueConfig(_Config):
    """``controller: {type: pursue, target: blue, ...}``"""

    type: Literal["pursue"]
    target: str = Field(min_length=1, description="the robot to catch (list it in 'knows')")
    reorient_deg: float = Field(
        default=22.5, gt=0, lt=180, description="turn on the spot beyond this"
    )
    speed_m_s: float = Field(default=1.0, gt=0, le=50)
    turn_rate_rad_s: float = Field(default=1.0, gt=0, le=50)
    reorient_speed_m_s: float = Field(
        default=0.0, ge=0, le=50, description="speed while reorienting"
    )
    sensor: str = Field(default="rangers", description="range sensor used to keep off walls")
    wall_margin_m: float = Field(default=0.12, ge=0, le=10, description="clearance kept from walls")


class EvadeConfig(_Config):
    """``controller: {type: evade, pursuer: red, ...}``"""

    type: Literal["evade"]
    pursuer: str = Field(min_length=1, description="the robot to flee (list it in 'knows')")
    alert_distance_m: float = Field(default=4.0, gt=0, le=1000)
    speed_m_s: float = Field(default=0.8, gt=0, le=50)
    turn_rate_rad_s: float = Field(default=2.5, gt=0, le=50)
    wander_speed_m_s: float | None = Field(
        default=None, ge=0, le=50, description="default speed / 2"
    )
    sensor: str = Field(default="rangers", description="range sensor used to keep off walls")
    space_sensor: str = Field(default="lidar", description="finds free space, if the robot has it")
    wall_margin_m: float = Field(default=0.12, ge=0, le=10, description="clearance kept from walls")


def _check_robot(name: str, field: str, ctx: ControllerContext) -> None:
    me = ctx.robot_names[ctx.robot_index] if ctx.robot_names else None
    if ctx.robot_names and (name not in ctx.robot_names or name == me):
        others = [n for n in ctx.robot_names if n != me]
        raise ValueError(f"{field}: {name!r} is not another robot (robots: {others})")


def _check_sensor(name: str, field: str, ctx: ControllerContext) -> None:
    names = [s.name for s in getattr(ctx.spec, "sensors", ())]
    if name not in names:
        raise ValueError(f"{field}: the robot has no sensor {name!r} (it has {names})")


def _body_and_mounts(ctx: ControllerContext, margin_m: float) -> dict:
    """The wall guard shaped like the robot's body, and where its sensors sit."""
    sensors = getattr(ctx.spec, "sensors", ())
    return {
        "guard": WallGuard.for_robot(ctx.spec, margin_m=margin_m),
        "mounts_xy_m": {s.name: tuple(s.mount_xy_m) for s in sensors},
    }


def build_pursue(cfg: PursueConfig, ctx: ControllerContext) -> Pursuer:
    _check_robot(cfg.target, "target", ctx)
    _check_sensor(cfg.sensor, "sensor", ctx)
    return construct(
        Pursuer,
        cfg,
        reorient_rad=math.radians(cfg.reorient_deg),
        **_body_and_mounts(ctx, cfg.wall_margin_m),
    )


def build_evade(cfg: EvadeConfig, ctx: ControllerContext) -> Evader:
    _check_robot(cfg.pursuer, "pursuer", ctx)
    _check_sensor(cfg.sensor, "sensor", ctx)
    return construct(Evader, cfg, **_body_and_mounts(ctx, cfg.wall_margin_m))


# ---------------------------------------------------------------------------------- teleop
class TeleopConfig(_Config):
    """``controller: {type: teleop, deadman_s: 0.5}``"""

    type: Literal["teleop"]
    deadman_s: float = Field(default=0.5, gt=0, le=3600)
    linear_speed_m_s: float = Field(default=0.5, gt=0, le=100)
    lateral_speed_m_s: float = Field(default=0.5, gt=0, le=100)
    turn_rate_rad_s: float = Field(default=1.0, gt=0, le=100)
    clock: Literal["simulation", "wall"] = Field(
        default="simulation", description="time of the dead-man timeout: sim time or time.monotonic"
    )


def build_teleop(cfg: TeleopConfig, ctx: ControllerContext) -> Teleop:
    """A ``Teleop`` from its config (the app keeps the object to send commands to it)."""
    return construct(Teleop, cfg, clock=time.monotonic if cfg.clock == "wall" else None)


# ---------------------------------------------------------------------------------- walls
class WallFollowConfig(_Config):
    """``controller: {type: wall_follow, side: left, ...}`` in a scenario."""

    type: Literal["wall_follow"]
    side: Literal["left", "right"] = "left"
    sensor: str = Field(default="lidar", description="a lidar, or the thesis's four rangers")
    distance_m: float = Field(
        default=0.6, gt=0, le=10, description="from the wall to the body centre"
    )
    speed_m_s: float = Field(default=0.4, gt=0, le=10)
    turn_rate_rad_s: float = Field(default=1.0, gt=0, le=20)
    heading_source: Literal["odometry", "true_pose"] = Field(
        default="odometry", description="rangers only: the heading held square to the walls"
    )


def build_wall_follow(cfg: WallFollowConfig, ctx: ControllerContext) -> WallFollower:
    """The controller for one robot of a scenario: geometry from its spec. Raises ValueError
    (the message names the field) for a sensor the robot lacks or a distance too short."""
    spec: Any = ctx.spec
    sensors = {s.name: s for s in spec.sensors}
    if cfg.sensor not in sensors:
        raise ValueError(
            f"sensor: the robot has no sensor {cfg.sensor!r} "
            f"(it has {', '.join(sorted(sensors)) or 'none'})"
        )
    sweep = math.hypot(spec.body_length_m / 2.0, spec.body_width_m / 2.0)
    if cfg.distance_m < sweep:
        raise ValueError(
            f"distance_m: {cfg.distance_m} m is too close for a body that sweeps "
            f"{sweep:.2f} m turning on the spot; use at least {math.ceil(sweep * 100) / 100:.2f}"
        )
    return construct(
        WallFollower,
        cfg,
        body_length_m=spec.body_length_m,
        body_width_m=spec.body_width_m,
        body_offset_x_m=spec.body_offset_x_m,
        sensor_mount_xy_m=sensors[cfg.sensor].mount_xy_m,
    )


# ---------------------------------------------------------------------------------- camera
class MarkerSearchConfig(_Config):
    """``controller: {type: marker_search, marker_id: 3, stop_distance_m: 0.8}``"""

    type: Literal["marker_search"]
    marker_id: int = Field(ge=0, le=1_000_000, description="the ArUco / AprilTag id to find")
    dictionary: Literal[
        "4x4_50", "4x4_100", "4x4_250", "4x4_1000", "5x5_50", "5x5_100", "5x5_250", "5x5_1000",
        "6x6_50", "6x6_100", "6x6_250", "6x6_1000", "7x7_50", "7x7_100", "7x7_250", "7x7_1000",
        "original", "mip_36h12",
        "apriltag_16h5", "apriltag_25h9", "apriltag_36h10", "apriltag_36h11",
    ] = "4x4_50"  # fmt: skip
    camera: str = Field(default="camera", description="the name of the robot's camera")
    stop_distance_m: float = Field(
        default=0.8, gt=0, le=20, description="from the marker to the camera"
    )
    speed_m_s: float = Field(default=0.4, gt=0, le=10)
    turn_rate_rad_s: float = Field(default=0.8, gt=0, le=10)
    clearance_m: float = Field(
        default=0.25, ge=0, le=5, description="kept from obstacles when exploring"
    )
    leg_m: float = Field(
        default=2.5, gt=0, le=100, description="longest straight leg between scans"
    )
    pose_source: PoseSource = "odometry"


def build_marker_search(cfg: MarkerSearchConfig, ctx: ControllerContext) -> MarkerSearch:
    """The controller for one robot: its camera (by name) and body from its spec."""
    from agvsim.world.markers import MarkerKind, dictionary_size

    tag = cfg.dictionary.startswith("apriltag_")
    kind = MarkerKind.APRILTAG if tag else MarkerKind.ARUCO
    ids = dictionary_size(kind, cfg.dictionary.removeprefix("apriltag_"))
    if cfg.marker_id >= ids:
        raise ValueError(
            f"marker_id: {cfg.marker_id} is not in {cfg.dictionary}, which holds ids "
            f"0..{ids - 1}; such a marker cannot exist"
        )
    spec: Any = ctx.spec
    cams = {c.name: c for c in getattr(spec, "cameras", ())}
    if cfg.camera not in cams:
        raise ValueError(
            f"camera: the robot has no camera {cfg.camera!r} (it has "
            f"{', '.join(sorted(cams)) or 'none'}; add {{type: camera}} to its sensors)"
        )
    if not Mobility.of(spec.model).can_spin:
        raise ValueError(
            "marker_search turns on the spot: use a model that can (differential, mecanum, "
            "omni3, or a tricycle with max_steer_rad >= pi/2)"
        )
    return construct(
        MarkerSearch,
        cfg,
        camera=cams[cfg.camera],
        body_half_width_m=spec.body_width_m / 2.0,
        body_front_m=spec.body_offset_x_m + spec.body_length_m / 2.0,
        body_height_m=spec.height_m,
    )


# ---------------------------------------------------------------------------------- registry
# Every controller type of a scenario file: type tag -> its config class and builder
BEHAVIOURS: dict[str, Behaviour] = {
    **BASIC,  # script, avoid, python, idle
    "goto_goal": Behaviour(GoalConfig, build=build_goal, keep_clear=True),
    "waypoints": Behaviour(WaypointsConfig, build=build_waypoints, keep_clear=True),
    "maze_solver": Behaviour(MazeSolverConfig, build=build_maze_solver, keep_clear=True),
    "pursue": Behaviour(PursueConfig, build=build_pursue),  # meant to reach its target
    "evade": Behaviour(EvadeConfig, build=build_evade, keep_clear=True),
    "teleop": Behaviour(TeleopConfig, build=build_teleop),  # the user drives
    "wall_follow": Behaviour(WallFollowConfig, build=build_wall_follow, keep_clear=True),
    "marker_search": Behaviour(MarkerSearchConfig, build=build_marker_search, keep_clear=True),
    # industrial guidance (docs/guidance.md)
    "line_follow": Behaviour(LineFollowConfig, build=build_line_follow),
    "route": Behaviour(RouteConfig, build=build_route),
}
