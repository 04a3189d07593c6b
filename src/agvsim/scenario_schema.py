"""The scenario schema: the pydantic models a scenario file is validated against, and the
formatting of validation errors into one clear line per fault ("did you mean ...?").

Loading and building live in ``agvsim.scenario``, which re-exports the names imported from it.
"""

from __future__ import annotations

import difflib
import re
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, TypeAlias, Union

from pydantic import (
    BaseModel,
    Discriminator,
    Field,
    PrivateAttr,
    Tag,
    TypeAdapter,
    ValidationError,
    create_model,
    field_validator,
    model_validator,
)

from agvsim.behaviours import BEHAVIOURS
from agvsim.config_base import StrictConfig, did_you_mean
from agvsim.control.api import ControlMode
from agvsim.fleet.config import LayoutConfig, Vda5050Config
from agvsim.kinematics import MODELS
from agvsim.master.config import MasterConfig
from agvsim.metrics.capture import CaptureConfig
from agvsim.metrics.coverage import CoverageConfig
from agvsim.metrics.reach import ReachConfig
from agvsim.scenario_controllers import (  # the basic controller configs, re-exported
    AvoidConfig as AvoidConfig,
)
from agvsim.scenario_controllers import (
    ControllerConfigBase,
    IdleConfig,
)
from agvsim.scenario_controllers import (
    PythonControllerConfig as PythonControllerConfig,
)
from agvsim.scenario_controllers import (
    ScriptConfig as ScriptConfig,
)
from agvsim.scenario_controllers import (
    ScriptStepConfig as ScriptStepConfig,
)
from agvsim.scenario_dynamics import DynamicsConfig, FloorConfig
from agvsim.scenario_guidance import (
    FloorCameraConfig,
    FloorCodesConfig,
    LineSensorConfig,
    ReflectorsConfig,
    SafetyConfig,
    TapeConfig,
)
from agvsim.scenario_params import PARAMS

# Bounded integers: numba kernels and OpenCV take 64-bit (or smaller) integers only
Seed = Annotated[int, Field(ge=0, le=2**63 - 1, description="0 .. 2^63 - 1")]
Cell = Annotated[int, Field(ge=0, le=10_000_000)]
Name = Annotated[str, Field(min_length=1, max_length=64)]
PathText = Annotated[str, Field(min_length=1, max_length=4096)]


# ---------------------------------------------------------------------------------- world
class RandomMaze(StrictConfig):
    rows: int = Field(default=8, ge=1, le=500, description="rooms north-south")
    cols: int = Field(default=8, ge=1, le=500, description="rooms west-east")
    seed: Seed = 0
    corridor_cells: int = Field(default=2, ge=1, le=50)
    wall_cells: int = Field(default=1, ge=1, le=50)
    loop_fraction: float = Field(default=0.0, ge=0.0, le=1.0)


class BoxObstacle(StrictConfig):
    x_m: float
    y_m: float
    theta_deg: float = 0.0
    length_m: float = Field(gt=0)
    width_m: float = Field(gt=0)


Byte = Annotated[int, Field(ge=0, le=255)]
RGBConfig = tuple[Byte, Byte, Byte]


class PaintConfig(StrictConfig):
    rows: tuple[Cell, Cell] = Field(description="first and last row (inclusive), row 0 = north")
    cols: tuple[Cell, Cell] = Field(description="first and last column (inclusive)")
    rgb: RGBConfig


class ColorsConfig(StrictConfig):
    """What the onboard camera sees: colours 0..255 and painted wall cells."""

    wall_rgb: RGBConfig = (175, 175, 185)
    floor_rgb: RGBConfig = (225, 225, 215)
    sky_rgb: RGBConfig = (200, 220, 240)
    box_rgb: RGBConfig = (170, 125, 80)
    shade_faces: bool = True
    floor_checker: bool = True
    paint: list[PaintConfig] = []


class _MarkerCommon(StrictConfig):
    face: Literal["north", "east", "south", "west"]
    cell: tuple[Cell, Cell] | None = Field(default=None, description="[row, col] of the wall cell")
    x_m: float | None = None
    y_m: float | None = None
    offset_m: float = Field(
        default=0.0, description="along the face, to the right seen from the front"
    )
    size_m: float = Field(
        default=0.4, gt=0, le=100, description="side of the code, quiet zone excluded"
    )
    center_z_m: float | None = Field(
        default=None, ge=0, description="height of the centre; default: half the wall"
    )
    name: Name | None = None

    @model_validator(mode="after")
    def _one_place(self) -> _MarkerCommon:
        if (self.x_m is None) != (self.y_m is None):
            raise ValueError("give both x_m and y_m, or cell")
        if (self.cell is None) == (self.x_m is None):
            raise ValueError("give exactly one place: cell [row, col] or x_m + y_m")
        return self


