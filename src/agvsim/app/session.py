"""The live simulation behind the browser app, with no browser in it.

A ``Session`` owns the scenario being edited (a plain dict, validated by the scenario schema on
every change), the running ``Simulation`` and one lock that guards both: every method is safe
to call from any thread (the viewer's GUI callbacks arrive on the server's threads, the
stepping runs on its own). Nothing here imports the viewer, so the whole app logic is tested
without a browser. Its parts, each in its own module:

* run control and pacing (:mod:`agvsim.app.run_control`): play, pause, speed, steps due;
* editing (:mod:`agvsim.app.editing`): robots, the maze, map and scenario files, as functions
  of the config that the session applies by rebuilding (:meth:`Session._replace`) or by
  changing the live simulation (the maze);
* keyboard driving (:mod:`agvsim.app.keyboard`);
* recording (:mod:`agvsim.app.recording`): the plots' history, online SLAM and "Record
  video", observers of the step loop (agvsim.run_loop);
* what the panel shows (:mod:`agvsim.app.view`): immutable snapshots built under the lock.

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
import threading
from pathlib import Path
from typing import Any

import numpy as np

from agvsim.app import editing, uploads
from agvsim.app.editing import PALETTE, EditError
from agvsim.app.keyboard import KEY_LIMIT, KEY_STEP, Keyboard, UnknownKey
from agvsim.app.placement import place_clear
from agvsim.app.recording import PLOT_WINDOW_S, TRAIL_POINTS, Histories, History, LiveSlam, Video
from agvsim.app.recording import free_map as _free_map
from agvsim.app.run_control import SPEEDS, RunControl
from agvsim.app.view import SessionView, session_view
from agvsim.control.traffic import StaticMap, refresh_static
from agvsim.run_loop import Observer, notify
from agvsim.scenario import Scenario, build, parse_scenario
from agvsim.scenario_schema import PythonControllerConfig
from agvsim.sim.engine import ControllerError, Simulation
from agvsim.world.grid import OccupancyGrid

__all__ = [
    "DEFAULT_OUT",
    "KEY_LIMIT",
    "KEY_STEP",
    "PALETTE",
    "PLOT_WINDOW_S",
    "SPEEDS",
    "TRAIL_POINTS",
    "EditError",
    "History",
    "Session",
]

#: where "Record video" writes by default (``agvsim serve --out``)
DEFAULT_OUT = Path("runs/app")


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
                if isinstance(r.controller, PythonControllerConfig)
            }
            if allow_python
            else set()
        )
        self.lock = threading.RLock()
        self.run = RunControl()
        self.keyboard = Keyboard()
        self.layout = 0
        self.world_version = 0
        self.sim: Simulation = self._build(self.config)
        self.slam = LiveSlam(
            lambda: self._scenario(self.config),
            lambda: any(r.get("slam") for r in self.config.get("robots", [])),
            self._report,
        )
        self.histories = Histories(self.sim)
        self.video = Video(self.out_dir)
        # the step loop's observers, in order (agvsim.run_loop)
        self.observers: list[Observer] = [self.slam, self.histories, self.video]

    # ------------------------------------------------------------------ the parts' state
    @property
    def playing(self) -> bool:
        return self.run.playing

    @property
    def speed_label(self) -> str:
        return self.run.speed_label

    @property
    def error(self) -> str | None:
        """The last controller (or SLAM) error; the run pauses on a controller error."""
        return self.run.error

    @property
    def keyboard_robot(self) -> str | None:
        return self.keyboard.robot

    @property
    def history(self) -> dict[str, History]:
        """Each robot's recent samples (plots, trails)."""
        return self.histories.by_robot

    @property
    def video_error(self) -> str | None:
        return self.video.error

    def view(self, selected: str | None) -> SessionView:
        """What the panel shows now (the run, robot ``selected``): an immutable snapshot."""
        with self.lock:
            return session_view(self, selected)

    # ------------------------------------------------------------------ building
    def _scenario(self, cfg: dict[str, Any]) -> Scenario:
        sc = parse_scenario(copy.deepcopy(cfg), self.source)
        sc._base_dir = self.base_dir
        sc._source = self.source
        editing.refuse_python(sc, self.source, self._trusted_python)
        return sc

    def _build(self, cfg: dict[str, Any]) -> Simulation:
        return build(self._scenario(cfg))

    def _report(self, error: str) -> None:
        self.run.error = error

    def _replace(self, cfg: dict[str, Any], fresh: set[str] = frozenset()) -> list[str]:  # type: ignore[assignment]
        """Rebuild from ``cfg``; robots not in ``fresh`` keep their live state, those in
        ``fresh`` start at their initial pose if it is free, else at the nearest free pose.
        Returns a note for each fresh robot placed elsewhere."""
        new = self._build(cfg)
        old = {r.name: j for j, r in enumerate(self.sim.robots)}
        rows = {
            i: old[r.name]
            for i, r in enumerate(new.robots)
            if r.name in old and r.name not in fresh
        }
        new.carry_over(self.sim.state, rows)
        notes = []
        for i, r in enumerate(new.robots):
            if r.name in fresh:
                note = place_clear(new, i)
                if note:
                    notes.append(note)
        new.sense_now()
        self.config, self.sim = cfg, new
        self.histories.rebuilt(new, fresh)
        self.layout += 1
        return notes

    # ------------------------------------------------------------------ run controls
    def play(self) -> None:
        with self.lock:
            self.run.play()

    def pause(self) -> None:
        with self.lock:
            self.run.pause()

    def set_speed(self, label: str) -> None:
        if label not in SPEEDS:
            raise EditError(f"unknown speed {label!r}; choose one of {', '.join(SPEEDS)}")
        with self.lock:
            self.run.set_speed(label)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps now (the single-step button), playing or not."""
        with self.lock:
            for _ in range(n):
                if not self._step_once():
                    break

    def advance(self, wall_dt_s: float, max_work_s: float = 0.03) -> int:
        """Called by the stepping thread: run the steps due after ``wall_dt_s`` of wall time at
        the chosen speed, spending at most ``max_work_s`` of work. Returns steps taken."""
        with self.lock:
            return self.run.advance(self.sim.dt_s, wall_dt_s, self._step_once, max_work_s)

    def reset(self) -> None:
        """Back to the scenario's initial poses and t = 0 (edits are kept)."""
        with self.lock:
            self.sim = self._build(self.config)
            self.run.error = None
            self.layout += 1
            self.histories.restart(self.sim)

    def close(self) -> None:
        """Release what the session holds (app.fleet_view.FleetSession: its MQTT links)."""

    def _step_once(self) -> bool:
        self.keyboard.feed(self.sim)
        try:
            self.sim.step()
        except ControllerError as err:
            self.run.failed(str(err))
            return False
        notify(self.observers, self.sim)
        return True

    # ------------------------------------------------------------------ recording
    def start_video(self, fps: float = 25.0, width_px: int = 720) -> Path:
        """Start recording MP4s of the run (top view, each onboard camera) into a new folder
        ``<out_dir>/video_<k>``; returns the folder. Refused while recording."""
        with self.lock:
            if self.video.recorder is not None:
                raise EditError(f"already recording into {self.video.recorder.out}; stop it first")
            folder = self.video.next_folder()
            try:
                self.video.start(self.sim, folder, fps, width_px)
            except (OSError, RuntimeError) as err:
                raise EditError(f"cannot record video into {folder}: {err}") from None
            return folder

    def stop_video(self) -> list[Path]:
        """Finish the video files (the frames still due are written first); returns their
        paths (empty when not recording)."""
        with self.lock:
            return self.video.stop()

    def video_status(self) -> tuple[Path, int, float] | None:
        """(folder, frames written, seconds of video) while recording, else None."""
        with self.lock:
            return self.video.status()

    def slam_map(self, name: str) -> tuple[np.ndarray, float, tuple[float, float]] | None:
        """The live SLAM map of robot ``name`` as ``(0 occupied .. 1 free, row 0 north; unknown
        0.5), resolution, lower-left corner)``, or None when it runs no SLAM (yet)."""
        with self.lock:
            grid = self.slam.live_map(self.sim, name)
        return None if grid is None else _free_map(grid)

    # ------------------------------------------------------------------ robots
    def robot_names(self) -> list[str]:
        with self.lock:
            return [r["name"] for r in self.config["robots"]]

    def robot_config(self, name: str) -> dict[str, Any]:
        with self.lock:
            return copy.deepcopy(self.config["robots"][editing.robot_index(self.config, name)])

    def apply_robot(self, name: str, robot: dict[str, Any]) -> str:
        """Replace robot ``name`` with ``robot`` (the mask's "apply"): validated like a scenario
        file, the robot rebuilt at ``robot['pose']`` (or, where another robot or a wall is in
        the way now, at the nearest free pose), the others carry on. Returns what was done, to
        show the user. Raises ScenarioError with the validation messages; nothing changes
        then."""
        with self.lock:
            cfg = editing.with_robot(self.config, name, robot)
            if self.keyboard.robot == name and robot.get("name") != name:
                raise EditError("stop keyboard driving before renaming this robot")
            new_name = robot.get("name", name)
            notes = self._replace(cfg, fresh={new_name})
            return "applied: " + ("; ".join(notes) if notes else f"{new_name} at its initial pose")

    def add_robot(self, model: str, x_m: float, y_m: float, theta_deg: float = 0.0) -> str:
        """A new robot of ``model`` with the four rangers and the thesis avoidance."""
        with self.lock:
            cfg, name = editing.with_new_robot(self.config, model, x_m, y_m, theta_deg)
            self._replace(cfg, fresh={name})
            return name

    def remove_robot(self, name: str) -> None:
        with self.lock:
            cfg = editing.without_robot(self.config, name)
            if self.keyboard.robot == name:
                self.keyboard.forget()
            self._replace(cfg)

    def free_spot(self, seed: int = 0) -> tuple[float, float]:
        """The centre of a free cell with free neighbours (for new robots), or EditError."""
        with self.lock:
            return editing.free_spot(self.sim, seed)

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

    # ------------------------------------------------------------------ keyboard driving
    def set_keyboard(self, name: str | None) -> None:
        """Drive robot ``name`` from the keyboard (its controller is swapped for a teleop
        controller until keyboard driving stops); ``None`` gives it its controller back."""
        with self.lock:
            if name is not None:
                editing.robot_index(self.config, name)  # EditError for an unknown robot
            cfg = copy.deepcopy(self.config)
            saved = self.keyboard.saved_controller
            self.keyboard.swap(cfg["robots"], name)
            try:
                self._replace(cfg)
            except Exception:
                self.keyboard.saved_controller = saved
                raise
            self.keyboard.driving(name)

    def key(self, name: str) -> tuple[float, float, float]:
        """One key press for the keyboard robot: up/down add forward speed, left/right turn
        rate, q/e sideways speed (holonomic robots), space stops. The command holds until the
        next key (the app stops it when its browser tab goes away)."""
        with self.lock:
            try:
                return self.keyboard.key(name)
            except UnknownKey as err:
                raise EditError(str(err)) from None

    def stop_keyboard_motion(self) -> None:
        with self.lock:
            self.keyboard.stop()

    # ------------------------------------------------------------------ the maze
    def cell_at(self, x_m: float, y_m: float) -> tuple[int, int] | None:
        with self.lock:
            return editing.cell_at(self.sim.world.grid, x_m, y_m)

    def toggle_cell(self, row: int, col: int) -> bool:
        """Flip one cell; returns whether it is now a wall. Refused under a robot."""
        with self.lock:
            grid, wall = editing.toggled(self.sim, row, col)
            self._set_grid(grid)
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
            self.set_grid(editing.random_grid(self.sim.world.grid.resolution_m, rows, cols, seed))

    def set_world(self, world: dict[str, Any]) -> None:
        """Rebuild with a new ``world:`` block (the tape brush); the robots keep their live
        state. A world the schema refuses raises ScenarioError and changes nothing."""
        with self.lock:
            self._replace({**self.config, "world": world})
            self.world_version += 1

    def _set_grid(self, grid: OccupancyGrid) -> None:
        self.sim.set_grid(grid)
        # the behaviours tell robots from walls with a distance field of the walls: renew it
        refresh_static(self.sim.bindings, StaticMap.of(grid, self.sim.world.boxes))
        self.config = {**self.config, "world": editing.world_with_grid(self.config["world"], grid)}
        self.world_version += 1

    def _unstick_robots(self) -> None:
        sim = self.sim
        stuck = sim.collider.hit_walls(sim.footprints(sim.state.poses))
        cfg = copy.deepcopy(self.config)
        moved = False
        for i, r in enumerate(sim.robots):
            rc = cfg["robots"][i]
            at_start = sim.state.poses.copy()
            at_start[i] = r.initial_pose
            start_bad = bool(sim.collider.hit_walls(sim.footprints(at_start))[i])
            if stuck[i] or start_bad:
                x, y = editing.free_spot(sim, seed=i + 17 * self.world_version)
                sim.place(i, (x, y, sim.state.poses[i, 2]))
                if start_bad:
                    rc["pose"] = {**rc.get("pose", {}), "x_m": x, "y_m": y}
                    moved = True
        if moved:
            self._replace(cfg)

    # ------------------------------------------------------------------ files
    def save_grid(self, fmt: str) -> tuple[str, bytes]:
        """The map as a file to download: (file name, bytes) for fmt txt, csv or png."""
        with self.lock:
            grid = self.sim.world.grid
        return editing.map_file(grid, fmt)

    def load_grid(self, name: str, content: bytes) -> None:
        """A map file sent from the browser (txt, csv, png, pgm): read as data, never run."""
        self.upload_limits.check_size(name, len(content))
        with self.lock:
            res = self.sim.world.grid.resolution_m
        self.set_grid(editing.read_map(name, content, res))

    def scenario_yaml(self) -> str:
        """The current setup (edits included) as a scenario file."""
        with self.lock:
            cfg = copy.deepcopy(self.config)
            driven, saved = self.keyboard.robot, self.keyboard.saved_controller
        if driven is not None and saved is not None:
            cfg["robots"][editing.robot_index(cfg, driven)]["controller"] = saved
        return editing.scenario_text(cfg)

    def load_yaml(self, text: str, source: str = "uploaded scenario.yaml") -> None:
        """Replace everything with a scenario file's content (see :meth:`load_upload`)."""
        name = source if source.lower().endswith(uploads.SCENARIO_SUFFIXES) else "scenario.yaml"
        self.load_upload(name, text.encode("utf-8"))

    def load_upload(self, name: str, content: bytes) -> None:
        """Replace everything with a scenario sent from the browser (agvsim.app.editing's
        ``read_upload``: parsed as data, it may read only the files sent with it and run no
        python controller). A refused upload raises (ScenarioError, UploadError) and leaves
        the running simulation as it was; it is checked and built before the lock is taken,
        so the simulation runs on meanwhile."""
        source, config, sim = editing.read_upload(name, content, self.upload_limits)
        with self.lock:
            self.source, self._trusted_python = source, set()
            self.config, self.sim = config, sim
            self.keyboard.forget()
            self.run.pause()
            self.run.error = None
            self.layout += 1
            self.world_version += 1
            self.histories.restart(self.sim)
