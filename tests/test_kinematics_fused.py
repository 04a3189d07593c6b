"""The car-like models' actuation kernel (agvsim.kinematics.fused) against the NumPy reference
(agvsim.kinematics.actuation): the same equations in the same order, so the same numbers to
the last bits a transcendental function may differ in (libm against NumPy's own loops), in
both control modes, for any parameters, commands and present steering angle; and the engine,
which runs it for every tricycle and Ackermann group, against the reference step by step."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.kinematics import Ackermann, Tricycle, actuation
from agvsim.kinematics.fused import actuate_car, car_kind, car_params
from agvsim.kinematics.params import HALF_TURN
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.spec import RobotSpec, World
from agvsim.world.grid import OccupancyGrid

HALF_PI = HALF_TURN.lt


def _fused(model, is_twist, twists, wheels, now, dt):
    k = len(now)
    out = (
        np.empty((k, 3)),
        np.empty((k, len(model.wheel_names))),
        np.empty(k),
        np.empty((k, len(model.steered_wheels))),
    )
    kind = car_kind(model)
    assert kind is not None
    parallel = getattr(model, "steering_geometry", "") == "parallel"
    actuate_car(kind, parallel, car_params(model, k), is_twist, twists, wheels, now, dt, *out)
    return out


def _close(got: np.ndarray, want: np.ndarray) -> None:
    # a few ulps of the largest magnitude in play (1e-12 relative is thousands of ulps)
    scale = max(1.0, float(np.abs(want).max(initial=0.0)))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * scale)


finite = st.floats(-3.0, 3.0, allow_nan=False)
SIZES = {
    "wheel_radius_m": st.floats(0.02, 0.5),
    "wheelbase_m": st.floats(0.1, 2.0),
    "half_track_m": st.floats(0.05, 1.0),
    "max_wheel_speed_rad_s": st.floats(1.0, 60.0),
    "max_steer_rate_rad_s": st.floats(0.1, 10.0),
}
models = st.one_of(
    st.builds(Tricycle, **SIZES, max_steer_rad=st.floats(0.1, math.pi / 2)),
    st.builds(
        Ackermann,
        **SIZES,
        max_steer_rad=st.floats(0.1, 0.99 * HALF_PI),
        steering_geometry=st.sampled_from(["ackermann", "parallel"]),
    ),
)


@settings(max_examples=300, deadline=None)
@given(
    model=models,
    twist=st.tuples(finite, finite, finite),
    wheels=st.tuples(st.floats(-80, 80), st.floats(-80, 80), finite),
    now=st.floats(-1.5, 1.5),
    still=st.booleans(),
    dt=st.sampled_from([0.01, 0.02, 0.1]),
)
def test_the_kernel_actuates_as_the_reference(model, twist, wheels, now, still, dt) -> None:
    """Both modes of one robot, in one call of two rows (row 0 a twist, row 1 wheel speeds
    and a steering angle): every output equals from_twist / from_wheels."""
    tw = np.array([(0.0, twist[1], 0.0) if still else twist] * 2)
    nd = len(model.driven_wheels)
    wh = np.array([[wheels[0], wheels[1] if nd == 2 else wheels[2], wheels[2]][: nd + 1]] * 2)
    steer_now = np.array([now, now])
    got = _fused(model, np.array([True, False]), tw, wh, steer_now, dt)
    by_twist = actuation.from_twist(model, tw[:1], steer_now[:1], dt)
    by_wheels = actuation.from_wheels(model, wh[1:, :nd], wh[1:, nd], steer_now[1:], dt)
    for row, ref in ((0, by_twist), (1, by_wheels)):
        _close(got[0][row], ref.twist[0])
        _close(got[1][row], ref.wheel_speeds[0])
        _close(got[2][row : row + 1], ref.steering)
        _close(got[3][row], ref.steer_angles[0])


def test_hand_worked_tricycle_and_ackermann() -> None:
    """A tricycle (r 0.1, L 0.5) asked for 0.5 m/s and 0.5 rad/s from straight wheels: the
    target angle atan(0.25 / 0.5) is rate limited to 3 rad/s x 0.02 s = 0.06 rad, and the front
    wheel turns at (0.5 cos 0.06 + 0.25 sin 0.06) / 0.1 rad/s. An Ackermann car (r 0.1, L 0.5,
    l 0.2, steering held at 0.3 rad) on wheel speeds (4, 6): vx = 0.5, omega = 0.5 tan 0.3 / 0.5,
    its front wheels at atan(k L / (1 -/+ k l)), k = tan 0.3 / 0.5."""
    tri = Tricycle(wheel_radius_m=0.1, wheelbase_m=0.5, half_track_m=0.2)
    tw, _, steering, angles = _fused(
        tri, np.array([True]), np.array([[0.5, 0.0, 0.5]]), np.zeros((1, 2)), np.zeros(1), 0.02
    )
    assert steering[0] == pytest.approx(0.06, abs=1e-15) and angles[0, 0] == steering[0]
    u = (0.5 * math.cos(0.06) + 0.25 * math.sin(0.06)) / 0.1
    assert tw[0] == pytest.approx([0.1 * u * math.cos(0.06), 0.0, 0.1 * u * math.sin(0.06) / 0.5])
    car = Ackermann(wheel_radius_m=0.1, wheelbase_m=0.5, half_track_m=0.2, max_steer_rad=0.6)
    tw, wheels, steering, angles = _fused(
        car,
        np.array([False]),
        np.zeros((1, 3)),
        np.array([[4.0, 6.0, 0.3]]),
        np.array([0.3]),
        0.02,
    )
    w = 0.5 * math.tan(0.3) / 0.5
    assert tw[0] == pytest.approx([0.5, 0.0, w], abs=1e-15)
    assert steering[0] == 0.3 and wheels[0, 2:].tolist() == [4.0, 6.0]
    k = math.tan(0.3) / 0.5
    assert angles[0] == pytest.approx(
        [math.atan(k * 0.5 / (1 - k * 0.2)), math.atan(k * 0.5 / (1 + k * 0.2))], abs=1e-15
    )
    # the inner front wheel runs on the larger circle's share: |(vx - w l, w L)| / r
    assert wheels[0, 0] == pytest.approx(math.hypot(0.5 - w * 0.2, w * 0.5) / 0.1, abs=1e-12)


class _Weave:
    """Batch controller: commands that change every step, in the robots' own modes."""

    def reset(self, k: int, rng: np.random.Generator) -> None:
        self.rng = rng

    def step(self, obs) -> np.ndarray:
        k = len(obs.true_pose)
        out = np.zeros((k, 3))
        out[:, 0] = self.rng.uniform(-0.5, 1.0, k)
        out[:, 2] = self.rng.uniform(-1.5, 1.5, k)
        return out


