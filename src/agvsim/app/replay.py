"""``agvsim replay RUN.mcap``: play a recording in the browser app.

The world and the robots (bodies, wheels, sensors, colours) are rebuilt from the scenario that
``agvsim run`` stored in the file (``/agvsim/scenario``), the walls from the recorded ``/map``;
nothing is simulated: at playback time t each robot stands at its recorded ground-truth pose
(the last sample at or before t) and each sensor shows its last recorded scan. Play, pause,
speed and a time slider drive it; the scene is drawn by the app's own ``SceneView``.

``ReplaySession`` holds no viewer, so it is tested without a browser.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agvsim.app.server import run_until_stopped
from agvsim.record.mcap_reader import Recording, RecordingError
from agvsim.record.ros2msg import topic_name

#: playback speeds: label -> recorded seconds per wall-clock second
REPLAY_SPEEDS: dict[str, float] = {"x0.25": 0.25, "x0.5": 0.5, "real time": 1.0, "x2": 2.0,
                                   "x5": 5.0, "x10": 10.0}  # fmt: skip
TRAIL_POINTS = 1500


@dataclass
class _Trail:
    trail: np.ndarray  # (K, 2) x, y: what SceneView reads of a history


def _replay_config(sc: dict) -> dict:
    """The stored scenario as the replay builds it: no controllers (nothing is driven), no
    cameras (their images are in the recording, not re-rendered), no metrics."""
    cfg = {k: v for k, v in sc.items() if k not in ("metrics",)}
    robots = []
    for r in sc.get("robots", []):
        r = dict(r)
        r["controller"] = {"type": "idle"}
        r["sensors"] = [s for s in r.get("sensors", []) if s.get("type") != "camera"]
        r.pop("slam", None)
        robots.append(r)
    cfg["robots"] = robots
    return cfg


class ReplaySession:
    """A recording being played back; duck-types what ``SceneView`` reads of a ``Session``
    (``lock``, ``sim``, ``layout``, ``world_version``, ``history``, ``config``)."""

    def __init__(self, path: str | Path):
        from agvsim.scenario import ScenarioError, parse_scenario, robot_spec
        from agvsim.sim.engine import Simulation
        from agvsim.sim.spec import World
        from agvsim.world.grid import OccupancyGrid

        self.path = Path(path)
        rec = Recording(self.path)
        sc_dict = rec.scenario_dict()
        if sc_dict is None:
            raise RecordingError(
                f"{self.path}: not an agvsim recording (no /agvsim/scenario topic); "
                "replay needs the scenario that `agvsim run` stores"
            )
        self.config = _replay_config(sc_dict)
        try:
            sc = parse_scenario(self.config, f"{self.path} (stored scenario)")
            specs = [robot_spec(rc, f"robots[{i}]", sc.dt_s) for i, rc in enumerate(sc.robots)]
        except ScenarioError as err:
            raise RecordingError(f"{self.path}: the stored scenario is invalid: {err}") from None
        boxes = np.array(
            [
                (b.x_m, b.y_m, np.deg2rad(b.theta_deg), b.length_m / 2, b.width_m / 2)
                for b in sc.world.boxes
            ],
            dtype=np.float64,
        ).reshape(-1, 5)
        maps = rec.occupancy("/map") if "/map" in rec.types else []
        if not maps:
            raise RecordingError(f"{self.path}: the recording holds no /map")
        self._map_t = np.array([m.t_s for m in maps])
        self._grids = [OccupancyGrid(m.occupied, m.resolution_m, m.origin_xy_m) for m in maps]
        self.sim = Simulation(World(self._grids[0], boxes), specs, [], dt_s=sc.dt_s, seed=sc.seed)
        names = [r.name for r in specs]
        # ground-truth poses, one table over all robots (they are recorded together)
        series = [rec.odometry(f"/{topic_name(n)}/ground_truth") for n in names]
        self.times = series[0][0]
        for n, (t, _, _) in zip(names, series, strict=True):
            if len(t) != len(self.times) or not np.array_equal(t, self.times):
                raise RecordingError(f"{self.path}: robot {n!r} has its own pose times")
        self.poses = np.stack([p for _, p, _ in series], axis=1)  # (T, N, 3)
        self.twists = np.stack([w for _, _, w in series], axis=1)
        # scans per sensor slot of the rebuilt simulation
        tab = self.sim.sensors
        self._scans: list[tuple[np.ndarray, np.ndarray] | None] = []
        for s in range(tab.count):
            topic = f"/{topic_name(names[int(tab.owner[s])])}/{topic_name(tab.specs[s].name)}"
            if topic in rec.types and rec.count(topic):
                ser = rec.laser_scans(topic)
                self._scans.append((ser.stamp_s, ser.ranges))
            else:
                self._scans.append(None)
        self.states: list[tuple[np.ndarray, list[str]]] = []
        for n in names:
            topic = f"/{topic_name(n)}/state"
            self.states.append(rec.strings(topic) if topic in rec.types else (np.zeros(0), []))
        self.lock = threading.RLock()
        self.layout = 0
        self.world_version = 0
        self._grid_index = 0
        self.history: dict[str, _Trail] = {n: _Trail(np.zeros((0, 2))) for n in names}
        self.playing = False
        self.speed = 1.0
        self.t_s = float(self.times[0]) if len(self.times) else 0.0
        self.seek(self.t_s)

    # ------------------------------------------------------------------ time
    @property
    def start_s(self) -> float:
        return float(self.times[0]) if len(self.times) else 0.0

    @property
    def end_s(self) -> float:
        return float(self.times[-1]) if len(self.times) else 0.0

    def seek(self, t_s: float) -> None:
        """Show the recording at time ``t_s`` (clamped to the recording)."""
        with self.lock:
            t = min(max(float(t_s), self.start_s), self.end_s)
            self.t_s = t
            k = max(int(np.searchsorted(self.times, t + 1e-9, side="right")) - 1, 0)
            scans: list = []
            for s, data in enumerate(self._scans):
                if data is None:
                    continue
                ts, ranges = data
                j = int(np.searchsorted(ts, t + 1e-9, side="right")) - 1
                scans.append((s, ts[j], ranges[j]) if j >= 0 else (s, None, None))
            recorded = len(self.times) > 0
            self.sim.show_recorded(
                t,
                self.poses[k] if recorded else None,
                self.twists[k] if recorded else None,
                scans,
            )
            g = max(int(np.searchsorted(self._map_t, t + 1e-9, side="right")) - 1, 0)
            if g != self._grid_index:
                self._grid_index = g
                self.sim.set_grid(self._grids[g])
                self.world_version += 1
            step = max(1, (k + 1) // TRAIL_POINTS)
            for i, name in enumerate(self.history):
                self.history[name] = _Trail(self.poses[: k + 1 : step, i, :2])

    def state_names(self) -> list[str]:
        """Each robot's controller state at the current time ("" before the first)."""
        out = []
        for ts, names in self.states:
            j = int(np.searchsorted(ts, self.t_s + 1e-9, side="right")) - 1
            out.append(names[j] if j >= 0 else "")
        return out

    def advance(self, wall_dt_s: float) -> bool:
        """Move the playback on by ``wall_dt_s`` wall seconds times the speed; stops at the
        end. Returns whether the time changed."""
        if not self.playing:
            return False
        t = self.t_s + wall_dt_s * self.speed
        if t >= self.end_s:
            t = self.end_s
            self.playing = False
        self.seek(t)
        return True

    def play(self) -> None:
        if self.t_s >= self.end_s:
            self.seek(self.start_s)
        self.playing = True

    def pause(self) -> None:
        self.playing = False


