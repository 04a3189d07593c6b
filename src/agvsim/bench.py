"""Benchmarks behind ``agvsim bench`` (the scripts in ``benchmarks/`` call these too).

Workload (issue #2): the thesis App. C.1 maze, differential robots carrying the thesis's
240-beam 10 m lidar at 10 Hz, kinematics at 50 Hz, the thesis's obstacle avoidance reading the
lidar's front beams, robots visible to each other's lidars, collision checks on. For 100 and
1000 robots the maze is tiled (ceil(sqrt(N / 10)) copies a side) so every copy holds about
ten robots, as crowded as the one-maze case can sensibly be. Figures are printed, never
asserted: compare ratios within one run.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable

import numba
import numpy as np

from agvsim.control.avoid import ObstacleAvoidance
from agvsim.kinematics import DifferentialDrive
from agvsim.scenario import cone_beams
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sensors.raycast import RayCaster
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.spec import OdometrySpec, RobotSpec, World
from agvsim.world.grid import OccupancyGrid
from agvsim.world.mazes import thesis_maze, tile, upsample


def free_starts(grid: OccupancyGrid, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) poses at centres of free cells whose 8 neighbours are free, headings on the axes."""
    occ = grid.occupied
    pad = np.pad(occ, 1, constant_values=True)
    clear = ~occ.copy()
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            clear &= ~pad[1 + dr : 1 + dr + occ.shape[0], 1 + dc : 1 + dc + occ.shape[1]]
    rows, cols = np.nonzero(clear)
    if len(rows) < n:
        raise ValueError(f"only {len(rows)} clear cells for {n} robots")
    pick = rng.choice(len(rows), size=n, replace=False)
    x, y = grid.cell_center(rows[pick], cols[pick])
    th = rng.integers(0, 4, size=n) * (np.pi / 2) - np.pi / 2
    return np.column_stack([x, y, th])


def fleet(n: int, seed: int = 0) -> Simulation:
    """The benchmark fleet of ``n`` robots (see the module docstring)."""
    k = max(1, math.ceil(math.sqrt(n / 10)))
    grid = tile(thesis_maze("thesis_c1"), k, k) if k > 1 else thesis_maze("thesis_c1")
    rng = np.random.default_rng(seed)
    poses = free_starts(grid, n, rng)
    model = DifferentialDrive(wheel_radius_m=0.1, half_track_m=0.25)
    lidar = RangeSensorSpec.thesis_lidar(rate_hz=10.0)
    sensors = (lidar,)
    robots = [
        RobotSpec(
            f"r{i}",
            model,
            initial_pose=tuple(p),
            body_length_m=0.5,
            body_width_m=0.4,
            sensors=sensors,
            odometry=OdometrySpec(0.01),
        )
        for i, p in enumerate(poses)
    ]
    front, back = cone_beams(lidar)
    ctrl = ObstacleAvoidance("lidar", front, back, trigger_m=0.8, speed_m_s=0.5)
    return Simulation(World(grid), robots, [Binding(ctrl, tuple(range(n)), batch=True)], seed=seed)


def steps_per_second(n: int, steps: int, warm: int = 10) -> dict:
    sim = fleet(n)
    for _ in range(warm):
        sim.step()
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
    wall = time.perf_counter() - t0
    sps = steps / wall
    return {
        "robots": n,
        "steps": steps,
        "steps_per_s": round(sps, 1),
        "realtime_factor": round(sps * sim.dt_s, 2),
        "threads": numba.get_num_threads(),
    }


def rays_per_second(grid: OccupancyGrid, sensors: int, repeats: int, seed: int = 0) -> float:
    """Steady-state rays/s of the ray-casting kernel on ONE thread, 240 beams, 10 m."""
    rng = np.random.default_rng(seed)
    xmin, xmax, ymin, ymax = grid.extent_m
    pts = np.empty((0, 2))
    while len(pts) < sensors:  # random free points, random headings
        cand = rng.uniform((xmin, ymin), (xmax, ymax), size=(4 * sensors, 2))
        pts = np.concatenate([pts, cand[~grid.is_occupied_at(cand[:, 0], cand[:, 1])]])
    poses = np.column_stack([pts[:sensors], rng.uniform(-np.pi, np.pi, sensors)])
    beams = RangeSensorSpec.thesis_lidar().beam_angles_rad
    angles = poses[:, 2:3] + beams[None, :]
    caster = RayCaster(grid)
    max_range = np.full(sensors, 10.0)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        caster.cast(poses[:, :2], angles, max_range)  # warm
        t0 = time.perf_counter()
        for _ in range(repeats):
            caster.cast(poses[:, :2], angles, max_range)
        wall = time.perf_counter() - t0
    finally:
        numba.set_num_threads(before)
    return sensors * len(beams) * repeats / wall