def test_the_engine_actuates_car_groups_as_the_reference() -> None:
    """Two tricycles and an Ackermann car (in its own group), one of the tricycles in forward
    mode, on an empty floor for 200 steps of changing commands: at every step the executed
    twist, wheel speeds and steering equal the reference actuation of that step's command."""
    from agvsim.control.api import ControlMode

    grid = OccupancyGrid(np.zeros((40, 40), dtype=bool), 1.0, (-20.0, -20.0))
    robots = [
        RobotSpec("t1", Tricycle(), initial_pose=(-4.0, 0.0, 0.0)),
        RobotSpec("a1", Ackermann(half_track_m=0.25), initial_pose=(0.0, 4.0, 0.0)),
        RobotSpec(
            "t2", Tricycle(wheelbase_m=0.7), ControlMode.FORWARD, initial_pose=(4.0, 0.0, 0.0)
        ),
    ]
    sim = Simulation(World(grid), robots, [Binding(_Weave(), (0, 1), batch=True)], seed=3)
    rng = np.random.default_rng(5)
    for _ in range(200):
        sim.control()
        st_ = sim.state
        st_.cmd_wheels[2, :2] = (rng.uniform(-10, 10), rng.uniform(-1.2, 1.2))
        st_.cmd_is_twist[2] = False
        before = st_.steering.copy()
        want = [
            actuation.from_twist(robots[0].model, st_.cmd_twist[:1], before[:1], sim.dt_s),
            actuation.from_twist(robots[1].model, st_.cmd_twist[1:2], before[1:2], sim.dt_s),
            actuation.from_wheels(
                robots[2].model, st_.cmd_wheels[2:, :1], st_.cmd_wheels[2:, 1], before[2:], sim.dt_s
            ),
        ]
        sim.advance()
        assert not st_.bump.any()
        for i, ref in enumerate(want):
            _close(st_.twists[i], ref.twist[0])
            _close(st_.wheel_speeds[i, : ref.wheel_speeds.shape[1]], ref.wheel_speeds[0])
            _close(st_.steering[i : i + 1], ref.steering)
            _close(st_.steer_angles[i, : ref.steer_angles.shape[1]], ref.steer_angles[0])
    assert np.abs(sim.state.steering).max() > 0.3  # the commands did steer
