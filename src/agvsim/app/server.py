"""``agvsim serve``: the browser app. One simulation, any number of browser tabs watching it.

Three loops: viser's server threads (GUI callbacks, client connections), a stepping thread
that keeps the simulation at the chosen speed, and the drawing loop that sends the scene to
every tab ``fps`` times a second. A tab that closes or reconnects only leaves or joins the
audience; the simulation never waits for a browser.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, TypeVar

from agvsim.app.session import DEFAULT_OUT, Session
from agvsim.app.uploads import DEFAULT_MAX_UPLOAD_BYTES, UploadLimits, refuse_large_uploads
from agvsim.scenario import Scenario, ScenarioError, load_scenario
from agvsim.signals import terminate_as_interrupt

log = logging.getLogger("agvsim.app")


@dataclass
class AppStats:
    """Measured rates: frames drawn per second, simulated seconds per wall second."""

    frames: int = 0
    steps: int = 0
    frame_times: list[float] = field(default_factory=list)


class App:
    """The running app. ``start()`` returns at once; ``stop()`` ends every loop."""

    def __init__(
        self,
        session: Session,
        host: str = "127.0.0.1",
        port: int = 8080,
        fps: float = 40.0,
        verbose: bool = False,
        notify: Callable[[str], None] = print,
    ):
        from agvsim.app.guard import open_viser
        from agvsim.app.panel import Panel
        from agvsim.app.scene import SceneView

        self.session, self.fps, self.notify, self.host = session, fps, notify, host
        # only the browser given the token (self.url) gets in (agvsim.app.guard)
        self.server, self.guard = open_viser(host, port, verbose)
        self.server.gui.set_panel_label("agvsim")
        self.scene = SceneView(self.server, session)
        self.panel = Panel(self.server, session, self.scene, notify)
        self.stats = AppStats()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.server.on_client_connect(self._connected)
        self.server.on_client_disconnect(self._disconnected)
        refuse_large_uploads(self.server, lambda: session.upload_limits, self._tell)

    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def url(self) -> str:
        """The address to open, with this launch's token."""
        from agvsim.app.guard import app_url

        return app_url(self.host, self.port, self.guard.token)

    def _tell(self, client_id: int, message: str) -> None:
        """Show ``message`` as a notification in one browser tab."""
        client = self.server.get_clients().get(client_id)
        if client is not None:
            client.add_notification("Upload refused", message, color="red", auto_close_seconds=10.0)

    def _connected(self, client) -> None:
        self.panel.add_client(client)

    def _disconnected(self, client) -> None:
        self.panel.remove_client(client.client_id)
        if not self.server.get_clients():
            # nobody is watching the keyboard robot any more: it stops (a dead-man switch)
            self.session.stop_keyboard_motion()

    # ------------------------------------------------------------------ loops
    def _step_loop(self) -> None:
        last = time.perf_counter()
        while not self._stop.is_set():
            now = time.perf_counter()
            try:
                n = self.session.advance(now - last)
            except Exception:  # the session pauses on controller errors; anything else: log
                log.exception("stepping the simulation failed")
                self.session.pause()
                n = 0
            last = now
            self.stats.steps += n
            if n == 0:
                time.sleep(0.004)
            else:
                time.sleep(0.0005)  # let the drawing loop and the GUI take the lock

    def _draw_loop(self) -> None:
        period = 1.0 / self.fps
        next_refresh = 0.0
        nxt = time.perf_counter()
        while not self._stop.is_set():
            t0 = time.perf_counter()
            try:
                self.scene.update()
                self.panel.follow()
                if t0 >= next_refresh:
                    self.panel.refresh()
                    next_refresh = t0 + 0.2
            except Exception:  # a drawing fault must not freeze the app: log it, go on
                log.exception("drawing the scene failed")
                time.sleep(0.2)
            self.stats.frames += 1
            self.stats.frame_times.append(t0)
            if len(self.stats.frame_times) > 2000:
                del self.stats.frame_times[:1000]
            nxt += period
            delay = nxt - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            else:
                nxt = time.perf_counter()

    def start(self) -> App:
        for target in (self._step_loop, self._draw_loop):
            t = threading.Thread(target=target, daemon=True, name=target.__name__)
            t.start()
            self._threads.append(t)
        return self

    def stop(self) -> None:
        """End the loops, finish a video being recorded (nothing recorded is lost), close
        the server."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        status = self.session.video_status()
        paths = self.session.stop_video()
        if paths and status is not None:
            saved = ", ".join(str(p) for p in paths)
            self.notify(f"video saved ({status[2]:.1f} s): {saved}")
        self.server.stop()
        self.session.close()  # a VDA 5050 fleet: OFFLINE, the embedded broker stops

    def frame_rate(self, window_s: float = 2.0) -> float:
        """Frames drawn per second over the last ``window_s`` seconds."""
        ft = self.stats.frame_times
        now = time.perf_counter()
        recent = [t for t in ft if t >= now - window_s]
        return len(recent) / window_s


def open_session(
    scenario: str | Path | Scenario | None,
    out_dir: str | Path = DEFAULT_OUT,
    broker: str | None = None,
    master: bool = True,
) -> Session:
    """The session of ``scenario``: a ``FleetSession`` (app.fleet_view) when it has a
    ``vda5050:`` block, its vehicles on ``broker`` (None: an embedded broker), driven by
    agvsim's master control unless ``master`` is False (then by yours)."""
    if scenario is not None and not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    if isinstance(scenario, Scenario) and scenario.vda5050 is not None:
        from agvsim.app.fleet_view import FleetSession

        return FleetSession(
            scenario, scenario._source, broker_url=broker, out_dir=out_dir, with_master=master
        )
    if broker is not None:
        raise ScenarioError(
            str(getattr(scenario, "_source", "scenario")),
            ["--broker needs a scenario with a 'vda5050:' block of vehicles"],
        )
    if scenario is None:
        from agvsim.scenario import parse_scenario

        default = Path(__file__).resolve().parents[3] / "scenarios" / "thesis_maze_avoid.yaml"
        if default.is_file():
            return Session(load_scenario(default), str(default), out_dir=out_dir)
        sc = parse_scenario(
            {
                "name": "thesis maze",
                "world": {"maze": "thesis_c1"},
                "robots": [
                    {
                        "name": "agv",
                        "model": "differential",
                        "sensors": [{"type": "rangers"}],
                        "controller": {"type": "avoid"},
                    }
                ],
            }
        )
        return Session(sc, "built-in scenario", out_dir=out_dir)
    return Session(scenario, scenario._source, out_dir=out_dir)


