"""Drag-to-place: a move gizmo (viser transform controls, x and y only) on the robot picked
in the Robot tab while "place robots" is ticked. Dragging it (best in the top plan view) and
letting go puts the robot at the free pose nearest to where it was let go, heading kept
(``Session.move_robot``); the gizmo then jumps to where the robot really went. A click on the
floor does the same (the panel's scene click)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from agvsim.app.session import EditError, Session

GIZMO_Z_M = 0.35  # above the bodies, so that it can be grabbed from above


class DragPlace:
    def __init__(self, scene: Any, session: Session, note: Callable[[str], None]):
        self.scene, self.session, self.note = scene, session, note
        self.handle: Any = None
        self.robot: str | None = None

    def show(self, name: str) -> None:
        """The gizmo on robot ``name`` (created on first use)."""
        self.robot = name
        with self.session.lock:
            x, y = (
                float(v)
                for v in self.session.sim.state.poses[self.session.sim.robot_index(name), :2]
            )
        if self.handle is None:
            self.handle = self.scene.add_transform_controls(
                "/place_robot",
                scale=1.5,
                active_axes=(True, True, False),
                disable_rotations=True,
                depth_test=False,
                position=(x, y, GIZMO_Z_M),
            )
            self.handle.on_update(self._on_update)
        else:
            self.handle.position = (x, y, GIZMO_Z_M)
            self.handle.visible = True

    def _on_update(self, event: Any) -> None:
        if getattr(event, "phase", "end") == "end":  # let go: place it (not at every move)
            self.release(*self.handle.position[:2])

    def hide(self) -> None:
        """Hidden, not removed (the browser may still address the node)."""
        if self.handle is not None:
            self.handle.visible = False
        self.robot = None

    @property
    def shown(self) -> bool:
        return self.handle is not None and self.robot is not None

    def release(self, x_m: float, y_m: float) -> str:
        """Let go at (x, y): the robot goes to the nearest free pose; returns the note shown."""
        if self.robot is None:
            return ""
        try:
            text = self.session.move_robot(self.robot, float(x_m), float(y_m))
        except EditError as err:
            text = f"**error:** {err}"
        self.note(text)
        self.show(self.robot)  # the gizmo follows the robot to where it really went
        return text
