"""Packaging contracts: one version, ``python -m agvsim``, typed package, licence shipped."""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
from pathlib import Path

import agvsim

ROOT = Path(__file__).resolve().parents[1]


def test_version_is_defined_once():
    assert importlib.metadata.version("agvsim") == agvsim.__version__
    lines = (ROOT / "pyproject.toml").read_text().splitlines()
    assert not [line for line in lines if line.startswith('version = "')]


def test_python_dash_m_runs_the_cli():
    done = subprocess.run(
        [sys.executable, "-m", "agvsim", "--version"], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"agvsim {agvsim.__version__}"


def test_typed_and_licensed():
    assert (Path(agvsim.__file__).parent / "py.typed").is_file()
    assert "MIT License" in (ROOT / "LICENSE").read_text()
