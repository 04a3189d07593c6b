"""``agvsim replay`` in a real headless Chromium (Playwright): the page draws the recorded
scene, and Play / Pause drive the playback.

Skipped without Debian's chromium, unless AGVSIM_REQUIRE_BROWSER=1 (as tests/test_app_browser).
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from agvsim.net import free_port

from helpers import PAGE_LOAD_MS, chromium, need_browser, wait_for

pytestmark = pytest.mark.slow  # a real browser

ROOM = {
    "name": "replay room",
    "world": {"picture": "#########\n#.......#\n#.......#\n#.......#\n#########"},
    "robots": [
        {
            "name": "agv",
            "model": "differential",
            "color": "#ff0000",
            "body": {"length_m": 1.2, "width_m": 0.9},
            "pose": {"x_m": -2.5, "y_m": 0.0},
            "sensors": [{"type": "lidar", "beams": 16, "rate_hz": 10}],
            "controller": {"type": "script", "steps": [{"duration_s": 9, "twist": [0.4, 0.0]}]},
        }
    ],
}


def test_replay_page_plays_the_recording(tmp_path):
    need_browser()
    from PIL import Image

    from agvsim.app.replay import ReplayApp, ReplaySession
    from agvsim.runner import run_scenario
    from agvsim.scenario import parse_scenario

    run_scenario(parse_scenario({**ROOM, "duration_s": 4.0}, "room"), tmp_path, plot=False)
    session = ReplaySession(tmp_path / "run.mcap")
    app = ReplayApp(session, port=free_port()).start()
    try:
        with chromium() as browser:
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(app.url)
            page.get_by_role("button", name="Play").wait_for(timeout=PAGE_LOAD_MS)
            page.get_by_role("button", name="Top view").click()
            page.wait_for_timeout(1500)
            canvas = page.locator("canvas").first
            img = np.asarray(Image.open(io.BytesIO(canvas.screenshot())).convert("RGB"))
            red = (img[..., 0] > 180) & (img[..., 1] < 90) & (img[..., 2] < 90)
            assert red.sum() > 30, "the red robot is not drawn"
            page.get_by_role("button", name="Play").click()
            wait_for(lambda: session.t_s > 0.5, what="playback to advance")
            page.get_by_role("button", name="Pause").click()
            wait_for(lambda: not session.playing, what="pause")
            t = session.t_s
            page.wait_for_timeout(400)
            assert session.t_s == t  # paused
            k = int(np.searchsorted(session.times, t + 1e-9, side="right")) - 1
            np.testing.assert_allclose(session.sim.state.poses, session.poses[k], atol=0)
        assert errors == []
    finally:
        app.stop()
