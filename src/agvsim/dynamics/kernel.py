"""The numba kernel of planar dynamics: one call advances every dynamic robot by one step.

Per robot and sub-step h (docs/dynamics.md has the derivation):

    steering   delta_rate -> clip((target - delta) / max(tau_s, h), +-rate), acceleration-limited
    wheel i    contact velocity u = v_P + omega x p_i; slip s (wheel frame, or along the roller
               axis a for Mecanum/omni wheels); friction F = -mu N q(|s|) s (friction circle);
               J phi' = tau_motor(phi) - r F . e  by backward Euler in phi (body velocity held)
    body       m (v_c' + omega x v_c) = sum F,   I_c omega' = sum (p_i - c) x F_i  (explicit,
               with the wheels' new speeds: Gauss-Seidel); the pose moves exactly on SE(2)
               with the mean of the sub-step's old and new twist

The step's start-to-end pose change is handed back as the constant twist that reproduces it
(the SE(2) logarithm), so the engine's swept collision checks move the body as before.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# columns of the per-robot table ``body`` (D, NB)
B_MASS, B_INERTIA, B_CX, B_CY, B_RADIUS, B_WHEELBASE, B_GAIN, B_GEAR = 0, 1, 2, 3, 4, 5, 6, 7
B_TMAX, B_TSTALL, B_W0, B_VSLIP, B_MAXSUB, B_DMAX, B_RATE, B_SACC = 8, 9, 10, 11, 12, 13, 14, 15
B_STAU, B_TYRE, B_STEER, B_NW = 16, 17, 18, 19
NB = 20
# columns of the per-wheel table ``wheel`` (D, W, NWC)
W_PX, W_PY, W_BETA, W_GAMMA, W_KIND, W_DRIVEN, W_STEER, W_NORMAL, W_J = 0, 1, 2, 3, 4, 5, 6, 7, 8
NWC = 9
KIND_2D = 0  # a standard wheel: friction in both directions (friction circle)
KIND_1D = 1  # force only along the axis at angle gamma to the rolling direction (rollers)
STEER_NONE, STEER_BICYCLE, STEER_ACKERMANN = 0, 1, 2
MAX_SUBSTEPS = 100_000


@njit(cache=True, error_model="numpy")
def _q(slip: float, vslip: float, tyre: bool) -> float:
    """Friction per unit of mu N and of slip speed: F = -mu N q(|s|) s."""
    if tyre:
        x = slip / vslip
        return 1.0 / vslip if x < 1e-8 else math.tanh(x) / slip
    return 1.0 / max(slip, vslip)


@njit(cache=True, error_model="numpy")
def _dq(slip: float, vslip: float, tyre: bool) -> float:
    """d q / d |s|."""
    if tyre:
        x = slip / vslip
        if x < 1e-8:
            return 0.0
        t = math.tanh(x)
        return (1.0 - t * t) / (vslip * slip) - t / (slip * slip)
    return 0.0 if slip < vslip else -1.0 / (slip * slip)


@njit(cache=True, error_model="numpy")
def motor_torque(
    gain: float,
    target: float,
    phi: float,
    gear: float,
    tmax: float,
    tstall: float,
    w0: float,
) -> tuple[float, float]:
    """Wheel torque (N m) of the P speed controller within the motor's limits, and its
    derivative in phi (-gain unsaturated, 0 saturated)."""
    cmd = gain * (target - phi)
    if cmd * phi > 0.0:  # driving: the torque-speed line of the motor
        lim = min(tmax, tstall * (1.0 - abs(phi) * gear / w0))
        lim = max(lim, 0.0)
    else:  # braking (or starting): the full torque
        lim = tmax
    lim *= gear
    if cmd > lim:
        return lim, 0.0
    if cmd < -lim:
        return -lim, 0.0
    return cmd, -gain


@njit(cache=True, error_model="numpy")
def _wheel_torques(
    p: float,
    v_main: float,
    s_side: float,
    c: float,
    r: float,
    mu_n: float,
    b: np.ndarray,
    target: float,
) -> tuple[float, float, float]:
    """Net torque g on a driven wheel spinning at p (motor + contact), dg/dp and the motor's
    torque. The contact slips by s_main = v_main - r c p along its force axis (c = 1 for a
    standard wheel, cos gamma for rollers) and s_side across it."""
    tau, dtau = motor_torque(b[B_GAIN], target, p, b[B_GEAR], b[B_TMAX], b[B_TSTALL], b[B_W0])
    vslip, tyre = b[B_VSLIP], b[B_TYRE] > 0.5
    sm = v_main - r * c * p
    slip = math.hypot(sm, s_side)
    q = _q(slip, vslip, tyre)
    dfds = q + (_dq(slip, vslip, tyre) * sm * sm / slip if slip > 0.0 else 0.0)
    return tau + r * c * mu_n * q * sm, dtau - r * r * c * c * mu_n * dfds, tau


@njit(cache=True, error_model="numpy")
def solve_wheel(
    p: float,
    h: float,
    jw: float,
    v_main: float,
    s_side: float,
    c: float,
    r: float,
    mu_n: float,
    b: np.ndarray,
    target: float,
) -> tuple[float, float]:
    """Backward Euler for one driven wheel's spin, J (p_new - p) = h g(p_new), with the body
    velocity held: g decreases in p, so the root is unique; safeguarded Newton finds it
    (stiff contacts and high controller gains stay stable, and a wheel that the brake
    overpowers locks at once). Returns the new spin and the motor torque."""
    g_max = b[B_GEAR] * max(b[B_TMAX], b[B_TSTALL]) + r * abs(c) * mu_n
    lo, hi = p - h * g_max / jw - 1e-12, p + h * g_max / jw + 1e-12
    r_lo, r_hi = -1.0, 1.0  # residual signs at the bracket ends; values once known
    known_lo, known_hi = False, False
    x, tau = p, 0.0
    side = 0  # which end the last step moved: +1 hi, -1 lo (Illinois rule)
    for _ in range(60):
        g, dg, tau = _wheel_torques(x, v_main, s_side, c, r, mu_n, b, target)
        res = jw * (x - p) - h * g
        if res == 0.0:
            return x, tau
        if res > 0.0:
            hi, r_hi, known_hi = x, res, True
            if side == 1:
                r_lo *= 0.5
            side = 1
        else:
            lo, r_lo, known_lo = x, res, True
            if side == -1:
                r_hi *= 0.5
            side = -1
        step = res / (jw - h * dg)
        if abs(step) <= 1e-13 * (1.0 + abs(x)):
            return x - step, tau
        xn = x - step
        if not lo < xn < hi:  # Newton left the bracket (a kink): false position or bisection
            xn = lo - r_lo * (hi - lo) / (r_hi - r_lo) if known_lo and known_hi else 0.5 * (lo + hi)
            if not lo < xn < hi:
                xn = 0.5 * (lo + hi)
        if hi - lo <= 1e-13 * (1.0 + abs(x)):
            return xn, tau
        x = xn
    return x, tau


@njit(cache=True, error_model="numpy")
def substep_count(body: np.ndarray, wheel: np.ndarray, mu_n: np.ndarray, dt: float) -> int:
    """Sub-steps for stability of the explicit body update: h (sum k_i / m + sum k_i
    |p_i - c|^2 / I) <= 1, a bound on h times the fastest contact rate, with the contact
    stiffness k_i = mu N_i / slip_speed (the wheels' spin is implicit and needs no bound);
    and h <= max_substep_s."""
    nw = int(body[B_NW])
    csum, cyaw = 0.0, 0.0
    for i in range(nw):
        k = mu_n[i] / body[B_VSLIP]
        dx, dy = wheel[i, W_PX] - body[B_CX], wheel[i, W_PY] - body[B_CY]
        csum += k
        cyaw += k * (dx * dx + dy * dy)
    rate = csum / body[B_MASS] + cyaw / body[B_INERTIA]
    h = body[B_MAXSUB]
    if rate > 0.0:
        h = min(h, 1.0 / rate)
    n = int(math.ceil(dt / h - 1e-9))
    return min(max(n, 1), MAX_SUBSTEPS)


@njit(cache=True, error_model="numpy")
def wheel_angle(wheel: np.ndarray, delta: float, wheelbase: float) -> float:
    """Rolling direction of a wheel in the robot frame (rad) for bicycle steering delta."""
    kind = int(wheel[W_STEER])
    if kind == STEER_BICYCLE:
        return wheel[W_BETA] + delta
    if kind == STEER_ACKERMANN:
        k = math.tan(delta) / wheelbase
        return wheel[W_BETA] + math.atan(k * wheelbase / (1.0 - k * wheel[W_PY]))
    return wheel[W_BETA]


@njit(cache=True, error_model="numpy")
def se2_log(dx: float, dy: float, dth: float, dt: float) -> tuple[float, float, float]:
    """The constant body twist that moves the identity to (dx, dy, dth) in dt (inverse of
    ``se2_step``)."""
    a = dth
    if abs(a) < 1e-6:
        sa = 1.0 - a * a / 6.0
        ca = a / 2.0 - a * a * a / 24.0
    else:
        sa = math.sin(a) / a
        h = math.sin(0.5 * a)
        ca = 2.0 * h * h / a
    det = sa * sa + ca * ca
    vx = (sa * dx + ca * dy) / det / dt
    vy = (-ca * dx + sa * dy) / det / dt
    return vx, vy, a / dt


@njit(cache=True, error_model="numpy", parallel=True)
def step_robots(
    dt: float,
    poses: np.ndarray,  # (D, 3) world poses at the step start
    regions: np.ndarray,  # (R, 5) x_min, y_min, x_max, y_max, mu
    floor_mu: float,
    body: np.ndarray,  # (D, NB)
    wheel: np.ndarray,  # (D, W, NWC)
    target: np.ndarray,  # (D, W) wheel-speed targets, rad/s (driven wheels)
    delta_target: np.ndarray,  # (D,) steering target, rad
    freeze: np.ndarray,  # (D,) bool: bumped or stopped, velocities to zero first
    vel: np.ndarray,  # (D, 3) in/out: instantaneous twist at P
    phi: np.ndarray,  # (D, W) in/out: wheel spin speeds, rad/s
    delta: np.ndarray,  # (D,) in/out: steering angle
    delta_rate: np.ndarray,  # (D,) in/out
    out_twist: np.ndarray,  # (D, 3) the step's equivalent constant twist
    out_angle: np.ndarray,  # (D, W) wheel rotation over the step, rad
    out_steer: np.ndarray,  # (D, W) each wheel's rolling direction at the end, rad
    out_torque: np.ndarray,  # (D, W) wheel torque at the end, N m
    out_slip: np.ndarray,  # (D, W) slip speed |s| at the end, m/s
    out_work: np.ndarray,  # (D, W) motor work over the step, J
    out_nsub: np.ndarray,  # (D,) sub-steps taken
) -> None:
    n_rob = poses.shape[0]
    n_reg = regions.shape[0]
    mu_all = np.zeros((n_rob, wheel.shape[1]))
    dirs_all = np.zeros((n_rob, wheel.shape[1], 4))
    for d in prange(n_rob):  # robots are independent: one thread each, same result
        mu_n = mu_all[d]
        dirs = dirs_all[d]  # cos, sin of each rolling direction and force axis
        b = body[d]
        nw = int(b[B_NW])
        if freeze[d]:
            vel[d, :] = 0.0
            phi[d, :] = 0.0
            delta_rate[d] = 0.0
        x0, y0, th0 = poses[d, 0], poses[d, 1], poses[d, 2]
        c0, s0 = math.cos(th0), math.sin(th0)
        for i in range(nw):
            wx = x0 + c0 * wheel[d, i, W_PX] - s0 * wheel[d, i, W_PY]
            wy = y0 + s0 * wheel[d, i, W_PX] + c0 * wheel[d, i, W_PY]
            mu = floor_mu
            for k in range(n_reg):
                if regions[k, 0] <= wx < regions[k, 2] and regions[k, 1] <= wy < regions[k, 3]:
                    mu = regions[k, 4]
            mu_n[i] = mu * wheel[d, i, W_NORMAL]
        n_sub = substep_count(b, wheel[d], mu_n, dt)
        h = dt / n_sub
        m, inertia, cx, cy = b[B_MASS], b[B_INERTIA], b[B_CX], b[B_CY]
        r, vslip, tyre = b[B_RADIUS], b[B_VSLIP], b[B_TYRE] > 0.5
        vx, vy, w = vel[d, 0], vel[d, 1], vel[d, 2]
        dl, dr = delta[d], delta_rate[d]
        rx, ry, rth = 0.0, 0.0, 0.0
        for i in range(nw):
            out_angle[d, i] = 0.0
            out_work[d, i] = 0.0
        steered = False
        for i in range(nw):  # fixed wheels: directions once a step
            wi = wheel[d, i]
            steered = steered or int(wi[W_STEER]) != STEER_NONE
            ang = wheel_angle(wi, dl, b[B_WHEELBASE])
            dirs[i, 0], dirs[i, 1] = math.cos(ang), math.sin(ang)
            dirs[i, 2], dirs[i, 3] = math.cos(ang + wi[W_GAMMA]), math.sin(ang + wi[W_GAMMA])
            out_steer[d, i] = ang
        cr, sr = 1.0, 0.0  # rotation of the body since the step start
        for _ in range(n_sub):
            if b[B_STEER] > 0.5:  # first-order servo, rate and acceleration limited
                rate = min(max((delta_target[d] - dl) / max(b[B_STAU], h), -b[B_RATE]), b[B_RATE])
                acc = b[B_SACC] * h
                dr += min(max(rate - dr, -acc), acc)
                dl += h * dr
                if abs(dl) > b[B_DMAX]:
                    dl = math.copysign(b[B_DMAX], dl)
                    dr = 0.0
            fx, fy, mz = 0.0, 0.0, 0.0
            for i in range(nw):
                wi = wheel[d, i]
                px, py = wi[W_PX], wi[W_PY]
                if steered and int(wi[W_STEER]) != STEER_NONE:
                    ang = wheel_angle(wi, dl, b[B_WHEELBASE])
                    dirs[i, 0], dirs[i, 1] = math.cos(ang), math.sin(ang)
                    dirs[i, 2], dirs[i, 3] = (
                        math.cos(ang + wi[W_GAMMA]),
                        math.sin(ang + wi[W_GAMMA]),
                    )
                    out_steer[d, i] = ang
                ca, sa = dirs[i, 0], dirs[i, 1]
                ux, uy = vx - w * py, vy + w * px  # contact point velocity, robot frame
                driven = wi[W_DRIVEN] > 0.5
                p = phi[d, i]
                tau = 0.0
                if int(wi[W_KIND]) == KIND_2D:
                    vl = ux * ca + uy * sa
                    vt = -ux * sa + uy * ca
                    if driven:
                        p, tau = solve_wheel(
                            p, h, wi[W_J], vl, vt, 1.0, r, mu_n[i], b, target[d, i]
                        )
                        sl = vl - r * p
                    else:  # free rolling
                        p = vl / r
                        sl = 0.0
                    sm = math.hypot(sl, vt)
                    k = mu_n[i] * _q(sm, vslip, tyre)
                    fl, ft = -k * sl, -k * vt
                    fxi, fyi = fl * ca - ft * sa, fl * sa + ft * ca
                else:
                    ax, ay = dirs[i, 2], dirs[i, 3]
                    ea = ca * ax + sa * ay  # cos gamma
                    su = ux * ax + uy * ay
                    if driven:
                        p, tau = solve_wheel(
                            p, h, wi[W_J], su, 0.0, ea, r, mu_n[i], b, target[d, i]
                        )
                        s = su - r * p * ea
                    else:  # free rolling along its rolling direction
                        p = (ux * ca + uy * sa) / r
                        s = su
                    sm = abs(s)
                    f = mu_n[i] * _q(sm, vslip, tyre) * s
                    fxi, fyi = -f * ax, -f * ay
                phi[d, i] = p
                fx += fxi
                fy += fyi
                mz += (px - cx) * fyi - (py - cy) * fxi
                out_angle[d, i] += p * h
                out_work[d, i] += tau * p * h
                out_torque[d, i] = tau
                out_slip[d, i] = sm
            # the body: the centre-of-mass velocity keeps its world direction (it turns by
            # -a in the body frame as the body turns by a = mean omega h), plus the forces
            w0 = w
            w += h * mz / inertia
            a = 0.5 * (w0 + w) * h
            sin_a, cos_a = math.sin(a), math.cos(a)
            vcx, vcy = vx - w0 * cy, vy + w0 * cx
            vcx, vcy = (
                cos_a * vcx + sin_a * vcy + h * fx / m,
                -sin_a * vcx + cos_a * vcy + h * fy / m,
            )
            vx0, vy0 = vx, vy
            vx, vy = vcx + w * cy, vcy - w * cx
            # the pose moves exactly (SE(2)) with the mean of the old and new twist
            mx, my = 0.5 * (vx0 + vx) * h, 0.5 * (vy0 + vy) * h
            sinc = 1.0 - a * a / 6.0 if abs(a) < 1e-6 else sin_a / a
            cosc = sinc * sin_a / (1.0 + cos_a)  # (1 - cos a) / a without cancellation
            dx, dy = mx * sinc - my * cosc, mx * cosc + my * sinc
            rx += cr * dx - sr * dy
            ry += sr * dx + cr * dy
            cr, sr = cr * cos_a - sr * sin_a, sr * cos_a + cr * sin_a
            rth += a
        vel[d, 0], vel[d, 1], vel[d, 2] = vx, vy, w
        delta[d], delta_rate[d] = dl, dr
        out_twist[d, 0], out_twist[d, 1], out_twist[d, 2] = se2_log(rx, ry, rth, dt)
        out_nsub[d] = n_sub
