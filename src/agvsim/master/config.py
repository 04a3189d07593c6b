"""The scenario's ``master:`` block: transport orders, dispatching, charging, breakdowns."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from agvsim.config_base import StrictConfig


class TransportEntry(StrictConfig):
    source: str = Field(description="station id (or node id) to pick the load at")
    destination: str = Field(description="station id (or node id) to drop it at")
    at_s: float = Field(
        default=0.0, ge=0, le=1e7, description="when the order is placed (simulated s)"
    )


class GenerateConfig(StrictConfig):
    """Orders placed at random (Poisson, seeded) between random source and destination."""

    rate_per_h: float = Field(gt=0, le=1e6, description="orders per simulated hour")
    sources: list[str] = Field(default_factory=list, description="default: every station")
    destinations: list[str] = Field(default_factory=list, description="default: every station")
    until_s: float | None = Field(
        default=None, gt=0, description="no new orders after (default: never)"
    )


class ChargingConfig(StrictConfig):
    low_pct: float = Field(default=30.0, ge=0, le=100, description="below this: go and charge")
    full_pct: float = Field(default=90.0, ge=0, le=100, description="charge up to this")

    @model_validator(mode="after")
    def _order(self) -> ChargingConfig:
        if self.full_pct <= self.low_pct:
            raise ValueError(
                f"master.charging: full_pct {self.full_pct} must be above low_pct {self.low_pct}"
            )
        return self


class BreakdownEntry(StrictConfig):
    vehicle: str = Field(description="serial number of the vehicle that fails")
    at_s: float = Field(ge=0, le=1e7, description="when (simulated s): it stops with a FATAL error")


class MasterConfig(StrictConfig):
    fleet_size: int | None = Field(
        default=None, ge=1, description="only the first N vehicles of vda5050 (sweeps)"
    )
    transports: list[TransportEntry] = Field(default_factory=list, max_length=1_000_000)
    generate: GenerateConfig | None = None
    dispatch: Literal["nearest_idle"] = Field(
        default="nearest_idle", description="dispatching policy (agvsim.master.dispatch.POLICIES)"
    )
    charging: ChargingConfig = Field(default_factory=ChargingConfig)
    breakdowns: list[BreakdownEntry] = Field(default_factory=list, max_length=100_000)
    stall_s: float = Field(
        default=300.0, gt=0, description="an order with no progress this long counts as stalled"
    )
    late_s: float = Field(
        default=15.0,
        gt=0,
        description="a vehicle this far behind its plan is re-planned (others stop waiting)",
    )
    margin_s: float = Field(default=0.5, ge=0, le=60, description="planned time between two visits")
    plan_weight: float = Field(
        default=1.3,
        ge=1,
        le=10,
        description="weighted A* in the route search: routes at most this much slower than "
        "the quickest that fits, found far sooner (1: always the quickest)",
    )
    dispatch_plans: int = Field(
        default=50,
        ge=1,
        le=1_000_000,
        description="routes searched a tick to dispatch waiting orders (the rest: next tick)",
    )
    horizon_nodes: int | None = Field(
        default=10,
        ge=0,
        le=1_000_000,
        description="nodes of the route sent beyond the base (the horizon); null: the whole route",
    )
