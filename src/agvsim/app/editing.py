"""Editing in the app, as functions of the scenario config (a plain dict, validated by the
scenario schema when the session rebuilds from it) and of the running simulation, which they
only read: robots added, replaced and removed, free spots, maze cells, map and scenario files.
The session applies what they return under its lock."""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from agvsim.app import uploads
from agvsim.scenario import Scenario, ScenarioError, build, load_scenario
from agvsim.scenario_schema import PythonControllerConfig
from agvsim.sim.engine import ControllerError, Simulation
from agvsim.world import loaders, mazes
from agvsim.world.grid import OccupancyGrid

PALETTE = ["#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"]
MAP_SAVERS = {"txt": loaders.save_text, "csv": loaders.save_csv, "png": loaders.save_png}
MAP_SUFFIXES = (".txt", ".csv", ".png", ".pgm")


class EditError(ValueError):
    """An edit the app refuses; the message is shown in the panel as it is."""


# ---------------------------------------------------------------------- robots
def robot_index(cfg: dict[str, Any], name: str) -> int:
    for k, r in enumerate(cfg["robots"]):
        if r["name"] == name:
            return k
    names = [r["name"] for r in cfg["robots"]]
    raise EditError(f"no robot named {name!r}; robots: {names}")


def with_robot(cfg: dict[str, Any], name: str, robot: dict[str, Any]) -> dict[str, Any]:
    """``cfg`` with robot ``name`` replaced by ``robot``."""
    out = copy.deepcopy(cfg)
    out["robots"][robot_index(cfg, name)] = copy.deepcopy(robot)
    return out


def with_new_robot(
    cfg: dict[str, Any], model: str, x_m: float, y_m: float, theta_deg: float
) -> tuple[dict[str, Any], str]:
    """``cfg`` with a new robot of ``model`` (the four rangers, the thesis avoidance) at the
    pose; returns it and the new robot's name (``<model>_<k>``)."""
    names = {r["name"] for r in cfg["robots"]}
    n = 1
    while f"{model}_{n}" in names:
        n += 1
    name = f"{model}_{n}"
    out = copy.deepcopy(cfg)
    out["robots"].append(
        {
            "name": name,
            "model": model,
            "pose": {"x_m": x_m, "y_m": y_m, "theta_deg": theta_deg},
            "color": PALETTE[len(out["robots"]) % len(PALETTE)],
            "sensors": [{"type": "rangers"}],
            "controller": {"type": "avoid"},
        }
    )
    return out, name


def without_robot(cfg: dict[str, Any], name: str) -> dict[str, Any]:
    """``cfg`` without robot ``name`` (nor in anyone's ``knows``); the last one stays."""
    if len(cfg["robots"]) == 1:
        raise EditError("a scenario needs at least one robot; add another first")
    out = copy.deepcopy(cfg)
    del out["robots"][robot_index(cfg, name)]
    for r in out["robots"]:
        if name in r.get("knows", []):
            r["knows"] = [o for o in r["knows"] if o != name]
    return out


def free_spot(sim: Simulation, seed: int = 0) -> tuple[float, float]:
    """The centre of a free cell with free neighbours, more than 1.5 m from every robot (for
    new robots), drawn with ``seed``; EditError when there is none."""
    g = sim.world.grid
    free = ~g.occupied
    ok = free.copy()
    ok[1:, :] &= free[:-1, :]
    ok[:-1, :] &= free[1:, :]
    ok[:, 1:] &= free[:, :-1]
    ok[:, :-1] &= free[:, 1:]
    rows, cols = np.nonzero(ok)
    if len(rows) == 0:
        raise EditError("no free spot in the map for a new robot")
    fp = sim.footprints(sim.state.poses)
    rng = np.random.default_rng(seed)
    for k in rng.permutation(len(rows)):
        x, y = g.cell_center(rows[k], cols[k])
        if np.all(np.hypot(fp[:, 0] - x, fp[:, 1] - y) > 1.5):
            return float(x), float(y)
    raise EditError("no free spot away from the other robots")


# ---------------------------------------------------------------------- the maze
def cell_at(grid: OccupancyGrid, x_m: float, y_m: float) -> tuple[int, int] | None:
    r, c = grid.cell_of(x_m, y_m)
    row, col = int(r), int(c)
    if 0 <= row < grid.rows and 0 <= col < grid.cols:
        return row, col
    return None


def toggled(sim: Simulation, row: int, col: int) -> tuple[OccupancyGrid, bool]:
    """The map with one cell flipped, and whether it is a wall now. Refused under a robot."""
    g = sim.world.grid
    if not (0 <= row < g.rows and 0 <= col < g.cols):
        raise EditError(f"cell ({row}, {col}) is outside the {g.rows} x {g.cols} map")
    wall = not bool(g.occupied[row, col])
    new = g.with_cell(row, col, wall)
    if wall:
        hit = sim.collider.__class__(new).hit_walls(sim.footprints(sim.state.poses))
        if hit.any():
            who = [r.name for r, h in zip(sim.robots, hit, strict=True) if h]
            raise EditError(f"cell ({row}, {col}) is under robot {who[0]!r}")
    return new, wall


