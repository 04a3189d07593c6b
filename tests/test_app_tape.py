"""The world editor's tape brush: clicks lay tape lines into the running scenario; the line
sensor reads them at once; the robots carry on; the tape is saved with the scenario."""

from __future__ import annotations

import numpy as np
import pytest

from agvsim.app.session import Session
from agvsim.app.tape_brush import TapeBrush
from agvsim.scenario import parse_scenario

ROOM = {
    "name": "tape room",
    "world": {"picture": "#########\n#.......#\n#.......#\n#.......#\n#.......#\n#########"},
    "robots": [
        {
            "name": "agv",
            "model": "differential",
            "pose": {"x_m": -1.5, "y_m": 0.0},
            "sensors": [{"type": "line", "mount_x_m": 0.3}],
            "controller": {"type": "script", "steps": [{"duration_s": 100, "twist": [0.2, 0.0]}]},
        }
    ],
}


def test_clicks_lay_tape_that_the_line_sensor_reads_at_once():
    s = Session(parse_scenario(ROOM, "room"), "test")
    s.step(10)
    before = s.sim.state.poses.copy()
    t_before = s.sim.state.t_s
    brush = TapeBrush(s)
    assert "click where it goes next" in brush.click(-3.0, 0.013)
    assert s.sim.world.tape is None  # one point is no tape yet
    v0 = s.world_version
    brush.click(3.0, 0.0)
    assert s.world_version == v0 + 1
    assert s.sim.world.tape is not None
    assert s.sim.world.tape.length_m == pytest.approx(np.hypot(6.0, 0.01))  # rounded to 1 cm
    # the robots carry on where they were, the clock too
    np.testing.assert_array_equal(s.sim.state.poses, before)
    assert s.sim.state.t_s == t_before
    s.step(1)
    assert s.sim.state.line_active.any()  # the bar over the tape lights up
    # extend, then a second line
    brush.click(3.0, 1.5)
    brush.new_line()
    brush.click(-3.0, -1.0)
    brush.click(-1.0, -1.0)
    lines = s.config["world"]["tape"]["lines"]
    assert lines == [
        {"points": [[-3.0, 0.01], [3.0, 0.0], [3.0, 1.5]]},
        {"points": [[-3.0, -1.0], [-1.0, -1.0]]},
    ]
    assert s.sim.world.tape.length_m == pytest.approx(np.hypot(6.0, 0.01) + 1.5 + 2.0)
    assert "tape:" in s.scenario_yaml()  # saved with the scenario


def test_a_click_off_the_map_lays_nothing():
    s = Session(parse_scenario(ROOM, "room"), "test")
    brush = TapeBrush(s)
    with pytest.raises(ValueError, match="off the map"):
        brush.click(50.0, 0.0)
    assert "tape" not in s.config["world"]
