"""The live simulation behind the browser app, with no browser in it.

A ``Session`` owns the scenario being edited (a plain dict, validated by the scenario schema on
every change), the running ``Simulation`` and the run controls. Every method is safe to call
from any thread (the viewer's GUI callbacks arrive on the server's threads, the stepping runs on
its own): one lock guards the simulation. Nothing here imports the viewer, so the whole app
logic is tested without a browser.

Editing a robot ("apply" in the mask) rebuilds the simulation from the edited scenario and
carries over the live state of every *other* robot (``Simulation.carry_over``: pose, motion,
wheels, steering, odometry, counters) and the clock; the edited robot restarts at the pose
given in the mask. Editing the maze changes the live simulation in place.

"Record video" (``start_video``) writes ``top.mp4`` and one MP4 per onboard camera, as
``agvsim run --video`` does, into a new folder ``<out_dir>/video_<k>``, a frame every 1/25 s of
*simulated* time from the step loop (paused: no frames); ``stop_video`` finishes the files.
"""

from __future__ import annotations

import copy
import tempfile
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from agvsim.app import uploads
from agvsim.app.placement import place_clear
from agvsim.control.teleop import Teleop
from agvsim.control.traffic import StaticMap, refresh_static
from agvsim.scenario import Scenario, ScenarioError, build, load_scenario, parse_scenario
from agvsim.sim.engine import ControllerError, Simulation
from agvsim.world import loaders, mazes
from agvsim.world.grid import OccupancyGrid

if TYPE_CHECKING:
    from agvsim.viz.video import VideoRecorder

#: where "Record video" writes by default (``agvsim serve --out``)
DEFAULT_OUT = Path("runs/app")
#: run speeds offered by the app: label -> simulated seconds per wall-clock second
SPEEDS: dict[str, float | None] = {"real time": 1.0, "x2": 2.0, "x10": 10.0, "max": None}
#: seconds of history kept for the live plots, and samples of trail kept per robot
PLOT_WINDOW_S = 10.0
TRAIL_POINTS = 4000
KEY_STEP = {"linear": 0.1, "lateral": 0.1, "turn": 0.25}  # per key press: m/s, m/s, rad/s
KEY_LIMIT = {"linear": 2.0, "lateral": 2.0, "turn": 3.0}


class EditError(ValueError):
    """An edit the app refuses; the message is shown in the panel as it is."""


@dataclass
class History:
    """Recent samples of one robot for the plots: time, wheel speeds, body twist."""

    t: deque = field(default_factory=lambda: deque(maxlen=2000))
    wheels: deque = field(default_factory=lambda: deque(maxlen=2000))
    twist: deque = field(default_factory=lambda: deque(maxlen=2000))
    trail: deque = field(default_factory=lambda: deque(maxlen=TRAIL_POINTS))


