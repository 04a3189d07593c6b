"""The thesis's obstacle avoidance (Fig. 22) as a state machine.

Drive straight on; when the front ranger reads less than the trigger distance, turn 90 deg to
the right, then drive on. The turn ends when the heading is within a tolerance of the target
(``reached``): the thesis's chart compared the angles with ``==`` and a robot turning in
discrete steps stepped right over the target. A bump backs the robot off for half a second.

Use it in a scenario (each robot that names the file gets a machine of its own):

    controller: {type: python, file: examples/avoid_statemachine.py, name: controller}

or draw it: ``agvsim statechart examples/avoid_statemachine.py:controller``.
"""

from __future__ import annotations

import math

from agvsim.control.api import command_for
from agvsim.control.statemachine import StateMachine, after, reached, wrap

QUARTER = math.pi / 2


def snap(angle: float) -> float:
    """The nearest multiple of 90 deg: a maze's walls are square, so are the robot's headings."""
    return wrap(round(angle / QUARTER) * QUARTER)


def build(
    trigger_m: float = 0.8,
    speed_m_s: float = 0.5,
    turn_rate_rad_s: float = 1.0,
    tolerance_rad: float = 0.01,
    sensor: str = "rangers",
) -> StateMachine:
    """A fresh chart (one per robot)."""
    sm = StateMachine("avoid", initial="drive", data={"target": 0.0})

    @sm.input
    def front(ctx) -> float:  # the front ranger, beam 0 (-inf, too close, counts as 0 m)
        return max(float(ctx.ranges(sensor)[0]), 0.0)

    @sm.entry("drive")
    def keep_heading(ctx):
        ctx.vars["target"] = snap(ctx.heading)

    @sm.state("drive")
    def drive(ctx):  # straight on, steering gently back onto the target heading
        error = wrap(ctx.vars["target"] - ctx.heading)
        omega = max(-turn_rate_rad_s, min(turn_rate_rad_s, 2.0 * error))
        return command_for(ctx.obs, speed_m_s, 0.0, omega)

    @sm.entry("turn_right")
    def aim_right(ctx):
        ctx.vars["target"] = snap(ctx.heading - QUARTER)

    @sm.state("turn_right")
    def turn(ctx):  # on the spot, slower near the target, back if it overshoots
        error = wrap(ctx.vars["target"] - ctx.heading)
        speed = max(0.2, min(1.0, 3.0 * abs(error))) * turn_rate_rad_s
        return command_for(ctx.obs, 0.0, 0.0, math.copysign(speed, error))

    @sm.state("back_off")
    def back_off(ctx):
        return command_for(ctx.obs, -0.5 * speed_m_s, 0.0, 0.0)

    def bumped(ctx) -> bool:
        return ctx.obs.bump

    def heading_reached(ctx) -> bool:
        return reached(ctx.heading, ctx.vars["target"], tolerance_rad)

    # a bump outranks everything else (priority 0 is tested first)
    sm.transition("drive", "back_off", guard=bumped, priority=0)
    sm.transition("turn_right", "back_off", guard=bumped, priority=0)
    sm.transition(
        "drive", "turn_right", guard=lambda ctx: ctx.front < trigger_m, priority=1,
        label=f"front < {trigger_m:g} m",
    )  # fmt: skip
    sm.transition("turn_right", "drive", guard=heading_reached, priority=1)
    sm.transition("back_off", "turn_right", guard=after(0.5))
    return sm


controller = build()  # the scenario loader runs this file once per robot: one machine each
