"""Drive a 1 m square on timers: 2 s straight at 0.5 m/s, a quarter turn left at 0.5 rad/s
(pi s), four times, then stop. Open loop, like a timed Stateflow chart: a timer fires at the
first step at or after its time (``after``), and the last step of a corner turns only what is
left of the 90 deg.

    controller: {type: python, file: examples/square_path.py, name: controller}
"""

from __future__ import annotations

import math

from agvsim.control.api import command_for
from agvsim.control.statemachine import StateMachine, after

SIDE_M, SPEED_M_S, TURN_RATE_RAD_S = 1.0, 0.5, 0.5


def build(sides: int = 4) -> StateMachine:
    sm = StateMachine("square", initial="side", data={"sides_done": 0})

    @sm.state("side")
    def straight(ctx):
        return command_for(ctx.obs, SPEED_M_S, 0.0, 0.0)

    @sm.exit("side")
    def count(ctx):
        ctx.vars["sides_done"] += 1

    @sm.state("corner")
    def turn_left(ctx):  # the last step of a corner turns only what is left of 90 deg
        left_rad = math.pi / 2 - TURN_RATE_RAD_S * ctx.time_in_state
        return command_for(ctx.obs, 0.0, 0.0, min(TURN_RATE_RAD_S, max(left_rad, 0.0) / ctx.dt))

    @sm.state("done")
    def stop(ctx):
        return command_for(ctx.obs, 0.0, 0.0, 0.0)

    side_s = SIDE_M / SPEED_M_S
    corner_s = (math.pi / 2) / TURN_RATE_RAD_S

    def last_side_done(ctx) -> bool:
        return ctx.vars["sides_done"] == sides - 1 and ctx.after(side_s)

    sm.transition("side", "done", guard=last_side_done)  # tested first: declared first
    sm.transition("side", "corner", guard=after(side_s))
    sm.transition("corner", "side", guard=after(corner_s))
    return sm


controller = build()
