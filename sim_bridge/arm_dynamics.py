"""The arm's bodies in the plant's dynamics: three planar links and the held object (numba kernels).

Relative to the body (notes §3.1), body k (links 1-3, then the object, a point mass with sphere inertia
0.4 m r^2 at offset_from_tip beyond link 3's tip; mass 0 when nothing is held) sits at r_k with the velocity
and acceleration of the prescribed joint motion (q'' piecewise constant). `arm_sums` adds the bodies to the
composite sums of the Newton-Euler system (first moment, inertia about O, the bias of their relative
accelerations and velocity terms: RNEA with zero base acceleration) and keeps the per-body data (SC) for
`arm_reaction`, the arm's reaction wrench on the UAV (notes §3.4 step 5) once the base accelerations are solved
(rigid_body.dynamics).
"""

from __future__ import annotations

import math

from numba import njit

from navig8_fc.core.layout import layout
from sim_bridge.plant_layout import D, P, put3

N_BODIES = 4  # links 1-3 and the object
# Per-body data of arm_sums for the reaction wrench (N_BODIES x SC.SIZE slots, caller-owned scratch)
SC = layout("SC", m=1, rx=1, rz=1, bx=1, by=1, bz=1, th=1, thd=1, thdd=1)
N_SC = int(SC.SIZE)


@njit(cache=True)
def own_inertia(k: int, ia: float, io: float, s: float, c: float):
    """Body k's own inertia about its centre, body axes: link rod Ia (E - e e^T) with e = [s, 0, c]
    (Table 1: Izz = 0 along the link) for k < 3, the object's sphere io E for k = 3. (xx, yy, zz, xz)."""
    if k < 3:
        return ia * c * c, ia, ia * s * s, -ia * s * c
    return io, io, io, 0.0


@njit(cache=True)
def euler_moment(ixx, iyy, izz, ixz, wx, wy, wz, thd, ax, ay, az):
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


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def object_inertia(mobj, p) -> float:
    """The held object's own inertia, a sphere's 0.4 m r^2 (kg m^2)."""
    return 0.4 * mobj * p[P.OBJ_R] * p[P.OBJ_R]


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def arm_sums(q, qd, qdd, mobj, p, wx, wy, wz, sc, jxx, jxy, jxz, jyy, jyz, jzz, bmx, bmy, bmz):
    """The arm's bodies added to the composite sums, at joint motion q, qd, qdd and base rate w (body axes).

    jxx..jzz: the inertia about O so far (the UAV's J0), bmx..bmz: the Euler bias so far (the UAV's w x J0 w); the
    bodies are added in order. Returns (m c, J_O, b_F, b_M): the first moment (the UAV's is zero, O is its CoM), the
    inertia about O, the bias force and moment. Fills sc (N_BODIES x SC) for arm_reaction."""
    ml = p[P.ML]
    ia = p[P.IA]
    L = p[P.L]
    mx, my, mz = p[P.MOUNT], p[P.MOUNT + 1], p[P.MOUNT + 2]
    mcx = 0.0
    mcy = 0.0
    mcz = 0.0
    bfx = 0.0
    bfy = 0.0
    bfz = 0.0
    th = 0.0
    thd = 0.0
    thdd = 0.0
    jx = mx
    jz = mz
    jvx = 0.0
    jvz = 0.0
    jax = 0.0
    jaz = 0.0
    io = object_inertia(mobj, p)
    for k in range(N_BODIES):
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
        ixx, iyy, izz, ixz = own_inertia(k, ia, io, s, c)
        jxx += ixx
        jyy += iyy
        jzz += izz
        jxz += ixz
        # Euler bias of the body's own inertia: I (thdd y + w x thd y) + W x I W, W = w + thd y
        # (w x (thd y) = [-wz thd, 0, wx thd])
        tx, ty, tz = euler_moment(ixx, iyy, izz, ixz, wx, wy, wz, thd, -wz * thd, thdd, wx * thd)
        bmx += tx
        bmy += ty
        bmz += tz
    return mcx, mcy, mcz, jxx, jxy, jxz, jyy, jyz, jzz, bfx, bfy, bfz, bmx, bmy, bmz


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def arm_reaction(sc, p, mobj, wx, wy, wz, aox, aoy, aoz, dwx, dwy, dwz, gbx, gby, gbz, d) -> None:
    """The arm's reaction wrench on the UAV into d (D.FR_*, D.MR_*), from arm_sums' per-body data sc, the base's
    rate w, its solved accelerations a_O and w' and gravity g_b in body axes.

    a_k = a_O + w' x r_k + b_k; link angular acceleration W'_k = w' + thdd y + w x thd y.
    F_r = -sum m_k (a_k - g); M_r,mount = -sum [(r_k - r_mount) x m_k (a_k - g) + I_k W'_k + W_k x I_k W_k]"""
    ia = p[P.IA]
    mx, my, mz = p[P.MOUNT], p[P.MOUNT + 1], p[P.MOUNT + 2]
    io = object_inertia(mobj, p)
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
    for k in range(N_BODIES):
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
        ixx, iyy, izz, ixz = own_inertia(k, ia, io, s, c)
        tx, ty, tz = euler_moment(ixx, iyy, izz, ixz, wx, wy, wz, thd, dwx - wz * thd, dwy + thdd, dwz + wx * thd)
        mrx -= tx
        mry -= ty
        mrz -= tz
    put3(d, D.FR_NOG, frx, fry, frz)
    put3(d, D.FR_G, frx + marm * gbx, fry + marm * gby, frz + marm * gbz)
    put3(d, D.MR_MOUNT_NOG, mrx, mry, mrz)
    # the weight acting at the arm bodies, seen at the mount: + sum (r_k - mount) x m_k g
    mgx = mrx + (gmy * gbz - gmz * gby)
    mgy = mry + (gmz * gbx - gmx * gbz)
    mgz = mrz + (gmx * gby - gmy * gbx)
    put3(d, D.MR_MOUNT_G, mgx, mgy, mgz)
    # about O: M_O = M_mount + r_mount x F_r
    fgx = d[D.FR_G]
    fgy = d[D.FR_G + 1]
    fgz = d[D.FR_G + 2]
    put3(d, D.MR_O_NOG, mrx + (my * frz - mz * fry), mry + (mz * frx - mx * frz), mrz + (mx * fry - my * frx))
    put3(d, D.MR_O_G, mgx + (my * fgz - mz * fgy), mgy + (mz * fgx - mx * fgz), mgz + (mx * fgy - my * fgx))
