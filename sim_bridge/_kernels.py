"""Numba hot path of the plant: multibody dynamics, RK4, actuators, joint servo, contact, sensors.

Everything here works on flat float64 arrays with the fixed layouts below (plain float maths, no
allocation in the inner loop), because numpy on 3-vectors costs ~1-16 us per operation and the
plant's budget is ~2-5 us per 1 ms physics step (docs/plant.md). The Python side
(`sim_bridge/plant.py`) owns the layouts' meaning; this module only computes.

Physics (notes §3.4, "what the simulator must compute"): a floating base (the UAV, origin O at the
UAV's own CoM, body frame FRD) carries three planar links and a point-mass object with sphere
inertia; the joint motion q(t) is prescribed by the servo model (q'' piecewise constant). The base
accelerations (a_O, w') solve the composite 6x6 Newton-Euler system

    [[m E, -m[c]x], [m[c]x, J_O]] [a_O; w'] = [F; M_O] - [b_F; b_M]

with the bias b = the arm's relative accelerations and the velocity terms (RNEA with zero base
acceleration). It is solved by the Schur complement: J_c w' = M_O - b_M - c x (F - b_F) with
J_c = J_O - m(|c|^2 E - c c^T) the inertia about the composite CoM, then a_O = (F - b_F)/m + c x w'.
"""

from __future__ import annotations

import math

from numba import njit

# ---------------------------------------------------------------------------------------------
# State vector x (float64)
# ---------------------------------------------------------------------------------------------
X_POS = 0  # 0:3 position of O, NED (m)
X_VEL = 3  # 3:6 velocity of O, NED (m/s)
X_QUAT = 6  # 6:10 attitude [w, x, y, z], body FRD -> NED
X_RATE = 10  # 10:13 body rates, FRD (rad/s)
N_BASE = 13  # the part of x integrated by RK4
X_ACT = 13  # 13:18 actuator outputs (alpha1, alpha3 rad; w1, w2, w3 rad/s)
X_ACTD = 18  # 18:23 their time derivatives
X_Q = 23  # 23:26 joint angles (rad)
X_QD = 26  # 26:29 joint rates (rad/s)
X_QDD = 29  # 29:32 joint accelerations over the current servo period (rad/s^2)
X_MOBJ = 32  # object mass (kg), 0 when nothing is held
X_QTGT = 33  # 33:36 joint targets the servo used last (rad)
N_X = 36

N_ACT = 5
N_CONTACT_MAX = 8

# ---------------------------------------------------------------------------------------------
# Parameter vector p (float64), built once by plant.py
# ---------------------------------------------------------------------------------------------
P_G = 0  # gravity (m/s^2)
P_M0 = 1  # UAV mass (kg)
P_J0 = 2  # 2:11 UAV inertia about O, row-major 3x3
P_ML = 11  # link mass
P_IA = 12  # link transverse inertia (slender rod)
P_L = 13  # link length
P_MOUNT = 14  # 14:17 joint-1 position relative to O, FRD
P_OBJ_D = 17  # object centre offset beyond the tip along link 3
P_OBJ_R = 18  # object sphere radius (inertia 0.4 m r^2)
P_PF = 19  # 19:34 force per unit U, 3x5 row-major (vehicle.propulsion_wrench)
P_PM = 34  # 34:49 moment about O per unit U, 3x5 row-major
P_PHI_H = 49  # 49:69 actuator transition matrices over h, 5 x [p11, p12, p21, p22]
P_GAM_H = 69  # 69:79 actuator input vectors over h, 5 x [g1, g2]
P_PHI_H2 = 79  # 79:99 same over h/2 (RK4 mid stages)
P_GAM_H2 = 99  # 99:109
P_ACT_MIN = 109  # 109:114
P_ACT_MAX = 114  # 114:119
P_H = 119  # physics step (s)
P_SERVO_N = 120  # physics steps per servo period
P_VMAX = 121  # joint rate limit (rad/s)
P_AMAX = 122  # joint acceleration limit (rad/s^2)
P_QLIM = 123  # joint angle limit (rad), targets are clamped to +-QLIM
P_KN = 124  # contact normal stiffness per point (N/m)
P_CN = 125  # contact normal damping per point (N s/m)
P_MU = 126  # friction coefficient
P_VEPS = 127  # friction regularisation speed (m/s)
P_NC = 128  # number of contact points
P_CP = 129  # 129:153 contact points, FRD relative to O (8 x 3)
P_H_US = 153  # physics step in microseconds (integer-valued)
N_P = 154

