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

from navig8_fc.core.layout import layout

# Layouts of the flat float64 vectors (navig8_fc.core.layout: one table gives the kernels their slot constants,
# X.POS, and plant.py its slices, X.POS.sl). Defined here, next to the kernels, so numba's cache follows them.

# State vector x
X = layout("X", pos=3,  # position of O, NED (m)
           vel=3,  # velocity of O, NED (m/s)
           quat=4,  # attitude [w, x, y, z], body FRD -> NED
           rate=3,  # body rates, FRD (rad/s)
           act=5,  # actuator outputs (alpha1, alpha3 rad; w1, w2, w3 rad/s); x[:X.ACT] is what RK4 integrates
           actd=5,  # their time derivatives
           q=3, qd=3,  # joint angles (rad) and rates (rad/s)
           qdd=3,  # joint accelerations over the current servo period (rad/s^2)
           mobj=1,  # object mass (kg), 0 when nothing is held
           qtgt=3)  # joint targets the servo used last (rad)
N_X = int(X.SIZE)
N_BASE = int(X.ACT)  # the part of x integrated by RK4
N_ACT = 5
N_CONTACT_MAX = 8

# Parameter vector p, built once by plant.py
P = layout("P", g=1,  # gravity (m/s^2)
           m0=1, j0=9,  # UAV mass (kg), inertia about O (row-major 3x3)
           ml=1, ia=1, l=1,  # link mass, transverse inertia (slender rod), length
           mount=3,  # joint-1 position relative to O, FRD
           obj_d=1, obj_r=1,  # object centre offset beyond the tip along link 3; sphere radius (0.4 m r^2)
           pf=15, pm=15,  # force and moment about O per unit U, 3x5 row-major (vehicle.propulsion_per_input)
           phi_h=20, gam_h=10,  # actuator transition matrices over h, 5 x [p11, p12, p21, p22]; inputs 5 x [g1, g2]
           phi_h2=20, gam_h2=10,  # the same over h/2 (RK4 mid stages)
           act_min=5, act_max=5,
           h=1, servo_n=1,  # physics step (s), physics steps per servo period
           vmax=1, amax=1, qlim=1,  # joint rate, acceleration and angle limits (targets clamped to +-qlim)
           stall_j=1, stall_us=1,  # fault: joint stall_j (-1: none) stops dead from stall_us on
           kn=1, cn=1, mu=1, veps=1,  # contact stiffness, damping per point; friction coeff., regularisation speed
           nc=1, cp=3 * N_CONTACT_MAX,  # number of contact points; the points, FRD relative to O
           h_us=1)  # physics step in microseconds (integer-valued)
N_P = int(P.SIZE)

# Derived quantities d, filled at the end of every advance() / evaluate()
D = layout("D", acc=3,  # absolute acceleration of O, body FRD (m/s^2)
           wdot=3,  # body angular acceleration (rad/s^2)
           spf=3,  # specific force at O, body (a_O - g), what an ideal accelerometer at O reads
           mass=1, com=3,  # total mass (kg), composite CoM relative to O, FRD
           jc=9, jo=9,  # inertia about the composite CoM and about O (3x3 row-major)
           fr_g=3, fr_nog=3,  # reaction force of the arm on the UAV with / without the arm's weight (N, FRD)
           mr_mount_g=3, mr_mount_nog=3,  # reaction moment about the mount (N m)
           mr_o_g=3, mr_o_nog=3,  # reaction moment about O
           fprop=3, mprop=3,  # propulsive force (N, FRD) and moment about O (N m)
           fcont=3, mcont=3,  # ground contact force and moment about O
           ncont=1)  # number of contact points touching
N_D = int(D.SIZE)

# Base modes: how the floating base is constrained (analysis variants; flight uses FREE).
BASE_FREE = 0
BASE_ATTITUDE_LOCKED = 1  # w = w' = 0, translation free: the limit of an infinitely stiff attitude loop
BASE_FIXED = 2  # a_O = w' = 0: the base is held (a test stand)

