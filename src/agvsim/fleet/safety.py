"""The protective field: a vehicle stops for anything its lidar sees on its path ahead.

The field follows the path the vehicle is about to drive (as a scanner's field set switched
along the track would): a lidar return counts when it lies within ``half_width_m`` of the path
between the vehicle's reference point and ``length_m`` further along it. The length grows with
speed (reaction distance plus braking distance), so a vehicle at rest near a wall is not
stopped by the wall, and a fast one sees far enough to stop in time.
"""

from __future__ import annotations

import math

import numpy as np


def field_length_m(
    speed_m_s: float, front_m: float, reaction_s: float, decel_m_s2: float, margin_m: float
) -> float:
    """How far ahead of the reference point the field reaches: the body's front, the distance
    driven during the reaction time, the braking distance v^2 / (2 a) and a margin."""
    v = abs(speed_m_s)
    return front_m + v * reaction_s + v * v / (2.0 * decel_m_s2) + margin_m


def scan_points(
    pose: np.ndarray,
    mount_xy: tuple[float, float],
    dirs: np.ndarray,
    ranges: np.ndarray,
    max_m: float,
) -> np.ndarray:
    """(K, 2) world points of the returns closer than ``max_m``; ``dirs`` (B, 2) are the beam
    directions in the robot frame."""
    near = ranges < max_m  # -inf (closer than the sensor's minimum) counts, at 0 m
    if not near.any():
        return np.zeros((0, 2))
    r = np.maximum(ranges[near], 0.0)[:, None]
    local = np.asarray(mount_xy)[None, :] + r * dirs[near]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.column_stack(
        [pose[0] + c * local[:, 0] - s * local[:, 1], pose[1] + s * local[:, 0] + c * local[:, 1]]
    )


def violated(points: np.ndarray, path: np.ndarray, half_width_m: float) -> bool:
    """True when a point lies within ``half_width_m`` of the sampled path ``(M, 2)``."""
    if len(points) == 0 or len(path) == 0:
        return False
    d2 = ((points[:, None, :] - path[None, :, :]) ** 2).sum(axis=2)
    return bool((d2 <= half_width_m * half_width_m).any())