# ---------------------------------------------------------------------------------------------
# Derived quantities d (float64), filled at the end of every advance() / evaluate()
# ---------------------------------------------------------------------------------------------
D_ACC = 0  # 0:3 absolute acceleration of O, body FRD (m/s^2)
D_WDOT = 3  # 3:6 body angular acceleration (rad/s^2)
D_SPF = 6  # 6:9 specific force at O, body (a_O - g), what an ideal accelerometer at O reads
D_MASS = 9  # total mass (kg)
D_COM = 10  # 10:13 composite CoM relative to O, FRD
D_JC = 13  # 13:22 inertia about the composite CoM (3x3 row-major)
D_JO = 22  # 22:31 inertia about O
D_FR_G = 31  # 31:34 reaction force of the arm on the UAV, gravity included (N, FRD)
D_FR_NOG = 34  # 34:37 same without the arm's weight (inertial part only)
D_MR_MOUNT_G = 37  # 37:40 reaction moment about the mount, gravity included (N m)
D_MR_MOUNT_NOG = 40  # 40:43
D_MR_O_G = 43  # 43:46 reaction moment about O, gravity included
D_MR_O_NOG = 46  # 46:49
D_FPROP = 49  # 49:52 propulsive force (N, FRD)
D_MPROP = 52  # 52:55 propulsive moment about O (N m)
D_FCONT = 55  # 55:58 ground contact force (N, FRD)
D_MCONT = 58  # 58:61 ground contact moment about O
D_NCONT = 61  # number of contact points touching
N_D = 62

# Base modes: how the floating base is constrained (analysis variants; flight uses FREE).
BASE_FREE = 0
BASE_ATTITUDE_LOCKED = 1  # w = w' = 0, translation free: the limit of an infinitely stiff attitude loop
BASE_FIXED = 2  # a_O = w' = 0: the base is held (a test stand)

# Command vector: 0:5 actuator commands (already validated and clamped by plant.py),
# 5 joint-override flag (1.0: use 6:9 as joint targets instead of the schedule), 6:9 targets.
C_ACT = 0
C_JOVR = 5
C_JTGT = 6
N_C = 9

# Arm schedule rows: [t0_us, t1_us, qa1, qa2, qa3, qb1, qb2, qb3]; target(t) interpolates linearly
# from qa at t0 to qb at t1 (a step is a zero-length segment's neighbour). Before the first row the
# first qa holds, after the last row the last qb holds.
N_SCHED_COLS = 8

# Scratch for advance()/evaluate(), owned by the caller (no allocation in the hot path).
N_WORK = 138 + N_X

# Sensor output vector s (float64), the SensorBundle's fields in this order.
S_GYRO = 0  # 0:3
S_ACC = 3  # 3:6
S_POS = 6  # 6:9
S_VEL = 9  # 9:12
S_QUAT = 12  # 12:16
S_DUCT = 16  # 16:18
S_PROP = 18  # 18:21
S_JQ = 21  # 21:24
S_JQD = 24  # 24:27
N_S = 27
# Noise draws per sample: gyro 3, accel 3, pos 3, vel 3, attitude 3, duct 2, prop 3, jq 3, jqd 3.
N_NOISE = 26
# Sigma vector: gyro, accel, pos, vel, attitude, duct, prop, joint pos, joint rate.
N_SIG = 9
# Sensor group bits (same values as sensors.SensorField).
G_IMU = 1
G_MOCAP = 2
G_ACT = 4
G_JOINT = 8


@njit(cache=True)
def _dcm(qw: float, qx: float, qy: float, qz: float):
    """Rows of R (body -> NED) from a unit quaternion."""
    return (
        1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy),
        2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx),
        2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy),
    )


@njit(cache=True)
def _own_inertia(k: int, ia: float, io: float, s: float, c: float):
    """Body k's own inertia about its centre, body axes: link rod Ia (E - e e^T) with e = [s, 0, c]
    (Table 1: Izz = 0 along the link) for k < 3, the object's sphere io E for k = 3. (xx, yy, zz, xz)."""
    if k < 3:
        return ia * c * c, ia, ia * s * s, -ia * s * c
    return io, io, io, 0.0


