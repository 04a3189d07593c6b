"""The sweep file: a base scenario, the values to vary, the seeds; and its plan.

```yaml
name: avoid speed x model
base: ../../scenarios/thesis_maze_avoid.yaml   # relative to this file, or an inline scenario
vary:                                          # dotted scenario paths -> values (a grid)
  robots.differential.controller.speed_m_s: [0.4, 0.8]
  robots.differential.sensors.rangers.noise_std_m: [0.0, 0.05]
cases:                                         # optional: named sets of values changed together
  small_wheels: {robots.0.params.wheel_radius_m: 0.05}
  big_wheels: {robots.0.params.wheel_radius_m: 0.15}
seeds: 3                                       # 0, 1, 2; or a list [4, 8]
duration_s: 20                                 # overrides the scenario's
out: runs/sweeps/avoid                         # relative to the current folder
plots: [differential.distance_m]               # table columns to plot (default: chosen)
```

:func:`plan_sweep` expands the grid (cases x vary values, the last key varying fastest) and
builds every variation's simulation BEFORE anything runs: a bad path, value or placement is
refused with the variation and the field named. Each run (variation x seed) gets an id, a hash
of its whole scenario, its seed, its duration and the files it reads, so a finished run is
found again after an interruption and redone only if something it depends on changed.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from agvsim.experiments.paths import PathError, set_path, split_path
from agvsim.experiments.runs import RunTask, dry_row
from agvsim.safe_yaml import YamlInputError, load_yaml_file
from agvsim.scenario import Scenario, ScenarioError, build, parse_scenario
from agvsim.scenario_schema import PythonControllerConfig as PythonController

ID_VERSION = 1  # bump when a run's outputs change meaning: every run is then redone
MAX_PROBLEMS = 25
MAX_VARIATIONS = 100_000  # each one is built before anything runs
WALL_COLUMNS = ("wall_time_s", "real_time_factor")


class SweepError(ValueError):
    """A sweep that cannot run; ``problems`` lists one clear line per fault."""

    def __init__(self, source: str, problems: list[str]):
        self.source, self.problems = source, problems
        super().__init__(f"{source}: " + "; ".join(problems))

    def __str__(self) -> str:
        shown = self.problems[:MAX_PROBLEMS]
        more = len(self.problems) - len(shown)
        lines = "\n".join(f"  - {p}" for p in shown) + (f"\n  ... and {more} more" if more else "")
        return f"{self.source} is not a valid sweep:\n{lines}"


class SweepConfig(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str | None = None
    description: str = ""
    base: str | dict[str, Any] = Field(description="scenario file (relative to the sweep file)")
    vary: dict[str, list[Any]] = Field({}, description="dotted scenario path -> values")
    cases: dict[str, dict[str, Any]] = Field({}, description="name -> {dotted path: value}")
    seeds: int | list[int] = Field(1, description="how many (0..n-1), or the seeds")
    duration_s: float | None = Field(None, gt=0, le=1e7, description="simulated s per run")
    out: str | None = Field(None, description="output folder (relative to the current folder)")
    plots: list[str] | None = Field(None, description="table columns to plot")

    @field_validator("vary")
    @classmethod
    def _values(cls, vary: dict[str, list[Any]]) -> dict[str, list[Any]]:
        problems = []
        for path, values in vary.items():
            try:
                split_path(path)
            except PathError as err:
                problems.append(str(err))
            if path == "seed":
                problems.append("seed: the sweep's 'seeds:' sets it; it is not varied")
            if not values:
                problems.append(f"{path}: give at least one value")
            keys = [_canonical(v) for v in values]
            dup = sorted({k for k in keys if keys.count(k) > 1})
            if dup:
                problems.append(f"{path}: values repeat: {', '.join(dup)}")
        if problems:
            raise ValueError("; ".join(problems))
        return vary

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, seeds: int | list[int]) -> int | list[int]:
        if isinstance(seeds, bool):
            raise ValueError("give a number of seeds or a list of seeds")
        if isinstance(seeds, int):
            if not 1 <= seeds <= 1_000_000:
                raise ValueError(f"the number of seeds must be 1..1000000, got {seeds}")
            return seeds
        if not seeds:
            raise ValueError("give at least one seed")
        if any(s < 0 for s in seeds):
            raise ValueError(f"seeds must be >= 0, got {seeds}")
        if len(set(seeds)) != len(seeds):
            raise ValueError(f"seeds repeat: {seeds}")
        return seeds


@dataclass(frozen=True)
class Variation:
    index: int
    case: str | None
    values: dict[str, Any]  # vary path -> value
    scenario: dict  # the base scenario with the case's and the values' changes
    label: str


@dataclass
class SweepPlan:
    """Everything a sweep will do, checked: variations, seeds, runs, columns, output folder."""

    source: str
    name: str
    config: SweepConfig
    base_dir: Path  # relative files of the scenario are found from here
    variations: list[Variation]
    seeds: list[int]
    duration_s: float | None
    out_dir: Path
    columns: list[str] = field(default_factory=list)  # the table's columns, in order
    plots: list[str] = field(default_factory=list)
    tasks: list[RunTask] = field(default_factory=list)

    @property
    def vary_columns(self) -> list[str]:
        return (["case"] if self.config.cases else []) + list(self.config.vary)


def load_sweep(path: str | Path) -> tuple[SweepConfig, Path]:
    """Read and validate a sweep file (not yet its variations: see ``plan_sweep``)."""
    path = Path(path)
    if not path.is_file():
        raise SweepError(str(path), ["no such file"])
    try:  # the scenario loader's bounded reader (UTF-8, size, depth, aliases)
        data = load_yaml_file(path)
    except YamlInputError as err:
        line = f"line {err.line}: " if err.line is not None else ""
        raise SweepError(str(path), [f"{line}{err.problem}"]) from None
    return parse_sweep(data, str(path)), path


def parse_sweep(data: Any, source: str = "sweep") -> SweepConfig:
    if not isinstance(data, dict):
        raise SweepError(source, [f"the file must hold a mapping of keys, got {type(data)}"])
    try:
        return SweepConfig.model_validate(data)
    except ValidationError as err:
        raise SweepError(source, _format(err)) from None


def plan_sweep(
    sweep: str | Path | SweepConfig,
    out_dir: str | Path | None = None,
    source_dir: str | Path | None = None,
) -> SweepPlan:
    """Expand and validate a sweep: every variation is parsed by the scenario schema and its
    simulation built; raises SweepError naming each bad variation and field."""
    if isinstance(sweep, SweepConfig):
        cfg, source = sweep, "sweep"
        here = Path(source_dir or ".")
        default_out = Path("runs/sweeps") / _slug(cfg.name or "sweep")
    else:
        cfg, path = load_sweep(sweep)
        source, here = str(path), path.parent
        default_out = Path("runs/sweeps") / _slug(path.stem)
    base, base_dir = _base(cfg, source, here)
    seeds = list(range(cfg.seeds)) if isinstance(cfg.seeds, int) else list(cfg.seeds)
    variations, problems = _expand(cfg, base, source)
    out = Path(out_dir) if out_dir is not None else Path(cfg.out) if cfg.out else default_out
    plan = SweepPlan(
        source=source,
        name=cfg.name or Path(source).stem,
        config=cfg,
        base_dir=base_dir.resolve(),
        variations=variations,
        seeds=seeds,
        duration_s=cfg.duration_s,
        out_dir=out,
    )
    _check_and_make_tasks(plan, problems)
    return plan


# --------------------------------------------------------------------------------- internals
def _base(cfg: SweepConfig, source: str, here: Path) -> tuple[dict, Path]:
    if isinstance(cfg.base, dict):
        return copy.deepcopy(cfg.base), here
    path = Path(cfg.base)
    if not path.is_absolute():
        path = here / path
    if not path.is_file():
        raise SweepError(source, [f"base: no such scenario file {str(path)!r}"])
    try:
        data = load_yaml_file(path)
    except YamlInputError as err:
        line = f" line {err.line}" if err.line is not None else ""
        raise SweepError(source, [f"base: {path}{line}: {err.problem}"]) from None
    if not isinstance(data, dict):
        raise SweepError(source, [f"base: {path} does not hold a scenario mapping"])
    return data, path.parent


def _expand(cfg: SweepConfig, base: dict, source: str) -> tuple[list[Variation], list[str]]:
    problems: list[str] = []
    clash = [p for c in cfg.cases.values() for p in c if p in cfg.vary]
    if clash:
        problems.append(f"cases and vary both set {sorted(set(clash))}: set each path in one")
    if cfg.duration_s is not None and "duration_s" in cfg.vary:
        problems.append("vary.duration_s: the sweep's duration_s already sets it; drop one")
    cases: list[tuple[str | None, dict]] = list(cfg.cases.items()) or [(None, {})]
    count = math.prod(len(v) for v in cfg.vary.values()) * len(cases)
    if count > MAX_VARIATIONS:
        sizes = " x ".join(
            str(n) for n in [len(cases)] * bool(cfg.cases) + list(map(len, cfg.vary.values()))
        )
        raise SweepError(
            source, [f"vary: {sizes} = {count} variations; at most {MAX_VARIATIONS} per sweep"]
        )
    paths = list(cfg.vary)
    short = _short_names(paths)
    out: list[Variation] = []
    for k, ((case, sets), values) in enumerate(
        itertools.product(cases, itertools.product(*cfg.vary.values()))
    ):
        chosen = dict(zip(paths, values, strict=True))
        label = ", ".join(
            ([f"case={case}"] if case is not None else [])
            + [f"{short[p]}={_fmt(v)}" for p, v in chosen.items()]
        )
        data = copy.deepcopy(base)
        bad = False
        for where, changes in ((f"cases.{case}", sets), ("vary", chosen)):
            for p, v in changes.items():
                try:
                    set_path(data, p, v)
                except PathError as err:
                    msg = f"{where}.{err}"
                    if msg not in problems:
                        problems.append(msg)
                    bad = True
        if cfg.duration_s is not None:
            data["duration_s"] = cfg.duration_s
        if not bad:
            out.append(Variation(k, case, chosen, data, label or "base"))
    return out, problems


def _check_and_make_tasks(plan: SweepPlan, problems: list[str]) -> None:
    """Build every variation (``problems``: those found so far); make the runs."""
    columns: list[str] = ["variation", *plan.vary_columns, "seed"]
    for var in plan.variations:
        where = f"variation {var.index} ({var.label})"
        try:
            sc = parse_scenario(var.scenario, where)
            sc._base_dir, sc._source = plan.base_dir, plan.source
            from agvsim.master.sweep import fleet_dry_row, is_fleet

            if is_fleet(sc):  # a fleet with its master control (docs/master.md)
                row = fleet_dry_row(sc, plan.seeds[0])
            else:
                sim = build(sc, seed=plan.seeds[0])
                row = dry_row(sc, sim, plan.source)
        except ScenarioError as err:
            problems += [f"{where}: {p}" for p in err.problems]
            continue
        columns += [c for c in row if c not in columns]
        files = _file_hashes(sc, plan.base_dir)
        for seed in plan.seeds:
            plan.tasks.append(
                RunTask(
                    run_id=_run_id(var.scenario, seed, plan.duration_s, files),
                    variation=var.index,
                    seed=seed,
                    scenario=var.scenario,
                    base_dir=str(plan.base_dir),
                    source=f"{plan.source} variation {var.index}",
                )
            )
    if problems:
        raise SweepError(plan.source, problems)
    plan.columns = columns
    plan.plots = _plots(plan, columns)


def _plots(plan: SweepPlan, columns: list[str]) -> list[str]:
    if plan.config.plots is not None:
        # SLAM scores are known only after a run: their names are not checked here
        bad = [c for c in plan.config.plots if c not in columns and not c.startswith("slam.")]
        if bad:
            opts = [c for c in columns if c not in ("variation", "seed", "run_id")]
            raise SweepError(
                plan.source,
                [
                    f"plots: no column {c!r}"
                    + (
                        f"; did you mean {close[0]!r}?"
                        if (close := difflib.get_close_matches(c, opts, n=1, cutoff=0.5))
                        else ""
                    )
                    + f" (columns: {', '.join(opts)})"
                    for c in bad
                ],
            )
        return list(plan.config.plots)
    preferred = [
        "master.orders_per_hour",
        "master.lead_time_mean_s",
        "reach.time_to_goal_s",
        "reach.reached",
        "capture.survival_time_s",
        "capture.captured",
        "coverage.visited_fraction",
        "coverage.seen_fraction",
    ]
    chosen = [c for c in preferred if c in columns]
    for c in columns:
        if c.endswith((".distance_m", ".collisions")) and c not in chosen:
            chosen.append(c)
    return chosen[:8]


def _file_hashes(sc: Scenario, base_dir: Path) -> dict[str, str]:
    """sha256 of the files a scenario reads (map file, python controllers)."""
    names = [sc.world.file] if sc.world.file else []
    names += [r.controller.file for r in sc.robots if isinstance(r.controller, PythonController)]
    out = {}
    for name in names:
        p = Path(name) if Path(name).is_absolute() else base_dir / name
        try:
            out[name] = hashlib.sha256(p.read_bytes()).hexdigest()
        except OSError:
            out[name] = "missing"
    return out


def _run_id(scenario: dict, seed: int, duration_s: float | None, files: dict) -> str:
    key = {"v": ID_VERSION, "scenario": scenario, "seed": seed, "dur": duration_s, "files": files}
    text = json.dumps(key, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def _canonical(v: Any) -> str:
    return json.dumps(v, sort_keys=True, default=str)


def _fmt(v: Any) -> str:
    if isinstance(v, float) and math.isfinite(v):
        return f"{v:g}"
    if isinstance(v, str | int | bool) or v is None:
        return str(v)
    return json.dumps(v, separators=(",", ":"), default=str)


def _short_names(paths: list[str]) -> dict[str, str]:
    """The last part of each path, or more of it where two would read the same."""
    out = {}
    for p in paths:
        parts = p.split(".")
        # "seed" alone would read as the run's seed: world.random.seed -> random.seed
        first = 2 if parts[-1] == "seed" and len(parts) > 1 else 1
        for n in range(first, len(parts) + 1):
            name = ".".join(parts[-n:])
            if sum(q.endswith("." + name) or q == name for q in paths) == 1:
                break
        out[p] = name
    return out


def _slug(text: str) -> str:
    keep = "".join(c if c.isalnum() or c in "-_" else "_" for c in text.strip())
    return keep.strip("_") or "sweep"


def _format(err: ValidationError) -> list[str]:
    out: list[str] = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"]) or "(top level)"
        if e["loc"][:1] == ("seeds",):  # one line for both members of int | list[int]
            msg = "seeds: give a number of seeds (1..1000000) or a list of seeds >= 0"
            msg += f" (got {e.get('input')!r})"
            if e["type"] == "value_error":
                msg = f"seeds: {e['msg'].removeprefix('Value error, ')}"
            elif len(e["loc"]) > 2:
                msg = f"{loc}: {e['msg']} (got {e.get('input')!r})"
            if not any(o.startswith("seeds") for o in out):
                out.append(msg)
        elif e["type"] == "extra_forbidden":
            key = str(e["loc"][-1])
            opts = list(SweepConfig.model_fields)
            close = difflib.get_close_matches(key, opts, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            out.append(f"{loc}: unknown key {key!r}{hint} (allowed: {', '.join(opts)})")
        elif e["type"] == "missing":
            out.append(f"{loc}: required field is missing")
        else:
            msg = e["msg"].removeprefix("Value error, ")
            value = e.get("input")
            shown = repr(value) if not isinstance(value, dict) and len(repr(value)) < 80 else ""
            out.append(f"{loc}: {msg}" + (f" (got {shown})" if shown else ""))
    return out