def jit_compile_seconds() -> float:
    """Compile every kernel from scratch in a fresh process with an empty numba cache."""
    code = (
        "import time; t0 = time.perf_counter();"
        "from agvsim.sensors.raycast import warmup as a;"
        "from agvsim.sim.collide import warmup as b;"
        "a(); b(); print(time.perf_counter() - t0)"
    )
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        res = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
        )
    return float(res.stdout.strip().splitlines()[-1])


def run_benchmarks(quick: bool = False, log: Callable[[str], object] | None = None) -> dict:
    say = log or (lambda _msg: None)
    out: dict = {
        "quick": quick,
        "cpu_count": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
    }
    say("JIT compile (fresh cache, separate process) ...")
    out["jit_compile_s"] = round(jit_compile_seconds(), 2)
    maze = thesis_maze("thesis_c1")
    sensors, reps = (200, 5) if quick else (1000, 20)
    say("rays/s on the 1 m maze ...")
    out["rays_per_s"] = {"maze_1m": round(rays_per_second(maze, sensors, reps))}
    say("rays/s on the same maze at 0.05 m ...")
    out["rays_per_s"]["maze_5cm"] = round(rays_per_second(upsample(maze, 20), sensors, reps))
    out["rays_per_s"]["threads"] = 1
    plan = [(1, 500), (100, 300), (1000, 50)] if quick else [(1, 3000), (100, 2000), (1000, 300)]
    out["fleet"] = {}
    for n, steps in plan:
        say(f"{n} robot(s), {steps} steps ...")
        out["fleet"][str(n)] = steps_per_second(n, steps)
    say("camera frames/s (320 x 240, one thread) ...")
    out["camera"] = camera_benchmark(quick)
    say("planar dynamics against kinematics, 1000 robots ...")
    from agvsim.bench_dynamics import dynamics_benchmark

    out["dynamics"] = dynamics_benchmark(quick)
    return out


def camera_benchmark(quick: bool = False, seed: int = 0) -> dict:
    """The onboard camera (issue #6): frames/s of one 320 x 240 camera on ONE thread in the
    thesis C.1 maze with 4 markers and 4 robots (boxes in view), at random free poses, level and
    pitched 10 deg; and steps/s of those 4 robots (50 Hz, each with a 10 Hz camera) against the
    same robots without cameras. The first frame's time (compile or cache load) is apart."""
    from agvsim.sensors.camera import CameraSpec
    from agvsim.world.markers import Appearance, Face, MarkerKind, MarkerSpec, place_markers

    grid = thesis_maze("thesis_c1")
    marks = [
        MarkerSpec(MarkerKind.ARUCO, Face.WEST, 0.4, 0.5, cell=(r, 19), marker_id=r)
        for r in (7, 8, 9, 10)
    ]
    world = World(grid, appearance=Appearance(markers=place_markers(marks, grid, 1.0)))
    rng = np.random.default_rng(seed)
    poses = free_starts(grid, 4, rng)
    model = DifferentialDrive(wheel_radius_m=0.1, half_track_m=0.25)

    def sim(cams: tuple, pitch: float = 0.0) -> Simulation:
        specs = tuple(CameraSpec(mount_xy_m=(0.25, 0.0), pitch_rad=pitch) for _ in cams)
        robots = [
            RobotSpec(
                f"r{i}",
                model,
                initial_pose=tuple(p),
                body_length_m=0.5,
                body_width_m=0.4,
                cameras=specs,
            )
            for i, p in enumerate(poses)
        ]
        return Simulation(world, robots, seed=seed)

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    out: dict = {"width_px": 320, "height_px": 240, "threads": 1}
    try:
        t0 = time.perf_counter()
        level = sim((1,))
        out["first_frame_s"] = round(time.perf_counter() - t0, 3)
        frames = 300 if quick else 2000
        free = free_starts(grid, 40, rng)
        for key, s in (("frames_per_s", level), ("frames_per_s_pitch10", sim((1,), 0.1745))):
            fp = s.footprints(s.state.poses)
            s.cameras.render(0, free[0], fp)  # type: ignore[union-attr]
            t0 = time.perf_counter()
            for k in range(frames):
                s.cameras.render(0, free[k % len(free)], fp)  # type: ignore[union-attr]
            out[key] = round(frames / (time.perf_counter() - t0), 1)
        steps = 200 if quick else 1000
        for key, s in (("steps_per_s_4_cameras", level), ("steps_per_s_no_camera", sim(()))):
            t0 = time.perf_counter()
            for _ in range(steps):
                s.step()
            out[key] = round(steps / (time.perf_counter() - t0), 1)
    finally:
        numba.set_num_threads(before)
    return out