@njit(cache=True)
def _dynamics(xb, q, qd, qdd, act, mobj, p, base_mode, out, sc, d, full):
    """Base-state derivative at one instant. xb: (13,) base state; q, qd, qdd: joint motion at this
    instant; act: actuator outputs (5). Writes dx/dt into out (13); sc (36,) is scratch for the
    per-body data of the reaction wrench. With full=True also fills the derived quantities d."""
    g = p[P_G]
    qw, qx, qy, qz = xb[6], xb[7], xb[8], xb[9]
    wx, wy, wz = xb[10], xb[11], xb[12]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _dcm(qw, qx, qy, qz)
    # gravity in body axes: R^T [0, 0, g]
    gbx, gby, gbz = g * r20, g * r21, g * r22

    # ---- arm kinematics relative to the body (notes §3.1) and composite sums ------------------
    ml = p[P_ML]
    ia = p[P_IA]
    L = p[P_L]
    mx, my, mz = p[P_MOUNT], p[P_MOUNT + 1], p[P_MOUNT + 2]
    m = p[P_M0] + 3.0 * ml + mobj
    # first moment m c (UAV contributes nothing: O is its CoM)
    mcx = 0.0
    mcy = 0.0
    mcz = 0.0
    # J_O accumulators (symmetric; J_xy = J_yz = 0 is NOT assumed for the mount's y offset)
    jxx = p[P_J0]
    jxy = p[P_J0 + 1]
    jxz = p[P_J0 + 2]
    jyy = p[P_J0 + 4]
    jyz = p[P_J0 + 5]
    jzz = p[P_J0 + 8]
    # UAV gyroscopic term w x J0 w goes into the Euler bias
    j0wx = p[P_J0] * wx + p[P_J0 + 1] * wy + p[P_J0 + 2] * wz
    j0wy = p[P_J0 + 3] * wx + p[P_J0 + 4] * wy + p[P_J0 + 5] * wz
    j0wz = p[P_J0 + 6] * wx + p[P_J0 + 7] * wy + p[P_J0 + 8] * wz
    bfx = 0.0
    bfy = 0.0
    bfz = 0.0
    bmx = wy * j0wz - wz * j0wy
    bmy = wz * j0wx - wx * j0wz
    bmz = wx * j0wy - wy * j0wx
    # arm-only sums for the reaction wrench: sum m_k (relative + velocity terms), and moments
    th = 0.0
    thd = 0.0
    thdd = 0.0
    jx = mx
    jz = mz
    jvx = 0.0
    jvz = 0.0
    jax = 0.0
    jaz = 0.0
    io = 0.4 * mobj * p[P_OBJ_R] * p[P_OBJ_R]
    for k in range(4):
        if k < 3:
            th += q[k]
            thd += qd[k]
            thdd += qdd[k]
        s = math.sin(th)
        c = math.cos(th)
        if k < 3:
            half = 0.5 * L
            mk = ml
        else:
            half = p[P_OBJ_D]
            mk = mobj
        # e = [s, 0, c], de/dth = [c, 0, -s]; a = thdd de - thd^2 e
        rx = jx + half * s
        rz = jz + half * c
        vx = jvx + half * thd * c
        vz = jvz - half * thd * s
        ax = jax + half * (thdd * c - thd * thd * s)
        az = jaz + half * (-thdd * s - thd * thd * c)
        ry = my
        if k < 3:
            # next joint
            jx += L * s
            jz += L * c
            jvx += L * thd * c
            jvz -= L * thd * s
            jax += L * (thdd * c - thd * thd * s)
            jaz += L * (-thdd * s - thd * thd * c)
        # bias acceleration of body k: w x (w x r) + 2 w x r' + r''   (r' and r'' have no y part)
        wrx = wy * rz - wz * ry
        wry = wz * rx - wx * rz
        wrz = wx * ry - wy * rx
        bx = wy * wrz - wz * wry + 2.0 * (wy * vz) + ax
        by = wz * wrx - wx * wrz + 2.0 * (wz * vx - wx * vz)
        bz = wx * wry - wy * wrx + 2.0 * (-wy * vx) + az
        # per-body data for the reaction wrench (no allocation in the hot path)
        sc[9 * k] = mk
        sc[9 * k + 1] = rx
        sc[9 * k + 2] = rz
        sc[9 * k + 3] = bx
        sc[9 * k + 4] = by
        sc[9 * k + 5] = bz
        sc[9 * k + 6] = th
        sc[9 * k + 7] = thd
        sc[9 * k + 8] = thdd
        bfx += mk * bx
        bfy += mk * by
        bfz += mk * bz
        bmx += mk * (ry * bz - rz * by)
        bmy += mk * (rz * bx - rx * bz)
        bmz += mk * (rx * by - ry * bx)
        mcx += mk * rx
        mcy += mk * ry
        mcz += mk * rz
        # point-mass inertia about O
        r2 = rx * rx + ry * ry + rz * rz
        jxx += mk * (r2 - rx * rx)
        jyy += mk * (r2 - ry * ry)
        jzz += mk * (r2 - rz * rz)
        jxy -= mk * rx * ry
        jxz -= mk * rx * rz
        jyz -= mk * ry * rz
        # own rotational inertia: rod Ia (E - e e^T) (Table 1: Izz = 0 along the link), or sphere io E
        ixx, iyy, izz, ixz = _own_inertia(k, ia, io, s, c)
        jxx += ixx
        jyy += iyy
        jzz += izz
        jxz += ixz
        # Euler bias of the body's own inertia: I (thdd y + w x thd y) + W x I W, W = w + thd y
        ux = -wz * thd  # w x (thd y) = [-wz thd, 0, wx thd]
        uy = thdd
        uz = wx * thd
        Wx = wx
        Wy = wy + thd
        Wz = wz
        iWx = ixx * Wx + ixz * Wz
        iWy = iyy * Wy
        iWz = ixz * Wx + izz * Wz
        bmx += ixx * ux + ixz * uz + (Wy * iWz - Wz * iWy)
        bmy += iyy * uy + (Wz * iWx - Wx * iWz)
        bmz += ixz * ux + izz * uz + (Wx * iWy - Wy * iWx)

    cx = mcx / m
    cy = mcy / m
    cz = mcz / m

    # ---- external wrench about O in body axes -------------------------------------------------
    # propulsion (notes §2.1-2.2), linear in U; thrust grows with w|w| so a reversed prop pushes back
    a1 = act[0]
    a3 = act[1]
    w1 = act[2]
    w2 = act[3]
    w3 = act[4]
    w1s = w1 * abs(w1)
    w3s = w3 * abs(w3)
    u0 = math.cos(a1) * w1s
    u1 = math.sin(a1) * w1s
    u2 = math.cos(a3) * w3s
    u3 = math.sin(a3) * w3s
    u4 = w2 * abs(w2)
    fpx = p[P_PF + 0] * u0 + p[P_PF + 1] * u1 + p[P_PF + 2] * u2 + p[P_PF + 3] * u3 + p[P_PF + 4] * u4
    fpy = p[P_PF + 5] * u0 + p[P_PF + 6] * u1 + p[P_PF + 7] * u2 + p[P_PF + 8] * u3 + p[P_PF + 9] * u4
    fpz = p[P_PF + 10] * u0 + p[P_PF + 11] * u1 + p[P_PF + 12] * u2 + p[P_PF + 13] * u3 + p[P_PF + 14] * u4
    mpx = p[P_PM + 0] * u0 + p[P_PM + 1] * u1 + p[P_PM + 2] * u2 + p[P_PM + 3] * u3 + p[P_PM + 4] * u4
    mpy = p[P_PM + 5] * u0 + p[P_PM + 6] * u1 + p[P_PM + 7] * u2 + p[P_PM + 8] * u3 + p[P_PM + 9] * u4
    mpz = p[P_PM + 10] * u0 + p[P_PM + 11] * u1 + p[P_PM + 12] * u2 + p[P_PM + 13] * u3 + p[P_PM + 14] * u4

    # ground contact: spring-damper + regularised Coulomb friction at the skid points (NED z = 0 ground)
    fcx = 0.0
    fcy = 0.0
    fcz = 0.0
    mcox = 0.0
    mcoy = 0.0
    mcoz = 0.0
    ncont = 0
    nc = int(p[P_NC])
    for i in range(nc):
        px = p[P_CP + 3 * i]
        py = p[P_CP + 3 * i + 1]
        pz = p[P_CP + 3 * i + 2]
        depth = xb[2] + r20 * px + r21 * py + r22 * pz
        if depth > 0.0:
            # point velocity in NED: v + R (w x p)
            ox = wy * pz - wz * py
            oy = wz * px - wx * pz
            oz = wx * py - wy * px
            vnx = xb[3] + r00 * ox + r01 * oy + r02 * oz
            vny = xb[4] + r10 * ox + r11 * oy + r12 * oz
            vnz = xb[5] + r20 * ox + r21 * oy + r22 * oz
            fn = p[P_KN] * depth + p[P_CN] * vnz
            if fn > 0.0:
                ncont += 1
                vt = math.sqrt(vnx * vnx + vny * vny + p[P_VEPS] * p[P_VEPS])
                ftx = -p[P_MU] * fn * vnx / vt
                fty = -p[P_MU] * fn * vny / vt
                ftz = -fn
                # NED -> body: R^T f
                fbx = r00 * ftx + r10 * fty + r20 * ftz
                fby = r01 * ftx + r11 * fty + r21 * ftz
                fbz = r02 * ftx + r12 * fty + r22 * ftz
                fcx += fbx
                fcy += fby
                fcz += fbz
                mcox += py * fbz - pz * fby
                mcoy += pz * fbx - px * fbz
                mcoz += px * fby - py * fbx

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
    if base_mode == BASE_FREE:
        # J_c = J_O - m (|c|^2 E - c c^T)
        c2 = cx * cx + cy * cy + cz * cz
        a11 = jxx - m * (c2 - cx * cx)
        a22 = jyy - m * (c2 - cy * cy)
        a33 = jzz - m * (c2 - cz * cz)
        a12 = jxy + m * cx * cy
        a13 = jxz + m * cx * cz
        a23 = jyz + m * cy * cz
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
    elif base_mode == BASE_ATTITUDE_LOCKED:
        dwx = 0.0
        dwy = 0.0
        dwz = 0.0
        aox = ex / m
        aoy = ey / m
        aoz = ez / m
    else:
        dwx = 0.0
        dwy = 0.0
        dwz = 0.0
        aox = 0.0
        aoy = 0.0
        aoz = 0.0

    # ---- state derivative ---------------------------------------------------------------------
    out[0] = xb[3]
    out[1] = xb[4]
    out[2] = xb[5]
    out[3] = r00 * aox + r01 * aoy + r02 * aoz
    out[4] = r10 * aox + r11 * aoy + r12 * aoz
    out[5] = r20 * aox + r21 * aoy + r22 * aoz
    # q' = 1/2 q (x) [0, w]
    out[6] = -0.5 * (qx * wx + qy * wy + qz * wz)
    out[7] = 0.5 * (qw * wx + qy * wz - qz * wy)
    out[8] = 0.5 * (qw * wy + qz * wx - qx * wz)
    out[9] = 0.5 * (qw * wz + qx * wy - qy * wx)
    if base_mode == BASE_FREE:
        out[10] = dwx
        out[11] = dwy
        out[12] = dwz
    else:
        out[10] = 0.0
        out[11] = 0.0
        out[12] = 0.0

    if not full:
        return

    d[D_ACC] = aox
    d[D_ACC + 1] = aoy
    d[D_ACC + 2] = aoz
    d[D_WDOT] = dwx
    d[D_WDOT + 1] = dwy
    d[D_WDOT + 2] = dwz
    d[D_SPF] = aox - gbx
    d[D_SPF + 1] = aoy - gby
    d[D_SPF + 2] = aoz - gbz
    d[D_MASS] = m
    d[D_COM] = cx
    d[D_COM + 1] = cy
    d[D_COM + 2] = cz
    c2 = cx * cx + cy * cy + cz * cz
    d[D_JO + 0] = jxx
    d[D_JO + 1] = jxy
    d[D_JO + 2] = jxz
    d[D_JO + 3] = jxy
    d[D_JO + 4] = jyy
    d[D_JO + 5] = jyz
    d[D_JO + 6] = jxz
    d[D_JO + 7] = jyz
    d[D_JO + 8] = jzz
    d[D_JC + 0] = jxx - m * (c2 - cx * cx)
    d[D_JC + 1] = jxy + m * cx * cy
    d[D_JC + 2] = jxz + m * cx * cz
    d[D_JC + 3] = d[D_JC + 1]
    d[D_JC + 4] = jyy - m * (c2 - cy * cy)
    d[D_JC + 5] = jyz + m * cy * cz
    d[D_JC + 6] = d[D_JC + 2]
    d[D_JC + 7] = d[D_JC + 5]
    d[D_JC + 8] = jzz - m * (c2 - cz * cz)
    d[D_FPROP] = fpx
    d[D_FPROP + 1] = fpy
    d[D_FPROP + 2] = fpz
    d[D_MPROP] = mpx
    d[D_MPROP + 1] = mpy
    d[D_MPROP + 2] = mpz
    d[D_FCONT] = fcx
    d[D_FCONT + 1] = fcy
    d[D_FCONT + 2] = fcz
    d[D_MCONT] = mcox
    d[D_MCONT + 1] = mcoy
    d[D_MCONT + 2] = mcoz
    d[D_NCONT] = ncont

    # ---- reaction wrench of the arm on the UAV (notes §3.4 step 5) -----------------------------
    # a_k = a_O + w' x r_k + b_k; link angular acceleration W'_k = w' + thdd y + w x thd y.
    # F_r = -sum m_k (a_k - g); M_r,mount = -sum [(r_k - r_mount) x m_k (a_k - g) + I_k W'_k + W_k x I_k W_k]
    frx = 0.0
    fry = 0.0
    frz = 0.0
    mrx = 0.0
    mry = 0.0
    mrz = 0.0
    marm = 0.0
    gmx = 0.0  # sum m_k (r_k - mount) for the weight's moment
    gmy = 0.0
    gmz = 0.0
    for k in range(4):
        mk = sc[9 * k]
        rx = sc[9 * k + 1]
        ry = my
        rz = sc[9 * k + 2]
        akx = aox + (dwy * rz - dwz * ry) + sc[9 * k + 3]
        aky = aoy + (dwz * rx - dwx * rz) + sc[9 * k + 4]
        akz = aoz + (dwx * ry - dwy * rx) + sc[9 * k + 5]
        dx_ = rx - mx
        dy_ = ry - my
        dz_ = rz - mz
        frx -= mk * akx
        fry -= mk * aky
        frz -= mk * akz
        mrx -= mk * (dy_ * akz - dz_ * aky)
        mry -= mk * (dz_ * akx - dx_ * akz)
        mrz -= mk * (dx_ * aky - dy_ * akx)
        marm += mk
        gmx += mk * dx_
        gmy += mk * dy_
        gmz += mk * dz_
        s = math.sin(sc[9 * k + 6])
        c = math.cos(sc[9 * k + 6])
        thd = sc[9 * k + 7]
        thdd = sc[9 * k + 8]
        ixx, iyy, izz, ixz = _own_inertia(k, ia, io, s, c)
        awx = dwx - wz * thd
        awy = dwy + thdd
        awz = dwz + wx * thd
        Wx = wx
        Wy = wy + thd
        Wz = wz
        iWx = ixx * Wx + ixz * Wz
        iWy = iyy * Wy
        iWz = ixz * Wx + izz * Wz
        mrx -= ixx * awx + ixz * awz + (Wy * iWz - Wz * iWy)
        mry -= iyy * awy + (Wz * iWx - Wx * iWz)
        mrz -= ixz * awx + izz * awz + (Wx * iWy - Wy * iWx)
    d[D_FR_NOG] = frx
    d[D_FR_NOG + 1] = fry
    d[D_FR_NOG + 2] = frz
    d[D_FR_G] = frx + marm * gbx
    d[D_FR_G + 1] = fry + marm * gby
    d[D_FR_G + 2] = frz + marm * gbz
    d[D_MR_MOUNT_NOG] = mrx
    d[D_MR_MOUNT_NOG + 1] = mry
    d[D_MR_MOUNT_NOG + 2] = mrz
    # the weight acting at the arm bodies, seen at the mount: + sum (r_k - mount) x m_k g
    mgx = mrx + (gmy * gbz - gmz * gby)
    mgy = mry + (gmz * gbx - gmx * gbz)
    mgz = mrz + (gmx * gby - gmy * gbx)
    d[D_MR_MOUNT_G] = mgx
    d[D_MR_MOUNT_G + 1] = mgy
    d[D_MR_MOUNT_G + 2] = mgz
    # about O: M_O = M_mount + r_mount x F_r
    fgx = d[D_FR_G]
    fgy = d[D_FR_G + 1]
    fgz = d[D_FR_G + 2]
    d[D_MR_O_NOG] = mrx + (my * frz - mz * fry)
    d[D_MR_O_NOG + 1] = mry + (mz * frx - mx * frz)
    d[D_MR_O_NOG + 2] = mrz + (mx * fry - my * frx)
    d[D_MR_O_G] = mgx + (my * fgz - mz * fgy)
    d[D_MR_O_G + 1] = mgy + (mz * fgx - mx * fgz)
    d[D_MR_O_G + 2] = mgz + (mx * fgy - my * fgx)