class ArucoMarkerConfig(_MarkerCommon):
    kind: Literal["aruco"]
    id: int = Field(ge=0, le=1_000_000)
    dictionary: Literal[
        "4x4_50", "4x4_100", "4x4_250", "4x4_1000", "5x5_50", "5x5_100", "5x5_250", "5x5_1000",
        "6x6_50", "6x6_100", "6x6_250", "6x6_1000", "7x7_50", "7x7_100", "7x7_250", "7x7_1000",
        "original", "mip_36h12",
    ] = "4x4_50"  # fmt: skip


class AprilTagMarkerConfig(_MarkerCommon):
    kind: Literal["apriltag"]
    id: int = Field(ge=0, le=1_000_000)
    family: Literal["16h5", "25h9", "36h10", "36h11"] = "36h11"


class QrMarkerConfig(_MarkerCommon):
    kind: Literal["qr"]
    text: str = Field(min_length=1, max_length=500)


class PatchMarkerConfig(_MarkerCommon):
    kind: Literal["patch"]
    rgb: RGBConfig


MarkerConfig = Annotated[
    ArucoMarkerConfig | AprilTagMarkerConfig | QrMarkerConfig | PatchMarkerConfig,
    Field(discriminator="kind"),
]


class WorldConfig(StrictConfig):
    maze: Literal["thesis_fig16", "thesis_c1"] | None = None
    matrix: list[list[int]] | None = None
    picture: str | None = Field(
        default=None, max_length=64 * 1024 * 1024, description="text picture: '#' wall, '.' free"
    )
    file: PathText | None = Field(default=None, description=".txt .csv .png .pgm or ROS map .yaml")
    random: RandomMaze | None = None
    cell_size_m: float = Field(default=1.0, gt=0, le=100)
    origin_xy_m: tuple[float, float] | None = None
    boxes: list[BoxObstacle] = []
    colors: ColorsConfig = ColorsConfig()
    markers: list[MarkerConfig] = []
    floor: FloorConfig | None = Field(default=None, description="friction for robots with dynamics")
    # guidance infrastructure (docs/guidance.md)
    tape: TapeConfig | None = None
    floor_codes: FloorCodesConfig | None = None
    reflectors: ReflectorsConfig | None = None

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
class Pose(StrictConfig):
    x_m: float = 0.0
    y_m: float = 0.0
    theta_deg: float = Field(default=0.0, title="heading")


class Body(StrictConfig):
    length_m: float = Field(default=0.6, gt=0, le=20)
    width_m: float = Field(default=0.45, gt=0, le=20)
    offset_x_m: float | None = Field(default=None, description="footprint centre ahead of P")


class SensorCommon(StrictConfig):
    name: Name | None = None
    rate_hz: float | None = Field(
        default=None, gt=0, le=10000, description="default: every step (rangers), 10 Hz (lidar)"
    )
    range_min_m: float = Field(default=0.0, ge=0)
    noise_std_m: float = Field(default=0.0, ge=0)
    dropout_prob: float = Field(default=0.0, ge=0, le=1)
    mount_x_m: float | None = None
    mount_y_m: float = 0.0
    mount_yaw_deg: float = 0.0


class RangersConfig(SensorCommon):
    type: Literal["rangers"]
    range_max_m: float = Field(default=1.0, gt=0, le=1000, title="range")


class LidarConfig(SensorCommon):
    type: Literal["lidar"]
    beams: int = Field(default=240, ge=1, le=100000)
    fov_deg: float = Field(default=360.0, gt=0, le=360, title="field of view")
    angle_min_deg: float | None = None
    range_max_m: float = Field(default=10.0, gt=0, le=1000, title="range")