class ReplayApp:
    """The browser player: ``SceneView`` for the scene, a small panel for the controls."""

    def __init__(self, session: ReplaySession, host: str = "127.0.0.1", port: int = 8080,
                 fps: float = 30.0):  # fmt: skip
        import viser

        from agvsim.app import shapes
        from agvsim.app.guard import open_viser
        from agvsim.app.scene import SceneView

        self.session, self.fps, self.host = session, fps, host
        # only the browser given the token (self.url) gets in (agvsim.app.guard)
        self.server, self.guard = open_viser(host, port)
        self.server.gui.set_panel_label(f"agvsim replay: {session.path.name}")
        self.server.gui.configure_theme(show_share_button=False)  # no public tunnel: offline
        self.scene = SceneView(self.server, session)  # type: ignore[arg-type]
        gui = self.server.gui
        s = session
        self.play_button = gui.add_button("Play", icon=viser.Icon.PLAYER_PLAY)
        self.play_button.on_click(lambda _: s.play())
        self.pause_button = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE)
        self.pause_button.on_click(lambda _: s.pause())
        self.speed = gui.add_dropdown("speed", tuple(REPLAY_SPEEDS), initial_value="real time")
        self.speed.on_update(lambda _: setattr(s, "speed", REPLAY_SPEEDS[self.speed.value]))
        span = max(s.end_s - s.start_s, 1e-3)
        self.slider = gui.add_slider(
            "time (s)", min=s.start_s, max=s.start_s + span, step=0.01, initial_value=s.t_s
        )
        self._setting = False
        self.slider.on_update(self._slider_moved)
        self.readout = gui.add_markdown("")
        beams = gui.add_checkbox("beams", initial_value=True)
        beams.on_update(lambda _: setattr(self.scene, "show_beams", beams.value))
        trails = gui.add_checkbox("trails", initial_value=True)
        trails.on_update(lambda _: setattr(self.scene, "show_trails", trails.value))
        top = gui.add_button("Top view")
        grid = s.sim.world.grid

        def place_top(event: Any) -> None:
            cam = shapes.camera_top(grid, event.client.camera.fov)
            event.client.camera.position = cam.position
            event.client.camera.look_at = cam.look_at

        top.on_click(place_top)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _slider_moved(self, _event: Any) -> None:
        if not self._setting:
            self.session.pause()
            self.session.seek(float(self.slider.value))

    def _loop(self) -> None:
        last = time.perf_counter()
        period = 1.0 / self.fps
        while not self._stop.is_set():
            now = time.perf_counter()
            s = self.session
            if s.advance(now - last) or abs(float(self.slider.value) - s.t_s) > 0.006:
                self._setting = True
                try:
                    self.slider.value = round(s.t_s, 2)
                finally:
                    self._setting = False
            last = now
            self.scene.update()
            states = ", ".join(
                f"{n}: {st}" for n, st in zip(s.history, s.state_names(), strict=True) if st
            )
            self.readout.content = f"t = {s.t_s:.2f} / {s.end_s:.2f} s  \n{states}"
            time.sleep(max(0.0, period - (time.perf_counter() - now)))

    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def url(self) -> str:
        """The address to open, with this launch's token."""
        from agvsim.app.guard import app_url

        return app_url(self.host, self.port, self.guard.token)

    def start(self) -> ReplayApp:
        self._thread = threading.Thread(target=self._loop, daemon=True, name="replay")
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self.server.stop()


def replay(
    path: str | Path,
    host: str = "127.0.0.1",
    port: int = 8080,
    speed: float = 1.0,
    play: bool = True,
    on_ready: Callable[[ReplayApp], None] | None = None,
) -> None:
    """Serve the player until Ctrl-C (or SIGTERM); ``on_ready(app)`` is called once it
    listens."""
    if not speed > 0:
        raise ValueError(f"replay speed must be > 0, got {speed}")
    session = ReplaySession(path)
    session.speed = float(speed)
    app = ReplayApp(session, host, port).start()
    if play:
        session.play()
    run_until_stopped(app, on_ready)
