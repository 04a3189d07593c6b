"""The core is headless: simulating imports no plotting, file-format, UI or CLI library."""

from __future__ import annotations

import subprocess
import sys

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
]
# (yaml is not listed: numba itself imports it, to read an optional .numba_config.yaml)
FORBIDDEN = [
    "matplotlib",
    "PIL",
    "typer",
    "rich",
    "pydantic",
    "agvsim.scenario",
    "agvsim.behaviours",
    "agvsim.viz",
    "agvsim.record",
    "agvsim.cli",
]


def test_core_imports_only_numeric_libraries():
    code = (
        "import sys\n"
        + "".join(f"import {m}\n" for m in CORE)
        + f"bad = [m for m in {FORBIDDEN!r} if m in sys.modules]\n"
        + "print(','.join(bad))\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True
    )
    assert res.stdout.strip() == "", f"core pulled in: {res.stdout.strip()}"


def test_public_api_names_resolve():
    import agvsim

    for name in agvsim.__all__:
        assert getattr(agvsim, name) is not None