# Command vector: actuator commands (already validated and clamped by plant.py), joint-override flag (1.0: use
# jtgt as joint targets instead of the schedule), joint targets.
C = layout("C", act=N_ACT, jovr=1, jtgt=3)
N_C = int(C.SIZE)

# Arm schedule rows: [t0_us, t1_us, qa1, qa2, qa3, qb1, qb2, qb3]; target(t) interpolates linearly
# from qa at t0 to qb at t1 (a step is a zero-length segment's neighbour). Before the first row the
# first qa holds, after the last row the last qb holds.
N_SCHED_COLS = 8

# Per-body data of _dynamics for the reaction wrench (4 bodies: 3 links and the object, SC.SIZE slots each)
SC = layout("SC", m=1, rx=1, rz=1, bx=1, by=1, bz=1, th=1, thd=1, thdd=1)
N_SC = int(SC.SIZE)
# Scratch for advance()/evaluate(), owned by the caller (no allocation in the hot path).
W = layout("W", xb=N_BASE, xs=N_BASE, k1=N_BASE, k2=N_BASE, k3=N_BASE, k4=N_BASE, q=3, qd=3, qdd=3,
           act0=N_ACT, acth=N_ACT, act1=N_ACT, sc=4 * N_SC, backup=N_X)
N_WORK = int(W.SIZE)

# Sensor output vector s, the SensorBundle's fields in this order.
S = layout("S", gyro=3, acc=3, pos=3, vel=3, quat=4, duct=2, prop=3, jq=3, jqd=3)
N_S = int(S.SIZE)
# Noise draws per sample (N(0, 1)); the mocap attitude noise is a small rotation vector.
NOISE = layout("NOISE", gyro=3, acc=3, pos=3, vel=3, att=3, duct=2, prop=3, jq=3, jqd=3)
N_NOISE = int(NOISE.SIZE)
# Standard deviations per sensor group (params.SensorParams)
# (gyro_bias, acc_bias: a constant offset on every body axis, the campaigns' sensor-bias factor)
SIG = layout("SIG", gyro=1, acc=1, pos=1, vel=1, att=1, duct=1, prop=1, jq=1, jqd=1, gyro_bias=1, acc_bias=1)
N_SIG = int(SIG.SIZE)
# Sensor group bits (same values as messages.SensorField), bit i = group i of sense()'s schedule.
G_IMU = 1
G_MOCAP = 2
G_ACT = 4
G_JOINT = 8
N_GROUPS = 4


@njit(cache=True)
def _dcm(qw: float, qx: float, qy: float, qz: float):
    """Rows of R (body -> NED) from a unit quaternion."""
    return (
        1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy),
        2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx),
        2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy),
    )


@njit(cache=True)
def _put3(v, at, a, b, c) -> None:
    """v[at:at + 3] = (a, b, c): one 3-vector slot of a layout."""
    v[at] = a
    v[at + 1] = b
    v[at + 2] = c


@njit(cache=True)
def _put_sym3(v, at, xx, xy, xz, yy, yz, zz) -> None:
    """v[at:at + 9] = the symmetric 3x3 matrix, row-major."""
    _put3(v, at, xx, xy, xz)
    _put3(v, at + 3, xy, yy, yz)
    _put3(v, at + 6, xz, yz, zz)


@njit(cache=True)
def _own_inertia(k: int, ia: float, io: float, s: float, c: float):
    """Body k's own inertia about its centre, body axes: link rod Ia (E - e e^T) with e = [s, 0, c]
    (Table 1: Izz = 0 along the link) for k < 3, the object's sphere io E for k = 3. (xx, yy, zz, xz)."""
    if k < 3:
        return ia * c * c, ia, ia * s * s, -ia * s * c
    return io, io, io, 0.0


