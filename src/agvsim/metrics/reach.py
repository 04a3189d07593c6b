"""Reach: when does a robot first come within ``radius_m`` of a goal point?

Checked after every step on the robot's reference point (ground truth). Reports whether and
when it got there, the path length travelled by then, and its closest approach.
"""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field


class Reach:
    """Metric: ``update(sim)`` each step (True once reached when ``end_run``), ``result()``."""

    def __init__(
        self,
        robot_index: int,
        goal_xy_m: tuple[float, float],
        radius_m: float,
        end_run: bool = True,
    ):
        if not radius_m > 0:
            raise ValueError(f"radius_m must be > 0, got {radius_m}")
        self.robot, self.goal = int(robot_index), (float(goal_xy_m[0]), float(goal_xy_m[1]))
        self.radius_m, self.end_run = float(radius_m), bool(end_run)
        self.reached = False
        self.time_s: float | None = None
        self.distance_m: float | None = None
        self.min_distance_m = math.inf

    def update(self, sim) -> bool:
        x, y = sim.state.poses[self.robot, :2]
        d = math.hypot(x - self.goal[0], y - self.goal[1])
        self.min_distance_m = min(self.min_distance_m, d)
        if not self.reached and d <= self.radius_m:
            self.reached, self.time_s = True, float(sim.state.t_s)
            self.distance_m = float(sim.state.distance_m[self.robot])
        return self.reached and self.end_run

    def result(self) -> dict:
        return {
            "reached": self.reached,
            "time_to_goal_s": self.time_s,
            "path_length_m": self.distance_m,
            "min_distance_m": self.min_distance_m if math.isfinite(self.min_distance_m) else None,
        }


class ReachConfig(BaseModel):
    """``metrics: {reach: {robot: agv1, x_m: 4.5, y_m: -4.5, radius_m: 0.5}}``"""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    robot: str = Field(min_length=1, description="robot name")
    x_m: float = Field(description="goal, world frame")
    y_m: float = Field(description="goal, world frame")
    radius_m: float = Field(0.5, gt=0, le=1000, description="distance that counts as there")
    end_run: bool = Field(True, description="stop the run when reached")


def build_reach(cfg: ReachConfig, robot_names: list[str] | tuple[str, ...]) -> Reach:
    names = list(robot_names)
    if cfg.robot not in names:
        raise ValueError(f"metrics.reach.robot: no robot named {cfg.robot!r}; robots: {names}")
    return Reach(names.index(cfg.robot), (cfg.x_m, cfg.y_m), cfg.radius_m, cfg.end_run)
