"""The plant's floating base (numba kernel): the composite Newton-Euler system and the base-state derivative.

Physics (notes §3.4, "what the simulator must compute"): a floating base (the UAV, origin O at the UAV's own CoM,
body frame FRD) carries three planar links and a point-mass object with sphere inertia (arm_dynamics); the joint
motion q(t) is prescribed by the servo (joint_servo). The base accelerations (a_O, w') solve the composite 6x6
Newton-Euler system

    [[m E, -m[c]x], [m[c]x, J_O]] [a_O; w'] = [F; M_O] - [b_F; b_M]

with the bias b = the arm's relative accelerations and the velocity terms (RNEA with zero base acceleration). It is
solved by the Schur complement: J_c w' = M_O - b_M - c x (F - b_F) with J_c = J_O - m(|c|^2 E - c c^T) the inertia
about the composite CoM, then a_O = (F - b_F)/m + c x w'. The external wrench about O: propulsion (actuators),
gravity m g at the composite CoM, ground contact (ground_contact).
"""

from __future__ import annotations

from numba import njit

from navig8_fc.core.jit import njit_cached
from sim_bridge import actuators, arm_dynamics, ground_contact, plant_layout
from sim_bridge.actuators import propulsion
from sim_bridge.arm_dynamics import arm_reaction, arm_sums
from sim_bridge.ground_contact import contact_wrench
from sim_bridge.plant_layout import BASE_ATTITUDE_LOCKED, BASE_FREE, D, P, X, put3, put_sym3


@njit(cache=True)
def dcm(qw: float, qx: float, qy: float, qz: float):
    """Rows of R (body -> NED) from a unit quaternion."""
    return (
        1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy),
        2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx),
        2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy),
    )


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def solve_base(base_mode, m, cx, cy, cz, a11, a12, a13, a22, a23, a33, ex, ey, ez, mox, moy, moz, bmx, bmy, bmz):
    """The base accelerations (a_O, w') in body axes, (aox, aoy, aoz, dwx, dwy, dwz), of the composite system with
    mass m, CoM c, inertia about the CoM J_c = a, F - b_F = e, external moment about O mo and Euler bias bm; the
    attitude-locked base has w' = 0, the fixed base a_O = w' = 0."""
    if base_mode == BASE_FREE:
        # rhs = M_O - b_M - c x (F - b_F)
        hx = mox - bmx - (cy * ez - cz * ey)
        hy = moy - bmy - (cz * ex - cx * ez)
        hz = moz - bmz - (cx * ey - cy * ex)
        # symmetric 3x3 solve by the adjugate (J_c is positive definite)
        k11 = a22 * a33 - a23 * a23
        k12 = a13 * a23 - a12 * a33
        k13 = a12 * a23 - a13 * a22
        k22 = a11 * a33 - a13 * a13
        k23 = a12 * a13 - a11 * a23
        k33 = a11 * a22 - a12 * a12
        det = a11 * k11 + a12 * k12 + a13 * k13
        dwx = (k11 * hx + k12 * hy + k13 * hz) / det
        dwy = (k12 * hx + k22 * hy + k23 * hz) / det
        dwz = (k13 * hx + k23 * hy + k33 * hz) / det
        # a_O = (F - b_F)/m + c x w'
        aox = ex / m + (cy * dwz - cz * dwy)
        aoy = ey / m + (cz * dwx - cx * dwz)
        aoz = ez / m + (cx * dwy - cy * dwx)
        return aox, aoy, aoz, dwx, dwy, dwz
    if base_mode == BASE_ATTITUDE_LOCKED:
        return ex / m, ey / m, ez / m, 0.0, 0.0, 0.0
    return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@njit_cached(plant_layout, arm_dynamics, actuators, ground_contact)
