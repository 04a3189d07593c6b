"""Where a robot rebuilt in a running simulation (the app's Apply, a new robot) may stand.

Its initial pose, when the body there is clear of walls, boxes and the other robots as they
stand now (by ``CLEARANCE_M``); otherwise the nearest pose that is, with the same heading,
searched on rings ``RING_STEP_M`` apart out to ``MAX_SEARCH_M``. Nearest is measured from the
initial pose, so a robot goes back as close to where the user put it as the others allow.
"""

from __future__ import annotations

import math

import numpy as np

from agvsim.sim.engine import Simulation

CLEARANCE_M = 0.1  # kept from walls, boxes and robots (so that no one starts bumping)
RING_STEP_M = 0.1
MAX_SEARCH_M = 6.0


def blocker(sim: Simulation, i: int, pose: tuple[float, float, float]) -> str | None:
    """What robot ``i`` at ``pose`` would overlap, grown by ``CLEARANCE_M``: another robot's
    name, "a wall", "a box"; None when the spot is free."""
    poses = sim.state.poses.copy()
    poses[i] = pose
    fp = sim.footprints(poses)
    fp[i, 3:5] += CLEARANCE_M
    if sim.collider.hit_walls(fp[i : i + 1])[0]:
        return "a wall"
    if len(sim.world.boxes) and sim.collider.hit_static(fp[i : i + 1], sim.world.boxes)[0]:
        return "a box"
    for a, b in sim.collider.overlapping_pairs(fp):
        if i in (a, b):
            return repr(sim.robots[int(b if a == i else a)].name)
    return None


def nearest_free_pose(
    sim: Simulation, i: int, pose: tuple[float, float, float]
) -> tuple[float, float, float] | None:
    """The free pose nearest to ``pose`` (same heading), or None within ``MAX_SEARCH_M``."""
    x0, y0, th = pose
    if blocker(sim, i, pose) is None:
        return pose
    for k in range(1, int(round(MAX_SEARCH_M / RING_STEP_M)) + 1):
        r = k * RING_STEP_M
        n = max(8, int(math.ceil(2.0 * math.pi * r / RING_STEP_M)))
        for a in np.linspace(0.0, 2.0 * math.pi, n, endpoint=False):
            cand = (x0 + r * math.cos(a), y0 + r * math.sin(a), th)
            if blocker(sim, i, cand) is None:
                return cand
    return None


def place_clear(sim: Simulation, i: int) -> str | None:
    """Put robot ``i`` at its initial pose if free, else at the nearest free pose (the pose
    and its odometry). Returns None when it stands at its initial pose, else what was done."""
    robot = sim.robots[i]
    x0, y0, th = (float(v) for v in robot.initial_pose)
    start = (x0, y0, th)
    why = blocker(sim, i, start)
    spot = start if why is None else nearest_free_pose(sim, i, start)
    if spot is None:
        msg = f"{robot.name}: no free pose within {MAX_SEARCH_M:g} m of its initial pose"
        sim.place(i, start)
        return f"{msg} ({x0:.2f}, {y0:.2f}) (in the way: {why}); it starts there"
    sim.place(i, spot)
    if why is None:
        return None
    return (
        f"{robot.name} placed at ({spot[0]:.2f}, {spot[1]:.2f}), "
        f"{math.hypot(spot[0] - x0, spot[1] - y0):.2f} m from its initial pose "
        f"({x0:.2f}, {y0:.2f}), where {why} is in the way"
    )
