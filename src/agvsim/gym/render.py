"""``rgb_array`` frames: the simulation's top view (``agvsim.viz.topview.render_top``) with the
goals drawn on it as green discs."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

GOAL_RGB = (40, 170, 70)


def frame(
    sim,
    goals_xy: np.ndarray,
    goal_radius_m: float,
    width_px: int,
    extent: tuple[float, float, float, float] | None = None,
    beams: bool = True,
) -> np.ndarray:
    """``(H, W, 3) uint8`` top view of ``sim`` (of ``extent`` only, when given) with a green
    disc of ``goal_radius_m`` at each of ``goals_xy (G, 2)``, drawn on the floor only (robots,
    walls and beams stay visible)."""
    from agvsim.viz.topview import FLOOR_RGB, View, render_top

    img = render_top(sim, width_px, beams=beams, extent=extent)
    view = View.fit(extent or sim.world.grid.extent_m, width_px, None)
    h, w = img.shape[:2]
    floor = np.all(img == np.array(FLOOR_RGB, dtype=np.uint8), axis=-1)
    r_px = max(1.0, goal_radius_m * view.px_per_m)
    for col, row in view.to_px(np.asarray(goals_xy, dtype=np.float64).reshape(-1, 2)):
        r0, r1 = max(0, int(row - r_px)), min(h, int(row + r_px) + 1)
        c0, c1 = max(0, int(col - r_px)), min(w, int(col + r_px) + 1)
        if r0 >= r1 or c0 >= c1:
            continue
        rr, cc = np.mgrid[r0:r1, c0:c1]
        disc = (rr + 0.5 - row) ** 2 + (cc + 0.5 - col) ** 2 <= r_px**2
        disc &= floor[r0:r1, c0:c1]
        img[r0:r1, c0:c1][disc] = GOAL_RGB
    return img


def check_render_mode(render_mode: str | None, allowed: Sequence[str]) -> str | None:
    if render_mode is not None and render_mode not in allowed:
        raise ValueError(
            f"render_mode: {render_mode!r} is not supported (allowed: None, "
            + ", ".join(repr(m) for m in allowed)
            + ")"
        )
    return render_mode
