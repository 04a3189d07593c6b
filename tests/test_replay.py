"""``agvsim replay``: the replay session shows exactly the recorded poses and scans at any time
(no browser needed), follows map changes, and drives the app's SceneView."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rosbags")

from agvsim.app.replay import ReplaySession  # noqa: E402
from agvsim.record.mcap_reader import RecordingError  # noqa: E402
from agvsim.record.mcap_writer import Recorder, scenario_yaml  # noqa: E402
from agvsim.scenario import build, parse_scenario  # noqa: E402

SCENARIO = {
    "name": "replay room",
    "world": {
        "picture": "##########\n#........#\n#........#\n#........#\n##########",
        "boxes": [{"x_m": 2.5, "y_m": 0.5, "length_m": 0.5, "width_m": 0.5}],
    },
    "robots": [
        {
            "name": "r1",
            "model": "differential",
            "pose": {"x_m": -3.0, "y_m": -0.5},
            "sensors": [{"type": "rangers"}, {"type": "lidar", "beams": 60, "rate_hz": 10}],
            "controller": {"type": "avoid", "speed_m_s": 0.5},
        },
        {
            "name": "r2",
            "model": "mecanum",
            "color": "#1f77b4",
            "pose": {"x_m": 1.0, "y_m": 0.5, "theta_deg": 180},
            "sensors": [{"type": "rangers"}],
            "controller": {
                "type": "script",
                "steps": [{"duration_s": 9, "twist": [0.2, 0.3, 0.0]}],
            },  # noqa: E501
        },
    ],
}


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    sc = parse_scenario(SCENARIO, "replay room")
    sim = build(sc)
    path = tmp_path_factory.mktemp("replay") / "run.mcap"
    rec = Recorder(path, sim, scenario_yaml(sc, 0))
    snaps = {0.0: (sim.state.poses.copy(), sim.state.scans.copy())}
    for k in range(100):  # 2 s
        sim.step()
        if k == 49:  # at t = 1 s a wall appears in the north-east room corner
            sim.set_grid(sim.world.grid.with_cell(1, 8, True))
        rec.record()
        snaps[round(sim.state.t_s, 6)] = (sim.state.poses.copy(), sim.state.scans.copy())
    rec.close()
    return path, snaps, sim


def test_poses_and_scans_at_any_time_are_the_recorded_ones(played):
    path, snaps, sim = played
    s = ReplaySession(path)
    assert (s.start_s, s.end_s) == (0.0, pytest.approx(2.0))
    assert [r.name for r in s.sim.robots] == ["r1", "r2"]
    for t in (0.0, 0.02, 0.5, 1.24, 2.0):
        s.seek(t)
        poses, scans = snaps[round(t, 6)]
        np.testing.assert_allclose(s.sim.state.poses, poses, atol=1e-12)
        # rangers (slots 0 and 2) fire every step: the scan of this very step, float32
        np.testing.assert_array_equal(s.sim.state.scans[0, :4], scans[0, :4].astype(np.float32))
    # between two samples: the last one at or before t (recorded values, not interpolated)
    s.seek(0.519)
    np.testing.assert_allclose(s.sim.state.poses, snaps[0.5][0], atol=1e-12)
    # the lidar (slot 1, 10 Hz) keeps its last scan until the next: at 0.55 s the 0.5 s one
    s.seek(0.55)
    np.testing.assert_array_equal(
        s.sim.state.scans[1, :60], snaps[0.5][1][1, :60].astype(np.float32)
    )
    s.seek(-5.0)
    assert s.t_s == 0.0
    s.seek(99.0)
    assert s.t_s == pytest.approx(2.0)
    assert len(s.history["r2"].trail) == 101


def test_playback_advances_at_the_chosen_speed_and_stops_at_the_end(played):
    path, snaps, _ = played
    s = ReplaySession(path)
    assert not s.advance(1.0)  # paused: nothing moves
    s.play()
    s.speed = 2.0
    assert s.advance(0.25) and s.t_s == pytest.approx(0.5)
    np.testing.assert_allclose(s.sim.state.poses, snaps[0.5][0], atol=1e-12)
    s.advance(10.0)
    assert s.t_s == pytest.approx(2.0) and not s.playing
    s.play()  # at the end, play starts over
    assert s.t_s == 0.0 and s.playing


def test_the_map_follows_the_recorded_changes(played):
    path, _, sim = played
    s = ReplaySession(path)
    assert not s.sim.world.grid.occupied[1, 8]
    v = s.world_version
    s.seek(1.5)
    assert s.sim.world.grid.occupied[1, 8] and s.world_version == v + 1
    np.testing.assert_array_equal(s.sim.world.grid.occupied, sim.world.grid.occupied)
    np.testing.assert_allclose(s.sim.world.boxes, sim.world.boxes)
    s.seek(0.2)
    assert not s.sim.world.grid.occupied[1, 8]


def test_state_names_follow_the_recording(played):
    path, _, _ = played
    s = ReplaySession(path)
    s.seek(0.0)
    assert s.state_names()[1] == "script"
    assert s.state_names()[0] != ""


def test_a_recording_without_scenario_is_refused(tmp_path):
    from agvsim.record.mcap_file import McapStreamWriter

    w = McapStreamWriter(tmp_path / "other.mcap")
    w.close()
    with pytest.raises(RecordingError, match="not an agvsim recording"):
        ReplaySession(tmp_path / "other.mcap")


def test_replay_app_draws_the_scene(played):
    from agvsim.app.replay import ReplayApp
    from agvsim.net import free_port

    path, snaps, _ = played
    s = ReplaySession(path)
    app = ReplayApp(s, port=free_port())
    try:
        s.seek(1.0)
        app.scene.update()  # SceneView reads the replay session like a live one
        assert app.scene.frames_sent == 1 and len(app.scene._robots) == 2
        node = app.scene._robots[1].frame
        np.testing.assert_allclose(node.position[:2], snaps[1.0][0][1, :2], atol=1e-6)
        app.slider.value = 0.5
        app._slider_moved(None)
        assert s.t_s == pytest.approx(0.5) and not s.playing
    finally:
        app.stop()
