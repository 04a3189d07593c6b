"""The side panel of the browser app: run controls, video recording, the robot mask, the maze
editor, views, live numbers and plots. Every widget calls into the ``Session``; nothing a
browser sends is run as code (scenario and map files are parsed as data, python controllers are
refused), and an uploaded scenario reads only the files sent with it (agvsim.app.uploads)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import viser

from agvsim.app.drag_place import DragPlace
from agvsim.app.friction_brush import paint_friction
from agvsim.app.mask import Field, MaskError, fields_in_error, mask_fields, robot_from_mask
from agvsim.app.session import SPEEDS, EditError, Session
from agvsim.app.tape_brush import TapeBrush
from agvsim.app.view import RobotView
from agvsim.kinematics import MODELS
from agvsim.scenario import ScenarioError
from agvsim.sim.spec import WALL_HEIGHT_M

VIEWS = ("panoramic", "top plan", "chase")
ONBOARD = "onboard camera"  # offered while the picked robot has a camera
KEYS = {
    "W": "up",
    "arrowup": "up",
    "S": "down",
    "arrowdown": "down",
    "A": "left",
    "arrowleft": "left",
    "D": "right",
    "arrowright": "right",
    "Q": "q",
    "E": "e",
    "space": "space",
}


def _error_md(text: str) -> str:
    lines = [ln.strip().removeprefix("- ") for ln in text.splitlines() if ln.strip()]
    return "\n".join(f"<span style='color:#c0392b'>&#9888; {ln}</span><br/>" for ln in lines)


class Panel:
    """Builds the GUI and keeps it in step with the session (``refresh()`` a few times a
    second)."""

    def __init__(
        self,
        server: viser.ViserServer,
        session: Session,
        scene: Any,
        notify: Callable[[str], None] = print,
    ):
        self.server, self.session, self.scene = server, session, scene
        self.notify = notify  # messages for the console (where videos were saved)
        self._video_saved = ""
        self.selected = session.robot_names()[0]
        self._overlay_due = 0.0
        self.view_of: dict[int, str] = {}  # client id -> view
        self._mask_widgets: dict[str, Any] = {}
        self._mask_hints: dict[str, str | None] = {}
        self._mask_folder: Any = None
        self.apply_msg: Any = None  # the result of Apply, next to the button
        self._apply_button: Any = None
        self._apply_note = ""
        self._plot_layout: tuple | None = None
        self._plot_sent: tuple | None = None  # (layout, last time, samples) the plots show
        self.view_pick: dict[int, Any] = {}  # client id -> its own view dropdown
        # GUI structure changes come from callbacks and from the refresh loop: one at a time
        self._gui_lock = threading.RLock()
        gui = server.gui
        gui.configure_theme(control_width="large", show_logo=False, show_share_button=False)
        tabs = gui.add_tab_group()
        self._run_tab, self._robot_tab = tabs.add_tab("Run"), tabs.add_tab("Robot")
        world_tab = tabs.add_tab("World")
        with self._run_tab:
            self._build_run()
            self.numbers = gui.add_markdown("")
            self.camera_view: Any = None  # the picked robot's camera (thesis Fig. 33)
            self._camera_key: tuple = ()
            self._camera_label = ""
            self.plot_wheels: Any = None
            self.plot_twist: Any = None
        with self._robot_tab:
            self.robot_pick = gui.add_dropdown(
                "robot", tuple(session.robot_names()), initial_value=self.selected
            )
            self.robot_pick.on_update(lambda _: self._select(self.robot_pick.value))
            self._build_robots()
            self.mask_msg = gui.add_markdown("")
            self._mask_anchor = gui.add_markdown("**Mask** (apply rebuilds the robot)")
        self._build_mask(session.robot_config(self.selected))
        with world_tab:
            self._build_files()
            self._build_world()
        self._known_layout = session.layout
        for key, name in KEYS.items():
            cmd = gui.add_command(f"drive: {name}", hotkey=key)  # type: ignore[arg-type]
            cmd.on_trigger(self._key_command(name))

    def _key_command(self, name: str) -> Callable[[Any], None]:
        """The callback of the drive command for key ``name``."""
        return lambda _event: self._key(name)

    # ------------------------------------------------------------------ run tab
    def _build_run(self) -> None:
        gui, s = self.server.gui, self.session
        self.status = gui.add_markdown("")
        self.play = gui.add_button("Play", icon=viser.Icon.PLAYER_PLAY)
        self.play.on_click(lambda _: self._do(s.play))
        self.pause = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE)
        self.pause.on_click(lambda _: self._do(s.pause))
        row = gui.add_button_group("", ("Step", "Step x10", "Reset"))
        row.on_click(
            lambda e: self._do(
                {"Step": lambda: s.step(1), "Step x10": lambda: s.step(10), "Reset": s.reset}[
                    e.target.value
                ]
            )
        )
        self.speed = gui.add_dropdown("speed", tuple(SPEEDS), initial_value=s.speed_label)
        self.speed.on_update(lambda _: self._do(lambda: s.set_speed(self.speed.value)))
        # each browser tab gets its own view dropdown here (add_client)
        self._view_order = gui.add_markdown("").order
        self.keyboard = gui.add_checkbox(
            "drive with keys",
            initial_value=False,
            hint="arrows/WASD add speed and turn rate, Q/E sideways, space stops "
            "(forward mode: the keys set wheel speeds)",
        )
        self.keyboard.on_update(
            lambda _: self._do(
                lambda: s.set_keyboard(self.selected if self.keyboard.value else None)
            )
        )
        self.record_video = gui.add_button(
            "Record video",
            icon=viser.Icon.PLAYER_RECORD,
            hint=f"MP4s of the top view and of each onboard camera, 25 frames per simulated "
            f"second, into a new folder {s.out_dir}/video_<k>",
        )
        self.record_video.on_click(lambda _: self._do(self.start_video))
        self.save_video = gui.add_button(
            "Stop & save video", icon=viser.Icon.PLAYER_STOP, disabled=True
        )
        self.save_video.on_click(lambda _: self._do(self.stop_video))
        self.video_msg = gui.add_markdown("")
        self.run_msg = gui.add_markdown("")

    def _build_robots(self) -> None:
        gui, s = self.server.gui, self.session
        self.new_model = gui.add_dropdown("new robot", tuple(MODELS), initial_value="differential")
        add = gui.add_button("Add robot", icon=viser.Icon.PLUS)
        add.on_click(lambda _: self._do(self._add_robot, self.mask_msg))
        rm = gui.add_button("Remove picked robot", icon=viser.Icon.TRASH)
        rm.on_click(lambda _: self._do(lambda: s.remove_robot(self.selected), self.mask_msg))

    def _build_files(self) -> None:
        gui, s = self.server.gui, self.session
        gui.add_markdown("**Scenario file**")
        save = gui.add_button("Save scenario (YAML)", icon=viser.Icon.DOWNLOAD)
        save.on_click(
            lambda e: _download(e.client, "scenario.yaml", s.scenario_yaml().encode("utf-8"))
        )
        load = gui.add_upload_button(
            "Load scenario",
            icon=viser.Icon.UPLOAD,
            mime_type=".yaml,.yml,.zip",
            hint="a scenario YAML, or a .zip of a scenario and its map files",
        )
        load.on_upload(
            lambda _: self._world_do(lambda: s.load_upload(load.value.name, load.value.content))
        )
        gui.add_markdown("**Show**")
        self.beams = gui.add_checkbox("beams", initial_value=True)
        self.beams.on_update(lambda _: setattr(self.scene, "show_beams", self.beams.value))
        self.trails = gui.add_checkbox("trails", initial_value=True)
        self.trails.on_update(lambda _: setattr(self.scene, "show_trails", self.trails.value))
        self.overlay = gui.add_checkbox("map overlay", initial_value=False)
        self.overlay.on_update(lambda _: self._toggle_overlay())

    def _toggle_overlay(self) -> None:
        self.scene.show_overlay = self.overlay.value
        self._overlay_due = 0.0
        self.scene.set_overlay(None)  # the world's grid until a SLAM map comes

    def _add_robot(self) -> None:
        x, y = self.session.free_spot(seed=len(self.session.robot_names()))
        self.selected = self.session.add_robot(self.new_model.value, x, y)

    def _do(self, fn: Any, where: Any = None) -> None:
        """Run an action; show its refusal in the panel instead of a traceback."""
        where = where or self.run_msg
        where.content = ""
        try:
            fn()
        except ScenarioError as err:
            where.content = _error_md("\n".join(err.problems))
        except (EditError, MaskError, ValueError) as err:
            where.content = _error_md(str(err))

    # ------------------------------------------------------------------ video
    def start_video(self) -> Path:
        folder = self.session.start_video()
        self._video_saved = ""
        self.notify(f"recording video into {folder}")
        self._refresh_video()
        return folder

    def stop_video(self) -> list[Path]:
        status = self.session.video_status()
        paths = self.session.stop_video()
        if paths and status is not None:
            _, frames, secs = status
            names = ", ".join(p.name for p in paths)
            self._video_saved = (
                f"&#10004; saved {secs:.1f} s ({frames} frames): `{paths[0].parent}/` {names}"
            )
            self.notify(f"video saved ({secs:.1f} s): " + ", ".join(str(p) for p in paths))
        self._refresh_video()
        return paths

    def _refresh_video(self) -> None:
        """The record / save buttons and the progress: seconds and frames written so far."""
        status = self.session.video_status()
        recording = status is not None
        if self.record_video.disabled != recording:
            self.record_video.disabled = recording
            self.save_video.disabled = not recording
        if status is not None:
            folder, frames, secs = status
            text = (
                f"<span style='color:#c0392b'>&#9679;</span> recording **{secs:.1f} s** "
                f"({frames} frames) into `{folder}/`"
            )
        else:
            error = self.session.video_error
            text = _error_md(error) if error else self._video_saved
        if self.video_msg.content != text:
            self.video_msg.content = text

    def _key(self, name: str) -> None:
        if self.session.keyboard_robot is None:
            self.run_msg.content = _error_md("tick 'drive with keys' first")
            return
        self.session.key(name)

    # ------------------------------------------------------------------ views
    def views(self) -> tuple[str, ...]:
        """The views a tab can pick: the onboard camera's only while the picked robot has one."""
        return (*VIEWS, ONBOARD) if self._camera_of_selected() is not None else VIEWS

    def _camera_of_selected(self) -> tuple[np.ndarray, Any] | None:
        """(pose, CameraSpec) of the picked robot's first camera, or None."""
        robot = self.session.view(self.selected).robot
        if robot is None or robot.camera is None:
            return None
        return robot.pose, robot.camera

    def add_client(self, client: Any) -> None:
        """A new browser tab: its own view dropdown (starting on the panoramic view, whatever
        other tabs show) in the Run tab."""
        with self._gui_lock, self._run_tab:
            pick = client.gui.add_dropdown(
                "view",
                self.views(),
                initial_value="panoramic",
                hint="this browser tab's view; chase and onboard camera follow the robot "
                "picked in the Robot tab",
                order=self._view_order,
            )
        self.view_pick[client.client_id] = pick
        pick.on_update(lambda _: self._set_view(client, pick.value))
        self._set_view(client, "panoramic")

    def remove_client(self, client_id: int) -> None:
        self.view_of.pop(client_id, None)
        self.view_pick.pop(client_id, None)

    def _refresh_view_options(self) -> None:
        """Offer the onboard camera to every tab while the picked robot has one."""
        views = self.views()
        for cid, pick in list(self.view_pick.items()):
            if tuple(pick.options) != views:
                value = pick.value if pick.value in views else "chase"
                pick.options = views
                pick.value = value
                self.view_of[cid] = value

    def _set_view(self, client: Any, view: str) -> None:
        if client.client_id not in self.server.get_clients():
            return  # the tab has closed
        self.view_of[client.client_id] = view
        from agvsim.app import shapes

        grid = self.session.sim.world.grid
        if view == "panoramic":
            self._place(client, shapes.camera_panoramic(grid))
        elif view == "top plan":
            self._place(client, shapes.camera_top(grid, client.camera.fov))

    def _place(self, client: Any, cam: Any, fov_rad: float | None = None) -> None:
        if client.client_id not in self.server.get_clients():
            return  # closed: nothing may be queued on its connection
        with client.atomic():
            if fov_rad is not None:
                client.camera.fov = fov_rad
            client.camera.up_direction = cam.up
            client.camera.position = cam.position
            client.camera.look_at = cam.look_at

    def follow(self) -> None:
        """Move chase cameras with their robot (every frame)."""
        from agvsim.app import shapes

        clients = self.server.get_clients().values()
        chasers = [c for c in clients if self.view_of.get(c.client_id) == "chase"]
        riders = [c for c in clients if self.view_of.get(c.client_id) == ONBOARD]
        if not chasers and not riders:
            return
        robot = self.session.view(self.selected).robot
        if robot is None:
            return
        cam = shapes.camera_chase(robot.pose)
        for c in chasers:
            self._place(c, cam)
        onboard = self._camera_of_selected()
        for c in riders:
            if onboard is None:
                self._place(c, cam)
                continue
            pose, spec = onboard
            self._place(c, shapes.camera_onboard(pose, spec), fov_rad=spec.vfov_rad)

    # ------------------------------------------------------------------ the mask
    def _select(self, name: str) -> None:
        # the robot list is set again after Apply: picking the robot already picked keeps
        # the mask and Apply's result
        if name not in self.session.robot_names() or name == self.selected:
            return
        self.selected = name
        if getattr(self, "_drag", None) is not None and self._drag.shown:
            self._drag.show(name)  # the drag gizmo moves to the newly picked robot
        self._apply_note = ""
        self._build_mask(self.session.robot_config(name))
        self._plot_layout = None

    def _build_mask(self, robot: dict) -> None:
        with self._gui_lock:
            self._build_mask_locked(robot)

    def _build_mask_locked(self, robot: dict) -> None:
        gui = self.server.gui
        if self._mask_folder is not None:
            # children first: removing a folder first makes the browser drop them with it and
            # then complain about each removal that follows ("non-existent component")
            for handle in (*self._mask_widgets.values(), self._apply_button, self.apply_msg):
                if handle is not None:
                    handle.remove()
            self._mask_folder.remove()
        self._mask_widgets = {}
        self._draft = robot
        order = self._mask_anchor.order + 0.01
        with self._robot_tab, gui.add_folder("mask", order=order) as folder:
            self._mask_folder = folder
            for f in mask_fields(robot, self.session.allow_python, self.session.sim.dt_s):
                self._mask_widgets[f.key] = self._widget(f)
                self._mask_hints[f.key] = f.hint or None
            apply = gui.add_button("Apply", icon=viser.Icon.CHECK)
            apply.on_click(lambda _: self._apply())
            self._apply_button = apply
            self.apply_msg = gui.add_markdown(self._apply_note)
        model = self._mask_widgets["model"]
        model.on_update(lambda _: self._model_changed())

    def _widget(self, f: Field) -> Any:
        gui = self.server.gui
        hint = f.hint or None
        if f.kind == "text":
            return gui.add_text(f.label, initial_value=str(f.value), hint=hint)
        if f.kind == "yaml":
            return gui.add_text(f.label, initial_value=str(f.value), multiline=True, hint=hint)
        if f.kind == "checkbox":
            return gui.add_checkbox(f.label, initial_value=bool(f.value), hint=hint)
        if f.kind == "dropdown":
            opts = f.options if f.value in f.options else (*f.options, f.value)
            return gui.add_dropdown(f.label, opts, initial_value=f.value, hint=hint)
        step = 1 if f.kind == "int" else f.step
        return gui.add_number(f.label, initial_value=f.value, step=step, hint=hint)

    def _values(self) -> dict[str, Any]:
        return {k: w.value for k, w in self._mask_widgets.items()}

    def _model_changed(self) -> None:
        try:
            draft = robot_from_mask(self._draft, self._values(), self.session.sim.dt_s)
        except MaskError as err:
            self.mask_msg.content = _error_md(str(err))
            return
        self._build_mask(draft)

    def _apply(self) -> None:
        """Apply the mask; the result (or the refusal, with the fields in error marked) shows
        under the Apply button (and stays there until the next Apply or another robot)."""
        with self._gui_lock:  # the refresh loop must not rebuild the mask meanwhile
            name = self.selected
            self.mask_msg.content = ""
            self._apply_note = ""
            robot: dict = {}
            try:
                robot = robot_from_mask(self._draft, self._values(), self.session.sim.dt_s)
                note = self.session.apply_robot(name, robot)
            except ScenarioError as err:
                self._show_apply_error(err.problems, robot)
                return
            except (MaskError, EditError) as err:
                self._show_apply_error([str(err)], robot)
                return
            self.selected = robot["name"]
            self._apply_note = f"<span style='color:#1e8449'>&#10004; {note}</span>"
            # the mask, robot list and plots (new history: they start again), once
            self._follow_layout(self.session.robot_names(), self.session.layout)

    def _show_apply_error(self, problems: list[str], robot: dict) -> None:
        """The problems under Apply; each field they name gets a warning sign and the problem
        as its hint (the others lose theirs)."""
        bad = fields_in_error(problems, robot) if robot else {}
        with self._gui_lock:
            for key, w in self._mask_widgets.items():
                label = w.label.removeprefix("\u26a0 ")
                if key in bad:
                    w.label, w.hint = "\u26a0 " + label, bad[key]
                elif label != w.label:
                    w.label, w.hint = label, self._mask_hints.get(key)
            if self.apply_msg is not None:
                self.apply_msg.content = _error_md("\n".join(problems))

    # ------------------------------------------------------------------ world tab
    def _build_world(self) -> None:
        gui, s = self.server.gui, self.session
        gui.add_markdown("**Maze editor**")
        self.edit = gui.add_checkbox(
            "edit maze",
            initial_value=False,
            hint="click a floor cell to add a wall, a wall to remove it",
        )
        self.place = gui.add_checkbox(
            "place robots",
            initial_value=False,
            hint="drag the gizmo on the robot picked in the Robot tab, or click the floor (best "
            "in the top plan view), to move it there, at the nearest free spot",
        )
        self._drag = DragPlace(self.server.scene, s, self._world_note)
        self.place.on_update(
            lambda _: self._drag.show(self.selected) if self.place.value else self._drag.hide()
        )
        self.tape = gui.add_checkbox(
            "draw tape",
            initial_value=False,
            hint="click the floor to lay guidance tape: the first click starts a line, each "
            "next one extends it (line sensors read it at once)",
        )
        self._tape = TapeBrush(s)
        gui.add_button("New tape line", icon=viser.Icon.PLUS).on_click(
            lambda _: self._world_do(self._new_tape_line)
        )
        self.brush_mu = gui.add_number(
            "paint friction mu",
            initial_value=0.0,
            min=0.0,
            max=5.0,
            step=0.05,
            hint="above 0: a click (edit maze on) paints the floor cell with this friction",
        )
        self.world_msg = gui.add_markdown("")
        self.maze_rows = gui.add_number(
            "rooms north-south", initial_value=5, min=1, max=200, step=1
        )
        self.maze_cols = gui.add_number("rooms west-east", initial_value=5, min=1, max=200, step=1)
        self.maze_seed = gui.add_number("seed", initial_value=0, step=1)
        rnd = gui.add_button("New random maze", icon=viser.Icon.DICE)
        rnd.on_click(
            lambda _: self._world_do(
                lambda: s.random_maze(
                    int(self.maze_rows.value), int(self.maze_cols.value), int(self.maze_seed.value)
                )
            )
        )
        up = gui.add_upload_button(
            "Load map (txt, csv, png)", icon=viser.Icon.UPLOAD, mime_type=".txt,.csv,.png,.pgm"
        )
        up.on_upload(lambda _: self._world_do(lambda: s.load_grid(up.value.name, up.value.content)))
        self.map_format = gui.add_dropdown("map format", ("txt", "csv", "png"), initial_value="txt")
        down = gui.add_button("Save map", icon=viser.Icon.DOWNLOAD)
        down.on_click(
            lambda e: self._world_do(
                lambda: _download(e.client, *s.save_grid(self.map_format.value))
            )
        )

        @self.server.scene.on_click()
        def _(event: Any) -> None:
            if self.place.value:
                self._world_do(lambda: self._place_robot(event.ray_origin, event.ray_direction))
            elif self.tape.value:
                self._world_do(lambda: self._click_tape(event.ray_origin, event.ray_direction))
            elif self.edit.value:
                self._world_do(lambda: self._click_cell(event.ray_origin, event.ray_direction))

    def _world_do(self, fn: Any) -> None:
        self._do(fn, self.world_msg)

    def _world_note(self, text: str) -> None:
        self.world_msg.content = text

    def _place_robot(self, origin: Any, direction: Any) -> None:
        o, d = np.asarray(origin, dtype=float), np.asarray(direction, dtype=float)
        if d[2] >= -1e-9:
            self.world_msg.content = _error_md("that click is not on the floor")
            return
        t = -o[2] / d[2]
        note = self.session.move_robot(self.selected, o[0] + t * d[0], o[1] + t * d[1])
        self.world_msg.content = note
        if self._drag.shown:
            self._drag.show(self.selected)

    def _new_tape_line(self) -> None:
        self._tape.new_line()
        self.world_msg.content = "the next click starts a new tape line"

    def _click_tape(self, origin: Any, direction: Any) -> None:
        o, d = np.asarray(origin, dtype=float), np.asarray(direction, dtype=float)
        if d[2] >= -1e-9:
            self.world_msg.content = _error_md("that click is not on the floor")
            return
        t = -o[2] / d[2]
        self.world_msg.content = self._tape.click(o[0] + t * d[0], o[1] + t * d[1])

    def _click_cell(self, origin: Any, direction: Any) -> None:
        cell = pick_cell(self.session, np.asarray(origin), np.asarray(direction))
        if cell is None:
            self.world_msg.content = _error_md("that click is not on the map")
            return
        if self.brush_mu.value > 0:  # the friction brush (agvsim.app.friction_brush)
            region = paint_friction(self.session, *cell, float(self.brush_mu.value))
            self.world_msg.content = f"cell {cell} now has friction {region.mu:g}"
            return
        wall = self.session.toggle_cell(*cell)
        self.world_msg.content = f"cell {cell} is now {'a wall' if wall else 'free'}"

    # ------------------------------------------------------------------ refresh
    def refresh(self) -> None:
        with self._gui_lock:
            self._refresh_locked()
        self._refresh_overlay()

    def _refresh_overlay(self) -> None:
        """With "map overlay" on: the picked robot's live SLAM map once a second (the world's
        grid when it runs no SLAM)."""
        now = time.perf_counter()
        if not self.overlay.value or now < self._overlay_due:
            return
        self._overlay_due = now + 1.0
        live = self.session.slam_map(self.selected)
        if live is None and self.scene.overlay is None:
            return
        self.scene.set_overlay(*(live or (None,)))

    def _follow_layout(self, names: list[str], layout: int) -> None:
        """The robots or the world changed: the robot list, the mask and the plots follow."""
        s = self.session
        self._known_layout = layout
        if self.selected not in names:
            self.selected = names[0]
        self.robot_pick.options = tuple(names)
        _show(self.robot_pick, self.selected)
        self._build_mask(s.robot_config(self.selected))
        self._plot_layout = None
        _show(self.keyboard, s.keyboard_robot is not None)

    def _refresh_locked(self) -> None:
        view = self.session.view(None)
        status = (
            f"**t = {view.t_s:8.2f} s** &nbsp; {'playing' if view.playing else 'paused'}"
            f" &nbsp; speed {view.speed_label}"
        )
        if view.layout != self._known_layout:
            self._follow_layout(list(view.robot_names), view.layout)
        if self.speed.value != view.speed_label:
            _show(self.speed, view.speed_label)
        self.status.content = status + (("<br/>" + _error_md(view.error)) if view.error else "")
        self._refresh_video()
        self._refresh_view_options()
        robot = self.session.view(self.selected).robot  # after a new layout: the picked one
        self._refresh_numbers(robot)
        self._refresh_camera(robot)

    def _refresh_camera(self, robot: RobotView | None) -> None:
        """The sensor camera view: the picked robot's latest camera frame under its numbers
        (refreshed with them, a few times a second); none when it has no camera."""
        frame = None if robot is None else robot.frame
        with self._gui_lock:
            if frame is None:
                if self.camera_view is not None:
                    self.camera_view.remove()
                    self.camera_view, self._camera_key = None, ()
                return
            img, name, key = frame
            if key == self._camera_key:
                return
            step = max(1, int(np.ceil(img.shape[1] / 320)))  # at most 320 px wide in the panel
            img = np.ascontiguousarray(img[::step, ::step])
            label = f"sensor camera ({self.selected}: {name})"
            if self.camera_view is not None and label != self._camera_label:
                self.camera_view.remove()
                self.camera_view = None
            if self.camera_view is None:
                with self._run_tab:
                    self.camera_view = self.server.gui.add_image(
                        img,
                        label=label,
                        format="jpeg",
                        jpeg_quality=85,
                        order=self.numbers.order + 0.01,
                    )
                self._camera_label = label
            else:
                self.camera_view.image = img
            self._camera_key = key

    def _refresh_numbers(self, robot: RobotView | None) -> None:
        if robot is None:
            return
        with self._gui_lock:
            self._refresh_numbers_locked(robot)

    def _refresh_numbers_locked(self, robot: RobotView) -> None:
        wheels, ws = list(robot.wheel_names), robot.wheel_speeds
        tw, pose, state = robot.twist, robot.pose, robot.state_name
        coll = (robot.wall_collisions, robot.robot_collisions)
        t, hw, ht = robot.history_t, robot.history_wheels, robot.history_twist
        rows = "".join(f"| {n} | {v:+.2f} |\n" for n, v in zip(wheels, ws, strict=True))
        self.numbers.content = (
            f"**{robot.name}** ({robot.model_name}, {robot.mode})\n\n"
            f"pose x {pose[0]:.2f} m, y {pose[1]:.2f} m, heading {np.degrees(pose[2]):.1f} deg\n\n"
            f"twist vx {tw[0]:+.2f} m/s, vy {tw[1]:+.2f} m/s, omega {tw[2]:+.2f} rad/s\n\n"
            f"state **{state}**, collisions: walls {coll[0]}, robots {coll[1]}\n\n"
            f"| wheel | rad/s |\n|---|---|\n{rows}"
        )
        if hw is None or ht is None:
            return
        if len(t) < 2:  # a robot just rebuilt: its first sample, held for a moment
            t = np.array([t[0] - 0.05, t[0]])
            hw, ht = np.repeat(hw, 2, axis=0), np.repeat(ht, 2, axis=0)
        keep = t >= t[-1] - 10.0
        t, hw, ht = t[keep], hw[keep], ht[keep]
        # the plots are made once, with a series for each of up to four wheels, and never
        # removed: a robot with fewer wheels leaves the rest flat and unlabelled
        colors = ["#d62728", "#1f77b4", "#2ca02c", "#ff7f0e"]
        hw4 = np.zeros((len(t), 4))
        hw4[:, : hw.shape[1]] = hw
        series: tuple[Any, ...] = (
            {"label": "t (s)"},
            *(
                {"label": f"{wheels[k]} (rad/s)", "stroke": colors[k], "width": 2}
                if k < len(wheels)
                else {"label": "-", "stroke": "rgba(0,0,0,0)", "width": 0}
                for k in range(4)
            ),
        )
        key = (self.selected, tuple(wheels))
        if self.plot_wheels is None:
            gui = self.server.gui
            with self._run_tab:
                self.plot_wheels = gui.add_uplot(
                    (t, *hw4.T),
                    series,
                    title="wheel speeds (rad/s)",
                    scales={"x": {"time": False}},
                    aspect=1.6,
                )
                self.plot_twist = gui.add_uplot(
                    (t, *ht.T),
                    (
                        {"label": "t (s)"},
                        {"label": "vx (m/s)", "stroke": "#444", "width": 2},
                        {"label": "vy (m/s)", "stroke": "#999", "width": 2},
                        {"label": "omega (rad/s)", "stroke": "#8e44ad", "width": 2},
                    ),
                    title="body twist",
                    scales={"x": {"time": False}},
                    aspect=1.6,
                )
            self._plot_layout = key
            return
        if self._plot_layout != key:  # another robot, or this one rebuilt: its own history
            self._plot_layout = key
            if tuple(self.plot_wheels.series) != series:
                # only when the wheels differ: the browser redraws an emptied plot when the
                # series are sent again (the empty plot after Apply)
                self.plot_wheels.series = series
        # the same history is not sent again (viser resends arrays on every assignment, and
        # a paused run's plots sent five times a second kept the browser redrawing them)
        sent = (key, float(t[-1]), len(t))
        if sent == self._plot_sent:
            return
        self._plot_sent = sent
        self.plot_wheels.data = (t, *hw4.T)
        self.plot_twist.data = (t, *ht.T)


def _download(client: Any, name: str, data: bytes) -> None:
    """Send a file to the browser tab that asked (none when it has closed)."""
    if client is not None:
        client.send_file_download(name, data)


def _show(handle: Any, value: object) -> None:
    """Set a GUI input's value (viser types its setter ``T | ndarray``, which mypy reads as a
    read-only property)."""
    handle.value = value


def pick_cell(
    session: Session, origin: np.ndarray, direction: np.ndarray
) -> tuple[int, int] | None:
    """The maze cell a click ray points at: a wall whose top it crosses, else the floor cell
    under it. None when the ray misses the map."""
    if abs(direction[2]) < 1e-9 or direction[2] > 0:
        return None
    for z in (WALL_HEIGHT_M, 0.0):
        t = (z - origin[2]) / direction[2]
        if t < 0:
            continue
        x, y = origin[0] + t * direction[0], origin[1] + t * direction[1]
        cell = session.cell_at(x, y)
        if cell is None:
            continue
        if z == 0.0 or session.sim.world.grid.occupied[cell]:
            return cell
    return None
