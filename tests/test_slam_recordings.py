"""The SLAM robustness suite's drawn buildings (docs/slam.md, "Slanted wings" and "A rack
warehouse"): the shipped pictures and routes are what their scripts draw."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]


def _generator(name: str):
    script = ROOT / "scripts" / f"make_{name}.py"
    spec = importlib.util.spec_from_file_location(f"make_{name}", script)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    ("name", "shape", "free"),
    [("slam_wings", (1020, 1440), (0.1, 0.5)), ("slam_warehouse", (800, 1200), (0.8, 0.99))],
)
def test_the_drawn_scenarios_are_what_their_generators_draw(tmp_path, name, shape, free):
    shutil.copy(ROOT / "scenarios" / f"{name}.yaml", tmp_path)
    _generator(name).main(tmp_path)
    shipped = np.asarray(Image.open(ROOT / "scenarios" / f"{name}.png"))
    drawn = np.asarray(Image.open(tmp_path / f"{name}.png"))
    assert np.array_equal(shipped, drawn)
    assert (tmp_path / f"{name}.yaml").read_text() == (
        ROOT / "scenarios" / f"{name}.yaml"
    ).read_text()
    # 5 cm cells; walls and free space both present
    assert drawn.shape == shape and free[0] < (drawn > 127).mean() < free[1]