class Session:
    """A scenario being run and edited. ``layout`` increases whenever the set of robots, their
    build or the world changes, so a viewer knows when to rebuild its scene."""

    def __init__(
        self,
        scenario: Scenario,
        source: str = "scenario",
        allow_python: bool = True,
        out_dir: str | Path = DEFAULT_OUT,
    ):
        self.source = source
        self.out_dir = Path(out_dir)  # where "Record video" puts its folders
        self.base_dir = scenario._base_dir
        self.allow_python = allow_python
        self.upload_limits = uploads.UploadLimits()  # agvsim serve --max-upload-mb
        self.config: dict[str, Any] = scenario.model_dump(mode="json", exclude_unset=True)
        # python controllers run only as the command-line scenario names them (file, name)
        self._trusted_python = (
            {
                (r.controller.file, r.controller.name)
                for r in scenario.robots
                if r.controller.type == "python"
            }
            if allow_python
            else set()
        )
        self.lock = threading.RLock()
        self.playing = False
        self.speed_label = "real time"
        self.error: str | None = None  # the last controller error (the run pauses on it)
        self.layout = 0
        self.world_version = 0
        self.keyboard_robot: str | None = None
        self._saved_controller: dict[str, Any] | None = None
        self._key_twist = np.zeros(3)
        self._budget_s = 0.0
        self.sim: Simulation = self._build(self.config)
        self._slams: dict[str, Any] = {}
        self._slam_sim: Simulation | None = None
        self.video: VideoRecorder | None = None  # while recording
        self.video_error: str | None = None
        self._reset_history()

    # ------------------------------------------------------------------ building
    def _scenario(self, cfg: dict[str, Any]) -> Scenario:
        sc = parse_scenario(copy.deepcopy(cfg), self.source)
        sc._base_dir = self.base_dir
        sc._source = self.source
        self._refuse_python(sc, self.source, self._trusted_python)
        return sc

    @staticmethod
    def _refuse_python(sc: Scenario, source: str, trusted: set[tuple[str, str]]) -> None:
        for r in sc.robots:
            c = r.controller
            if c.type == "python" and (c.file, c.name) not in trusted:
                raise ScenarioError(
                    source,
                    [
                        f"robot {r.name!r}: python controllers cannot come from the browser; "
                        "only those of the scenario given on the command line run"
                    ],
                )

    def _build(self, cfg: dict[str, Any]) -> Simulation:
        return build(self._scenario(cfg))

    def _reset_history(self) -> None:
        self.history = {r.name: History() for r in self.sim.robots}
        self._sample()

    def _replace(self, cfg: dict[str, Any], fresh: set[str] = frozenset()) -> list[str]:  # type: ignore[assignment]
        """Rebuild from ``cfg``; robots not in ``fresh`` keep their live state, those in
        ``fresh`` start at their initial pose if it is free, else at the nearest free pose.
        Returns a note for each fresh robot placed elsewhere."""
        new = self._build(cfg)
        old = {r.name: j for j, r in enumerate(self.sim.robots)}
        rows = {i: old[r.name] for i, r in enumerate(new.robots) if r.name in old}
        new.carry_over(
            self.sim.state, {i: j for i, j in rows.items() if new.robots[i].name not in fresh}
        )
        notes = []
        for i, r in enumerate(new.robots):
            if r.name in fresh:
                note = place_clear(new, i)
                if note:
                    notes.append(note)
        new.sense_now()
        self.config, self.sim = cfg, new
        old_hist = self.history
        self.history = {
            r.name: (History() if r.name in fresh else old_hist.get(r.name, History()))
            for r in new.robots
        }
        self.layout += 1
        return notes

    # ------------------------------------------------------------------ run controls
    def play(self) -> None:
        with self.lock:
            self.playing, self.error = True, None
            self._budget_s = 0.0

    def pause(self) -> None:
        with self.lock:
            self.playing = False

    def set_speed(self, label: str) -> None:
        if label not in SPEEDS:
            raise EditError(f"unknown speed {label!r}; choose one of {', '.join(SPEEDS)}")
        with self.lock:
            self.speed_label, self._budget_s = label, 0.0

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps now (the single-step button), playing or not."""
        with self.lock:
            for _ in range(n):
                if not self._step_once():
                    break

    def reset(self) -> None:
        """Back to the scenario's initial poses and t = 0 (edits are kept)."""
        with self.lock:
            self.sim = self._build(self.config)
            self.error = None
            self.layout += 1
            self._reset_history()

    def close(self) -> None:
        """Release what the session holds (app.fleet_view.FleetSession: its MQTT links)."""

    def _step_once(self) -> bool:
        self._feed_keyboard()
        try:
            self.sim.step()
        except ControllerError as err:
            self.playing, self.error = False, str(err)
            return False
        self._slam_update()
        self._sample()
        if self.video is not None:
            self._record_video()
        return True

    # ------------------------------------------------------------------ video
    def start_video(self, fps: float = 25.0, width_px: int = 720) -> Path:
        """Start recording MP4s of the run (top view, each onboard camera) into a new folder
        ``<out_dir>/video_<k>``; returns the folder. Refused while recording."""
        from agvsim.viz.video import VideoRecorder

        with self.lock:
            if self.video is not None:
                raise EditError(f"already recording into {self.video.out}; stop it first")
            k = 1
            while (self.out_dir / f"video_{k}").exists():
                k += 1
            folder = self.out_dir / f"video_{k}"
            try:
                self.video = VideoRecorder(self.sim, folder, fps=fps, width_px=width_px)
            except (OSError, RuntimeError) as err:
                raise EditError(f"cannot record video into {folder}: {err}") from None
            self.video_error = None
            return folder

    def stop_video(self) -> list[Path]:
        """Finish the video files (the frames still due are written first); returns their
        paths (empty when not recording)."""
        with self.lock:
            video, self.video = self.video, None
            if video is None:
                return []
            try:
                video.close()
            except (OSError, RuntimeError, ValueError) as err:
                self.video_error = f"video: {err}"
            return video.paths

    def video_status(self) -> tuple[Path, int, float] | None:
        """(folder, frames written, seconds of video) while recording, else None."""
        with self.lock:
            v = self.video
            return None if v is None else (v.out, v.frames, v.seconds)

    def _record_video(self) -> None:
        video = self.video
        if video is None:
            return
        try:
            video.follow(self.sim)  # a rebuilt simulation (edit, reset) carries on
            video.record()
        except (OSError, RuntimeError, ValueError) as err:  # e.g. a full disk, ffmpeg gone
            self.stop_video()
            self.video_error = f"video stopped: {err}"

    # ------------------------------------------------------------------ online SLAM
    def _slam_update(self) -> None:
        """Feed the robots' ``slam:`` blocks (rebuilt whenever the simulation is rebuilt)."""
        if self._slam_sim is not self.sim:
            self._slam_sim, self._slams = self.sim, {}
            if any(r.get("slam") for r in self.config.get("robots", [])):
                from agvsim.online_slam import build_online_slams

                try:
                    slams = build_online_slams(self._scenario(self.config), self.sim)
                except (ValueError, ScenarioError) as err:
                    self.error = f"slam: {err}"
                    return
                self._slams = {o.name: o for o in slams}
        for o in self._slams.values():
            o.update()

    def slam_map(self, name: str) -> tuple[np.ndarray, float, tuple[float, float]] | None:
        """The live SLAM map of robot ``name`` as ``(0 occupied .. 1 free, row 0 north; unknown
        0.5), resolution, lower-left corner)``, or None when it runs no SLAM (yet)."""
        with self.lock:
            o = self._slams.get(name) if self._slam_sim is self.sim else None
            grid = None if o is None else o.live_map()
        if grid is None:
            return None
        free = 1.0 - grid.probability[::-1]
        free[grid.logodds[::-1] == 0] = 0.5
        return free, grid.resolution_m, grid.origin_xy_m

    def advance(self, wall_dt_s: float, max_work_s: float = 0.03) -> int:
        """Called by the stepping thread: run the steps due after ``wall_dt_s`` of wall time at
        the chosen speed, spending at most ``max_work_s`` of work. Returns steps taken."""
        with self.lock:
            if not self.playing:
                return 0
            speed = SPEEDS[self.speed_label]
            dt = self.sim.dt_s
            if speed is not None:
                # never bank more than a quarter second: a stall must not cause a burst
                self._budget_s = min(self._budget_s + wall_dt_s * speed, 0.25 * speed)
            t0, taken = time.perf_counter(), 0
            while speed is None or self._budget_s >= dt * (1.0 - 1e-9):
                if not self._step_once():
                    break
                taken += 1
                if speed is not None:
                    self._budget_s -= dt
                if time.perf_counter() - t0 > max_work_s:
                    break
            return taken

    def _sample(self) -> None:
        st = self.sim.state
        k = st.step
        every = max(1, int(round(0.05 / self.sim.dt_s)))  # plots at 20 Hz of sim time
        if k % every:
            return
        for i, r in enumerate(self.sim.robots):
            h = self.history.get(r.name)
            if h is None:
                continue
            h.t.append(st.t_s)
            h.wheels.append(st.wheel_speeds[i].copy())
            h.twist.append(st.twists[i].copy())
            h.trail.append((float(st.poses[i, 0]), float(st.poses[i, 1])))

    # ------------------------------------------------------------------ robots
    def robot_names(self) -> list[str]:
        with self.lock:
            return [r["name"] for r in self.config["robots"]]

    def robot_config(self, name: str) -> dict[str, Any]:
        with self.lock:
            return copy.deepcopy(self.config["robots"][self._index(name)])

    def _index(self, name: str) -> int:
        for k, r in enumerate(self.config["robots"]):
            if r["name"] == name:
                return k
        raise EditError(f"no robot named {name!r}; robots: {self.robot_names()}")

    def apply_robot(self, name: str, robot: dict[str, Any]) -> str:
        """Replace robot ``name`` with ``robot`` (the mask's "apply"): validated like a scenario
        file, the robot rebuilt at ``robot['pose']`` (or, where another robot or a wall is in
        the way now, at the nearest free pose), the others carry on. Returns what was done, to
        show the user. Raises ScenarioError with the validation messages; nothing changes
        then."""
        with self.lock:
            cfg = copy.deepcopy(self.config)
            k = self._index(name)
            cfg["robots"][k] = copy.deepcopy(robot)
            if self.keyboard_robot == name and robot.get("name") != name:
                raise EditError("stop keyboard driving before renaming this robot")
            new_name = robot.get("name", name)
            notes = self._replace(cfg, fresh={new_name})
            return "applied: " + ("; ".join(notes) if notes else f"{new_name} at its initial pose")

    def add_robot(self, model: str, x_m: float, y_m: float, theta_deg: float = 0.0) -> str:
        """A new robot of ``model`` with the four rangers and the thesis avoidance."""
        with self.lock:
            names = set(self.robot_names())
            n = 1
            while f"{model}_{n}" in names:
                n += 1
            name = f"{model}_{n}"
            cfg = copy.deepcopy(self.config)
            cfg["robots"].append(
                {
                    "name": name,
                    "model": model,
                    "pose": {"x_m": x_m, "y_m": y_m, "theta_deg": theta_deg},
                    "color": PALETTE[len(cfg["robots"]) % len(PALETTE)],
                    "sensors": [{"type": "rangers"}],
                    "controller": {"type": "avoid"},
                }
            )
            self._replace(cfg, fresh={name})
            return name

    def remove_robot(self, name: str) -> None:
        with self.lock:
            if len(self.config["robots"]) == 1:
                raise EditError("a scenario needs at least one robot; add another first")
            cfg = copy.deepcopy(self.config)
            del cfg["robots"][self._index(name)]
            for r in cfg["robots"]:
                if name in r.get("knows", []):
                    r["knows"] = [o for o in r["knows"] if o != name]
            if self.keyboard_robot == name:
                self.keyboard_robot, self._saved_controller = None, None
            self._replace(cfg)

    def free_spot(self, seed: int = 0) -> tuple[float, float]:
        """The centre of a free cell with free neighbours (for new robots), or ValueError."""
        with self.lock:
            g = self.sim.world.grid
            occ = g.occupied
            free = ~occ
            ok = free.copy()
            ok[1:, :] &= free[:-1, :]
            ok[:-1, :] &= free[1:, :]
            ok[:, 1:] &= free[:, :-1]
            ok[:, :-1] &= free[:, 1:]
            rows, cols = np.nonzero(ok)
            if len(rows) == 0:
                raise EditError("no free spot in the map for a new robot")
            fp = self.sim.footprints(self.sim.state.poses)
            rng = np.random.default_rng(seed)
            for k in rng.permutation(len(rows)):
                x, y = g.cell_center(rows[k], cols[k])
                if np.all(np.hypot(fp[:, 0] - x, fp[:, 1] - y) > 1.5):
                    return float(x), float(y)
            raise EditError("no free spot away from the other robots")

    # ------------------------------------------------------------------ keyboard driving
    def set_keyboard(self, name: str | None) -> None:
        """Drive robot ``name`` from the keyboard (its controller is swapped for a teleop
        controller until keyboard driving stops); ``None`` gives it its controller back."""
        with self.lock:
            cfg = copy.deepcopy(self.config)
            if self.keyboard_robot is not None:
                k = self._index(self.keyboard_robot)
                cfg["robots"][k]["controller"] = self._saved_controller or {"type": "idle"}
            prev, self.keyboard_robot = self.keyboard_robot, None
            self._key_twist[:] = 0.0
            if name is not None:
                k = self._index(name)
                self._saved_controller = cfg["robots"][k].get("controller", {"type": "idle"})
                cfg["robots"][k]["controller"] = {"type": "teleop", "clock": "wall"}
            try:
                self._replace(cfg)
            except ScenarioError:
                self.keyboard_robot = prev
                raise
            self.keyboard_robot = name

    def key(self, name: str) -> tuple[float, float, float]:
        """One key press for the keyboard robot: up/down add forward speed, left/right turn
        rate, q/e sideways speed (holonomic robots), space stops. The command holds until the
        next key (the app stops it when its browser tab goes away)."""
        k = name.strip().lower()
        k = {"w": "up", "s": "down", "a": "left", "d": "right", " ": "space", "x": "space"}.get(
            k, k.removeprefix("arrow")
        )
        steps = {
            "up": (0, KEY_STEP["linear"]),
            "down": (0, -KEY_STEP["linear"]),
            "q": (1, KEY_STEP["lateral"]),
            "e": (1, -KEY_STEP["lateral"]),
            "left": (2, KEY_STEP["turn"]),
            "right": (2, -KEY_STEP["turn"]),
        }
        with self.lock:
            if k == "space":
                self._key_twist[:] = 0.0
            elif k in steps:
                axis, step = steps[k]
                lim = (KEY_LIMIT["linear"], KEY_LIMIT["lateral"], KEY_LIMIT["turn"])[axis]
                self._key_twist[axis] = float(np.clip(self._key_twist[axis] + step, -lim, lim))
                self._key_twist[axis] = round(self._key_twist[axis], 6)
            else:
                raise EditError(f"unknown key {name!r}; use arrows/WASD, q/e and space")
            return tuple(float(v) for v in self._key_twist)  # type: ignore[return-value]

    def stop_keyboard_motion(self) -> None:
        with self.lock:
            self._key_twist[:] = 0.0

    def _teleop(self) -> Teleop | None:
        if self.keyboard_robot is None:
            return None
        i = self.sim.robot_index(self.keyboard_robot)
        for b in self.sim.bindings:
            if i in b.robots and isinstance(b.controller, Teleop):
                return b.controller
        return None

    def _feed_keyboard(self) -> None:
        tele = self._teleop()
        if tele is not None:
            vx, vy, om = self._key_twist
            if vx == vy == om == 0.0:
                tele.stop()
            else:
                tele.set_twist(vx, vy, om)

    def move_robot(self, name: str, x_m: float, y_m: float) -> str:
        """Put robot ``name`` (heading kept) at the free pose nearest to (x, y) now, as the
        app's "place robots" click does; its initial pose stays. Returns what was done."""
        from agvsim.app.placement import MAX_SEARCH_M, nearest_free_pose

        with self.lock:
            i = self.sim.robot_index(name)
            th = float(self.sim.state.poses[i, 2])
            spot = nearest_free_pose(self.sim, i, (float(x_m), float(y_m), th))
            if spot is None:
                raise EditError(f"no free place for {name} within {MAX_SEARCH_M:g} m of that point")
            self.sim.place(i, spot)
            self.sim.sense_now()
            h = self.history.get(name)
            if h is not None:
                h.trail.clear()
            return f"{name} placed at ({spot[0]:.2f}, {spot[1]:.2f})"

    # ------------------------------------------------------------------ the maze
    def cell_at(self, x_m: float, y_m: float) -> tuple[int, int] | None:
        with self.lock:
            g = self.sim.world.grid
            r, c = g.cell_of(x_m, y_m)
            r, c = int(r), int(c)
            if 0 <= r < g.rows and 0 <= c < g.cols:
                return r, c
            return None

    def toggle_cell(self, row: int, col: int) -> bool:
        """Flip one cell; returns whether it is now a wall. Refused under a robot."""
        with self.lock:
            g = self.sim.world.grid
            if not (0 <= row < g.rows and 0 <= col < g.cols):
                raise EditError(f"cell ({row}, {col}) is outside the {g.rows} x {g.cols} map")
            wall = not bool(g.occupied[row, col])
            new = g.with_cell(row, col, wall)
            if wall:
                hit = self.sim.collider.__class__(new).hit_walls(
                    self.sim.footprints(self.sim.state.poses)
                )
                if hit.any():
                    who = [r.name for r, h in zip(self.sim.robots, hit, strict=True) if h]
                    raise EditError(f"cell ({row}, {col}) is under robot {who[0]!r}")
            self._set_grid(new)
            return wall

    def set_grid(self, grid: OccupancyGrid, move_robots: bool = True) -> None:
        """A whole new map (random maze, loaded file). Robots whose start or current pose is
        now inside a wall are moved to free cells."""
        with self.lock:
            self._set_grid(grid)
            if move_robots:
                self._unstick_robots()

    def random_maze(self, rows: int, cols: int, seed: int) -> None:
        with self.lock:
            res = self.sim.world.grid.resolution_m
            cells = max(1, int(round(1.0 / res))) if res < 1 else 1
            try:
                g = mazes.random_maze(
                    rows, cols, seed, corridor_cells=2 * cells, wall_cells=cells, resolution_m=res
                )
            except ValueError as err:
                raise EditError(f"random maze: {err}") from None
            self.set_grid(g)

    def _set_grid(self, grid: OccupancyGrid) -> None:
        self.sim.set_grid(grid)
        # the behaviours tell robots from walls with a distance field of the walls: renew it
        refresh_static(self.sim.bindings, StaticMap.of(grid, self.sim.world.boxes))
        self.config = {**self.config, "world": _world_with_grid(self.config["world"], grid)}
        self.world_version += 1

    def _unstick_robots(self) -> None:
        sim = self.sim
        fp = sim.footprints(sim.state.poses)
        stuck = sim.collider.hit_walls(fp)
        cfg = copy.deepcopy(self.config)
        moved = False
        for i, r in enumerate(sim.robots):
            rc = cfg["robots"][i]
            x0, y0, th0 = r.initial_pose
            at_start = sim.state.poses.copy()
            at_start[i] = (x0, y0, th0)
            start_bad = bool(sim.collider.hit_walls(sim.footprints(at_start))[i])
            if stuck[i] or start_bad:
                x, y = self.free_spot(seed=i + 17 * self.world_version)
                sim.place(i, (x, y, sim.state.poses[i, 2]))
                fp = sim.footprints(sim.state.poses)
                if start_bad:
                    rc["pose"] = {**rc.get("pose", {}), "x_m": x, "y_m": y}
                    moved = True
        if moved:
            self._replace(cfg)

    def save_grid(self, fmt: str) -> tuple[str, bytes]:
        """The map as a file to download: (file name, bytes) for fmt txt, csv or png."""
        savers = {"txt": loaders.save_text, "csv": loaders.save_csv, "png": loaders.save_png}
        if fmt not in savers:
            raise EditError(f"unknown map format {fmt!r}; choose txt, csv or png")
        with self.lock:
            grid = self.sim.world.grid
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"maze.{fmt}"
            savers[fmt](grid, path)
            return path.name, path.read_bytes()

    def load_grid(self, name: str, content: bytes) -> None:
        """A map file sent from the browser (txt, csv, png, pgm): read as data, never run."""
        self.upload_limits.check_size(name, len(content))
        suffix = Path(name).suffix.lower()
        if suffix not in (".txt", ".csv", ".png", ".pgm"):
            raise EditError(f"{name}: maps load from .txt, .csv, .png or .pgm files")
        with self.lock:
            res = self.sim.world.grid.resolution_m
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / Path(name).name
            path.write_bytes(content)
            try:
                grid = loaders.load_map(path, resolution_m=res)
            except (loaders.MapFormatError, ValueError) as err:
                raise EditError(str(err).replace(str(path), name)) from None
        self.set_grid(grid)

    # ------------------------------------------------------------------ scenario files
    def scenario_yaml(self) -> str:
        """The current setup (edits included) as a scenario file."""
        with self.lock:
            cfg = copy.deepcopy(self.config)
        if self.keyboard_robot is not None and self._saved_controller is not None:
            k = [r["name"] for r in cfg["robots"]].index(self.keyboard_robot)
            cfg["robots"][k]["controller"] = self._saved_controller
        return yaml.dump(cfg, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=100)

    def load_yaml(self, text: str, source: str = "uploaded scenario.yaml") -> None:
        """Replace everything with a scenario file's content (see :meth:`load_upload`)."""
        name = source if source.lower().endswith(uploads.SCENARIO_SUFFIXES) else "scenario.yaml"
        self.load_upload(name, text.encode("utf-8"))

    def load_upload(self, name: str, content: bytes) -> None:
        """Replace everything with a scenario sent from the browser: a YAML file, or a .zip
        of a scenario and its map files (agvsim.app.uploads). It is parsed as data by the
        scenario loader, with its limits; it may read only the files sent with it and run no
        python controller. A refused upload raises (ScenarioError, UploadError) and leaves
        the running simulation as it was; it is checked and built before the lock is taken,
        so the simulation runs on meanwhile."""
        bundle = uploads.unpack(name, content, self.upload_limits)
        with tempfile.TemporaryDirectory(prefix="agvsim-upload-") as tmp:
            folder = Path(tmp)
            path = bundle.write(folder)

            def hide(problems: list[str]) -> list[str]:  # no server path in a message
                return [p.replace(f"{folder}/", "").replace(str(folder), ".") for p in problems]

            try:
                # its limits: block may lower the limits, never raise them
                sc = load_scenario(path, limits_from_file=False)
                uploads.check_references(sc.world.file, bundle)
                self._refuse_python(sc, bundle.scenario, set())  # nothing from a browser runs
                sim = build(sc)
            except ScenarioError as err:
                raise ScenarioError(bundle.scenario, hide(err.problems)) from None
            except uploads.UploadError:
                raise
            except (ControllerError, ValueError, RecursionError) as err:  # data a parser choked on
                problem = f"cannot be loaded: {type(err).__name__}: {err}"
                raise ScenarioError(bundle.scenario, hide([problem])) from None
        config: dict[str, Any] = sc.model_dump(mode="json", exclude_unset=True)
        if sc.world.file is not None:  # the map is part of the scenario now: no file kept
            config["world"] = _world_with_grid(config["world"], sim.world.grid)
        with self.lock:
            self.source, self._trusted_python = bundle.scenario, set()
            self.config, self.sim = config, sim
            self.keyboard_robot, self._saved_controller = None, None
            self.playing, self.error = False, None
            self.layout += 1
            self.world_version += 1
            self._reset_history()


def _world_with_grid(world: dict[str, Any], grid: OccupancyGrid) -> dict[str, Any]:
    """A world config whose map is ``grid``, written inline as a text picture."""
    out = dict(world)
    for k in ("maze", "matrix", "picture", "file", "random"):
        out.pop(k, None)
    out["picture"] = loaders.format_text_picture(grid)
    out["cell_size_m"] = grid.resolution_m
    out["origin_xy_m"] = list(grid.origin_xy_m)
    return out


PALETTE = ["#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"]


class _Dumper(yaml.SafeDumper):
    """Multi-line strings (the maze picture) as literal blocks."""


def _str_presenter(dumper: yaml.SafeDumper, data: str) -> yaml.Node:
    style = "|" if "\n" in data else None
    return dumper.represent_scalar("tag:yaml.org,2002:str", data, style=style)


_Dumper.add_representer(str, _str_presenter)