@njit(cache=True)
def _servo_accel(e: float, v: float, h: float, amax: float, vmax: float) -> float:
    """Joint acceleration for the next servo period h: time-optimal, rate- and acceleration-limited.

    e = target - q, v = q'. Far from the target the law rides the continuous braking curve
    v = sign(e) sqrt(2 a_max |e|), which is invariant under exact constant-acceleration steps, so the
    motion is the bang-coast-bang trapezoid that hits both limits (notes §3.4: 4 rad/s, 42 rad/s^2).
    Close to the target it switches to the two-step deadbeat law a = (e - 1.5 v h)/h^2, which lands
    exactly on (e, v) = (0, 0) and gives a = 0 at rest, so the servo does not chatter.
    """
    # deadbeat terminal: a0 now, a1 = -v/h - a0 next period; use it when both fit the limits
    a0 = (e - 1.5 * v * h) / (h * h)
    a1 = -v / h - a0
    if abs(a0) <= amax and abs(a1) <= amax and abs(v + a0 * h) <= vmax:
        return a0
    # braking curve: the next-period velocity that puts the state on v = sign(e) sqrt(2 A |e|)
    s = e - 0.5 * v * h
    ah = amax * h
    v1 = math.sqrt(ah * ah + 8.0 * amax * abs(s)) - ah
    v1 = 0.5 * v1 if s >= 0.0 else -0.5 * v1
    if v1 > vmax:
        v1 = vmax
    elif v1 < -vmax:
        v1 = -vmax
    a = (v1 - v) / h
    if a > amax:
        a = amax
    elif a < -amax:
        a = -amax
    return a