class CameraConfig(StrictConfig):
    """The onboard camera: RGB and depth images (agvsim.sensors.camera)."""

    type: Literal["camera"]
    name: Name | None = None
    width_px: int = Field(default=320, ge=8, le=4096)
    height_px: int = Field(default=240, ge=8, le=4096)
    hfov_deg: float = Field(default=60.0, gt=0, lt=170, title="field of view")
    rate_hz: float = Field(default=10.0, gt=0, le=1000)
    range_max_m: float = Field(default=30.0, gt=0, le=1000, title="range")
    mount_x_m: float | None = Field(default=None, description="default: the front of the body")
    mount_y_m: float = 0.0
    mount_z_m: float | None = Field(
        default=None, gt=0, title="mount height", description="default: 5 cm above the body"
    )
    mount_yaw_deg: float = 0.0
    pitch_deg: float = Field(
        default=0.0, ge=-80, le=80, title="pitch down", description="positive: looking down"
    )
    noise_std: float = Field(
        default=0.0,
        ge=0,
        le=255,
        title="noise std (0..255)",
        description="Gaussian pixel noise, std in 0..255 levels; 0 = off",
    )


SensorConfig = Annotated[
    RangersConfig | LidarConfig | CameraConfig | LineSensorConfig | FloorCameraConfig,
    Field(discriminator="type"),
]


class OdometryConfig(StrictConfig):
    wheel_noise_rel: float = Field(default=0.01, ge=0, le=1)
    wheel_noise_abs_rad_s: float = Field(default=0.0, ge=0)
    steering_noise_deg: float = Field(default=0.0, ge=0)


if TYPE_CHECKING:
    ControllerConfig: TypeAlias = ControllerConfigBase
else:  # every controller type of the registry (agvsim.behaviours.BEHAVIOURS), on "type"
    ControllerConfig = Annotated[
        Union[tuple(b.config for b in BEHAVIOURS.values())],  # noqa: UP007
        Field(discriminator="type"),
    ]


class MetricsConfig(StrictConfig):
    capture: CaptureConfig | None = None
    reach: ReachConfig | None = None
    coverage: CoverageConfig | None = None


class SlamBlock(StrictConfig):
    """Online graph SLAM on one of the robot's lidars and its wheel odometry (agvsim.slam)."""

    sensor: Name = Field(
        default="lidar", description="the lidar (range fan) whose scans SLAM reads"
    )
    resolution_m: float = Field(
        default=0.05, gt=0.005, le=1.0, description="map cell size (20 cells/m)"
    )
    max_range_m: float | None = Field(
        default=None,
        gt=0,
        description="readings used up to this range; default: the sensor's maximum",
    )
    loop_min_score: float = Field(
        default=0.55,
        gt=0,
        lt=1,
        description="loop-closure acceptance threshold (mean match likelihood)",
    )
    loop_search_radius_m: float = Field(
        default=3.0, gt=0, le=1000, description="loop-closure radius"
    )
    map_period_s: float = Field(
        default=1.0, gt=0, description="how often the live map is redrawn (browser app overlay)"
    )
    long_corridors: bool = Field(
        default=True,
        description="far, edge-on wall samples spread along their wall while the scans come "
        "densely, so corridors beyond the lidar's reach do not hold tracking back; false: every "
        "return a bump (agvsim slam --point-samples; docs/slam.md)",
    )


class _RobotBase(StrictConfig):
    """The keys of every robot entry. ``model`` and its typed ``params`` come with the model's
    own class (``ROBOT_CONFIGS``), generated from the kinematic dataclass."""

    name: Name
    model: str
    mode: ControlMode = ControlMode.INVERSE
    params: Any = Field(default=None, description="model parameters, see `agvsim models`")
    body: Body = Body()
    pose: Pose = Pose()
    color: str = Field(default="#d62728", max_length=64)
    sensors: list[SensorConfig] = []
    odometry: OdometryConfig = OdometryConfig()
    controller: ControllerConfig = IdleConfig(type="idle")
    knows: list[Name] = Field(
        default=[], description="robots whose true pose this robot's controller sees (obs.others)"
    )
    slam: SlamBlock | None = None
    dynamics: DynamicsConfig | None = Field(
        default=None, description="mass, motors, friction (agvsim.dynamics); none: kinematic"
    )
    safety: SafetyConfig | None = Field(
        default=None, description="a safety laser scanner's field sets (docs/safety_fields.md)"
    )

    @field_validator("color")
    @classmethod
    def _a_colour(cls, value: str) -> str:
        if re.fullmatch(r"#([0-9a-fA-F]{3}|[0-9a-fA-F]{6})", value):
            return value
        from matplotlib.colors import is_color_like  # names: only when one is given

        if not is_color_like(value):
            raise ValueError(
                "not a colour (allowed: '#rrggbb', '#rgb' or a matplotlib colour "
                "name such as 'red' or 'tab:blue')"
            )
        return value


