"""The browser app's sensor camera view (thesis Fig. 33): the picked robot's camera frame shows
in the panel and follows new frames; a robot without a camera shows none."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from agvsim.scenario import load_scenario, parse_scenario

pytestmark = pytest.mark.slow  # the app with cameras

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture()
def app():
    pytest.importorskip("viser")
    from agvsim.app.server import App
    from agvsim.app.session import Session
    from agvsim.net import free_port

    data = load_scenario(ROOT / "scenarios" / "marker_search.yaml").model_dump(exclude_none=True)
    data["robots"].append(
        {"name": "blind", "model": "differential", "pose": {"x_m": -3.5, "y_m": -3.0}}
    )
    a = App(Session(parse_scenario(data)), port=free_port())  # loops not started: driven here
    yield a
    a.server.stop()


def test_the_picked_robots_camera_frame_is_shown_and_follows_new_frames(app):
    panel, session = app.panel, app.session
    panel._select("seeker")
    panel.refresh()
    view = panel.camera_view
    assert view is not None
    assert np.array_equal(view.image, np.asarray(session.sim.state.images[0]))
    assert "seeker" in panel._camera_label
    for _ in range(10):  # 0.2 s: two new frames at 10 Hz
        session.sim.step()
    panel.refresh()
    assert panel.camera_view is view
    assert np.array_equal(view.image, np.asarray(session.sim.state.images[0]))
    panel._select("blind")
    panel.refresh()
    assert panel.camera_view is None


def test_the_3d_view_draws_every_marker_on_its_wall(app):
    from agvsim.app import shapes

    app.scene.update()
    markers = app.session.sim.world.appearance.markers
    assert len(markers) == 6 and len(app.scene._markers) == 6
    for node, mk in zip(app.scene._markers, markers, strict=True):
        pos, q = shapes.marker_pose(mk)
        assert np.asarray(node.position) == pytest.approx(pos, abs=1e-6)
        assert np.asarray(node.wxyz) == pytest.approx(q, abs=1e-6)
    # a new world (here the same maze edited) redraws them once, not twice
    app.session.toggle_cell(1, 1)
    app.scene.update()
    assert len(app.scene._markers) == 6


def test_a_camera_turned_on_in_the_mask_shows_its_frames(app):
    panel, session = app.panel, app.session
    panel._select("blind")
    w = panel._mask_widgets
    assert w["sensors.camera"].value is False
    w["sensors.camera"].value = True
    w["sensors.camera.width_px"].value = 64
    w["sensors.camera.height_px"].value = 48
    panel._apply()
    assert "applied" in panel.apply_msg.content
    (spec,) = session.sim.robots[session.sim.robot_index("blind")].cameras
    assert (spec.width_px, spec.height_px) == (64, 48)
    panel.refresh()
    assert panel.camera_view is not None and panel.camera_view.image.shape == (48, 64, 3)
    panel._mask_widgets["sensors.camera.width_px"].value = 0
    panel._apply()
    assert "width_px" in panel.apply_msg.content and "greater than or equal to 8" in (
        panel.apply_msg.content
    )
    panel._mask_widgets["sensors.camera"].value = False
    panel._apply()
    assert session.sim.robots[session.sim.robot_index("blind")].cameras == ()
    panel.refresh()
    assert panel.camera_view is None
