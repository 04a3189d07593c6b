"""The world editor's tape brush: clicks on the floor lay guidance tape (docs/guidance.md).

The first click of a line marks where it starts, each later click adds a straight piece to
it; "new tape line" starts another. Points are rounded to the centimetre. The tape becomes
``world.tape.lines`` of the scenario the session runs, saves and restarts from; the world is
rebuilt with it at once (robots keep their live state), so line sensors read it from the
next step.
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from agvsim.app.session import Session


class TapeBrush:
    def __init__(self, session: Session):
        self.session = session
        self.start: tuple[float, float] | None = None  # a line's first point, not yet laid
        self.extending = False  # the next click extends the scenario's last tape line

    def new_line(self) -> None:
        self.start, self.extending = None, False

    def click(self, x_m: float, y_m: float) -> str:
        """Lay tape to the floor point (x, y); returns what was done. Raises ValueError for a
        point off the map."""
        s = self.session
        p = (round(float(x_m), 2), round(float(y_m), 2))
        with s.lock:
            grid = s.sim.world.grid
            x0, x1, y0, y1 = grid.extent_m
            if not (x0 <= p[0] <= x1 and y0 <= p[1] <= y1):
                raise ValueError(f"({p[0]:.2f}, {p[1]:.2f}) is off the map: no tape there")
            if not self.extending and self.start is None:
                self.start = p
                return f"tape starts at ({p[0]:.2f}, {p[1]:.2f}): click where it goes next"
            world: dict[str, Any] = copy.deepcopy(s.config["world"])
            tape = world.setdefault("tape", {})
            lines = tape.setdefault("lines", [])
            if self.extending and lines and "points" in lines[-1]:
                lines[-1]["points"].append(list(p))
            else:
                assert self.start is not None
                lines.append({"points": [list(self.start), list(p)]})
                self.start, self.extending = None, True
            s.set_world(world)
            n = len(lines[-1]["points"])
            return f"tape line {len(lines)}: {n} points, the last at ({p[0]:.2f}, {p[1]:.2f})"
