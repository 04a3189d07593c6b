"""Ray-casting throughput: rays per second of :class:`agvsim.sensors.raycast.RayCaster`.

Run ``python benchmarks/bench_rays.py``. Prints the compile (or cache-load) time apart from the
steady-state throughput, for a 20 x 20 maze of 1 m cells and the same maze at 0.05 m cells
(400 x 400), lidars of 240 beams (1.5 deg apart) and 10 m range at random free poses.
"""

from __future__ import annotations

import argparse
import math
import time

import numba
import numpy as np

from agvsim.sensors.raycast import RayCaster, warmup
from agvsim.world.grid import OccupancyGrid


def test_maze(cell_m: float = 1.0) -> OccupancyGrid:
    """The 20 m x 20 m maze used here: a border wall and a few interior walls, drawn on a 20 x 20
    matrix of 1 m cells and refined to ``cell_m`` cells (1 / cell_m must be an integer)."""
    m = np.zeros((20, 20), dtype=bool)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = True
    m[4, 2:12] = True
    m[4:12, 15] = True
    m[8, 5:13] = True
    m[12:18, 5] = True
    m[12, 9:18] = True
    m[15, 9:14] = True
    m[16:19, 12] = True
    k = int(round(1.0 / cell_m))
    if abs(k * cell_m - 1.0) > 1e-9:
        raise ValueError(f"1 / cell_m must be an integer, got cell_m = {cell_m}")
    fine = np.kron(m, np.ones((k, k), dtype=bool))
    return OccupancyGrid.from_matrix(fine, cell_m)


def random_free_poses(grid: OccupancyGrid, n: int, rng: np.random.Generator) -> np.ndarray:
    """``(n, 3)`` poses x, y, theta whose position is on a free cell."""
    out = np.empty((0, 3))
    xmin, xmax, ymin, ymax = grid.extent_m
    while len(out) < n:
        p = np.column_stack(
            [
                rng.uniform(xmin, xmax, 2 * n),
                rng.uniform(ymin, ymax, 2 * n),
                rng.uniform(-np.pi, np.pi, 2 * n),
            ]
        )
        out = np.vstack([out, p[~grid.is_occupied_at(p[:, 0], p[:, 1])]])
    return out[:n]


def bench_rays(
    grid: OccupancyGrid,
    n_sensors: int = 2000,
    beams: int = 240,
    max_range: float = 10.0,
    repeats: int = 5,
    threads: int = 1,
    seed: int = 0,
) -> dict:
    """Steady-state rays per second for ``n_sensors`` lidars at random free poses (no boxes).

    Returns a dict with ``rays_per_s`` (best of ``repeats``), ``median_rays_per_s``,
    ``compile_s`` (compile or cache load, measured first), ``rays`` per call and ``threads``.
    """
    compile_s = warmup()
    previous = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        rng = np.random.default_rng(seed)
        poses = random_free_poses(grid, n_sensors, rng)
        inc = 2.0 * np.pi / beams
        angles = poses[:, 2:3] + (-np.pi + inc * np.arange(beams))[None, :]
        caster = RayCaster(grid)
        out = np.empty((n_sensors, beams))
        origins = np.ascontiguousarray(poses[:, :2])
        caster.cast(origins, angles, max_range, out=out)  # first call on these shapes
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            caster.cast(origins, angles, max_range, out=out)
            times.append(time.perf_counter() - t0)
    finally:
        numba.set_num_threads(previous)
    rays = n_sensors * beams
    return {
        "rays_per_s": rays / min(times),
        "median_rays_per_s": rays / float(np.median(times)),
        "compile_s": compile_s,
        "rays": rays,
        "threads": threads,
        "hit_fraction": float(np.isfinite(out).mean()),
    }


def bench_fleet(
    n_robots: int,
    beams: int = 240,
    max_range: float = 10.0,
    repeats: int = 5,
    threads: int = 1,
    area_per_robot_m2: float = 40.0,
    seed: int = 0,
) -> dict:
    """Rays per second for ``n_robots`` robots (0.6 m x 0.4 m footprints, one lidar each, its own
    footprint ignored) spread at constant density over an empty walled map: with the box broad
    phase the cost per ray should not grow with the number of robots."""
    side = max(4, int(math.ceil(math.sqrt(n_robots * area_per_robot_m2))))
    occ = np.zeros((side, side), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    grid = OccupancyGrid.from_matrix(occ, 1.0)
    rng = np.random.default_rng(seed)
    poses = random_free_poses(grid, n_robots, rng)
    boxes = np.column_stack([poses, np.full(n_robots, 0.3), np.full(n_robots, 0.2)])
    inc = 2.0 * np.pi / beams
    angles = poses[:, 2:3] + (-np.pi + inc * np.arange(beams))[None, :]
    origins = np.ascontiguousarray(poses[:, :2])
    own = np.arange(n_robots)
    caster = RayCaster(grid)
    previous = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        out = caster.cast(origins, angles, max_range, boxes, own)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            caster.cast(origins, angles, max_range, boxes, own, out=out)
            times.append(time.perf_counter() - t0)
    finally:
        numba.set_num_threads(previous)
    return {
        "rays_per_s": n_robots * beams / min(times),
        "robots": n_robots,
        "threads": threads,
        "box_hit_fraction": float(np.isfinite(out).mean()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--sensors", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    for cell in (1.0, 0.05):
        grid = test_maze(cell)
        r = bench_rays(grid, n_sensors=args.sensors, repeats=args.repeats, threads=args.threads)
        print(
            f"maze 20 m, cells {cell:g} m ({grid.rows}x{grid.cols}), {r['threads']} thread(s): "
            f"{r['rays_per_s'] / 1e6:6.2f} M rays/s best, {r['median_rays_per_s'] / 1e6:6.2f} M "
            f"median ({r['rays']} rays/call, {100 * r['hit_fraction']:.0f}% hits; "
            f"compile/load {r['compile_s']:.2f} s)"
        )
    for n in (100, 1000):
        r = bench_fleet(n, threads=args.threads)
        print(
            f"fleet of {n:4d} robots with footprints, {r['threads']} thread(s): "
            f"{r['rays_per_s'] / 1e6:6.2f} M rays/s"
        )


if __name__ == "__main__":
    main()
