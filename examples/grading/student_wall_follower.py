"""An example student controller: follow the wall on the left with the lidar.

Keeping a hand on the left wall walks every corridor of a maze without loops, so it finds any
goal in one, without a map. It is graded with

    agvsim grade examples/grading/student_wall_follower.py --suite examples/grading/suite.yaml

The grader loads ``controller`` from this file (a class is made once per task): an object with
``reset()`` and ``step(obs) -> Twist``, as any ``python`` controller of a scenario.
"""

import math

import numpy as np

from agvsim.control.api import Twist


class LeftWallFollower:
    """Drive at ``speed_m_s`` with the left wall ``wall_m`` away; turn right on the spot when
    something is ahead; swing left round a corner when the wall on the left ends."""

    def __init__(self, wall_m: float = 0.55, speed_m_s: float = 0.6):
        self.wall_m, self.speed_m_s = wall_m, speed_m_s
        self.reset()

    def reset(self):
        self.state_name = "follow"
        self.back_until_s = -1.0

    def step(self, obs):
        scan = obs.scans["lidar"]
        ranges = np.where(np.isposinf(scan.ranges), scan.range_max_m, scan.ranges)
        ranges = np.maximum(ranges, 0.0)  # -inf: closer than range_min
        angles = scan.robot_angle_min_rad + scan.angle_increment_rad * np.arange(ranges.size)

        def nearest(lo_deg, hi_deg):
            inside = (angles >= math.radians(lo_deg)) & (angles <= math.radians(hi_deg))
            return float(ranges[inside].min())

        front = nearest(-20, 20)
        front_left = nearest(20, 60)
        left = nearest(60, 110)
        if obs.bump:  # touched something: back off for half a second
            self.back_until_s = obs.t_s + 0.5
        if obs.t_s < self.back_until_s:
            self.state_name = "back_off"
            return Twist(-0.2, 0.0, -0.5)
        blocked = front < self.wall_m + 0.25 or front_left < 0.7 * self.wall_m
        if self.state_name == "turn_right":  # turn until the way ahead is clear
            blocked = front < self.wall_m + 0.6 or front_left < self.wall_m
        if blocked:
            self.state_name = "turn_right"
            return Twist(0.0, 0.0, -1.2)
        if left > 2.0 * self.wall_m and front_left > 2.5 * self.wall_m:
            self.state_name = "round_corner"
            return Twist(0.6 * self.speed_m_s, 0.0, 1.0)
        self.state_name = "follow"
        turn = float(np.clip(1.0 * (left - self.wall_m), -1.2, 1.2))
        return Twist(self.speed_m_s, 0.0, turn)


controller = LeftWallFollower
