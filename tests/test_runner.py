"""Runs write every output, also when a controller fails or the user presses Ctrl-C."""

from __future__ import annotations

import csv
import json

import pytest

from agvsim.runner import run_scenario
from agvsim.sim.engine import ControllerError

SCENARIO = """
name: failing controller
duration_s: 10
world: {{picture: "#####\\n#...#\\n#...#\\n#...#\\n#####", cell_size_m: 2.0}}
robots:
  - name: student
    model: differential
    pose: {{x_m: -1.0, y_m: 0.0}}
    controller: {{type: python, file: ctrl.py, name: step}}
"""

CONTROLLER = """
def step(obs):
    if obs.t_s >= 1.0:
        raise {exc}("stop here")
    return (0.2, 0.0, 0.0)
"""


@pytest.mark.parametrize(
    ("exc", "expected", "status"),
    [
        ("RuntimeError", ControllerError, "controller_error"),
        ("KeyboardInterrupt", KeyboardInterrupt, "interrupted"),
    ],
)
def test_outputs_survive_a_failure(tmp_path, exc, expected, status):
    (tmp_path / "ctrl.py").write_text(CONTROLLER.format(exc=exc))
    (tmp_path / "s.yaml").write_text(SCENARIO.format())
    out = tmp_path / "out"
    with pytest.raises(expected):
        run_scenario(tmp_path / "s.yaml", out)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run"]["status"] == status
    assert summary["run"]["simulated_time_s"] == pytest.approx(1.0)
    if exc == "RuntimeError":
        assert "student" in summary["run"]["error"] and "stop here" in summary["run"]["error"]
    with (out / "trajectory.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 51  # t = 0 .. 1.0 s at 50 Hz
    assert float(rows[-1]["x"]) == pytest.approx(-1.0 + 0.2 * 1.0)
    assert (out / "plot.png").stat().st_size > 10_000


def test_run_is_deterministic_bit_for_bit(tmp_path):
    runs = []
    for k in range(2):
        run_scenario(
            "scenarios/thesis_maze_avoid.yaml", tmp_path / str(k), duration_s=6, seed=5, plot=False
        )
        runs.append((tmp_path / str(k) / "trajectory.csv").read_bytes())
    assert runs[0] == runs[1]
