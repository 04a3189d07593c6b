"""``slam_<robot>/compare.png``: the SLAM map over the true walls, and the three paths."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agvsim.viz.plot import map_figure, save_figure


def plot_slam_comparison(
    slam_map,
    grid,
    estimate: np.ndarray,
    truth: np.ndarray,
    odometry: np.ndarray,
    path: Path,
    title: str = "",
) -> None:
    """True walls light grey, the SLAM map's occupied cells black (its free space faint blue);
    the true path green, SLAM red dashed, odometry alone orange."""
    fig, ax = map_figure(grid, width_in=9.0, dpi=120, wall_vmax=4)
    xmin, xmax, ymin, ymax = grid.extent_m
    p = slam_map.probability
    ox, oy = slam_map.origin_xy_m
    h, w = p.shape
    ext = (ox, ox + w * slam_map.resolution_m, oy, oy + h * slam_map.resolution_m)
    rgba = np.zeros((h, w, 4))
    free = (p < 0.196) & (slam_map.logodds != 0)
    rgba[free] = (0.55, 0.75, 1.0, 0.25)
    rgba[p > 0.65] = (0.0, 0.0, 0.0, 1.0)
    ax.imshow(rgba, origin="lower", extent=ext, interpolation="nearest")
    ax.plot(truth[:, 0], truth[:, 1], "-", color="tab:green", lw=1.6, label="true path")
    ax.plot(odometry[:, 0], odometry[:, 1], "-", color="tab:orange", lw=0.9, label="odometry")
    ax.plot(estimate[:, 0], estimate[:, 1], "--", color="tab:red", lw=1.0, label="SLAM")
    ax.set_xlim(min(xmin, ext[0]), max(xmax, ext[1]))
    ax.set_ylim(min(ymin, ext[2]), max(ymax, ext[3]))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.85)
    ax.set_title(title + "\n(grey: true walls, black: SLAM occupied cells)", fontsize=10)
    save_figure(fig, path)
