"""What the ``agvsim`` command tells a newcomer: errors before anything else, every output it
wrote, numbers as people write them."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from agvsim.cli import app

ROOM = """\
name: room with a camera
duration_s: 0.3
world:
  picture: |
    #######
    #.....#
    #.....#
    #.....#
    #######
robots:
  - name: agv
    model: differential
    sensors: [{type: camera, name: front, width_px: 32, height_px: 24}]
    controller: {type: script, steps: [{duration_s: 10, twist: [0.2, 0.0]}]}
"""


def test_run_of_a_missing_file_says_so_first(tmp_path):
    res = CliRunner().invoke(app, ["run", str(tmp_path / "nonexistent.yaml")])
    assert res.exit_code == 2
    assert "no such file" in res.output
    assert "preparing" not in res.output and "compiles" not in res.output


def test_models_prints_parameters_as_people_write_them():
    res = CliRunner().invoke(app, ["models"])
    assert res.exit_code == 0
    assert "max_steer_rad = 1.5708" in res.output
    assert "1.5707963267948966" not in res.output
    # every parameter with what it allows, from the one declaration on the model's dataclass
    assert "max_steer_rad = 0.610865  (a positive number below pi/2 rad (90 deg))" in res.output
    assert "steering_geometry = ackermann  (ackermann | parallel)" in res.output


@pytest.mark.slow  # writes videos (ffmpeg)
def test_run_lists_every_video_it_wrote(tmp_path):
    scenario = tmp_path / "room.yaml"
    scenario.write_text(ROOM)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", str(scenario), "--out", str(out), "--video", "-q"])
    assert res.exit_code == 0, res.output
    videos = sorted(p.name for p in Path(out).glob("*.mp4"))
    assert len(videos) == 2 and "top.mp4" in videos  # the top view and the camera
    listed = res.output.split("outputs in", 1)[1]
    for name in ("summary.json", "trajectory.csv", "plot.png", "run.mcap", *videos):
        assert name in listed


def test_a_slow_first_step_is_explained_not_hidden_in_the_real_time_factor(tmp_path, monkeypatch):
    """summary.json gives the wall time to the end of the first step (numba's kernels load
    there, compiled on a machine's first run); when that is most of the run, ``agvsim run``
    says so beside the real-time factor. A first step made 5.2 s slow stands in for a
    compile (in a test numba's cache is usually warm)."""
    import json
    import time

    from agvsim import runner

    scenario = tmp_path / "room.yaml"
    scenario.write_text(
        ROOM.replace(
            "sensors: [{type: camera, name: front, width_px: 32, height_px: 24}]", "sensors: []"
        )
    )
    res = CliRunner().invoke(app, ["run", str(scenario), "--out", str(tmp_path / "a"), "-q"])
    assert res.exit_code == 0, res.output
    run = json.loads((tmp_path / "a" / "summary.json").read_text())["run"]
    assert 0.0 < run["first_step_s"] <= run["wall_time_s"]

    on_step = runner._FirstStep.on_step

    def slow(self, sim):  # type: ignore[no-untyped-def]
        if self.at is None:
            time.sleep(5.2)
        on_step(self, sim)

    monkeypatch.setattr(runner._FirstStep, "on_step", slow)
    res = CliRunner().invoke(app, ["run", str(scenario), "--out", str(tmp_path / "b")])
    assert res.exit_code == 0, res.output
    run = json.loads((tmp_path / "b" / "summary.json").read_text())["run"]
    assert 5.2 <= run["first_step_s"] <= run["wall_time_s"]
    assert "numba compiled the simulator's kernels" in " ".join(res.output.split())