def random_grid(resolution_m: float, rows: int, cols: int, seed: int) -> OccupancyGrid:
    """A random maze of ``rows`` x ``cols`` rooms at the map's resolution."""
    cells = max(1, int(round(1.0 / resolution_m))) if resolution_m < 1 else 1
    try:
        return mazes.random_maze(
            rows,
            cols,
            seed,
            corridor_cells=2 * cells,
            wall_cells=cells,
            resolution_m=resolution_m,
        )
    except ValueError as err:
        raise EditError(f"random maze: {err}") from None


def world_with_grid(world: dict[str, Any], grid: OccupancyGrid) -> dict[str, Any]:
    """A world config whose map is ``grid``, written inline as a text picture."""
    out = dict(world)
    for k in ("maze", "matrix", "picture", "file", "random"):
        out.pop(k, None)
    out["picture"] = loaders.format_text_picture(grid)
    out["cell_size_m"] = grid.resolution_m
    out["origin_xy_m"] = list(grid.origin_xy_m)
    return out


# ---------------------------------------------------------------------- files
def map_file(grid: OccupancyGrid, fmt: str) -> tuple[str, bytes]:
    """The map as a file to download: (file name, bytes) for fmt txt, csv or png."""
    if fmt not in MAP_SAVERS:
        raise EditError(f"unknown map format {fmt!r}; choose txt, csv or png")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"maze.{fmt}"
        MAP_SAVERS[fmt](grid, path)
        return path.name, path.read_bytes()


def read_map(name: str, content: bytes, resolution_m: float) -> OccupancyGrid:
    """A map file sent from the browser (txt, csv, png, pgm), read as data, never run."""
    suffix = Path(name).suffix.lower()
    if suffix not in MAP_SUFFIXES:
        raise EditError(f"{name}: maps load from .txt, .csv, .png or .pgm files")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / Path(name).name
        path.write_bytes(content)
        try:
            return loaders.load_map(path, resolution_m=resolution_m)
        except (loaders.MapFormatError, ValueError) as err:
            raise EditError(str(err).replace(str(path), name)) from None


def refuse_python(sc: Scenario, source: str, trusted: set[tuple[str, str]]) -> None:
    """A ``python`` controller runs only as the command-line scenario names it."""
    for r in sc.robots:
        c = r.controller
        if isinstance(c, PythonControllerConfig) and (c.file, c.name) not in trusted:
            raise ScenarioError(
                source,
                [
                    f"robot {r.name!r}: python controllers cannot come from the browser; "
                    "only those of the scenario given on the command line run"
                ],
            )


def read_upload(
    name: str, content: bytes, limits: uploads.UploadLimits
) -> tuple[str, dict[str, Any], Simulation]:
    """A scenario sent from the browser: a YAML file, or a .zip of a scenario and its map
    files (agvsim.app.uploads), parsed as data by the scenario loader with its limits; it may
    read only the files sent with it and run no python controller. Returns (its name, its
    config with the map inline, its simulation); raises ScenarioError / UploadError."""
    bundle = uploads.unpack(name, content, limits)
    with tempfile.TemporaryDirectory(prefix="agvsim-upload-") as tmp:
        folder = Path(tmp)
        path = bundle.write(folder)

        def hide(problems: list[str]) -> list[str]:  # no server path in a message
            return [p.replace(f"{folder}/", "").replace(str(folder), ".") for p in problems]

        try:
            # its limits: block may lower the limits, never raise them
            sc = load_scenario(path, limits_from_file=False)
            uploads.check_references(sc.world.file, bundle)
            refuse_python(sc, bundle.scenario, set())  # nothing from a browser runs
            sim = build(sc)
        except ScenarioError as err:
            raise ScenarioError(bundle.scenario, hide(err.problems)) from None
        except uploads.UploadError:
            raise
        except (ControllerError, ValueError, RecursionError) as err:  # data a parser choked on
            problem = f"cannot be loaded: {type(err).__name__}: {err}"
            raise ScenarioError(bundle.scenario, hide([problem])) from None
    config: dict[str, Any] = sc.model_dump(mode="json", exclude_unset=True)
    if sc.world.file is not None:  # the map is part of the scenario now: no file kept
        config["world"] = world_with_grid(config["world"], sim.world.grid)
    return bundle.scenario, config, sim


def scenario_text(cfg: dict[str, Any]) -> str:
    """A scenario config as a YAML file (the maze picture as a literal block)."""
    return yaml.dump(cfg, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=100)


class _Dumper(yaml.SafeDumper):
    """Multi-line strings (the maze picture) as literal blocks."""


def _str_presenter(dumper: yaml.SafeDumper, data: str) -> yaml.Node:
    style = "|" if "\n" in data else None
    return dumper.represent_scalar("tag:yaml.org,2002:str", data, style=style)


_Dumper.add_representer(str, _str_presenter)
