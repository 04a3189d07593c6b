"""The numba kernel of planar dynamics: one call advances every dynamic robot by one step.

Per robot the state is y = (v_c, omega, phi_1..phi_W): the centre of mass velocity and yaw
rate (robot frame) and the driven wheels' spin. Its equations (docs/dynamics.md):

    wheel i    contact velocity u = v_c + omega x (p_i - c); slip s (wheel frame, or along
               the roller axis a for Mecanum/omni wheels); friction F = -mu N q(|s|) s
               (friction circle); J phi' = tau_motor(phi) - r F . e
    body       m (v_c' + omega x v_c) = sum F,   I_c omega' = sum (p_i - c) x F_i
    steering   a first-order servo, rate and acceleration limited (integrated apart: it
               does not depend on the body)

Each sub-step h is one step of the two-stage L-stable SDIRK method (Alexander's, order 2,
gamma = 1 - 1/sqrt 2): Y1 = y + gamma h f(Y1); y' = Y2 = y + (1 - gamma) h f(Y1) + gamma h
f(Y2). Each stage is solved by Newton's method; its linear system (body + wheels) is
symmetric positive definite and each wheel is eliminated in closed form, leaving 3 x 3.
A step is one sub-step unless ``max_substep_s`` is shorter; a sub-step is halved (on a
dyadic grid, see ``substep_count``) where a kink of the friction law or a torque limit is
crossed, where new targets start a transient, where the error estimate is large and where a
stage's Newton iteration did not converge (what still does not at the shortest sub-step is
counted per robot and handed back). The pose moves exactly on SE(2) with the stage twists
weighted (1 - gamma, gamma). The step's start-to-end pose change is handed back as the
constant twist that reproduces it (the SE(2) logarithm), so the engine's swept collision
checks move the body as before.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# columns of the per-robot table ``body`` (D, NB)
B_MASS, B_INERTIA, B_CX, B_CY, B_RADIUS, B_WHEELBASE, B_GAIN, B_GEAR = 0, 1, 2, 3, 4, 5, 6, 7
B_TMAX, B_TSTALL, B_W0, B_VSLIP, B_MAXSUB, B_DMAX, B_RATE, B_SACC = 8, 9, 10, 11, 12, 13, 14, 15
B_STAU, B_TYRE, B_STEER, B_NW, B_MTAU, B_LEVER = 16, 17, 18, 19, 20, 21
NB = 22
# columns of the per-wheel table ``wheel`` (D, W, NWC)
W_PX, W_PY, W_BETA, W_GAMMA, W_KIND, W_DRIVEN, W_STEER, W_NORMAL, W_J = 0, 1, 2, 3, 4, 5, 6, 7, 8
W_DIRS = 9  # 9-12: cos, sin of the rolling direction and of the force axis, unsteered
NWC = 13
NKAP = 15  # columns of solve_stage's per-wheel scratch
KIND_2D = 0  # a standard wheel: friction in both directions (friction circle)
KIND_1D = 1  # force only along the axis at angle gamma to the rolling direction (rollers)
STEER_NONE, STEER_BICYCLE, STEER_ACKERMANN = 0, 1, 2
MAX_SUBSTEPS = 100_000
CHUNKS = 64  # robots are split into this many chunks (threads take chunks), each with its scratch
GAMMA = 1.0 - 1.0 / math.sqrt(2.0)  # SDIRK2: L-stable, second order
REFINE_PER_TIME_CONSTANT = 0.0125  # the shortest sub-step, in controller time constants
REFINE_MAX_S = 1e-3  # the shortest sub-step is at most this long
MAX_LEVELS = 12  # halvings of a sub-step at most
ERROR_TOL_M_S = 1e-3  # a sub-step is halved where its error estimate exceeds this
SERVO_STEP_S = 1e-3  # the steering servo's own step
NEWTON_ITERATIONS = 30  # at most, per stage (two or three when nothing saturates)
NEWTON_TOL_M_S = 1e-5  # converged when no velocity (or r phi) moved by more: the next
# correction, quadratically smaller, is ~1e-9 m/s
# rounding-level licence for the compiler (reassociation, fused multiply-add, reciprocals,
# the sign of zero); never "no infinities": a motor without a speed limit has w0 = inf
FASTMATH = {"reassoc", "contract", "arcp", "nsz"}


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def _q(slip: float, vslip: float, tyre: bool) -> float:
    """Friction per unit of mu N and of slip speed: F = -mu N q(|s|) s."""
    if tyre:
        x = slip / vslip
        return 1.0 / vslip if x < 1e-8 else math.tanh(x) / slip
    return 1.0 / max(slip, vslip)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def _dq(slip: float, vslip: float, tyre: bool) -> float:
    """d q / d |s|."""
    if tyre:
        x = slip / vslip
        if x < 1e-8:
            return 0.0
        t = math.tanh(x)
        return (1.0 - t * t) / (vslip * slip) - t / (slip * slip)
    return 0.0 if slip < vslip else -1.0 / (slip * slip)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
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


@njit(inline="always", cache=True, error_model="numpy", fastmath=FASTMATH)
def substep_count(body: np.ndarray, d: int, dt: float) -> tuple[int, int]:
    """Sub-steps of a step: ``n`` of at most max_substep_s (one by default: the method is
    L-stable, stiff contacts need no bound), each halved up to ``levels`` times where a wheel
    crosses the friction law's kink or a motor's torque limit, where targets change, where
    the error estimate is large and where Newton's method did not converge, down to
    REFINE_PER_TIME_CONSTANT x the shorter of the motor's and the steering servo's time
    constants, or REFINE_MAX_S if shorter."""
    tau = body[d, B_MTAU]
    if body[d, B_STEER] > 0.5:
        tau = min(tau, body[d, B_STAU])
    n = min(max(int(math.ceil(dt / body[d, B_MAXSUB] - 1e-9)), 1), MAX_SUBSTEPS)
    levels = 0
    h_min = min(REFINE_PER_TIME_CONSTANT * tau, REFINE_MAX_S)
    while levels < MAX_LEVELS and dt / n / (1 << levels) > h_min:
        levels += 1
    return n, levels


@njit(inline="always", cache=True, error_model="numpy", fastmath=FASTMATH)
def wheel_angle(wheel: np.ndarray, d: int, i: int, delta: float, wheelbase: float) -> float:
    """Rolling direction of wheel i of robot d in the robot frame (rad) for bicycle steering
    delta."""
    kind = int(wheel[d, i, W_STEER])
    if kind == STEER_BICYCLE:
        return wheel[d, i, W_BETA] + delta
    if kind == STEER_ACKERMANN:
        k = math.tan(delta) / wheelbase
        return wheel[d, i, W_BETA] + math.atan(k * wheelbase / (1.0 - k * wheel[d, i, W_PY]))
    return wheel[d, i, W_BETA]


@njit(inline="always", cache=True, error_model="numpy", fastmath=FASTMATH)
def set_directions(
    wheel: np.ndarray, d: int, nw: int, delta: float, wheelbase: float, dirs: np.ndarray
):
    """dirs (W, 4): cos, sin of robot d's wheels''s rolling direction and of its force axis."""
    for i in range(nw):
        if int(wheel[d, i, W_STEER]) == STEER_NONE:
            for k in range(4):
                dirs[i, k] = wheel[d, i, W_DIRS + k]
            continue
        ang = wheel_angle(wheel, d, i, delta, wheelbase)
        gam = wheel[d, i, W_GAMMA]
        dirs[i, 0], dirs[i, 1] = math.cos(ang), math.sin(ang)
        dirs[i, 2], dirs[i, 3] = math.cos(ang + gam), math.sin(ang + gam)


