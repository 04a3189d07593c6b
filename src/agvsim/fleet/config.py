"""The scenario's ``layout:`` and ``vda5050:`` blocks (validated like the rest of the file)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from agvsim.config_base import StrictConfig


class LayoutConfig(StrictConfig):
    """A LIF file (path beside the scenario), or a layout derived from the world's grid."""

    file: str | None = Field(default=None, description="LIF file (.json) next to the scenario")
    layout_id: str | None = Field(
        default=None, description="which layout of the file (default: first)"
    )
    from_grid: bool = Field(default=False, description="derive nodes and edges from the free cells")
    simplify: bool = Field(
        default=True, description="derived: nodes only at junctions, corners, ends"
    )

    @model_validator(mode="after")
    def _one_source(self) -> LayoutConfig:
        if (self.file is None) == (not self.from_grid):
            raise ValueError("layout: give either 'file' or 'from_grid: true'")
        return self


class VehicleEntry(StrictConfig):
    robot: str = Field(description="name of the robot that is this vehicle")
    serial: str | None = Field(
        default=None,
        pattern=r"^[A-Za-z0-9_.:-]+$",
        description="serialNumber (default: the robot's name)",
    )
    start_node: str | None = Field(default=None, description="layout node it starts parked on")
    battery_pct: float = Field(default=80.0, ge=0, le=100)
    load_kg: float = Field(
        default=50.0,
        ge=0,
        le=100_000,
        description="mass of a picked load whose pick action gives no 'weight' (kg): carried "
        "by a robot with a dynamics: block, it changes its mass and braking",
    )
    battery_wh: float = Field(
        default=1000.0,
        gt=0,
        le=1e7,
        description="energy at 100 % charge (Wh): a robot with a dynamics: block drains it by "
        "its motors' power; without one the charge drains by distance",
    )


class Vda5050Config(StrictConfig):
    version: Literal["2.1.0", "3.0.0"] = "2.1.0"
    interface_name: str = Field(default="uagv", pattern=r"^[A-Za-z0-9_.:-]+$")
    manufacturer: str = Field(default="agvsim", pattern=r"^[A-Za-z0-9_.:-]+$")
    map_id: str = "map"
    safety_sensor: str = Field(
        default="lidar", description="the range fan the protective field reads"
    )
    max_speed_m_s: float = Field(default=1.0, gt=0, le=10)
    state_period_s: float = Field(default=1.0, gt=0, le=30, description="state at least this often")
    visualization_period_s: float = Field(
        default=1.0, ge=0, le=60, description="0: no visualization"
    )
    pick_time_s: float = Field(default=3.0, ge=0, le=3600)
    drop_time_s: float = Field(default=3.0, ge=0, le=3600)
    vehicles: list[VehicleEntry] = Field(min_length=1, max_length=100_000)

    @model_validator(mode="after")
    def _unique(self) -> Vda5050Config:
        robots = [v.robot for v in self.vehicles]
        serials = [v.serial or v.robot for v in self.vehicles]
        for what, vals in (("robots", robots), ("serials", serials)):
            dup = sorted({x for x in vals if vals.count(x) > 1})
            if dup:
                raise ValueError(f"vda5050.vehicles: {what} must be unique; repeated: {dup}")
        return self