@njit(cache=True)
def _euler_moment(ixx, iyy, izz, ixz, wx, wy, wz, thd, ax, ay, az):
    """I a + W x I W for a body of own inertia I (x-z symmetric: xx, yy, zz, xz) turning at W = w + thd y (its joint
    rate about body y on top of the base's w) with angular acceleration a (Euler's equation about its centre)."""
    Wx = wx
    Wy = wy + thd
    Wz = wz
    iWx = ixx * Wx + ixz * Wz
    iWy = iyy * Wy
    iWz = ixz * Wx + izz * Wz
    return (ixx * ax + ixz * az + (Wy * iWz - Wz * iWy), iyy * ay + (Wz * iWx - Wx * iWz),
            ixz * ax + izz * az + (Wx * iWy - Wy * iWx))


@njit(cache=True)
def _dynamics(xb, q, qd, qdd, act, mobj, p, base_mode, out, sc, d, full):
    """Base-state derivative at one instant. xb: the base state (x[:N_BASE], X layout); q, qd, qdd: joint motion
    at this instant; act: actuator outputs (5). Writes dx/dt into out (N_BASE); sc (4 x SC) is scratch for the
    per-body data of the reaction wrench. With full=True also fills the derived quantities d."""
    g = p[P.G]
    qw, qx, qy, qz = xb[X.QUAT], xb[X.QUAT + 1], xb[X.QUAT + 2], xb[X.QUAT + 3]
    wx, wy, wz = xb[X.RATE], xb[X.RATE + 1], xb[X.RATE + 2]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _dcm(qw, qx, qy, qz)
    # gravity in body axes: R^T [0, 0, g]
    gbx, gby, gbz = g * r20, g * r21, g * r22

    # ---- arm kinematics relative to the body (notes §3.1) and composite sums ------------------
    ml = p[P.ML]
    ia = p[P.IA]
    L = p[P.L]
    mx, my, mz = p[P.MOUNT], p[P.MOUNT + 1], p[P.MOUNT + 2]
    m = p[P.M0] + 3.0 * ml + mobj
    # first moment m c (UAV contributes nothing: O is its CoM)
    mcx = 0.0
    mcy = 0.0
    mcz = 0.0
    # J_O accumulators (symmetric; J_xy = J_yz = 0 is NOT assumed for the mount's y offset)
    jxx = p[P.J0]
    jxy = p[P.J0 + 1]
    jxz = p[P.J0 + 2]
    jyy = p[P.J0 + 4]
    jyz = p[P.J0 + 5]
    jzz = p[P.J0 + 8]
    # UAV gyroscopic term w x J0 w goes into the Euler bias
    j0wx = p[P.J0] * wx + p[P.J0 + 1] * wy + p[P.J0 + 2] * wz
    j0wy = p[P.J0 + 3] * wx + p[P.J0 + 4] * wy + p[P.J0 + 5] * wz
    j0wz = p[P.J0 + 6] * wx + p[P.J0 + 7] * wy + p[P.J0 + 8] * wz
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
    io = 0.4 * mobj * p[P.OBJ_R] * p[P.OBJ_R]
    for k in range(4):
        o = N_SC * k  # body k's slots in sc
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
            half = p[P.OBJ_D]
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
        sc[o + SC.M] = mk
        sc[o + SC.RX] = rx
        sc[o + SC.RZ] = rz
        sc[o + SC.BX] = bx
        sc[o + SC.BY] = by
        sc[o + SC.BZ] = bz
        sc[o + SC.TH] = th
        sc[o + SC.THD] = thd
        sc[o + SC.THDD] = thdd
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
        # (w x (thd y) = [-wz thd, 0, wx thd])
        tx, ty, tz = _euler_moment(ixx, iyy, izz, ixz, wx, wy, wz, thd, -wz * thd, thdd, wx * thd)
        bmx += tx
        bmy += ty
        bmz += tz

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
    fpx = p[P.PF + 0] * u0 + p[P.PF + 1] * u1 + p[P.PF + 2] * u2 + p[P.PF + 3] * u3 + p[P.PF + 4] * u4
    fpy = p[P.PF + 5] * u0 + p[P.PF + 6] * u1 + p[P.PF + 7] * u2 + p[P.PF + 8] * u3 + p[P.PF + 9] * u4
    fpz = p[P.PF + 10] * u0 + p[P.PF + 11] * u1 + p[P.PF + 12] * u2 + p[P.PF + 13] * u3 + p[P.PF + 14] * u4
    mpx = p[P.PM + 0] * u0 + p[P.PM + 1] * u1 + p[P.PM + 2] * u2 + p[P.PM + 3] * u3 + p[P.PM + 4] * u4
    mpy = p[P.PM + 5] * u0 + p[P.PM + 6] * u1 + p[P.PM + 7] * u2 + p[P.PM + 8] * u3 + p[P.PM + 9] * u4
    mpz = p[P.PM + 10] * u0 + p[P.PM + 11] * u1 + p[P.PM + 12] * u2 + p[P.PM + 13] * u3 + p[P.PM + 14] * u4

    # ground contact: spring-damper + regularised Coulomb friction at the skid points (NED z = 0 ground)
    fcx = 0.0
    fcy = 0.0
    fcz = 0.0
    mcox = 0.0
    mcoy = 0.0
    mcoz = 0.0
    ncont = 0
    nc = int(p[P.NC])
    for i in range(nc):
        px = p[P.CP + 3 * i]
        py = p[P.CP + 3 * i + 1]
        pz = p[P.CP + 3 * i + 2]
        depth = xb[X.POS + 2] + r20 * px + r21 * py + r22 * pz
        if depth > 0.0:
            # point velocity in NED: v + R (w x p)
            ox = wy * pz - wz * py
            oy = wz * px - wx * pz
            oz = wx * py - wy * px
            vnx = xb[X.VEL] + r00 * ox + r01 * oy + r02 * oz
            vny = xb[X.VEL + 1] + r10 * ox + r11 * oy + r12 * oz
            vnz = xb[X.VEL + 2] + r20 * ox + r21 * oy + r22 * oz
            fn = p[P.KN] * depth + p[P.CN] * vnz
            if fn > 0.0:
                ncont += 1
                vt = math.sqrt(vnx * vnx + vny * vny + p[P.VEPS] * p[P.VEPS])
                ftx = -p[P.MU] * fn * vnx / vt
                fty = -p[P.MU] * fn * vny / vt
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
    # J_c = J_O - m (|c|^2 E - c c^T), the inertia about the composite CoM
    c2 = cx * cx + cy * cy + cz * cz
    a11 = jxx - m * (c2 - cx * cx)
    a22 = jyy - m * (c2 - cy * cy)
    a33 = jzz - m * (c2 - cz * cz)
    a12 = jxy + m * cx * cy
    a13 = jxz + m * cx * cz
    a23 = jyz + m * cy * cz
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

    _put3(d, D.ACC, aox, aoy, aoz)
    _put3(d, D.WDOT, dwx, dwy, dwz)
    _put3(d, D.SPF, aox - gbx, aoy - gby, aoz - gbz)
    d[D.MASS] = m
    _put3(d, D.COM, cx, cy, cz)
    _put_sym3(d, D.JO, jxx, jxy, jxz, jyy, jyz, jzz)
    _put_sym3(d, D.JC, a11, a12, a13, a22, a23, a33)
    _put3(d, D.FPROP, fpx, fpy, fpz)
    _put3(d, D.MPROP, mpx, mpy, mpz)
    _put3(d, D.FCONT, fcx, fcy, fcz)
    _put3(d, D.MCONT, mcox, mcoy, mcoz)
    d[D.NCONT] = ncont

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
        o = N_SC * k
        mk = sc[o + SC.M]
        rx = sc[o + SC.RX]
        ry = my
        rz = sc[o + SC.RZ]
        akx = aox + (dwy * rz - dwz * ry) + sc[o + SC.BX]
        aky = aoy + (dwz * rx - dwx * rz) + sc[o + SC.BY]
        akz = aoz + (dwx * ry - dwy * rx) + sc[o + SC.BZ]
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
        s = math.sin(sc[o + SC.TH])
        c = math.cos(sc[o + SC.TH])
        thd = sc[o + SC.THD]
        thdd = sc[o + SC.THDD]
        ixx, iyy, izz, ixz = _own_inertia(k, ia, io, s, c)
        tx, ty, tz = _euler_moment(ixx, iyy, izz, ixz, wx, wy, wz, thd, dwx - wz * thd, dwy + thdd, dwz + wx * thd)
        mrx -= tx
        mry -= ty
        mrz -= tz
    _put3(d, D.FR_NOG, frx, fry, frz)
    _put3(d, D.FR_G, frx + marm * gbx, fry + marm * gby, frz + marm * gbz)
    _put3(d, D.MR_MOUNT_NOG, mrx, mry, mrz)
    # the weight acting at the arm bodies, seen at the mount: + sum (r_k - mount) x m_k g
    mgx = mrx + (gmy * gbz - gmz * gby)
    mgy = mry + (gmz * gbx - gmx * gbz)
    mgz = mrz + (gmx * gby - gmy * gbx)
    _put3(d, D.MR_MOUNT_G, mgx, mgy, mgz)
    # about O: M_O = M_mount + r_mount x F_r
    fgx = d[D.FR_G]
    fgy = d[D.FR_G + 1]
    fgz = d[D.FR_G + 2]
    _put3(d, D.MR_O_NOG, mrx + (my * frz - mz * fry), mry + (mz * frx - mx * frz), mrz + (mx * fry - my * frx))
    _put3(d, D.MR_O_G, mgx + (my * fgz - mz * fgy), mgy + (mz * fgx - mx * fgz), mgz + (mx * fgy - my * fgx))


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
    """Exact second-order actuator outputs after tau (phi, gam = P.PHI_H or P.PHI_H2 offsets)."""
    for i in range(N_ACT):
        y = x[X.ACT + i]
        yd = x[X.ACTD + i]
        u = cmd[C.ACT + i]
        out[i] = p[phi + 4 * i] * y + p[phi + 4 * i + 1] * yd + p[gam + 2 * i] * u