def serve(
    scenario: str | Path | Scenario | None = None,
    host: str = "127.0.0.1",
    port: int = 8080,
    play: bool = False,
    on_ready: Callable[[App], None] | None = None,
    out_dir: str | Path = DEFAULT_OUT,
    notify: Callable[[str], None] = print,
    max_upload_bytes: int = DEFAULT_MAX_UPLOAD_BYTES,
    broker: str | None = None,
    master: bool = True,
) -> None:
    """Run the app until Ctrl-C (or SIGTERM); a video being recorded is finished first.
    ``max_upload_bytes``: the most one file sent from a browser may have. ``broker``: the
    MQTT broker of a scenario's VDA 5050 vehicles (None: an embedded one)."""
    session = open_session(scenario, out_dir, broker, master)
    session.upload_limits = UploadLimits(max_upload_bytes, max_unpacked_bytes=4 * max_upload_bytes)
    try:
        app = App(session, host=host, port=port, notify=notify).start()
    except BaseException:
        session.close()
        raise
    if play:
        app.session.play()
    run_until_stopped(app, on_ready)


class _Stoppable(Protocol):
    def stop(self) -> None: ...


_AppT = TypeVar("_AppT", bound=_Stoppable)


def run_until_stopped(app: _AppT, on_ready: Callable[[_AppT], None] | None = None) -> None:
    """The serve loop of ``agvsim serve`` and ``agvsim replay``: call ``on_ready(app)`` (the
    app is started and listening), wait until Ctrl-C or SIGTERM (agvsim.signals), then
    ``app.stop()``, which finishes what must be finished (a video being recorded) and closes
    the server."""
    if on_ready is not None:
        on_ready(app)
    with terminate_as_interrupt():
        try:
            while True:
                time.sleep(0.5)
        except KeyboardInterrupt:
            pass
        finally:
            app.stop()