def dynamics(xb, q, qd, qdd, act, mobj, p, base_mode, out, sc, d, full):
    """Base-state derivative at one instant. xb: the base state (x[:N_BASE], X layout); q, qd, qdd: joint motion
    at this instant; act: actuator outputs (5). Writes dx/dt into out (N_BASE); sc (arm_dynamics: N_BODIES x SC) is
    scratch for the per-body data of the reaction wrench. With full=True also fills the derived quantities d."""
    g = p[P.G]
    qw, qx, qy, qz = xb[X.QUAT], xb[X.QUAT + 1], xb[X.QUAT + 2], xb[X.QUAT + 3]
    wx, wy, wz = xb[X.RATE], xb[X.RATE + 1], xb[X.RATE + 2]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = dcm(qw, qx, qy, qz)
    # gravity in body axes: R^T [0, 0, g]
    gbx, gby, gbz = g * r20, g * r21, g * r22

    # ---- composite sums: the UAV (J0 about O; its gyroscopic term w x J0 w in the Euler bias), then the arm --------
    m = p[P.M0] + 3.0 * p[P.ML] + mobj
    j0wx = p[P.J0] * wx + p[P.J0 + 1] * wy + p[P.J0 + 2] * wz
    j0wy = p[P.J0 + 3] * wx + p[P.J0 + 4] * wy + p[P.J0 + 5] * wz
    j0wz = p[P.J0 + 6] * wx + p[P.J0 + 7] * wy + p[P.J0 + 8] * wz
    mcx, mcy, mcz, jxx, jxy, jxz, jyy, jyz, jzz, bfx, bfy, bfz, bmx, bmy, bmz = arm_sums(
        q, qd, qdd, mobj, p, wx, wy, wz, sc, p[P.J0], p[P.J0 + 1], p[P.J0 + 2], p[P.J0 + 4], p[P.J0 + 5],
        p[P.J0 + 8], wy * j0wz - wz * j0wy, wz * j0wx - wx * j0wz, wx * j0wy - wy * j0wx)
    cx = mcx / m
    cy = mcy / m
    cz = mcz / m

    # ---- external wrench about O in body axes -------------------------------------------------
    fpx, fpy, fpz, mpx, mpy, mpz = propulsion(act, p)
    # R as a fresh tuple of its entries: passing dcm's own result tuple on made the whole step ~10 % slower
    fcx, fcy, fcz, mcox, mcoy, mcoz, ncont = contact_wrench(xb, p, wx, wy, wz,
                                                             (r00, r01, r02, r10, r11, r12, r20, r21, r22))
    fx = fpx + fcx + m * gbx
    fy = fpy + fcy + m * gby
    fz = fpz + fcz + m * gbz
    # gravity acts at the composite CoM: moment m c x g_b about O
    mox = mpx + mcox + (mcy * gbz - mcz * gby)
    moy = mpy + mcoy + (mcz * gbx - mcx * gbz)
    moz = mpz + mcoz + (mcx * gby - mcy * gbx)

    # ---- solve the 6x6 composite Newton-Euler system (Schur complement) -------------------------
    ex = fx - bfx
    ey = fy - bfy
    ez = fz - bfz
    # J_c = J_O - m (|c|^2 E - c c^T), the inertia about the composite CoM
    c2 = cx * cx + cy * cy + cz * cz
    a11 = jxx - m * (c2 - cx * cx)
    a22 = jyy - m * (c2 - cy * cy)
    a33 = jzz - m * (c2 - cz * cz)
    a12 = jxy + m * cx * cy
    a13 = jxz + m * cx * cz
    a23 = jyz + m * cy * cz
    aox, aoy, aoz, dwx, dwy, dwz = solve_base(base_mode, m, cx, cy, cz, a11, a12, a13, a22, a23, a33, ex, ey, ez,
                                              mox, moy, moz, bmx, bmy, bmz)

    # ---- state derivative ---------------------------------------------------------------------
    out[X.POS] = xb[X.VEL]
    out[X.POS + 1] = xb[X.VEL + 1]
    out[X.POS + 2] = xb[X.VEL + 2]
    out[X.VEL] = r00 * aox + r01 * aoy + r02 * aoz
    out[X.VEL + 1] = r10 * aox + r11 * aoy + r12 * aoz
    out[X.VEL + 2] = r20 * aox + r21 * aoy + r22 * aoz
    # q' = 1/2 q (x) [0, w]
    out[X.QUAT] = -0.5 * (qx * wx + qy * wy + qz * wz)
    out[X.QUAT + 1] = 0.5 * (qw * wx + qy * wz - qz * wy)
    out[X.QUAT + 2] = 0.5 * (qw * wy + qz * wx - qx * wz)
    out[X.QUAT + 3] = 0.5 * (qw * wz + qx * wy - qy * wx)
    if base_mode == BASE_FREE:
        out[X.RATE] = dwx
        out[X.RATE + 1] = dwy
        out[X.RATE + 2] = dwz
    else:
        out[X.RATE] = 0.0
        out[X.RATE + 1] = 0.0
        out[X.RATE + 2] = 0.0

    if not full:
        return

    put3(d, D.ACC, aox, aoy, aoz)
    put3(d, D.WDOT, dwx, dwy, dwz)
    put3(d, D.SPF, aox - gbx, aoy - gby, aoz - gbz)
    d[D.MASS] = m
    put3(d, D.COM, cx, cy, cz)
    put_sym3(d, D.JO, jxx, jxy, jxz, jyy, jyz, jzz)
    put_sym3(d, D.JC, a11, a12, a13, a22, a23, a33)
    put3(d, D.FPROP, fpx, fpy, fpz)
    put3(d, D.MPROP, mpx, mpy, mpz)
    put3(d, D.FCONT, fcx, fcy, fcz)
    put3(d, D.MCONT, mcox, mcoy, mcoz)
    d[D.NCONT] = ncont
    arm_reaction(sc, p, mobj, wx, wy, wz, aox, aoy, aoz, dwx, dwy, dwz, gbx, gby, gbz, d)
