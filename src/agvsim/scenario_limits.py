"""Resource limits on a scenario: what a legal-looking file may ask the simulator to do.

A scenario can be valid in every field and still never finish (``dt_s: 1e-9``), or exhaust the
memory (a random maze of 50,001 x 50,001 cells, a 4096 x 4096 camera at 1 kHz). The loader
refuses such files up front with a message naming the field, the limit and how to raise it.

Two kinds of limit, documented in docs/scenario.md ("Limits"):

* limits on the run (``max_steps``, ``max_robots``, ``max_grid_cells``,
  ``max_camera_pixels_per_s``, ``max_lidar_rays_per_s``): a scenario raises them for itself
  in a ``limits:`` block, unless it comes from somewhere untrusted (the browser's upload
  passes ``limits_from_file=False``);
* limits on reading the YAML (``yaml_max_bytes``, ``yaml_max_nodes``, ``yaml_max_depth``):
  they protect the reading itself, so only the caller raises them (``agvsim run/validate
  --limit NAME=VALUE``, or ``load_scenario(path, limits=Limits(...))``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import TYPE_CHECKING, Any

from agvsim.safe_yaml import YamlLimits
from agvsim.world.loaders import MAX_CELLS

if TYPE_CHECKING:
    from agvsim.scenario_schema import LimitsConfig, Scenario, WorldConfig

MAX_MAGNITUDE = 1e12  # of any float in a scenario: squares stay finite, float32 holds it


def too_large(value: Any) -> float | None:
    """The first float in ``value`` (a number, or a list / tuple of them, nested) whose
    magnitude is over MAX_MAGNITUDE, or None."""
    if isinstance(value, float):
        return value if abs(value) > MAX_MAGNITUDE else None
    if isinstance(value, list | tuple):
        for v in value:
            if (bad := too_large(v)) is not None:
                return bad
    return None


RUN_LIMITS = (
    "max_steps",
    "max_robots",
    "max_grid_cells",
    "max_camera_pixels_per_s",
    "max_lidar_rays_per_s",
)


@dataclass(frozen=True)
class Limits:
    """Every limit with its default (see the module docstring for who may raise which)."""

    max_steps: int = 10_000_000  # duration_s / dt_s
    max_robots: int = 10_000
    max_grid_cells: int = MAX_CELLS  # rows x cols of the map (5000 x 5000)
    max_camera_pixels_per_s: float = 100e6  # width x height x rate, all cameras together
    max_lidar_rays_per_s: float = 50e6  # beams x rate, all range sensors together
    yaml_max_bytes: int = 16 * 1024 * 1024
    yaml_max_nodes: int = 250_000  # values in the YAML, aliases expanded (~1.5 s to read)
    yaml_max_depth: int = 64  # nested lists / mappings

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (0 < v < math.inf):
                raise ValueError(f"limit {f.name}: must be a number > 0, got {v!r}")

    @property
    def yaml(self) -> YamlLimits:
        return YamlLimits(self.yaml_max_bytes, self.yaml_max_nodes, self.yaml_max_depth)

    @classmethod
    def from_options(cls, items: list[str] | None) -> Limits:
        """Limits from ``NAME=VALUE`` strings (the CLI's ``--limit``); ValueError names the bad
        one and lists the known names."""
        known = [f.name for f in fields(cls)]
        kw: dict[str, Any] = {}
        for item in items or []:
            name, sep, value = item.partition("=")
            name = name.strip()
            if not sep or name not in known:
                raise ValueError(
                    f"--limit {item!r}: give NAME=VALUE with NAME one of {', '.join(known)}"
                )
            try:
                number = float(value)
            except ValueError:
                number = math.nan
            if not (0 < number < math.inf):
                raise ValueError(f"--limit {item!r}: the value must be a number > 0")
            kw[name] = int(number) if number.is_integer() and number < 2**63 else number
        return cls(**kw)

    def with_block(self, block: LimitsConfig | None, from_file: bool, source: str) -> Limits:
        """These limits with a scenario's ``limits:`` block applied. A file that may not raise
        its own limits (``from_file`` False) can only lower them."""
        from agvsim.scenario import ScenarioError

        if block is None:
            return self
        given = {k: getattr(block, k) for k in RUN_LIMITS if getattr(block, k) is not None}
        if not from_file:
            raised = [k for k, v in given.items() if v > getattr(self, k)]
            if raised:
                raise ScenarioError(
                    source,
                    [
                        f"limits.{k}: {given[k]:g} is above {getattr(self, k):g}; a scenario "
                        "from here cannot raise its own limits (open it from the command line)"
                        for k in raised
                    ],
                )
        return replace(self, **given)


def _how(name: str, needed: float) -> str:
    value = f"{math.ceil(needed):d}" if needed < 1e18 else f"{needed:.3g}"
    return (
        f"raise it with 'limits: {{{name}: {value}}}' in the scenario or "
        f"'--limit {name}={value}' (docs/scenario.md, 'Limits')"
    )


def steps_of(duration_s: float, dt_s: float, limits: Limits, where: str) -> int:
    """The number of steps of a run; ValueError when it is not finite or over the limit."""
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"{where}: {duration_s!r} is not allowed (a finite number of s > 0)")
    n = duration_s / dt_s
    if not n <= limits.max_steps:
        raise ValueError(
            f"{where}: {duration_s:g} s in steps of dt_s = {dt_s:g} s is {n:,.0f} steps, over "
            f"the limit max_steps = {limits.max_steps:,}; " + _how("max_steps", n)
        )
    return int(round(n))


def check_robot_count(n: int, limits: Limits) -> None:
    """ValueError when a scenario lists more than ``max_robots`` robots."""
    if n > limits.max_robots:
        raise ValueError(
            f"robots: {n:,} robots is over the limit max_robots = {limits.max_robots:,}; "
            + _how("max_robots", n)
        )


def check_grid_cells(rows: int, cols: int, limits: Limits, where: str) -> None:
    """ValueError when a map of ``rows x cols`` cells is over ``max_grid_cells``."""
    n = rows * cols
    if n > limits.max_grid_cells:
        raise ValueError(
            f"{where}: the map would have {rows:,} x {cols:,} = {n:,} cells, over the limit "
            f"max_grid_cells = {limits.max_grid_cells:,}; " + _how("max_grid_cells", n)
        )


def grid_shape(world: WorldConfig) -> tuple[int, int] | None:
    """(rows, cols) of an inline or generated map (None for a map file or a packaged maze)."""
    if world.random is not None:
        r = world.random
        pitch = r.corridor_cells + r.wall_cells
        return r.rows * pitch + r.wall_cells, r.cols * pitch + r.wall_cells
    if world.matrix is not None:
        return len(world.matrix), max((len(row) for row in world.matrix), default=0)
    if world.picture is not None:
        lines = world.picture.strip("\n").splitlines() or [""]
        return len(lines), max(len(line.rstrip()) for line in lines)
    return None


def _slam_windows(sc: Scenario, limits: Limits) -> list[str]:
    """SLAM rasters a window of twice the range used around each scan: bound its cells."""
    out = []
    for k, r in enumerate(sc.robots):
        if r.slam is None:
            continue
        sensor = next((s for s in r.sensors if s.name == r.slam.sensor), None)
        if sensor is None:
            sensor = next((s for s in r.sensors if s.type == r.slam.sensor), None)
        if sensor is None or sensor.type == "camera":
            continue  # reported by the SLAM set-up itself
        reach = r.slam.max_range_m or sensor.range_max_m  # type: ignore[union-attr]
        side = math.ceil(2.0 * reach / r.slam.resolution_m)
        if side * side > limits.max_grid_cells:
            out.append(
                f"robots[{k}].slam: a map window of 2 x {reach:g} m at resolution_m "
                f"{r.slam.resolution_m:g} is {side:,} x {side:,} cells, over the limit "
                f"max_grid_cells = {limits.max_grid_cells:,}; lower max_range_m, raise "
                "resolution_m, or " + _how("max_grid_cells", side * side)
            )
    return out


def check_scenario(sc: Scenario, limits: Limits) -> list[str]:
    """One line per limit the validated scenario breaks (empty when it keeps them all)."""
    problems = []
    try:
        steps_of(sc.duration_s, sc.dt_s, limits, "duration_s")
    except ValueError as err:
        problems.append(str(err))
    try:
        check_robot_count(len(sc.robots), limits)
    except ValueError as err:
        problems.append(str(err))
    shape = grid_shape(sc.world)
    if shape is not None:
        try:
            where = "world.random" if sc.world.random is not None else "world"
            check_grid_cells(*shape, limits, where)
        except ValueError as err:
            problems.append(str(err))
    problems += _slam_windows(sc, limits)
    pixels = rays = 0.0
    step_hz = 1.0 / sc.dt_s  # a sensor takes at most one reading a step
    for r in sc.robots:
        for s in r.sensors:
            if s.type == "line":  # a line sensor reads every step: no rays, no pixels
                continue
            rate = s.rate_hz or (10.0 if s.type == "lidar" else step_hz)
            if s.type in ("camera", "floor_camera"):
                pixels += s.width_px * s.height_px * min(rate, step_hz)  # type: ignore[union-attr]
            else:
                beams = 4 if s.type == "rangers" else s.beams  # type: ignore[union-attr]
                rays += beams * min(rate, step_hz)
    if pixels > limits.max_camera_pixels_per_s:
        problems.append(
            f"robots[].sensors (cameras): width_px x height_px x rate_hz adds up to "
            f"{pixels:,.0f} pixels per simulated second, over the limit "
            f"max_camera_pixels_per_s = {limits.max_camera_pixels_per_s:,.0f}; "
            + _how("max_camera_pixels_per_s", pixels)
        )
    if rays > limits.max_lidar_rays_per_s:
        problems.append(
            f"robots[].sensors (lidars, rangers): beams x rate_hz adds up to {rays:,.0f} rays "
            f"per simulated second, over the limit max_lidar_rays_per_s = "
            f"{limits.max_lidar_rays_per_s:,.0f}; " + _how("max_lidar_rays_per_s", rays)
        )
    return problems
