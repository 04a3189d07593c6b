"""The layers hold: the core is headless, SLAM imports nothing of the simulator or the record
layer, and every module sits in the import-linter layers of pyproject.toml (docs/design.md)."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CORE = [
    "agvsim.kinematics",
    "agvsim.world.grid",
    "agvsim.world.mazes",
    "agvsim.sensors.raycast",
    "agvsim.sensors.range_sensor",
    "agvsim.sim.engine",
    "agvsim.control.avoid",
    "agvsim.control.script",
    "agvsim.control.goal",
    "agvsim.control.maze_solver",
    "agvsim.control.teleop",
    "agvsim.control.pursuit",
    "agvsim.slam.posegraph",
    "agvsim.slam.graph_slam",
    "agvsim.slam.offline",
]
# (yaml is not listed: numba itself imports it, to read an optional .numba_config.yaml)
FORBIDDEN = [
    "matplotlib",
    "PIL",
    "typer",
    "rich",
    "pydantic",
    "rosbags",
    "mcap",
    "agvsim.scenario",
    "agvsim.behaviours",
    "agvsim.viz",
    "agvsim.record",
    "agvsim.cli",
]


def _loaded_by(modules: list[str], watch: list[str]) -> list[str]:
    """Which of ``watch`` are in ``sys.modules`` after importing ``modules`` (a fresh process)."""
    code = (
        "import sys\n"
        + "".join(f"import {m}\n" for m in modules)
        + f"print(','.join(m for m in {watch!r} if m in sys.modules))\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True
    )
    return [m for m in res.stdout.strip().split(",") if m]


def test_core_imports_only_numeric_libraries():
    assert _loaded_by(CORE, FORBIDDEN) == []


def test_the_pose_graph_optimiser_loads_no_recording_reader():
    watch = ["agvsim.record", "rosbags", "agvsim.sim", "agvsim.world", "agvsim.control"]
    assert _loaded_by(["agvsim.slam.posegraph", "agvsim.slam"], watch) == []


def test_import_linter_contracts_are_kept():
    pytest.importorskip("importlinter")
    code = (
        "from importlinter.cli import lint_imports\n"
        "raise SystemExit(lint_imports(config_filename='pyproject.toml', no_cache=True, "
        "no_logo=True))\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stdout + res.stderr


def test_every_top_level_module_has_a_layer():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    contract = config["tool"]["importlinter"]["contracts"][0]
    assert contract["type"] == "layers"
    placed = {
        name.strip() for layer in contract["layers"] for name in layer.replace("|", ":").split(":")
    }
    package = ROOT / "src" / "agvsim"
    modules = {
        f"agvsim.{p.stem}"
        for p in package.iterdir()
        if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").is_file()
    }
    assert sorted(modules - placed) == []
    assert sorted(placed - modules) == []


def test_public_api_names_resolve():
    import agvsim

    for name in agvsim.__all__:
        assert getattr(agvsim, name) is not None
