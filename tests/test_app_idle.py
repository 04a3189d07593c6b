"""A paused app sends the browser nothing: the scene's trails and the panel's plots go out
when the run has moved, not at every frame (a paused page that kept redrawing its trails four
times a second took seconds to answer a click in a software-rendered browser)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest
from test_app_session import scenario

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@pytest.fixture()
def app(tmp_path: Path):
    pytest.importorskip("viser")
    from agvsim.app.server import App
    from agvsim.app.session import Session
    from agvsim.net import free_port
    from agvsim.scenario import parse_scenario

    a = App(Session(parse_scenario(scenario())), port=free_port())  # loops not started
    yield a
    a.server.stop()


def _frames(app, n: int) -> Counter:
    """Draw ``n`` frames and refresh the panel each time; the messages queued, by kind and
    scene node or updated field (viser queues every update to the browser through its
    websocket server)."""
    sent: Counter = Counter()
    ws = app.server._websock_server
    queue = ws.queue_message

    def count(message) -> None:
        what = getattr(message, "name", None) or tuple(getattr(message, "updates", {}))
        sent[(type(message).__name__, what)] += 1
        queue(message)

    ws.queue_message = count
    try:
        for _ in range(n):
            app.scene.update()
            app.panel.refresh()
    finally:
        ws.queue_message = queue
    return sent


def test_a_paused_run_sends_nothing_and_a_moving_one_its_trails_and_plots(app):
    s = app.session
    s.step(50)  # a run with a trail and a history to plot
    _frames(app, 20)  # everything drawn once
    assert _frames(app, 40) == Counter()  # paused: forty frames, not one message
    s.step(10)
    moved = _frames(app, 20)
    assert moved[("LineSegmentsMessage", "/trails")] >= 1  # the longer trail
    assert moved[("GuiUpdateMessage", ("data",))] >= 2  # both plots' new samples
    assert _frames(app, 40) == Counter()  # and quiet again
