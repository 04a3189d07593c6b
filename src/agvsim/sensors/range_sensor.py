"""Range sensors: one model for the thesis's single-beam rangers and its 360 deg lidar.

A sensor is a fan of beams mounted on the robot. Its scan follows ``sensor_msgs/LaserScan``:
beam i points at ``angle_min_rad + i * angle_increment_rad`` in the sensor frame, ranges in
metres; a beam with no return within ``range_max_m`` reads ``+inf``; an obstacle closer than
``range_min_m`` reads ``-inf`` (REP-117). Noise and dropout are applied outside the ray-casting
kernel with the simulation's generator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RangeSensorSpec:
    name: str
    num_beams: int
    angle_min_rad: float
    angle_increment_rad: float
    range_max_m: float
    range_min_m: float = 0.0
    rate_hz: float = 10.0
    noise_std_m: float = 0.0
    dropout_prob: float = 0.0
    mount_xy_m: tuple[float, float] = (0.0, 0.0)
    mount_yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        if self.num_beams < 1:
            raise ValueError(f"sensor {self.name!r}: num_beams must be >= 1, got {self.num_beams}")
        if not (0.0 <= self.range_min_m < self.range_max_m):
            raise ValueError(
                f"sensor {self.name!r}: need 0 <= range_min_m < range_max_m, got "
                f"{self.range_min_m} and {self.range_max_m}"
            )
        if not self.rate_hz > 0:
            raise ValueError(f"sensor {self.name!r}: rate_hz must be > 0, got {self.rate_hz}")
        if self.noise_std_m < 0 or not (0.0 <= self.dropout_prob <= 1.0):
            raise ValueError(
                f"sensor {self.name!r}: noise_std_m must be >= 0 and dropout_prob in [0, 1]"
            )

    @classmethod
    def fan(
        cls,
        name: str,
        num_beams: int,
        fov_rad: float,
        range_max_m: float,
        angle_min_rad: float | None = None,
        **kw,
    ) -> RangeSensorSpec:
        """Evenly spread beams. A full circle (fov = 2 pi) has increment 2 pi / n and starts at
        -pi unless told; a partial fan spans [-fov/2, +fov/2] with n beams on its ends."""
        full = abs(fov_rad - 2 * np.pi) < 1e-9
        if num_beams == 1:
            inc = 0.0
        else:
            inc = fov_rad / num_beams if full else fov_rad / (num_beams - 1)
        if angle_min_rad is None:
            angle_min_rad = -np.pi if full else -fov_rad / 2.0
        return cls(name, num_beams, float(angle_min_rad), float(inc), float(range_max_m), **kw)

    @classmethod
    def thesis_rangers(cls, range_max_m: float = 1.0, **kw) -> RangeSensorSpec:
        """The thesis's four single-beam rangers at 0, 90, 180, 270 deg: index 0 front, 1 left,
        2 back, 3 right."""
        return cls("rangers", 4, 0.0, np.pi / 2, range_max_m, **kw)

    @classmethod
    def thesis_lidar(cls, **kw) -> RangeSensorSpec:
        """The thesis's SLAM lidar: 240 beams 1.5 deg apart, 10 m, 10 Hz."""
        kw.setdefault("rate_hz", 10.0)
        return cls("lidar", 240, -np.pi + np.deg2rad(1.5), np.deg2rad(1.5), 10.0, **kw)

    @property
    def beam_angles_rad(self) -> np.ndarray:
        """(B,) beam angles in the sensor frame."""
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.num_beams)


def apply_noise(
    ranges: np.ndarray,
    range_min: np.ndarray,
    range_max: np.ndarray,
    noise_std: np.ndarray,
    dropout: np.ndarray,
    rng: np.random.Generator,
) -> np.ndarray:
    """Turn exact ranges ``(S, B)`` (inf = no return) into readings: Gaussian noise on returns
    (kept inside [range_min, range_max]), dropouts read inf, returns closer than range_min read
    -inf. Per-sensor parameters are ``(S,)``. Draws from ``rng`` only for noisy sensors, in
    sensor order, so results are reproducible."""
    out = ranges.copy()
    lo, hi = range_min[:, None], range_max[:, None]
    hit = np.isfinite(out)
    noisy = noise_std > 0
    if noisy.any():
        idx = np.flatnonzero(noisy)
        sub = out[idx]
        sub = sub + rng.standard_normal(sub.shape) * noise_std[idx, None]
        sub = np.where(np.isfinite(sub), np.clip(sub, lo[idx], hi[idx]), sub)
        out[idx] = sub
    drop = dropout > 0
    if drop.any():
        idx = np.flatnonzero(drop)
        mask = rng.random(out[idx].shape) < dropout[idx, None]
        sub = out[idx]
        sub[mask] = np.inf
        out[idx] = sub
    too_close = hit & (ranges < lo)
    out[too_close] = -np.inf
    return out
