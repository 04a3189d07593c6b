"""The SLAM robustness suite's drawn building (docs/slam.md, "Slanted wings"): the shipped
picture and route are what ``scripts/make_slam_wings.py`` draws."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]


def _generator():
    script = ROOT / "scripts" / "make_slam_wings.py"
    spec = importlib.util.spec_from_file_location("make_slam_wings", script)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_wings_scenario_is_what_its_generator_draws(tmp_path):
    shutil.copy(ROOT / "scenarios" / "slam_wings.yaml", tmp_path)
    _generator().main(tmp_path)
    shipped = np.asarray(Image.open(ROOT / "scenarios" / "slam_wings.png"))
    drawn = np.asarray(Image.open(tmp_path / "slam_wings.png"))
    assert np.array_equal(shipped, drawn)
    assert (tmp_path / "slam_wings.yaml").read_text() == (
        ROOT / "scenarios" / "slam_wings.yaml"
    ).read_text()
    # 72 m x 51 m at 5 cm; walls and free space both present
    assert drawn.shape == (1020, 1440) and 0.1 < (drawn > 127).mean() < 0.5
