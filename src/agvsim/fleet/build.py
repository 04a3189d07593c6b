"""A scenario with a ``vda5050:`` block becomes a ``Fleet``: the simulation, with one vehicle
agent per listed robot driving it (``FleetDriver``), and the layout they run on."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from agvsim.control.api import ControlMode
from agvsim.fleet.battery import Battery
from agvsim.fleet.config import Vda5050Config
from agvsim.fleet.dialect import DIALECTS
from agvsim.fleet.driver import FleetDriver
from agvsim.fleet.vehicle import Lidar, Vehicle, VehicleConfig
from agvsim.scenario import Scenario, ScenarioError, build, build_grid
from agvsim.scenario_schema import IdleConfig, Pose
from agvsim.sim.engine import Binding, Simulation
from agvsim.world.lif import Layout, LifError, layout_from_grid, load_lif


@dataclass
class Fleet:
    sim: Simulation
    vehicles: list[Vehicle]
    layout: Layout | None
    config: Vda5050Config

    @property
    def interface_name(self) -> str:
        return self.config.interface_name

    def topic(self, v: Vehicle, name: str) -> str:
        """``interfaceName/majorVersion/manufacturer/serialNumber/topic``."""
        c = v.cfg
        return f"{self.config.interface_name}/{c.dialect.major}/{c.manufacturer}/{c.serial}/{name}"

    def vehicle(self, serial: str) -> Vehicle:
        for v in self.vehicles:
            if v.cfg.serial == serial:
                return v
        raise KeyError(f"no vehicle {serial!r}")


def vehicle_type_of(cfg: Vda5050Config, model: str) -> str:
    """The LIF vehicleTypeId of a robot model: ``<manufacturer>.<model>``."""
    return f"{cfg.manufacturer}.{model}"


def load_layout(sc: Scenario, base_dir: Path) -> Layout | None:
    lc = sc.layout
    if lc is None:
        return None
    if lc.from_grid:
        cfg = sc.vda5050
        types = sorted({vehicle_type_of(cfg, r.model) for r in sc.robots}) if cfg else ["agv"]
        return layout_from_grid(build_grid(sc.world, base_dir), types, "grid", lc.simplify)
    path = Path(lc.file or "")
    path = path if path.is_absolute() else base_dir / path
    try:
        layouts = load_lif(path)
    except LifError as err:
        raise ScenarioError(sc._source, [f"layout.file: {p}" for p in err.problems]) from None
    if lc.layout_id is None:
        if not layouts:
            raise ScenarioError(sc._source, [f"layout.file: {path.name} holds no layout"])
        return layouts[0]
    for lay in layouts:
        if lay.layout_id == lc.layout_id:
            return lay
    ids = [lay.layout_id for lay in layouts]
    raise ScenarioError(sc._source, [f"layout.layout_id: {lc.layout_id!r} not in {ids}"])


def build_fleet(sc: Scenario, epoch: datetime | None = None, seed: int | None = None) -> Fleet:
    """The simulation and its vehicles; raises ScenarioError for a bad block."""
    cfg = sc.vda5050
    if cfg is None:
        raise ScenarioError(sc._source, ["the scenario has no 'vda5050:' block of vehicles"])
    base = sc._base_dir
    layout = load_layout(sc, base)
    names = [r.name for r in sc.robots]
    problems, robots = [], list(sc.robots)
    for k, v in enumerate(cfg.vehicles):
        where = f"vda5050.vehicles[{k}]"
        if v.robot not in names:
            problems.append(f"{where}.robot: no robot named {v.robot!r}; robots: {names}")
            continue
        i = names.index(v.robot)
        rc = robots[i]
        pose = rc.pose
        if v.start_node is not None:
            if layout is None or v.start_node not in layout.nodes:
                problems.append(f"{where}.start_node: {v.start_node!r} is not a layout node")
                continue
            x, y = layout.node_xy(v.start_node)
            pose = Pose(x_m=x, y_m=y, theta_deg=rc.pose.theta_deg)
        robots[i] = rc.model_copy(
            update={
                "pose": pose,
                "mode": ControlMode.INVERSE,
                "controller": IdleConfig(type="idle"),
            }
        )
    if problems:
        raise ScenarioError(sc._source, problems)
    base_sim = build(sc.model_copy(update={"robots": robots}), seed=seed, base_dir=base)
    epoch = epoch or datetime.now(UTC)
    dialect = DIALECTS[cfg.version]
    vehicles: list[Vehicle] = []
    groups: dict[tuple[str, int] | None, list[tuple[int, Vehicle]]] = {}
    for v in cfg.vehicles:
        i = names.index(v.robot)
        spec = base_sim.robots[i]
        # the robot's own safety scanner's sensor (its safety: block), else the fleet's
        wanted = cfg.safety_sensor if spec.safety is None else spec.safety.sensor
        sensor = next((s for s in spec.sensors if s.name == wanted), None)
        lidar = None
        if sensor is not None:
            ang = sensor.beam_angles_rad + sensor.mount_yaw_rad
            lidar = Lidar(
                np.column_stack([np.cos(ang), np.sin(ang)]), sensor.mount_xy_m, sensor.range_max_m
            )
        vc = VehicleConfig(
            serial=v.serial or v.robot,
            manufacturer=cfg.manufacturer,
            vehicle_type=vehicle_type_of(cfg, sc.robots[i].model),
            dialect=dialect,
            map_id=cfg.map_id,
            max_speed_m_s=cfg.max_speed_m_s,
            state_period_s=cfg.state_period_s,
            vis_period_s=cfg.visualization_period_s,
            action_durations={"pick": cfg.pick_time_s, "drop": cfg.drop_time_s},
            load_kg=v.load_kg,
        )
        battery = (
            Battery(v.battery_pct)
            if spec.dynamics is None
            else Battery.of_energy(v.battery_pct, v.battery_wh)
        )
        veh = Vehicle(vc, spec, layout, lidar, v.start_node, epoch, battery)
        vehicles.append(veh)
        key = None if sensor is None else (sensor.name, sensor.num_beams)
        groups.setdefault(key, []).append((i, veh))
    bindings = list(base_sim.bindings)
    for key, members in groups.items():
        idx = tuple(i for i, _ in members)
        sensor_name = None if key is None else key[0]
        bindings.append(Binding(FleetDriver([veh for _, veh in members], sensor_name), idx, True))
    sim = Simulation(
        base_sim.world,
        base_sim.robots,
        bindings,
        dt_s=base_sim.dt_s,
        seed=base_sim.seed,
        knows={r.name: r.knows for r in sc.robots if r.knows},
        on_controller_error=sc.on_controller_error,
    )
    for b in bindings:
        if isinstance(b.controller, FleetDriver):
            b.controller.watch_power(sim, b.robots)
    return Fleet(sim, vehicles, layout, cfg)