@njit(cache=True)
def _schedule_target(sched, t_us: float, j: int) -> float:
    n = sched.shape[0]
    if t_us < sched[0, 0]:
        return sched[0, 2 + j]
    # binary search for the last row with t0 <= t
    lo = 0
    hi = n - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if sched[mid, 0] <= t_us:
            lo = mid
        else:
            hi = mid - 1
    t0 = sched[lo, 0]
    t1 = sched[lo, 1]
    if t_us >= t1:
        return sched[lo, 5 + j]
    return sched[lo, 2 + j] + (sched[lo, 5 + j] - sched[lo, 2 + j]) * (t_us - t0) / (t1 - t0)


@njit(cache=True)
def _act_at(x, p, cmd, phi, gam, out):
    """Exact second-order actuator outputs after tau (phi, gam = P_PHI_H or P_PHI_H2 offsets)."""
    for i in range(N_ACT):
        y = x[X_ACT + i]
        yd = x[X_ACTD + i]
        u = cmd[C_ACT + i]
        out[i] = p[phi + 4 * i] * y + p[phi + 4 * i + 1] * yd + p[gam + 2 * i] * u


@njit(cache=True)
def advance(x, p, cmd, sched, n_steps, t0_us, base_mode, d, w) -> int:
    """Advance the state x in place by n_steps physics steps from time t0_us (an integer on the
    physics grid). w is caller-owned scratch (N_WORK) so the hot path does not allocate.
    Returns 0, or 1 if the state became non-finite (x is then left as it was)."""
    h = p[P_H]
    h_us = int(p[P_H_US])
    servo_n = int(p[P_SERVO_N])
    hs = h * servo_n
    amax = p[P_AMAX]
    vmax = p[P_VMAX]
    qlim = p[P_QLIM]
    xb = w[0:13]
    xs = w[13:26]
    k1 = w[26:39]
    k2 = w[39:52]
    k3 = w[52:65]
    k4 = w[65:78]
    q = w[78:81]
    qd = w[81:84]
    qdd = w[84:87]
    act0 = w[87:92]
    acth = w[92:97]
    act1 = w[97:102]
    sc = w[102:138]
    backup = w[138:138 + N_X]
    for i in range(N_X):
        backup[i] = x[i]
    mobj = x[X_MOBJ]
    for n in range(n_steps):
        t_us = t0_us + n * h_us
        # ---- joint servo: new q'' at the start of each servo period -------------------------
        if (t_us // h_us) % servo_n == 0:
            for j in range(3):
                if cmd[C_JOVR] > 0.5:
                    tgt = cmd[C_JTGT + j]
                else:
                    tgt = _schedule_target(sched, float(t_us), j)
                if tgt > qlim:
                    tgt = qlim
                elif tgt < -qlim:
                    tgt = -qlim
                x[X_QTGT + j] = tgt
                if abs(tgt - x[X_Q + j]) <= 1e-12 and abs(x[X_QD + j]) <= 1e-9:
                    # arrived: snap the round-off residue of the deadbeat law so the joint rests exactly
                    x[X_Q + j] = tgt
                    x[X_QD + j] = 0.0
                    x[X_QDD + j] = 0.0
                else:
                    x[X_QDD + j] = _servo_accel(tgt - x[X_Q + j], x[X_QD + j], hs, amax, vmax)
        for i in range(N_BASE):
            xb[i] = x[i]
        for j in range(3):
            qdd[j] = x[X_QDD + j]
        # ---- actuator outputs at t, t + h/2, t + h (exact, ZOH command) ---------------------
        for i in range(N_ACT):
            act0[i] = x[X_ACT + i]
        _act_at(x, p, cmd, P_PHI_H2, P_GAM_H2, acth)
        _act_at(x, p, cmd, P_PHI_H, P_GAM_H, act1)
        # ---- RK4 on the base with the exact joint and actuator trajectories -----------------
        for j in range(3):
            q[j] = x[X_Q + j]
            qd[j] = x[X_QD + j]
        _dynamics(xb, q, qd, qdd, act0, mobj, p, base_mode, k1, sc, d, False)
        th = 0.5 * h
        for j in range(3):
            q[j] = x[X_Q + j] + x[X_QD + j] * th + 0.5 * qdd[j] * th * th
            qd[j] = x[X_QD + j] + qdd[j] * th
        for i in range(N_BASE):
            xs[i] = xb[i] + th * k1[i]
        _dynamics(xs, q, qd, qdd, acth, mobj, p, base_mode, k2, sc, d, False)
        for i in range(N_BASE):
            xs[i] = xb[i] + th * k2[i]
        _dynamics(xs, q, qd, qdd, acth, mobj, p, base_mode, k3, sc, d, False)
        for j in range(3):
            q[j] = x[X_Q + j] + x[X_QD + j] * h + 0.5 * qdd[j] * h * h
            qd[j] = x[X_QD + j] + qdd[j] * h
        for i in range(N_BASE):
            xs[i] = xb[i] + h * k3[i]
        _dynamics(xs, q, qd, qdd, act1, mobj, p, base_mode, k4, sc, d, False)
        for i in range(N_BASE):
            x[i] = xb[i] + (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        qn = math.sqrt(x[6] * x[6] + x[7] * x[7] + x[8] * x[8] + x[9] * x[9])
        for i in range(6, 10):
            x[i] /= qn
        # ---- joints: exact for constant q'' ---------------------------------------------------
        for j in range(3):
            x[X_Q + j] = q[j]
            x[X_QD + j] = qd[j]
        # ---- actuators: exact discretisation, then the hard stops ----------------------------
        for i in range(N_ACT):
            yd = (p[P_PHI_H + 4 * i + 2] * x[X_ACT + i] + p[P_PHI_H + 4 * i + 3] * x[X_ACTD + i]
                  + p[P_GAM_H + 2 * i + 1] * cmd[C_ACT + i])
            y = act1[i]
            if y > p[P_ACT_MAX + i]:
                y = p[P_ACT_MAX + i]
                if yd > 0.0:
                    yd = 0.0
            elif y < p[P_ACT_MIN + i]:
                y = p[P_ACT_MIN + i]
                if yd < 0.0:
                    yd = 0.0
            x[X_ACT + i] = y
            x[X_ACTD + i] = yd
    for i in range(N_X):
        if not math.isfinite(x[i]):
            for j in range(N_X):
                x[j] = backup[j]
            return 1
    evaluate(x, p, base_mode, d, w)
    return 0


@njit(cache=True)
def evaluate(x, p, base_mode, d, w) -> None:
    """Fill the derived quantities d at the current state (q'' = the current servo period's)."""
    _dynamics(x[0:N_BASE], x[X_Q:X_Q + 3], x[X_QD:X_QD + 3], x[X_QDD:X_QDD + 3], x[X_ACT:X_ACT + N_ACT],
              x[X_MOBJ], p, base_mode, w[13:26], w[102:138], d, True)


@njit(cache=True)
def sense(x, d, sig, noise, prev, groups, out) -> None:
    """Sensor sample: truth + sigma * N(0,1) for the groups due now, previous values for the others.

    The mocap attitude noise is a small body-frame rotation q_meas = q (x) [1, dth/2] (renormalised).
    """
    for i in range(N_S):
        out[i] = prev[i]
    if groups & G_IMU:
        for i in range(3):
            out[S_GYRO + i] = x[X_RATE + i] + sig[0] * noise[i]
            out[S_ACC + i] = d[D_SPF + i] + sig[1] * noise[3 + i]
    if groups & G_MOCAP:
        for i in range(3):
            out[S_POS + i] = x[X_POS + i] + sig[2] * noise[6 + i]
            out[S_VEL + i] = x[X_VEL + i] + sig[3] * noise[9 + i]
        hx = 0.5 * sig[4] * noise[12]
        hy = 0.5 * sig[4] * noise[13]
        hz = 0.5 * sig[4] * noise[14]
        qw, qx, qy, qz = x[6], x[7], x[8], x[9]
        ow = qw - qx * hx - qy * hy - qz * hz
        ox = qw * hx + qx + qy * hz - qz * hy
        oy = qw * hy - qx * hz + qy + qz * hx
        oz = qw * hz + qx * hy - qy * hx + qz
        nq = math.sqrt(ow * ow + ox * ox + oy * oy + oz * oz)
        if ow < 0.0:
            nq = -nq  # keep w >= 0 (same rotation)
        out[S_QUAT] = ow / nq
        out[S_QUAT + 1] = ox / nq
        out[S_QUAT + 2] = oy / nq
        out[S_QUAT + 3] = oz / nq
    if groups & G_ACT:
        out[S_DUCT] = x[X_ACT] + sig[5] * noise[15]
        out[S_DUCT + 1] = x[X_ACT + 1] + sig[5] * noise[16]
        out[S_PROP] = x[X_ACT + 2] + sig[6] * noise[17]
        out[S_PROP + 1] = x[X_ACT + 3] + sig[6] * noise[18]
        out[S_PROP + 2] = x[X_ACT + 4] + sig[6] * noise[19]
    if groups & G_JOINT:
        for i in range(3):
            out[S_JQ + i] = x[X_Q + i] + sig[7] * noise[20 + i]
            out[S_JQD + i] = x[X_QD + i] + sig[8] * noise[23 + i]