@njit(inline="always", cache=True, error_model="numpy", fastmath=FASTMATH)
def servo(
    body: np.ndarray, d: int, delta: float, rate: float, target: float, dur: float
) -> tuple[float, float]:
    """The steering servo over ``dur`` seconds: first order (exact between its own steps of
    at most SERVO_STEP_S), rate limited by the model and acceleration limited by the
    actuator's torque, the angle by the model's limit. Returns (angle, rate)."""
    if dur <= 0.0:
        return delta, rate
    n = int(math.ceil(dur / SERVO_STEP_S - 1e-9))
    hs = dur / n
    gain = -math.expm1(-hs / body[d, B_STAU]) / hs  # the exact first-order step, as a rate
    acc = body[d, B_SACC] * hs
    for _ in range(n):
        want = min(max((target - delta) * gain, -body[d, B_RATE]), body[d, B_RATE])
        rate += min(max(want - rate, -acc), acc)
        delta += hs * rate
        if abs(delta) > body[d, B_DMAX]:
            delta = math.copysign(body[d, B_DMAX], delta)
            rate = 0.0
    return delta, rate


@njit(inline="always", cache=True, error_model="numpy", fastmath=FASTMATH)
def solve_stage(
    body: np.ndarray,  # (D, NB)
    wheel: np.ndarray,  # (D, W, NWC)
    d: int,  # the robot
    mu_n: np.ndarray,  # (W,) mu N under each wheel
    dirs: np.ndarray,  # (W, 4) directions at the stage's time
    target: np.ndarray,  # (D, W) wheel-speed targets
    gh: float,  # gamma h
    a: np.ndarray,  # (3 + W,) the stage's explicit part: y = a + gamma h f(y)
    y: np.ndarray,  # (3 + W,) in: first guess; out: the stage value
    tau: np.ndarray,  # (W,) out: motor torque at y
    slip: np.ndarray,  # (W,) out: slip speed at y; phi of free wheels in y
    kap: np.ndarray,  # (W, NKAP) scratch
    iterations: int,  # Newton iterations at most
) -> tuple[int, float]:
    """Newton's method for one implicit stage, y = a + gh f(y), y = (v_c, omega, phi).
    Returns the regime of the solution: per wheel, whether it slides (past the Coulomb
    law's kink) and whether its motor is at a torque limit (two bits a wheel); and 0.0 when
    the iteration converged, else its last correction (m/s: velocities, the yaw rate and
    spins times the wheel radius), the residual it stopped at.

    Each iteration linearises the contact forces F(s) (dF/ds = D, symmetric negative
    semi-definite: friction is the gradient of a convex function of the slip) and the motor
    torque; the system [M - gh sum H, -gh k_i; -gh k_i^T, J_i - gh g_i'] is symmetric
    positive definite; each wheel's row is solved for its spin and put into the body's 3 x 3
    (the Schur complement). The yaw-rate coupling omega x v_c stays out of the matrix (it
    is slow: the iteration still contracts at once)."""
    nw = int(body[d, B_NW])
    m, inertia, cx, cy = body[d, B_MASS], body[d, B_INERTIA], body[d, B_CX], body[d, B_CY]
    r, vslip, tyre = body[d, B_RADIUS], body[d, B_VSLIP], body[d, B_TYRE] > 0.5
    sig = 0
    big = 0.0
    for _ in range(iterations):
        sig = 0
        vx, vy, w = y[0], y[1], y[2]
        # the body's rows, times the mass: M (y - a) - gh (Q + M gyro)
        r0 = m * (vx - a[0]) - gh * m * w * vy
        r1 = m * (vy - a[1]) + gh * m * w * vx
        r2 = inertia * (w - a[2])
        s00, s01, s02, s11, s12, s22 = m, 0.0, 0.0, m, 0.0, inertia
        for i in range(nw):
            dx, dy = wheel[d, i, W_PX] - cx, wheel[d, i, W_PY] - cy
            ux, uy = vx - w * dy, vy + w * dx  # contact point velocity
            ca, sa = dirs[i, 0], dirs[i, 1]
            driven = wheel[d, i, W_DRIVEN] > 0.5
            p = y[3 + i]
            if int(wheel[d, i, W_KIND]) == KIND_2D and driven:
                # rows of u.e and u.n in (v_c, omega)
                gm0, gm1, gm2 = ca, sa, -dy * ca + dx * sa
                gs0, gs1, gs2 = -sa, ca, dy * sa + dx * ca
                sm = ux * ca + uy * sa - r * p
                st = -ux * sa + uy * ca
                sn = math.sqrt(sm * sm + st * st)
                q = _q(sn, vslip, tyre)
                dqs = _dq(sn, vslip, tyre) / sn if sn > 0.0 else 0.0
                fm, ft = -mu_n[i] * q * sm, -mu_n[i] * q * st
                d00 = -mu_n[i] * (q + dqs * sm * sm)
                d01 = -mu_n[i] * dqs * sm * st
                d11 = -mu_n[i] * (q + dqs * st * st)
                q0, q1, q2 = gm0 * fm + gs0 * ft, gm1 * fm + gs1 * ft, gm2 * fm + gs2 * ft
                # H = G^T D G, the generalised force's derivative in (v_c, omega)
                t0, t1, t2 = d00 * gm0 + d01 * gs0, d00 * gm1 + d01 * gs1, d00 * gm2 + d01 * gs2
                u0, u1, u2 = d01 * gm0 + d11 * gs0, d01 * gm1 + d11 * gs1, d01 * gm2 + d11 * gs2
                h00, h01, h02 = gm0 * t0 + gs0 * u0, gm0 * t1 + gs0 * u1, gm0 * t2 + gs0 * u2
                h11, h12, h22 = gm1 * t1 + gs1 * u1, gm1 * t2 + gs1 * u2, gm2 * t2 + gs2 * u2
                k0, k1, k2 = -r * t0, -r * t1, -r * t2  # dQ/dphi = (dg/dv)^T
                rc, dmain, fmain = r, d00, fm
                kap[i, 5], kap[i, 6], kap[i, 7], kap[i, 8] = sm, st, gm0, gm1
                kap[i, 9], kap[i, 10], kap[i, 11], kap[i, 12] = gm2, gs0, gs1, gs2
            else:
                if int(wheel[d, i, W_KIND]) == KIND_2D:  # a free standard wheel: side force only
                    ax, ay = -sa, ca
                else:
                    ax, ay = dirs[i, 2], dirs[i, 3]
                rc = r * (ca * ax + sa * ay) if driven else 0.0
                g0, g1, g2 = ax, ay, -dy * ax + dx * ay
                sm = ux * ax + uy * ay - rc * p
                sn = abs(sm)
                q = _q(sn, vslip, tyre)
                fm = -mu_n[i] * q * sm
                dmain = -mu_n[i] * (q + _dq(sn, vslip, tyre) * sn)
                q0, q1, q2 = g0 * fm, g1 * fm, g2 * fm
                h00, h01, h02 = dmain * g0 * g0, dmain * g0 * g1, dmain * g0 * g2
                h11, h12, h22 = dmain * g1 * g1, dmain * g1 * g2, dmain * g2 * g2
                k0, k1, k2 = -rc * dmain * g0, -rc * dmain * g1, -rc * dmain * g2
                fmain = fm
                kap[i, 5], kap[i, 6], kap[i, 7], kap[i, 8] = sm, 0.0, g0, g1
                kap[i, 9], kap[i, 10], kap[i, 11], kap[i, 12] = g2, 0.0, 0.0, 0.0
                if not driven:  # it rolls freely: its spin follows the contact
                    y[3 + i] = (ux * ca + uy * sa) / r
            slip[i] = sn
            kap[i, 13] = rc if driven else 0.0
            if not tyre and sn >= vslip:
                sig |= 1 << (2 * i)
            r0 -= gh * q0
            r1 -= gh * q1
            r2 -= gh * q2
            s00 -= gh * h00
            s01 -= gh * h01
            s02 -= gh * h02
            s11 -= gh * h11
            s12 -= gh * h12
            s22 -= gh * h22
            if driven:
                tq, dtq = motor_torque(
                    body[d, B_GAIN],
                    target[d, i],
                    p,
                    body[d, B_GEAR],
                    body[d, B_TMAX],
                    body[d, B_TSTALL],
                    body[d, B_W0],
                )
                tau[i] = tq
                if dtq == 0.0:
                    sig |= 1 << (2 * i + 1)
                jw = wheel[d, i, W_J]
                rp = jw * (p - a[3 + i]) - gh * (tq - rc * fmain)
                dinv = 1.0 / (jw - gh * (dtq + rc * rc * dmain))
                # eliminate the spin: dphi = (-rp + gh k . dv) / d
                c = gh * gh * dinv
                s00 -= c * k0 * k0
                s01 -= c * k0 * k1
                s02 -= c * k0 * k2
                s11 -= c * k1 * k1
                s12 -= c * k1 * k2
                s22 -= c * k2 * k2
                e = gh * dinv * rp
                r0 += e * k0
                r1 += e * k1
                r2 += e * k2
                kap[i, 0], kap[i, 1], kap[i, 2], kap[i, 3], kap[i, 4] = k0, k1, k2, dinv, rp
            else:
                tau[i] = 0.0
                kap[i, 3] = 0.0
        # solve S dv = -r (S symmetric positive definite) by its cofactors
        c00 = s11 * s22 - s12 * s12
        c01 = s02 * s12 - s01 * s22
        c02 = s01 * s12 - s02 * s11
        det = s00 * c00 + s01 * c01 + s02 * c02
        c11 = s00 * s22 - s02 * s02
        c12 = s01 * s02 - s00 * s12
        c22 = s00 * s11 - s01 * s01
        dv0 = -(c00 * r0 + c01 * r1 + c02 * r2) / det
        dv1 = -(c01 * r0 + c11 * r1 + c12 * r2) / det
        dv2 = -(c02 * r0 + c12 * r1 + c22 * r2) / det
        for i in range(nw):
            kap[i, 14] = 0.0
            if kap[i, 3] != 0.0:
                dphi = gh * (kap[i, 0] * dv0 + kap[i, 1] * dv1 + kap[i, 2] * dv2) - kap[i, 4]
                kap[i, 14] = dphi * kap[i, 3]
        # the friction law is flat past its kink: from a sliding wheel Newton's step can
        # jump across the whole slip zone to sliding the other way and back (a cycle that
        # never converges, and energy from nothing). Cut such a step where its slip comes
        # closest to zero: inside the zone, where the next step sees the law's slope.
        frac = 1.0
        for i in range(nw):
            if slip[i] < vslip:  # this iteration's |s| (kap 5, 6)
                continue
            sm, st = kap[i, 5], kap[i, 6]
            dsm = kap[i, 7] * dv0 + kap[i, 8] * dv1 + kap[i, 9] * dv2 - kap[i, 13] * kap[i, 14]
            dst = kap[i, 10] * dv0 + kap[i, 11] * dv1 + kap[i, 12] * dv2
            dd = dsm * dsm + dst * dst
            if dd <= 0.0:
                continue
            t = -(sm * dsm + st * dst) / dd
            if 0.0 < t < 1.0 and math.hypot(sm + t * dsm, st + t * dst) < vslip:
                frac = min(frac, t)
        dv0 *= frac
        dv1 *= frac
        dv2 *= frac
        y[0] += dv0
        y[1] += dv1
        y[2] += dv2
        big = max(abs(dv0), abs(dv1), abs(dv2) * body[d, B_RADIUS])
        for i in range(nw):
            if kap[i, 3] != 0.0:
                dphi = kap[i, 14] * frac
                y[3 + i] += dphi
                big = max(big, abs(dphi) * body[d, B_RADIUS])
        if big <= NEWTON_TOL_M_S and frac == 1.0:  # a cut step is no proof
            return sig, 0.0
    return sig, max(big, NEWTON_TOL_M_S)  # not converged (a cut last step: at least tol)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
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


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, parallel=True)
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
    last_target: np.ndarray,  # (D, W) in/out: the previous step's targets
    vel: np.ndarray,  # (D, 3) in/out: instantaneous twist at P
    phi: np.ndarray,  # (D, W) in/out: wheel spin speeds, rad/s
    delta: np.ndarray,  # (D,) in/out: steering angle
    delta_rate: np.ndarray,  # (D,) in/out
    out_twist: np.ndarray,  # (D, 3) the step's equivalent constant twist
    out_angle: np.ndarray,  # (D, W) wheel rotation over the step, rad
    steer_cols: np.ndarray,  # (D, S) the steered wheels' columns (model order), -1: none
    out_steer: np.ndarray,  # (D, S) the steered wheels' rolling directions at the end, rad
    out_torque: np.ndarray,  # (D, W) wheel torque at the end, N m
    out_slip: np.ndarray,  # (D, W) slip speed |s| at the end, m/s
    out_work: np.ndarray,  # (D, W) motor work over the step, J
    out_nsub: np.ndarray,  # (D,) sub-steps taken
    out_speed: np.ndarray,  # (D, 2) speed of P at the start and at the end, m/s
    out_braking: np.ndarray,  # (D,) bool: every driven wheel's target is zero
    out_unconverged: np.ndarray,  # (D,) stages whose Newton iteration did not converge
    out_residual: np.ndarray,  # (D,) the largest correction such a stage stopped at, m/s
    iterations: int,  # Newton iterations at most, per stage (NEWTON_ITERATIONS)
) -> None:
    n_rob, n_w = poses.shape[0], wheel.shape[1]
    n_reg = regions.shape[0]
    # scratch: one set per chunk of robots (a few chunks a thread), reused robot after robot
    n_chunk = min(n_rob, CHUNKS)
    for c in prange(n_chunk):  # robots are independent: any split gives the same result
        mu_n = np.empty(n_w)  # mu N under each wheel
        # per stage (the first, the second and last): wheel directions, the stage value, torques
        dirs, ys, taus = np.empty((2, n_w, 4)), np.empty((2, 3 + n_w)), np.empty((2, n_w))
        dirs1, dirs2, y1, y2, tau1, tau2 = dirs[0], dirs[1], ys[0], ys[1], taus[0], taus[1]
        y0, a, slip = np.empty(3 + n_w), np.empty(3 + n_w), np.empty(n_w)
        kap = np.empty((n_w, NKAP))
        for d in range(c * n_rob // n_chunk, (c + 1) * n_rob // n_chunk):
            nw = int(body[d, B_NW])
            out_speed[d, 0] = math.sqrt(vel[d, 0] ** 2 + vel[d, 1] ** 2)
            braking = True
            for i in range(nw):
                if wheel[d, i, W_DRIVEN] > 0.5 and abs(target[d, i]) > 1e-12:
                    braking = False
            out_braking[d] = braking
            if freeze[d]:
                vel[d, :] = 0.0
                phi[d, :] = 0.0
                delta_rate[d] = 0.0
            x0, y0p, th0 = poses[d, 0], poses[d, 1], poses[d, 2]
            c0, s0 = math.cos(th0), math.sin(th0)
            for i in range(nw):
                wx = x0 + c0 * wheel[d, i, W_PX] - s0 * wheel[d, i, W_PY]
                wy = y0p + s0 * wheel[d, i, W_PX] + c0 * wheel[d, i, W_PY]
                mu = floor_mu
                for k in range(n_reg):
                    if regions[k, 0] <= wx < regions[k, 2] and regions[k, 1] <= wy < regions[k, 3]:
                        mu = regions[k, 4]
                mu_n[i] = mu * wheel[d, i, W_NORMAL]
            n_sub, levels = substep_count(body, d, dt)
            cx, cy = body[d, B_CX], body[d, B_CY]
            lever = body[d, B_LEVER]
            steered = body[d, B_STEER] > 0.5
            dl, dr = delta[d], delta_rate[d]
            set_directions(wheel, d, nw, dl, body[d, B_WHEELBASE], dirs1)
            set_directions(wheel, d, nw, dl, body[d, B_WHEELBASE], dirs2)
            # the state at the centre of mass
            y2[0], y2[1], y2[2] = vel[d, 0] - vel[d, 2] * cy, vel[d, 1] + vel[d, 2] * cx, vel[d, 2]
            for i in range(nw):
                y2[3 + i] = phi[d, i]
            for i in range(n_w):
                out_angle[d, i] = 0.0
                out_work[d, i] = 0.0
                out_torque[d, i] = 0.0
                out_slip[d, i] = 0.0
            rx, ry, rth = 0.0, 0.0, 0.0
            cr, sr = 1.0, 0.0  # rotation of the body since the step start
            sig0 = -1  # the regime at the sub-step's start (unknown at first)
            taken = 0
            unconverged, residual = 0, 0.0
            ticks = 1 << levels  # a base sub-step in the finest sub-steps
            # new targets (the rim speed by more than ERROR_TOL_M_S) start a transient that the
            # error estimate misses (the contacts settle in milliseconds): the step
            # begins with the shortest sub-step and doubles it on the dyadic grid from there
            jump = freeze[d]
            for i in range(nw):
                jump = (
                    jump
                    or body[d, B_RADIUS] * abs(target[d, i] - last_target[d, i]) > ERROR_TOL_M_S
                )
                last_target[d, i] = target[d, i]
            for base in range(n_sub):
                level, pos = (levels if jump and base == 0 else 0), 0
                while pos < ticks:
                    h = dt / n_sub / (1 << level)
                    gh = GAMMA * h
                    y0[:] = y2
                    dl0, dr0 = dl, dr
                    if steered:  # the servo to the first stage's time, then to the end
                        dl, dr = servo(body, d, dl, dr, delta_target[d], gh)
                        set_directions(wheel, d, nw, dl, body[d, B_WHEELBASE], dirs1)
                        dl, dr = servo(body, d, dl, dr, delta_target[d], h - gh)
                        set_directions(wheel, d, nw, dl, body[d, B_WHEELBASE], dirs2)
                    # both stages through one call site: the solver is inlined into this loop
                    # once (twice doubled the kernel's compile time)
                    sig1, res1, sig2, res2 = 0, 0.0, 0, 0.0
                    for stage in range(2):
                        if stage == 0:
                            a[:] = y0
                            y1[:] = y0
                        else:
                            # second stage: a = y0 + (1 - gamma) h f(Y1),
                            # f(Y1) = (Y1 - y0) / (gamma h)
                            for k in range(3 + nw):
                                a[k] = y0[k] + (1.0 - GAMMA) / GAMMA * (y1[k] - y0[k])
                            for k in range(3 + nw):  # first guess: f(Y2) = f(Y1)
                                y2[k] = a[k] + y1[k] - y0[k]
                        sig, res = solve_stage(
                            body,
                            wheel,
                            d,
                            mu_n,
                            dirs[stage],
                            target,
                            gh,
                            a,
                            ys[stage],
                            taus[stage],
                            slip,
                            kap,
                            iterations,
                        )
                        if stage == 0:
                            sig1, res1 = sig, res
                        else:
                            sig2, res2 = sig, res
                    # the local error's estimate: gamma h |f(Y2) - f(Y1)|, velocities in m/s
                    est = 0.0
                    for k in range(3 + nw):
                        e = abs(y2[k] - a[k] - (y1[k] - y0[k]))
                        est = max(
                            est, e * (1.0 if k < 2 else (lever if k == 2 else body[d, B_RADIUS]))
                        )
                    kink = sig1 != sig2 or (sig0 >= 0 and sig0 != sig1)
                    if level < levels and (kink or est > ERROR_TOL_M_S or res1 > 0 or res2 > 0):
                        # a kink of the friction law or a torque limit inside: halve the step
                        y2[:] = y0
                        dl, dr = dl0, dr0
                        level += 1
                        continue
                    sig0 = sig2
                    taken += 1
                    for res in (res1, res2):  # counted in the sub-steps kept only
                        if res > 0.0:
                            unconverged += 1
                            residual = max(residual, res)
                    pos += 1 << (levels - level)
                    while level > 0 and pos % (1 << (levels - level + 1)) == 0:
                        level -= 1  # back to longer steps on their grid
                    # the pose: exactly on SE(2) with the stages' twists at P, weighted like f
                    vx = (1.0 - GAMMA) * (y1[0] + y1[2] * cy) + GAMMA * (y2[0] + y2[2] * cy)
                    vy = (1.0 - GAMMA) * (y1[1] - y1[2] * cx) + GAMMA * (y2[1] - y2[2] * cx)
                    rot = ((1.0 - GAMMA) * y1[2] + GAMMA * y2[2]) * h
                    mx, my = vx * h, vy * h
                    sin_a, cos_a = math.sin(rot), math.cos(rot)
                    sinc = 1.0 - rot * rot / 6.0 if abs(rot) < 1e-6 else sin_a / rot
                    cosc = sinc * sin_a / (1.0 + cos_a)  # (1 - cos a) / a without cancellation
                    dx, dy = mx * sinc - my * cosc, mx * cosc + my * sinc
                    rx += cr * dx - sr * dy
                    ry += sr * dx + cr * dy
                    cr, sr = cr * cos_a - sr * sin_a, sr * cos_a + cr * sin_a
                    rth += rot
                    for i in range(nw):
                        p1, p2 = y1[3 + i], y2[3 + i]
                        out_angle[d, i] += h * ((1.0 - GAMMA) * p1 + GAMMA * p2)
                        out_work[d, i] += h * ((1.0 - GAMMA) * tau1[i] * p1 + GAMMA * tau2[i] * p2)
            for i in range(nw):
                phi[d, i] = y2[3 + i]
                out_torque[d, i] = tau2[i]
                out_slip[d, i] = slip[i]
            w = y2[2]
            vel[d, 0], vel[d, 1], vel[d, 2] = y2[0] + w * cy, y2[1] - w * cx, w
            out_speed[d, 1] = math.sqrt(vel[d, 0] ** 2 + vel[d, 1] ** 2)
            for j in range(steer_cols.shape[1]):
                c = steer_cols[d, j]
                out_steer[d, j] = (
                    0.0 if c < 0 else wheel_angle(wheel, d, c, dl, body[d, B_WHEELBASE])
                )
            delta[d], delta_rate[d] = dl, dr
            out_twist[d, 0], out_twist[d, 1], out_twist[d, 2] = se2_log(rx, ry, rth, dt)
            out_nsub[d] = taken
            out_unconverged[d], out_residual[d] = unconverged, residual
