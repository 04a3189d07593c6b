"""Benchmark of planar dynamics (issue 20): what a step costs with every robot dynamic against
the same robots moving kinematically, at 50 Hz control.

Two workloads, each run kinematic then dynamic (figures printed, never asserted):

* ``bare``: N differential robots on an open floor, no sensors, a batch controller driving
  arcs (0.8 m/s, 0.4 rad/s): the step is nothing but actuation, motion and collision checks,
  so the ratio is the dynamics' own cost;
* ``fleet``: ``agvsim bench``'s fleet (thesis maze, 240-beam lidars at 10 Hz, obstacle
  avoidance), the robots given a 60 kg dynamics block.

The dynamics uses its automatic sub-steps (reported, with the compile time apart). Rates are
steps per CPU second (see ``_rate``).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numba
import numpy as np

from agvsim.bench import fleet
from agvsim.dynamics import DynamicsSpec, MotorSpec
from agvsim.kinematics import DifferentialDrive
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.spec import OdometrySpec, RobotSpec, World
from agvsim.world.grid import OccupancyGrid

SPEC = DynamicsSpec(mass_kg=60.0, motor=MotorSpec(torque_max_nm=1.5))


class Arcs:
    """Batch controller: every robot drives the same arc."""

    def reset(self, k: int, rng: np.random.Generator) -> None:
        self.cmd = np.tile([0.8, 0.0, 0.4], (k, 1))

    def step(self, obs: object) -> np.ndarray:
        return self.cmd


def bare(n: int, dynamic: bool) -> Simulation:
    side = int(np.ceil(np.sqrt(n)))
    size = 4 * side + 4
    grid = OccupancyGrid(np.zeros((size, size), bool), 1.0, (-size / 2, -size / 2))
    xs = (np.arange(n) % side) * 4.0 - size / 2 + 4.0
    ys = (np.arange(n) // side) * 4.0 - size / 2 + 4.0
    model = DifferentialDrive(wheel_radius_m=0.1, half_track_m=0.25)
    robots = [
        RobotSpec(
            f"r{i}",
            model,
            initial_pose=(float(xs[i]), float(ys[i]), 0.0),
            body_length_m=0.5,
            body_width_m=0.4,
            odometry=OdometrySpec(0.01),
            dynamics=SPEC if dynamic else None,
        )
        for i in range(n)
    ]
    return Simulation(World(grid), robots, [Binding(Arcs(), tuple(range(n)), batch=True)])


def dynamic_fleet(n: int) -> Simulation:
    sim = fleet(n)
    robots = [replace(r, dynamics=SPEC) for r in sim.robots]
    return Simulation(sim.world, robots, sim.bindings, dt_s=sim.dt_s, seed=sim.seed)


def _rate(sim: Simulation, steps: int, warm: int = 5) -> float:
    """Steps per CPU second of this process (time.process_time: on a shared machine other
    processes' load does not count; numba runs one thread here, so it equals wall time on an
    idle machine)."""
    for _ in range(warm):
        sim.step()
    t0 = time.process_time()
    for _ in range(steps):
        sim.step()
    return steps / (time.process_time() - t0)


def dynamics_benchmark(quick: bool = False, n: int = 1000) -> dict:
    t0 = time.perf_counter()
    first = bare(1, True)
    first.step()  # compile or load the kernels
    out: dict = {
        "robots": n,
        "dt_s": first.dt_s,
        "first_step_s": round(time.perf_counter() - t0, 2),
        "threads": numba.get_num_threads(),
    }
    steps = 50 if quick else 200
    for name, make in (("bare", lambda d: bare(n, d)), ("fleet", None)):
        kin = make(False) if make else fleet(n)
        dyn = make(True) if make else dynamic_fleet(n)
        k_rate = _rate(kin, steps)
        d_rate = _rate(dyn, steps)
        assert dyn.dynamics is not None
        out[name] = {
            "kinematic_steps_per_s": round(k_rate, 1),
            "dynamic_steps_per_s": round(d_rate, 1),
            "cost_ratio": round(k_rate / d_rate, 2),
            "substeps_per_step": int(dyn.dynamics.last_substeps.max()),
        }
    return out