@njit(cache=True)
def _joints_at(x, qdd, tau, q, qd) -> None:
    """Joint angles and rates tau after the state x with q'' held (exact for constant acceleration)."""
    for j in range(3):
        q[j] = x[X.Q + j] + x[X.QD + j] * tau + 0.5 * qdd[j] * tau * tau
        qd[j] = x[X.QD + j] + qdd[j] * tau


@njit(cache=True)
def _stage_state(xb, tau, k, xs) -> None:
    """An RK4 stage's base state: xs = xb + tau k."""
    for i in range(N_BASE):
        xs[i] = xb[i] + tau * k[i]


@njit(cache=True)
def advance(x, p, cmd, sched, n_steps, t0_us, base_mode, d, w) -> int:
    """Advance the state x in place by n_steps physics steps from time t0_us (an integer on the
    physics grid). w is caller-owned scratch (N_WORK) so the hot path does not allocate.
    Returns 0, or 1 if the state became non-finite (x is then left as it was)."""
    h = p[P.H]
    h_us = int(p[P.H_US])
    servo_n = int(p[P.SERVO_N])
    hs = h * servo_n
    amax = p[P.AMAX]
    vmax = p[P.VMAX]
    qlim = p[P.QLIM]
    stall_j = int(p[P.STALL_J])
    stall_us = p[P.STALL_US]
    xb = w[W.XB:W.XB + N_BASE]
    xs = w[W.XS:W.XS + N_BASE]
    k1 = w[W.K1:W.K1 + N_BASE]
    k2 = w[W.K2:W.K2 + N_BASE]
    k3 = w[W.K3:W.K3 + N_BASE]
    k4 = w[W.K4:W.K4 + N_BASE]
    q = w[W.Q:W.Q + 3]
    qd = w[W.QD:W.QD + 3]
    qdd = w[W.QDD:W.QDD + 3]
    act0 = w[W.ACT0:W.ACT0 + N_ACT]
    acth = w[W.ACTH:W.ACTH + N_ACT]
    act1 = w[W.ACT1:W.ACT1 + N_ACT]
    sc = w[W.SC:W.SC + 4 * N_SC]
    backup = w[W.BACKUP:W.BACKUP + N_X]
    for i in range(N_X):
        backup[i] = x[i]
    mobj = x[X.MOBJ]
    for n in range(n_steps):
        t_us = t0_us + n * h_us
        # ---- joint servo: new q'' at the start of each servo period -------------------------
        if (t_us // h_us) % servo_n == 0:
            for j in range(3):
                if cmd[C.JOVR] > 0.5:
                    tgt = cmd[C.JTGT + j]
                else:
                    tgt = _schedule_target(sched, float(t_us), j)
                if tgt > qlim:
                    tgt = qlim
                elif tgt < -qlim:
                    tgt = -qlim
                x[X.QTGT + j] = tgt
                if j == stall_j and t_us >= stall_us:
                    # a jammed joint: stopped within one servo period (its reaction is in the dynamics), whatever
                    # it is told from then on
                    x[X.QDD + j] = -x[X.QD + j] / hs
                elif abs(tgt - x[X.Q + j]) <= 1e-12 and abs(x[X.QD + j]) <= 1e-9:
                    # arrived: snap the round-off residue of the deadbeat law so the joint rests exactly
                    x[X.Q + j] = tgt
                    x[X.QD + j] = 0.0
                    x[X.QDD + j] = 0.0
                else:
                    x[X.QDD + j] = _servo_accel(tgt - x[X.Q + j], x[X.QD + j], hs, amax, vmax)
        for i in range(N_BASE):
            xb[i] = x[i]
        for j in range(3):
            qdd[j] = x[X.QDD + j]
        # ---- actuator outputs at t, t + h/2, t + h (exact, ZOH command) ---------------------
        for i in range(N_ACT):
            act0[i] = x[X.ACT + i]
        _act_at(x, p, cmd, P.PHI_H2, P.GAM_H2, acth)
        _act_at(x, p, cmd, P.PHI_H, P.GAM_H, act1)
        # ---- RK4 on the base with the exact joint and actuator trajectories -----------------
        for j in range(3):
            q[j] = x[X.Q + j]
            qd[j] = x[X.QD + j]
        _dynamics(xb, q, qd, qdd, act0, mobj, p, base_mode, k1, sc, d, False)
        th = 0.5 * h
        _joints_at(x, qdd, th, q, qd)
        _stage_state(xb, th, k1, xs)
        _dynamics(xs, q, qd, qdd, acth, mobj, p, base_mode, k2, sc, d, False)
        _stage_state(xb, th, k2, xs)
        _dynamics(xs, q, qd, qdd, acth, mobj, p, base_mode, k3, sc, d, False)
        _joints_at(x, qdd, h, q, qd)
        _stage_state(xb, h, k3, xs)
        _dynamics(xs, q, qd, qdd, act1, mobj, p, base_mode, k4, sc, d, False)
        for i in range(N_BASE):
            x[i] = xb[i] + (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        qw, qx, qy, qz = x[X.QUAT], x[X.QUAT + 1], x[X.QUAT + 2], x[X.QUAT + 3]
        qn = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        for i in range(4):
            x[X.QUAT + i] /= qn
        # ---- joints: exact for constant q'' ---------------------------------------------------
        for j in range(3):
            x[X.Q + j] = q[j]
            x[X.QD + j] = qd[j]
        # ---- actuators: exact discretisation, then the hard stops ----------------------------
        for i in range(N_ACT):
            yd = (p[P.PHI_H + 4 * i + 2] * x[X.ACT + i] + p[P.PHI_H + 4 * i + 3] * x[X.ACTD + i]
                  + p[P.GAM_H + 2 * i + 1] * cmd[C.ACT + i])
            y = act1[i]
            if y > p[P.ACT_MAX + i]:
                y = p[P.ACT_MAX + i]
                if yd > 0.0:
                    yd = 0.0
            elif y < p[P.ACT_MIN + i]:
                y = p[P.ACT_MIN + i]
                if yd < 0.0:
                    yd = 0.0
            x[X.ACT + i] = y
            x[X.ACTD + i] = yd
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
    _dynamics(x[0:N_BASE], x[X.Q:X.Q + 3], x[X.QD:X.QD + 3], x[X.QDD:X.QDD + 3], x[X.ACT:X.ACT + N_ACT],
              x[X.MOBJ], p, base_mode, w[W.XS:W.XS + N_BASE], w[W.SC:W.SC + 4 * N_SC], d, True)


@njit(cache=True)
def sense(x, d, sig, noise, prev, t_us, due_us, period_us, out) -> int:
    """Sensor sample at t_us: truth + sigma * N(0,1) for the groups due now, previous values for the others.
    Returns the groups sampled (G_* bits). due_us, period_us (int64, one per group in G_* bit order): a group is
    due when t_us >= its due time, which then moves past t_us by whole periods.

    The mocap attitude noise is a small body-frame rotation q_meas = q (x) [1, dth/2] (renormalised).
    """
    groups = 0
    for i in range(N_GROUPS):
        if t_us >= due_us[i]:
            groups |= 1 << i
            due_us[i] += period_us[i] * ((t_us - due_us[i]) // period_us[i] + 1)
    for i in range(N_S):
        out[i] = prev[i]
    if groups & G_IMU:
        for i in range(3):
            out[S.GYRO + i] = x[X.RATE + i] + sig[SIG.GYRO_BIAS] + sig[SIG.GYRO] * noise[NOISE.GYRO + i]
            out[S.ACC + i] = d[D.SPF + i] + sig[SIG.ACC_BIAS] + sig[SIG.ACC] * noise[NOISE.ACC + i]
    if groups & G_MOCAP:
        for i in range(3):
            out[S.POS + i] = x[X.POS + i] + sig[SIG.POS] * noise[NOISE.POS + i]
            out[S.VEL + i] = x[X.VEL + i] + sig[SIG.VEL] * noise[NOISE.VEL + i]
        hx = 0.5 * sig[SIG.ATT] * noise[NOISE.ATT]
        hy = 0.5 * sig[SIG.ATT] * noise[NOISE.ATT + 1]
        hz = 0.5 * sig[SIG.ATT] * noise[NOISE.ATT + 2]
        qw, qx, qy, qz = x[X.QUAT], x[X.QUAT + 1], x[X.QUAT + 2], x[X.QUAT + 3]
        ow = qw - qx * hx - qy * hy - qz * hz
        ox = qw * hx + qx + qy * hz - qz * hy
        oy = qw * hy - qx * hz + qy + qz * hx
        oz = qw * hz + qx * hy - qy * hx + qz
        nq = math.sqrt(ow * ow + ox * ox + oy * oy + oz * oz)
        if ow < 0.0:
            nq = -nq  # keep w >= 0 (same rotation)
        out[S.QUAT] = ow / nq
        out[S.QUAT + 1] = ox / nq
        out[S.QUAT + 2] = oy / nq
        out[S.QUAT + 3] = oz / nq
    if groups & G_ACT:
        out[S.DUCT] = x[X.ACT] + sig[SIG.DUCT] * noise[NOISE.DUCT]
        out[S.DUCT + 1] = x[X.ACT + 1] + sig[SIG.DUCT] * noise[NOISE.DUCT + 1]
        out[S.PROP] = x[X.ACT + 2] + sig[SIG.PROP] * noise[NOISE.PROP]
        out[S.PROP + 1] = x[X.ACT + 3] + sig[SIG.PROP] * noise[NOISE.PROP + 1]
        out[S.PROP + 2] = x[X.ACT + 4] + sig[SIG.PROP] * noise[NOISE.PROP + 2]
    if groups & G_JOINT:
        for i in range(3):
            out[S.JQ + i] = x[X.Q + i] + sig[SIG.JQ] * noise[NOISE.JQ + i]
            out[S.JQD + i] = x[X.QD + i] + sig[SIG.JQD] * noise[NOISE.JQD + i]
    return groups
