"""Lidar on an image map: ranges agree with the true (curved) geometry within the resolution."""

from __future__ import annotations

import numpy as np
from PIL import Image

from agvsim.kinematics import Mecanum
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.engine import Simulation
from agvsim.sim.spec import RobotSpec, World
from agvsim.world.loaders import load_image

RES = 0.05
R_IN, R_OUT = 3.0, 3.5


def ring_png(path) -> None:
    """A 10 m x 10 m picture at 0.05 m per pixel: a black ring around the centre."""
    n = 200
    c = (np.arange(n) + 0.5) * RES - 5.0  # pixel centres, metres from the image centre
    x, y = np.meshgrid(c, -c)  # image row 0 is north
    r = np.hypot(x, y)
    img = np.where((r >= R_IN) & (r <= R_OUT), 0, 255).astype(np.uint8)
    Image.fromarray(img).save(path)


def test_lidar_inside_a_ring_matches_the_circle(tmp_path):
    ring_png(tmp_path / "ring.png")
    grid = load_image(tmp_path / "ring.png", resolution_m=RES)
    assert grid.extent_m == (-5.0, 5.0, -5.0, 5.0)
    lidar = RangeSensorSpec.fan("lidar", 720, 2 * np.pi, 10.0, rate_hz=10.0)
    p = np.array([0.7, -0.4])
    robot = RobotSpec(
        "r",
        Mecanum(),
        initial_pose=(p[0], p[1], 0.3),
        body_length_m=0.4,
        body_width_m=0.4,
        sensors=(lidar,),
    )
    sim = Simulation(World(grid), [robot])
    scan = sim.observation(0).scans["lidar"]
    a = 0.3 + scan.angle_min_rad + scan.angle_increment_rad * np.arange(720)
    d = np.column_stack([np.cos(a), np.sin(a)])
    pd = d @ p
    exact = -pd + np.sqrt(pd**2 - p @ p + R_IN**2)  # distance to the inner circle
    err = scan.ranges - exact
    # a pixel whose centre is on the circle may stick out by up to half its diagonal
    assert np.all(np.abs(err) <= RES * np.sqrt(2) / 2 + 1e-9)
    assert np.abs(err).mean() < RES / 2
