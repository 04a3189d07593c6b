"""Capture: when does a pursuer first come within ``radius_m`` of an evader?

Checked after every step on the centres of the robots' bodies (ground truth; for car-like
models the body centre lies ahead of the rear-axle reference point). The
result holds whether and when the evader was caught, how long it survived (the capture time,
else the time run) and the closest the two came.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import BaseModel, ConfigDict, Field


class Capture:
    """Metric: ``update(sim)`` each step (True once caught when ``end_run``), ``result()``."""

    def __init__(self, pursuer_index: int, evader_index: int, radius_m: float, end_run=True):
        if pursuer_index == evader_index:
            raise ValueError("the pursuer and the evader must be different robots")
        if not radius_m > 0:
            raise ValueError(f"radius_m must be > 0, got {radius_m}")
        self.pursuer, self.evader = int(pursuer_index), int(evader_index)
        self.radius_m, self.end_run = float(radius_m), bool(end_run)
        self.captured = False
        self.time_to_capture_s: float | None = None
        self.t_s = 0.0
        self.min_distance_m = math.inf

    def update(self, sim) -> bool:
        centres = sim.footprints(sim.state.poses)[:, :2]
        d = float(np.hypot(*(centres[self.pursuer] - centres[self.evader])))
        self.t_s = float(sim.state.t_s)
        self.min_distance_m = min(self.min_distance_m, d)
        if not self.captured and d <= self.radius_m:
            self.captured, self.time_to_capture_s = True, self.t_s
        return self.captured and self.end_run

    def result(self) -> dict:
        return {
            "captured": self.captured,
            "time_to_capture_s": self.time_to_capture_s,
            "survival_time_s": self.time_to_capture_s if self.captured else self.t_s,
            "min_distance_m": self.min_distance_m if math.isfinite(self.min_distance_m) else None,
        }


class CaptureConfig(BaseModel):
    """``metrics: {capture: {pursuer: red, evader: blue, radius_m: 0.8}}``"""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    pursuer: str = Field(min_length=1, description="robot name")
    evader: str = Field(min_length=1, description="robot name")
    radius_m: float = Field(0.8, gt=0, le=1000, description="centre distance that counts")
    end_run: bool = Field(True, description="stop the run at the capture")


def build_capture(cfg: CaptureConfig, robot_names: list[str] | tuple[str, ...]) -> Capture:
    """The metric for a scenario's robots; refuses unknown or equal names."""
    names = list(robot_names)
    for field, name in (("pursuer", cfg.pursuer), ("evader", cfg.evader)):
        if name not in names:
            raise ValueError(f"metrics.capture.{field}: no robot named {name!r} (robots: {names})")
    if cfg.pursuer == cfg.evader:
        raise ValueError("metrics.capture: pursuer and evader must be different robots")
    return Capture(names.index(cfg.pursuer), names.index(cfg.evader), cfg.radius_m, cfg.end_run)