# One robot config class a kinematic model (kinematics.MODELS), its params typed from the
# model's dataclass (agvsim.scenario_params)
def _robot_config(kind: str, params: type[StrictConfig]) -> type[_RobotBase]:
    tag: Any = Literal[kind]
    return create_model(
        f"{MODELS[kind].__name__}Robot",
        __base__=_RobotBase,
        model=(tag, ...),
        params=(params, Field(default=params(), description=f"{kind} parameters")),
    )


ROBOT_CONFIGS = {kind: _robot_config(kind, params) for kind, params in PARAMS.items()}

# A robot whose model is missing or unknown: its fields are still checked, so that one
# refusal lists every fault ("model: required", "unknown key 'modle'", ...)
_ANY_MODEL: Any = Literal[tuple(MODELS)]
_UnknownModelRobot = create_model(
    "UnknownModelRobot",
    __base__=_RobotBase,
    model=(_ANY_MODEL, ...),
    params=(dict[Name, Any], {}),
)
UNKNOWN_MODEL = "?"  # its tag


def _model_tag(entry: Any) -> str:
    model = entry.get("model") if isinstance(entry, dict) else getattr(entry, "model", None)
    return model if isinstance(model, str) and model in MODELS else UNKNOWN_MODEL


if TYPE_CHECKING:
    RobotConfig: TypeAlias = _RobotBase
else:  # a union discriminated by ``model``
    RobotConfig = Annotated[
        Union[  # noqa: UP007
            tuple(Annotated[cls, Tag(kind)] for kind, cls in ROBOT_CONFIGS.items())
            + (Annotated[_UnknownModelRobot, Tag(UNKNOWN_MODEL)],)
        ],
        Discriminator(_model_tag),
    ]
_ROBOT = TypeAdapter(RobotConfig)


def parse_robot(entry: dict[str, Any]) -> RobotConfig:
    """One robot entry of a scenario, validated (pydantic's ValidationError when invalid)."""
    return _ROBOT.validate_python(entry)


class LimitsConfig(StrictConfig):
    """The scenario raising (or lowering) its own run limits; see agvsim.scenario_limits."""

    max_steps: int | None = Field(default=None, ge=1, le=10**15, description="duration_s / dt_s")
    max_robots: int | None = Field(
        default=None, ge=1, le=10**9, description="robots in the scenario"
    )
    max_grid_cells: int | None = Field(default=None, ge=1, le=10**12, description="map rows x cols")
    max_camera_pixels_per_s: float | None = Field(
        default=None, gt=0, description="width x height x rate, all cameras"
    )
    max_lidar_rays_per_s: float | None = Field(
        default=None, gt=0, description="beams x rate, all range sensors"
    )


class Scenario(StrictConfig):
    name: str = Field(default="unnamed scenario", max_length=200)
    description: str = Field(default="", max_length=20_000)
    seed: Seed = 0
    duration_s: float = Field(default=60.0, gt=0, le=1e7)
    dt_s: float = Field(default=0.02, gt=0, le=1.0)
    world: WorldConfig
    robots: list[RobotConfig] = Field(min_length=1)
    metrics: MetricsConfig = MetricsConfig()
    on_controller_error: Literal["stop_run", "stop_robot"] = Field(
        default="stop_run", description="a failing controller ends the run, or only stops its robot"
    )
    limits: LimitsConfig | None = Field(default=None, description="raise the run's resource limits")
    layout: LayoutConfig | None = Field(
        default=None, description="a track layout (LIF), docs/fleet.md"
    )
    vda5050: Vda5050Config | None = Field(
        default=None, description="VDA 5050 vehicles, docs/fleet.md"
    )
    master: MasterConfig | None = Field(
        default=None,
        description="transport orders, charging, breakdowns for the master, docs/master.md",
    )
    _base_dir: Path = PrivateAttr(default=Path("."))
    _source: str = PrivateAttr(default="scenario")
    _limits: Any = PrivateAttr(default=None)  # the Limits it was checked against

    @model_validator(mode="after")
    def _unique_names(self) -> Scenario:
        names = [r.name for r in self.robots]
        counts = Counter(names)  # not names.count(): 100,000 robots must not take minutes
        dup = sorted(n for n, c in counts.items() if c > 1)
        if dup:
            shown = dup[:20] + ([f"... {len(dup) - 20} more"] if len(dup) > 20 else [])
            raise ValueError(f"robot names must be unique; repeated: {shown}")
        m = self.metrics
        named: list[tuple[str, Any]] = [("capture.pursuer", m.capture and m.capture.pursuer)]
        named += [("capture.evader", m.capture and m.capture.evader)]
        named += [("reach.robot", m.reach and m.reach.robot)]
        named += [("coverage.robot", m.coverage and m.coverage.robot)]
        for field, name in named:
            if name and name not in counts:
                raise ValueError(
                    f"metrics.{field}: {short_repr(name)} is not a robot"
                    + did_you_mean(name, list(counts)[:50])
                )
        for k, r in enumerate(self.robots):
            for other in r.knows:
                if other not in counts or other == r.name:
                    raise ValueError(
                        f"robots[{k}].knows: {other!r} is not another robot"
                        + did_you_mean(other, [n for n in names if n != r.name])
                    )
        return self


