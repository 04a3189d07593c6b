"""Kinematic models (agvsim.kinematics): the contract checker on every model, golden values worked
by hand from the reference equations (DESIGN.md section 3), and hypothesis properties."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from agvsim.kinematics import (
    MODELS,
    Ackermann,
    DifferentialDrive,
    Mecanum,
    Omni3,
    Tricycle,
    actuation,
    contract,
    from_twist,
    from_wheels,
    integrate_se2,
    stack_models,
    wrap_angle,
)
from agvsim.kinematics.contract import check_model

# deterministic hypothesis runs, set per test (no global profile: other test files are not ours)
PROPERTY = settings(
    derandomize=True,
    database=None,
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)

KINDS = sorted(MODELS)


def rows(*values: float) -> np.ndarray:
    """One robot's values as a (1, k) batch."""
    return np.array([values], dtype=np.float64)


# --------------------------------------------------------------------------- contract checker


@pytest.mark.parametrize("kind", KINDS)
def test_contract_default_parameters(kind: str) -> None:
    check_model(MODELS[kind]())


def _resized(model, factor: float):
    """A copy of ``model`` with every length times ``factor`` and a different wheel limit."""
    changes = {
        f.name: getattr(model, f.name) * factor
        for f in dataclasses.fields(model)
        if f.name.endswith("_m")
    }
    changes["max_wheel_speed_rad_s"] = model.max_wheel_speed_rad_s * (2.0 - factor / 2.0)
    return dataclasses.replace(model, **changes)


@pytest.mark.parametrize("kind", KINDS)
def test_contract_stack_of_three_sizes(kind: str) -> None:
    base = MODELS[kind]()
    stacked = stack_models([_resized(base, f) for f in (0.6, 1.0, 1.7)])
    assert np.shape(stacked.wheel_radius_m) == (3,)
    check_model(stacked, rng=np.random.default_rng(7))


def test_contract_ackermann_variants() -> None:
    check_model(Ackermann(steering_geometry="parallel"))
    check_model(Tricycle(max_steer_rad=0.7, max_steer_rate_rad_s=1.0))
    # per-robot steering limits in one stack
    check_model(
        stack_models(
            [Ackermann(max_steer_rad=a, max_steer_rate_rad_s=1.0 + a) for a in (0.3, 0.6, 0.9)]
        )
    )


# broken models: the checker must catch each one and say which property failed


@dataclasses.dataclass(frozen=True)
class _SwappedWheels(DifferentialDrive):
    def forward(self, drive, steering=None):
        return super().forward(drive[..., ::-1], steering)


@dataclasses.dataclass(frozen=True)
class _WrongDriveFor(Tricycle):
    def drive_for(self, twist, steering):
        return twist[..., :1] / self.wheel_radius_m  # ignores the steering angle


@dataclasses.dataclass(frozen=True)
class _BatchDependent(Mecanum):
    def forward(self, drive, steering=None):
        out = super().forward(drive, steering)
        return out + 1e-6 * len(out)  # depends on how many robots are in the batch


@dataclasses.dataclass(frozen=True)
class _FlatPositions(Omni3):
    def wheel_positions_m(self):
        return super().wheel_positions_m().reshape(-1)


@dataclasses.dataclass(frozen=True)
class _SkidSteer(Ackermann):
    def steer_angles_for(self, steering):
        return super().steer_angles_for(steering) * 1.01


@pytest.mark.parametrize(
    ("model", "prop"),
    [
        (_SwappedWheels(), "forward(inverse(t)) == t"),
        (_WrongDriveFor(), "drive_for(t, inverse(t).steering)"),
        (_BatchDependent(), "forward(inverse(t)) == t"),
        (_FlatPositions(), "wheel_positions_m"),
        (_SkidSteer(), "wheels roll"),
    ],
)
def test_contract_catches_broken_models(model, prop: str) -> None:
    with pytest.raises(AssertionError) as info:
        check_model(model)
    message = str(info.value)
    assert type(model).__name__ in message
    assert prop in message


