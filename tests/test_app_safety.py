"""The safety scanner in the browser app: the ``safety:`` block edited as YAML in the Robot
tab's mask (validated with the scenario's messages) and the field sets drawn under each robot
in their status colour (app.safety_view)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from test_safety_stage import scenario

from agvsim.app.mask import MaskError, fields_in_error, mask_fields, robot_from_mask
from agvsim.app.safety_view import FieldsView, polygon_segments
from agvsim.app.session import Session
from agvsim.net import free_port
from agvsim.scenario import ScenarioError, parse_scenario
from agvsim.sensors.safety_fields import CLEAR, PROTECTIVE, WARNING
from agvsim.sim.safety import STATUS_RGB


def session() -> Session:
    data = scenario("differential", [{"duration_s": 30, "twist": [0.8, 0.0]}], box_at_m=3.5)
    return Session(parse_scenario(data), "test")


def test_the_safety_block_is_edited_as_yaml_in_the_mask():
    s = session()
    before = s.robot_config("agv")
    values = {f.key: f.value for f in mask_fields(before)}
    assert yaml.safe_load(values["safety"]) == before["safety"]
    # a field too short for the top speed: the scenario's message, on the safety field
    block = yaml.safe_load(values["safety"])
    block["field_sets"][2]["protective"] = [[-0.4, -0.3], [0.8, -0.3], [0.8, 0.3], [-0.4, 0.3]]
    values["safety"] = yaml.safe_dump(block)
    with pytest.raises(ScenarioError) as err:
        s.apply_robot("agv", robot_from_mask(before, values))
    where = fields_in_error(err.value.problems, before)
    assert "safety.field_sets[2]: the protective field reaches 0.800 m ahead" in where["safety"]
    assert s.robot_config("agv") == before
    values["safety"] = "field_sets: [oops"
    with pytest.raises(MaskError, match="not valid YAML"):
        robot_from_mask(before, values)
    values["safety"] = "- a list"
    with pytest.raises(MaskError, match="need 'key: value' lines"):
        robot_from_mask(before, values)
    # a lower warning speed is applied; an empty field removes the scanner
    block = yaml.safe_load(mask_fields(before)[-1].value)
    block["warning_speed_m_s"] = 0.2
    values["safety"] = yaml.safe_dump(block)
    s.apply_robot("agv", robot_from_mask(before, values))
    assert s.sim.robots[0].safety.warning_speed_m_s == 0.2
    values["safety"] = ""
    s.apply_robot("agv", robot_from_mask(s.robot_config("agv"), values))
    assert s.sim.robots[0].safety is None and s.sim.safety is None
    assert "safety" not in s.robot_config("agv")


def test_field_sets_are_drawn_in_their_status_colour():
    import viser

    s = session()
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        view = FieldsView()
        spec = s.sim.robots[0].safety
        for status in (CLEAR, WARNING, PROTECTIVE):
            view.update(server, s.sim.robots, np.array([2]), np.array([status]))
            (key, nodes) = view._drawn[0]
            assert key == (2, status) and len(nodes) == 2  # protective and warning
            rgb = np.asarray(nodes[0].colors).reshape(-1, 3)[0]
            assert tuple(rgb) == tuple(int(round(255 * c)) for c in STATUS_RGB[status])
            np.testing.assert_allclose(
                np.asarray(nodes[0].points), polygon_segments(spec.field_sets[2].protective)
            )
        view.update(server, s.sim.robots, np.array([-1]), np.array([PROTECTIVE]))
        assert view._drawn[0][1] == []  # no active set: nothing to draw
    finally:
        server.stop()


def test_polygon_segments_close_the_outline():
    seg = polygon_segments([(0, 0), (1, 0), (1, 2)], z_m=0.5)
    assert seg.shape == (3, 2, 3)
    assert seg[-1, 1].tolist() == [0.0, 0.0, 0.5] and seg[0, 0].tolist() == [0.0, 0.0, 0.5]
