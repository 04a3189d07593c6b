"""``plot.png``: the map, every robot's trajectory, its final footprint and its last scan."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


def plot_run(sim, trajectories: dict[str, np.ndarray], path: Path, title: str = "") -> None:
    """Draw the run. ``trajectories`` maps robot name -> (T, 2) xy samples."""
    from matplotlib.patches import Polygon

    fig, ax = map_figure(sim.world.grid, width_in=9.5, dpi=110, wall_vmax=1.4)
    xmin, xmax, ymin, ymax = sim.world.grid.extent_m
    for b in sim.world.boxes:
        ax.add_patch(Polygon(_corners(b), closed=True, color="0.35"))
    _draw_guidance(ax, sim.world)
    if sim.dynamics is not None:  # friction only acts on robots with dynamics
        _draw_floor(ax, sim.world.floor)
    st = sim.state
    fps = sim.footprints(st.poses)
    for i, robot in enumerate(sim.robots):
        xy = trajectories.get(robot.name)
        if xy is not None and len(xy):
            ax.plot(xy[:, 0], xy[:, 1], "-", color=robot.color, lw=1.2, label=robot.name)
            ax.plot(xy[0, 0], xy[0, 1], "o", color=robot.color, ms=4)
        ax.add_patch(Polygon(_corners(fps[i]), closed=True, fc=robot.color, ec="k", lw=0.6))
        p = st.poses[i]
        ax.arrow(p[0], p[1], 0.4 * np.cos(p[2]), 0.4 * np.sin(p[2]), width=0.03, color="k")
        slots = sim.sensors.slots_of[i]
        if slots:  # the sensor with most beams: its last scan as points
            s = max(slots, key=lambda k: sim.sensors.specs[k].num_beams)
            scan = sim.scan(s)
            spec = sim.sensors.specs[s]
            r = scan.ranges
            ok = np.isfinite(r)
            a = p[2] + scan.robot_angle_min_rad + scan.angle_increment_rad * np.arange(len(r))
            mx, my = spec.mount_xy_m
            ox = p[0] + np.cos(p[2]) * mx - np.sin(p[2]) * my
            oy = p[1] + np.sin(p[2]) * mx + np.cos(p[2]) * my
            ax.plot(
                ox + r[ok] * np.cos(a[ok]),
                oy + r[ok] * np.sin(a[ok]),
                ".",
                color="tab:blue" if spec.num_beams > 4 else "tab:green",
                ms=2.5,
            )
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (east)")
    ax.set_ylabel("y [m] (north)")
    ax.set_title(title or f"t = {st.t_s:.1f} s")
    if sim.robots:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    save_figure(fig, path, bbox_inches="tight")


def _draw_guidance(ax: Axes, world) -> None:
    """Tape (with its spots), floor codes and reflectors, where the world has them."""
    tape = getattr(world, "tape", None)
    if tape is not None and len(tape.segments):
        from matplotlib.collections import LineCollection

        segs = tape.segments.reshape(-1, 2, 2)
        ax.add_collection(LineCollection(segs, colors="tab:blue", linewidths=1.5, alpha=0.6))
        if len(tape.spot_xy):
            ax.plot(*tape.spot_xy.T, "o", color="tab:red", ms=4, label="tape spots")
    codes = getattr(world, "floor_codes", None)
    if codes is not None:
        xy = np.array([codes.code_xy(k) for k in range(codes.cols * codes.rows)])
        ax.plot(*xy.T, "s", color="k", ms=2, label="floor codes")
    refl = getattr(world, "reflectors", None)
    if refl is not None and len(refl.xy):
        ax.plot(*refl.xy.T, "D", color="gold", mec="k", ms=5, label="reflectors")


MAX_FLOOR_LABELS = 20  # more friction regions (a painted floor) are drawn without labels


def _draw_floor(ax: Axes, floor) -> None:
    """The floor's friction regions (agvsim.dynamics), shaded the darker the more slippery
    than the floor around them, each labelled with its mu while there are few."""
    from matplotlib.patches import Rectangle

    for r in floor.regions:
        slip = min(max(1.0 - r.mu / max(floor.mu, 1e-9), 0.0), 1.0)
        w, h = r.x_max_m - r.x_min_m, r.y_max_m - r.y_min_m
        ax.add_patch(
            Rectangle((r.x_min_m, r.y_min_m), w, h, fc="tab:cyan", alpha=0.12 + 0.3 * slip, lw=0)
        )
        if len(floor.regions) <= MAX_FLOOR_LABELS:
            ax.text(
                r.x_min_m + w / 2, r.y_min_m + h / 2, f"mu {r.mu:g}",
                ha="center", va="center", fontsize=7, color="tab:blue",
            )  # fmt: skip


def map_figure(grid, width_in: float, dpi: int, wall_vmax: float) -> tuple[Figure, Axes]:
    """A figure ``width_in`` inches wide, as tall as the map's aspect asks (3 to 12 in, plus
    room for the title), with the map's walls drawn in grey (the larger ``wall_vmax``, the
    lighter) over its extent in metres. Returns ``(fig, ax)``; :func:`save_figure` ends it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xmin, xmax, ymin, ymax = grid.extent_m
    aspect = (ymax - ymin) / max(xmax - xmin, 1e-9)
    fig, ax = plt.subplots(figsize=(width_in, max(3.0, min(12.0, 8 * aspect)) + 0.6), dpi=dpi)
    ax.imshow(
        grid.occupied,
        cmap="Greys",
        vmin=0,
        vmax=wall_vmax,
        origin="upper",
        extent=(xmin, xmax, ymin, ymax),
        interpolation="nearest",
    )
    return fig, ax


def save_figure(fig: Figure, path: Path, **savefig_kw) -> None:
    """Lay out, write and close a figure from :func:`map_figure`."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, **savefig_kw)
    plt.close(fig)


def _corners(box: np.ndarray) -> np.ndarray:
    cx, cy, th, hl, hw = box
    c, s = np.cos(th), np.sin(th)
    local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
    return np.column_stack(
        [cx + c * local[:, 0] - s * local[:, 1], cy + s * local[:, 0] + c * local[:, 1]]
    )