def _euler_steps(poses, twists, dt):
    """Explicit Euler: a regular polygon, which closes after a full turn like the exact map."""
    out = np.array(poses, dtype=np.float64)
    th = out[:, 2].copy()
    out[:, 0] += (np.cos(th) * twists[:, 0] - np.sin(th) * twists[:, 1]) * dt
    out[:, 1] += (np.sin(th) * twists[:, 0] + np.cos(th) * twists[:, 1]) * dt
    out[:, 2] = wrap_angle(th + twists[:, 2] * dt)
    return out


def test_contract_catches_euler_integration(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(contract, "integrate_se2", _euler_steps)
    with pytest.raises(AssertionError, match="full circle"):
        check_model(DifferentialDrive())


def test_contract_catches_per_wheel_clipping(monkeypatch: pytest.MonkeyPatch) -> None:
    exact = actuation.from_drive

    def clipped(model, drive, steering):
        limit = model.max_wheel_speed_rad_s
        return exact(model, np.clip(drive, -limit, limit), steering)

    monkeypatch.setattr(actuation, "from_drive", clipped)
    with pytest.raises(AssertionError, match="saturation keeps direction"):
        check_model(DifferentialDrive())


def test_contract_batch_consistency_is_checked() -> None:
    @dataclasses.dataclass(frozen=True)
    class FirstRobotLimits(DifferentialDrive):
        """Uses robot 0's radius for every robot of a stack in forward mode."""

        def forward(self, drive, steering=None):
            r = np.asarray(self.wheel_radius_m)
            one = dataclasses.replace(self, wheel_radius_m=r.flat[0] + 0 * r)
            return DifferentialDrive.forward(one, drive, steering)

    stacked = stack_models([FirstRobotLimits(wheel_radius_m=r) for r in (0.1, 0.1, 0.1)])
    check_model(stacked)  # equal radii: nothing to see
    stacked = stack_models([FirstRobotLimits(wheel_radius_m=r) for r in (0.1, 0.2, 0.3)])
    with pytest.raises(AssertionError, match="FirstRobotLimits"):
        check_model(stacked)


# --------------------------------------------------------------------------- golden values


def test_differential_golden() -> None:
    m = DifferentialDrive(wheel_radius_m=0.1, half_track_m=0.25)
    # v = r (phi_r + phi_l) / 2 = 0.1 * (5 + 5) / 2 = 0.5; omega = 0.1 * (5 - 5) / 0.5 = 0
    np.testing.assert_allclose(m.forward(rows(5.0, 5.0)), rows(0.5, 0.0, 0.0), atol=1e-15)
    # v = 0.1 * (6 + 4) / 2 = 0.5; omega = 0.1 * (6 - 4) / (2 * 0.25) = 0.2 / 0.5 = 0.4
    np.testing.assert_allclose(m.forward(rows(4.0, 6.0)), rows(0.5, 0.0, 0.4), atol=1e-15)
    # phi_l = (0.5 - 0.4 * 0.25) / 0.1 = 0.4 / 0.1 = 4; phi_r = (0.5 + 0.1) / 0.1 = 6
    ws = m.inverse(rows(0.5, 0.0, 0.4))
    np.testing.assert_allclose(ws.speeds, rows(4.0, 6.0), rtol=1e-14)
    assert ws.steer_angles.shape == (1, 0)
    # wheel positions: left at y = +l, right at y = -l
    np.testing.assert_array_equal(m.wheel_positions_m(), [[0.0, 0.25], [0.0, -0.25]])


def test_mecanum_golden() -> None:
    m = Mecanum(wheel_radius_m=0.05, half_length_m=0.2, half_width_m=0.15)
    # k = lx + ly = 0.35; twist (0.4, 0.2, 1.0):
    # w1 = (0.4 - 0.2 - 0.35) / 0.05 = -0.15 / 0.05 = -3
    # w2 = (0.4 + 0.2 + 0.35) / 0.05 =  0.95 / 0.05 = 19
    # w3 = (0.4 + 0.2 - 0.35) / 0.05 =  0.25 / 0.05 = 5
    # w4 = (0.4 - 0.2 + 0.35) / 0.05 =  0.55 / 0.05 = 11
    ws = m.inverse(rows(0.4, 0.2, 1.0))
    np.testing.assert_allclose(ws.speeds, rows(-3.0, 19.0, 5.0, 11.0), rtol=1e-13)
    # forward: vx = 0.05/4 (-3 + 19 + 5 + 11) = 0.0125 * 32 = 0.4
    #          vy = 0.0125 (3 + 19 + 5 - 11) = 0.0125 * 16 = 0.2
    #          omega = 0.05 / (4 * 0.35) (3 + 19 - 5 + 11) = 28 * 0.05 / 1.4 = 1.0
    np.testing.assert_allclose(m.forward(rows(-3.0, 19.0, 5.0, 11.0)), rows(0.4, 0.2, 1.0))
    # wheels 1 front-left (lx, ly), 2 front-right (lx, -ly), 3 rear-left, 4 rear-right
    np.testing.assert_array_equal(
        m.wheel_positions_m(), [[0.2, 0.15], [0.2, -0.15], [-0.2, 0.15], [-0.2, -0.15]]
    )
    assert m.wheel_names == ("front_left", "front_right", "rear_left", "rear_right")
    # pure strafe: (-10, 10, 10, -10) -> vy = 0.0125 * 40 = 0.5, vx = omega = 0
    np.testing.assert_allclose(
        m.forward(rows(-10.0, 10.0, 10.0, -10.0)), rows(0.0, 0.5, 0.0), atol=1e-15
    )


def test_omni3_golden() -> None:
    m = Omni3(wheel_radius_m=0.05, base_radius_m=0.2)
    # wheels at 0, 120, 240 deg: sin = (0, s3/2, -s3/2), cos = (1, -1/2, -1/2), s3 = sqrt(3)
    # phi_i = (-sin a_i vx + cos a_i vy + R omega) / r, twist (0.1 s3, 0.3, 1):
    # -sin a_i vx = (0, -0.15, +0.15); cos a_i vy = (0.3, -0.15, -0.15); R omega = 0.2
    # phi = (0 + 0.3 + 0.2, -0.15 - 0.15 + 0.2, 0.15 - 0.15 + 0.2) / 0.05 = (10, -2, 4)
    s3 = 1.7320508075688772
    ws = m.inverse(rows(0.1 * s3, 0.3, 1.0))
    np.testing.assert_allclose(ws.speeds, rows(10.0, -2.0, 4.0), rtol=1e-13, atol=1e-13)
    # forward: vx = (2 r / 3) sum(-sin a_i phi_i) = (0.1/3)(0 + s3 + 2 s3) = 0.1 s3
    #          vy = (0.1/3)(10 + 1 - 2) = 0.3; omega = 0.05 / 0.6 * (10 - 2 + 4) = 1
    np.testing.assert_allclose(m.forward(rows(10.0, -2.0, 4.0)), rows(0.1 * s3, 0.3, 1.0))
    # spinning on the spot: every wheel R omega / r = 0.2 / 0.05 = 4
    np.testing.assert_allclose(m.inverse(rows(0.0, 0.0, 1.0)).speeds, rows(4.0, 4.0, 4.0))
    # wheel 0 ("front") at (R, 0)
    np.testing.assert_allclose(m.wheel_positions_m()[0], [0.2, 0.0])


def test_tricycle_golden() -> None:
    m = Tricycle(wheel_radius_m=0.1, wheelbase_m=0.5, half_track_m=0.2)
    # v = 1, omega = 2: delta = atan(L omega / v) = atan(0.5 * 2 / 1) = atan(1) = pi/4
    # front wheel v / (r cos delta) = 1 / (0.1 * sqrt(2)/2) = 10 sqrt(2) = 14.142135623730951
    # rear wheels (R -/+ l) v / (R r), R = L / tan(delta) = 0.5:
    #   (0.5 - 0.2) / (0.5 * 0.1) = 6,  (0.5 + 0.2) / 0.05 = 14   (= (v -/+ omega l) / r)
    ws = m.inverse(rows(1.0, 0.0, 2.0))
    np.testing.assert_allclose(ws.steering, [0.7853981633974483], rtol=1e-15)
    np.testing.assert_allclose(ws.steer_angles, [[0.7853981633974483]], rtol=1e-15)
    np.testing.assert_allclose(ws.speeds, rows(14.142135623730951, 6.0, 14.0), rtol=1e-14)
    # forward: vx = r u cos(delta) = 0.1 * 10 sqrt(2) * sqrt(2)/2 = 1, omega = r u sin / L = 2
    got = m.forward(rows(14.142135623730951), np.array([0.7853981633974483]))
    np.testing.assert_allclose(got, rows(1.0, 0.0, 2.0), rtol=1e-14, atol=1e-15)
    # front wheel at (L, 0), rear wheels on the axle through the reference point
    np.testing.assert_array_equal(m.wheel_positions_m(), [[0.5, 0.0], [0.0, 0.2], [0.0, -0.2]])
    assert m.wheel_names == ("front", "rear_left", "rear_right")
    # turning on the spot (v = 0, omega = 1): delta = 90 deg, front L omega / r = 5,
    # rear (0 -/+ 0.2) / 0.1 = -2, 2
    ws = m.inverse(rows(0.0, 0.0, 1.0))
    np.testing.assert_allclose(ws.steering, [math.pi / 2])
    np.testing.assert_allclose(ws.speeds, rows(5.0, -2.0, 2.0), rtol=1e-14)


def test_ackermann_golden_true_geometry() -> None:
    m = Ackermann(wheel_radius_m=0.1, wheelbase_m=0.5, half_track_m=0.2)
    # v = 1, omega = 1: R = v / omega = 1; bicycle delta = atan(L / R) = atan(0.5)
    # front left (inner, y = +l): atan(L / (R - l)) = atan(0.5 / 0.8) = atan(0.625)
    #   = 0.5585993153435624 rad (32.005 deg), speed sqrt(0.8^2 + 0.5^2) |omega| / r
    #   = sqrt(0.89) * 10 = 9.433981132056603
    # front right (outer): atan(0.5 / 1.2) = atan(5/12) = 0.39479111969976155 (22.620 deg),
    #   speed sqrt(1.2^2 + 0.5^2) / 0.1 = sqrt(1.69) / 0.1 = 1.3 / 0.1 = 13
    # rear (R -/+ l) v / (R r) = 0.8 / 0.1 = 8, 1.2 / 0.1 = 12
    ws = m.inverse(rows(1.0, 0.0, 1.0))
    np.testing.assert_allclose(ws.steering, [0.4636476090008061], rtol=1e-15)
    np.testing.assert_allclose(
        ws.steer_angles, rows(0.5585993153435624, 0.39479111969976155), rtol=1e-14
    )
    np.testing.assert_allclose(ws.speeds, rows(9.433981132056603, 13.0, 8.0, 12.0), rtol=1e-14)
    np.testing.assert_array_equal(
        m.wheel_positions_m(), [[0.5, 0.2], [0.5, -0.2], [0.0, 0.2], [0.0, -0.2]]
    )
    # forward: vx = r (8 + 12) / 2 = 1, omega = vx tan(atan 0.5) / L = 0.5 / 0.5 = 1
    got = m.forward(rows(8.0, 12.0), np.array([0.4636476090008061]))
    np.testing.assert_allclose(got, rows(1.0, 0.0, 1.0), rtol=1e-14, atol=1e-15)

    # turning right (omega = -1, R = -1): the left wheel is now the outer one
    # left atan(0.5 / (-1 - 0.2)) = -atan(5/12), speed sqrt(1.44 + 0.25) * 1 / 0.1 = 13
    # right atan(0.5 / (-1 + 0.2)) = -atan(0.625), speed 9.433981132056603
    # rear (1 -/+ (-1)(0.2)) / 0.1 = 12, 8
    ws = m.inverse(rows(1.0, 0.0, -1.0))
    np.testing.assert_allclose(
        ws.steer_angles, rows(-0.39479111969976155, -0.5585993153435624), rtol=1e-14
    )
    np.testing.assert_allclose(ws.speeds, rows(13.0, 9.433981132056603, 12.0, 8.0), rtol=1e-14)

    # reversing on the same circle (v = -1, omega = -1, R = 1): same angles, every wheel rolls
    # backwards, so the speeds are the negatives of the first case
    ws = m.inverse(rows(-1.0, 0.0, -1.0))
    np.testing.assert_allclose(
        ws.steer_angles, rows(0.5585993153435624, 0.39479111969976155), rtol=1e-14
    )
    np.testing.assert_allclose(ws.speeds, rows(-9.433981132056603, -13.0, -8.0, -12.0), rtol=1e-14)

    # forward mode gives the same per-wheel angles for the bicycle angle atan(0.5)
    act = from_wheels(
        m, rows(10.0, 10.0), np.array([0.4636476090008061]), np.array([0.4636476090008061]), 0.05
    )
    np.testing.assert_allclose(
        act.steer_angles, rows(0.5585993153435624, 0.39479111969976155), rtol=1e-14
    )


def test_ackermann_golden_parallel_option() -> None:
    m = Ackermann(
        wheel_radius_m=0.1, wheelbase_m=0.5, half_track_m=0.2, steering_geometry="parallel"
    )
    # the thesis's approximation: both front wheels at the bicycle angle atan(0.5)
    ws = m.inverse(rows(1.0, 0.0, 1.0))
    np.testing.assert_allclose(
        ws.steer_angles, rows(0.4636476090008061, 0.4636476090008061), rtol=1e-15
    )
    np.testing.assert_allclose(ws.speeds, rows(9.433981132056603, 13.0, 8.0, 12.0), rtol=1e-14)
    act = from_wheels(
        m, rows(8.0, 12.0), np.array([0.4636476090008061]), np.array([0.4636476090008061]), 0.05
    )
    np.testing.assert_allclose(
        act.steer_angles, rows(0.4636476090008061, 0.4636476090008061), rtol=1e-15
    )


def test_steering_rate_and_angle_limits_golden() -> None:
    m = Ackermann(max_steer_rad=0.6108652381980153, max_steer_rate_rad_s=2.0)  # 35 deg
    # target 1.0 rad is beyond 35 deg = 0.6108652381980153; steps of 2 rad/s * 0.1 s = 0.2 rad
    expected = [0.2, 0.4, 0.6, 0.6108652381980153, 0.6108652381980153]
    now = np.array([0.0])
    for want in expected:
        now = from_wheels(m, rows(10.0, 10.0), np.array([1.0]), now, 0.1).steering
        np.testing.assert_allclose(now, [want], rtol=0, atol=1e-12)
    # models without steering always report 0
    act = from_wheels(DifferentialDrive(), rows(1.0, 2.0), np.array([1.0]), np.array([0.0]), 0.1)
    np.testing.assert_array_equal(act.steering, [0.0])


def test_saturation_golden() -> None:
    m = DifferentialDrive(wheel_radius_m=0.1, half_track_m=0.25, max_wheel_speed_rad_s=20.0)
    # twist (2.5, 0, 2): phi_l = (2.5 - 0.5) / 0.1 = 20, phi_r = (2.5 + 0.5) / 0.1 = 30 > 20,
    # so both wheels are scaled by 20 / 30: (40/3, 20), and the twist to (5/3, 0, 4/3)
    act = from_twist(m, rows(2.5, 0.0, 2.0), np.zeros(1), 0.05)
    np.testing.assert_allclose(act.drive, rows(40.0 / 3.0, 20.0), rtol=1e-14)
    np.testing.assert_allclose(act.twist, rows(5.0 / 3.0, 0.0, 4.0 / 3.0), rtol=1e-14)
    # forward mode: (-60, 15) peaks at 60 -> scaled by 1/3 to (-20, 5)
    act = from_wheels(m, rows(-60.0, 15.0), np.zeros(1), np.zeros(1), 0.05)
    np.testing.assert_allclose(act.drive, rows(-20.0, 5.0), rtol=1e-14)


@pytest.mark.parametrize("dt", [0.02, 0.05])
@pytest.mark.parametrize("steps", [50, 157, 1000])
def test_full_circle_returns_to_start(steps: int, dt: float) -> None:
    omega = 2.0 * math.pi / (steps * dt)
    twists = np.array([[0.5, 0.0, omega], [0.3, 0.2, -omega]])  # a car and a holonomic robot
    start = np.array([[1.0, -2.0, 3.0], [-4.0, 0.5, -3.1]])
    pose = start
    for _ in range(steps):
        pose = integrate_se2(pose, twists, dt)
    np.testing.assert_allclose(pose[:, :2], start[:, :2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(wrap_angle(pose[:, 2] - start[:, 2]), 0.0, atol=1e-9)
    # halfway round (steps even) the car is at the far side of its circle: 2 R = 2 v / omega
    if steps % 2 == 0:
        pose = start[:1]
        for _ in range(steps // 2):
            pose = integrate_se2(pose, twists[:1], dt)
        dist = math.hypot(pose[0, 0] - 1.0, pose[0, 1] + 2.0)
        assert dist == pytest.approx(2 * 0.5 / omega, rel=1e-12)


# --------------------------------------------------------------------------- properties


speeds = st.floats(-2.0, 2.0, allow_nan=False)


def reachable(model, vx: float, vy: float, omega: float) -> np.ndarray:
    """(vx, vy, omega) projected on what ``model`` can do: vy = 0 if non-holonomic; for car-like
    models omega = vx tan(delta) / L with |delta| <= 0.99 max_steer (so omega = 0 at vx = 0
    when max_steer < 90 deg)."""
    if not model.holonomic:
        vy = 0.0
    if model.has_steering and model.max_steer_rad < math.pi / 2:
        cap = abs(vx) * math.tan(0.99 * model.max_steer_rad) / model.wheelbase_m
        omega = min(max(omega, -cap), cap)
    return rows(vx, vy, omega)


@pytest.mark.parametrize("kind", KINDS)
@PROPERTY
@given(vx=speeds, vy=speeds, omega=st.floats(-5.0, 5.0, allow_nan=False))
@example(vx=0.0, vy=0.0, omega=0.0)
@example(vx=0.0, vy=0.0, omega=1.0)
@example(vx=-1.0, vy=0.5, omega=-3.0)
def test_forward_inverse_round_trip(kind: str, vx: float, vy: float, omega: float) -> None:
    model = MODELS[kind]()
    t = reachable(model, vx, vy, omega)
    ws = model.inverse(t)
    back = model.forward(ws.speeds[:, list(model.driven_wheels)], ws.steering)
    np.testing.assert_allclose(back, t, rtol=0, atol=1e-12 + 1e-9 * np.abs(t).max())


@pytest.mark.parametrize("kind", KINDS)
@PROPERTY
@given(
    vx=speeds,
    vy=speeds,
    omega=st.floats(-5.0, 5.0, allow_nan=False),
    beyond=st.floats(1.01, 100.0),
)
@example(vx=0.5, vy=0.3, omega=0.4, beyond=10.0)
def test_saturation_keeps_direction(
    kind: str, vx: float, vy: float, omega: float, beyond: float
) -> None:
    model = MODELS[kind]()
    t = reachable(model, vx, vy, omega)
    ws = model.inverse(t)
    driven = list(model.driven_wheels)
    peak = np.abs(ws.speeds[:, driven]).max()
    assume(peak > 1e-6)
    limit = model.max_wheel_speed_rad_s
    big = t * (beyond * limit / peak)  # the fastest driven wheel at `beyond` times its limit
    act = from_twist(model, big, ws.steering, 0.05)
    # the executed twist is the command scaled by 1 / beyond: same direction, peak == limit
    np.testing.assert_allclose(act.twist, big / beyond, rtol=0, atol=1e-9 * np.abs(big).max())
    assert np.abs(act.drive).max() == pytest.approx(limit, rel=1e-12)
    assert np.abs(act.wheel_speeds[:, driven]).max() <= limit + 1e-12


poses = st.tuples(st.floats(-10.0, 10.0), st.floats(-10.0, 10.0), st.floats(-math.pi, math.pi))
body_twists = st.tuples(speeds, speeds, st.floats(-5.0, 5.0))
steps = st.floats(1e-3, 0.5)


@PROPERTY
@given(pose=poses, twist=body_twists, dt=steps)
@example(pose=(0.0, 0.0, 0.0), twist=(1.0, 0.0, 0.0), dt=0.1)
@example(pose=(1.0, 2.0, 3.0), twist=(1.0, -0.5, 1e-9), dt=0.1)
def test_integrate_se2_composes(pose, twist, dt: float) -> None:
    p, t = rows(*pose), rows(*twist)
    one = integrate_se2(p, t, dt)
    two = integrate_se2(integrate_se2(p, t, dt / 2), t, dt / 2)
    np.testing.assert_allclose(two[:, :2], one[:, :2], rtol=0, atol=1e-12)
    assert abs(float(wrap_angle(two[0, 2] - one[0, 2]))) <= 1e-12


@PROPERTY
@given(pose=poses, twist=body_twists, dt=steps)
def test_integrate_se2_is_invertible(pose, twist, dt: float) -> None:
    p, t = rows(*pose), rows(*twist)
    back = integrate_se2(integrate_se2(p, t, dt), -t, dt)
    np.testing.assert_allclose(back[:, :2], p[:, :2], rtol=0, atol=1e-12)
    assert abs(float(wrap_angle(back[0, 2] - p[0, 2]))) <= 1e-12


def test_integrate_se2_accurate_just_above_series_threshold() -> None:
    a = 1.02e-6  # omega dt, just above the 1e-6 switch to the Taylor series
    got = integrate_se2(np.zeros((1, 3)), rows(1.0, 0.0, a), 1.0)
    # exact: dx = sin(a) / a, dy = (1 - cos a) / a = 2 sin(a/2)^2 / a (no cancellation)
    np.testing.assert_allclose(got[0, 1], 2 * math.sin(a / 2) ** 2 / a, rtol=0, atol=1e-13)


# --------------------------------------------------------------------------- invalid input


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("value", [-0.1, 0.0, float("nan"), float("inf")])
def test_bad_wheel_radius_is_refused(kind: str, value: float) -> None:
    with pytest.raises(ValueError, match="wheel_radius_m"):
        MODELS[kind](wheel_radius_m=value)


@pytest.mark.parametrize(
    ("cls", "field", "value"),
    [
        (DifferentialDrive, "half_track_m", 0.0),
        (DifferentialDrive, "max_wheel_speed_rad_s", -1.0),
        (Tricycle, "wheelbase_m", 0.0),
        (Tricycle, "max_steer_rate_rad_s", 0.0),
        (Ackermann, "wheelbase_m", 0.0),
        (Ackermann, "half_track_m", -0.2),
        (Ackermann, "max_steer_rad", math.pi / 2),
        (Ackermann, "max_steer_rad", 2.0),
        (Ackermann, "max_steer_rad", np.array([0.5, math.pi / 2])),
        (Ackermann, "steering_geometry", "bicycle"),
        (Mecanum, "half_width_m", -0.2),
        (Omni3, "base_radius_m", 0.0),
        (Omni3, "wheel_radius_m", np.array([0.05, -0.05])),
    ],
)
def test_bad_parameter_is_refused_by_name(cls, field: str, value) -> None:
    with pytest.raises(ValueError, match=field):
        cls(**{field: value})


def test_stack_models_refuses_mixtures() -> None:
    with pytest.raises(ValueError):
        stack_models([])
    with pytest.raises(TypeError):
        stack_models([DifferentialDrive(), Mecanum()])
    with pytest.raises(ValueError, match="steering_geometry"):
        stack_models([Ackermann(), Ackermann(steering_geometry="parallel")])


@pytest.mark.parametrize("kind", KINDS)
def test_twist_of_wrong_shape_is_refused(kind: str) -> None:
    with pytest.raises(ValueError, match="twist"):
        MODELS[kind]().inverse(np.zeros((2, 2)))


# --------------------------------------------------------------------------- known bugs


def test_ackermann_wide_track_large_steer() -> None:
    check_model(Ackermann(wheelbase_m=0.5, half_track_m=0.4, max_steer_rad=1.2))


@given(
    shape=st.sampled_from([(), (1,), (4,), (2, 3)]),
    k=st.integers(1, 5),
    seed=st.integers(0, 2**16),
)
def test_columns_is_np_stack_on_the_last_axis(shape, k, seed):
    """The kinematics' ``columns`` (np.stack without its per-call cost) gives np.stack's
    array bit for bit, a number filling its whole column."""
    from agvsim.kinematics.base import columns

    rng = np.random.default_rng(seed)
    cols = [rng.standard_normal(shape) for _ in range(k)]
    out = columns(*cols)
    assert out.shape == shape + (k,) and out.dtype == np.float64
    assert np.array_equal(out, np.stack(cols, axis=-1))
    filled = columns(cols[0], 0.0, 2.5)
    assert np.array_equal(filled, np.stack([cols[0], np.zeros(shape), np.full(shape, 2.5)], -1))