# ---------------------------------------------------------------------------- error messages
def _loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:  # a key that is not a plain name (a user's odd key) is quoted
            text = str(part)
            plain = re.fullmatch(r"[\w\-]{1,64}", text) or text.startswith("'")
            quoted = repr(text if len(text) <= 40 else text[:30] + "...")
            out += ("." if out else "") + (text if plain else quoted)
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
    fields = model.model_fields
    f = fields.get("type") or fields.get("kind") or fields.get("model")
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


MAX_PROBLEMS = 30  # listed in one refusal; the rest are counted


def short_repr(value: Any, limit: int = 80) -> str:
    """``repr(value)``, cut to ``limit`` characters (a 5 MB name is not echoed back)."""
    try:
        text = repr(value)
    except ValueError:  # an int too long to print
        return f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 12] + f"... ({len(text):,} chars)"


def _untagged(loc: tuple) -> tuple:
    """``loc`` without the model tag pydantic puts after a robot's index: the file has no
    such level (``robots[0].params.x``, not ``robots[0].differential.params.x``)."""
    if len(loc) > 2 and loc[0] == "robots" and (loc[2] in MODELS or loc[2] == UNKNOWN_MODEL):
        return loc[:2] + loc[3:]
    return loc


def _format_errors(err: ValidationError) -> list[str]:
    out = []
    errors = err.errors()
    for e in errors[:MAX_PROBLEMS]:
        loc = tuple(e["loc"])
        where = _loc(_untagged(loc))
        if e["type"] == "extra_forbidden" and loc[-2:-1] == ("params",) and loc[0] == "robots":
            key, kind = str(loc[-1]), str(loc[2])
            out.append(
                f"{_loc(_untagged(loc[:-1]))}: unknown parameter {short_repr(key)} for model "
                f"{kind!r}" + did_you_mean(key, list(PARAMS[kind].model_fields))
            )
        elif e["type"] == "extra_forbidden":
            key = str(loc[-1])
            out.append(
                f"{where}: unknown key {short_repr(key)}"
                + did_you_mean(key, _fields_at(Scenario, loc))
            )
        elif e["type"] == "literal_error" and isinstance(e.get("input"), str):
            opts = re.findall(r"'([^']*)'", str(e.get("ctx", {}).get("expected", "")))
            close = difflib.get_close_matches(e["input"], opts, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            shown = short_repr(e["input"])
            out.append(f"{where}: {shown} is not allowed{hint} (allowed: {', '.join(opts)})")
        elif e["type"] == "missing":
            out.append(f"{where}: required field is missing")
        elif e["type"] == "union_tag_invalid":
            ctx = e.get("ctx", {})
            tag = ctx.get("tag", "?")
            expected = ctx.get("expected_tags", "")
            opts = [t.strip(" '") for t in str(expected).split(",")]
            out.append(f"{where}: unknown type {short_repr(tag)}" + did_you_mean(str(tag), opts))
        else:
            msg = e["msg"].removeprefix("Value error, ")
            if e["type"] == "finite_number":
                msg = "must be a finite number (NaN and inf are not allowed)"
            value = e.get("input")
            shown = short_repr(value) if not isinstance(value, dict | list) else ""
            if isinstance(value, dict | list) and len(value) <= 8:
                shown = short_repr(value)
            if not loc and re.match(r"[\w.\[\]]+: ", msg):
                out.append(msg)  # a whole-object check that names its own field
                continue
            out.append(f"{where}: {msg}" + (f" (got {shown})" if shown else ""))
    if len(errors) > MAX_PROBLEMS:
        out.append(f"... and {len(errors) - MAX_PROBLEMS:,} more problems")
    return out
