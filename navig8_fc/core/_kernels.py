"""Numba hot path of the controller tick: UAM model + G_C^-1, KF correct, outer loops, INDI increment.

Plain float maths on flat float64 vectors whose slots are named by the layouts below (navig8_fc.core.layout:
one table gives the kernels their constants and the Python callers their slices): the controller's vectors
have 3-5 components, where numpy's per-call overhead dominates. Each algorithm is written once, here; its
plain-Python path is the kernel's `py_func`. tests/unit/test_vehicle.py and test_fc_kernels.py check them
against independent oracles (a vector-form model, finite differences, numpy/scipy). Pure: no I/O, no clocks.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from navig8_fc.core.layout import layout

# Vehicle geometry the model kernels take (vehicle.model_geometry builds it from a VehicleConfig).
GEO = layout("GEO", link_len=1, link_mass=1, link_inertia=1, mount_x=1, mount_z=1, uam_mass=1,
             j11=1, j22=1, j33=1, j13=1,  # UAV inertia about O (x-z symmetric)
             obj_offset=1, obj_radius=1)  # object centre beyond the tip along link 3; sphere radius
# Mass properties (mass_props): the 3x3 inertia about the CoM and its rate go to their own arrays.
MP = layout("MP", mass=1, cx=1, cz=1,
            ma_x=1, ma_z=1,  # sum_k m_k r''_k over the arm bodies (first moment's second derivative)
            tip_ax=1, tip_az=1,  # acceleration of the arm's tip (link 3's end)
            obj_x=1, obj_z=1,  # position of the object's centre (tip + offset along link 3), relative to O
            hdc=1,  # d/dt of the bodies' pitch angular momentum relative to the body, about the composite CoM
            jo=4)  # inertia about O: xx, yy, zz, xz
_N_MP = int(MP.SIZE)  # np.empty takes an int, not an IntEnum member
# UAM model + G_C^-1 (uam_model), the controller's per-tick view
UO = layout("UO", mass=1, cx=1, cz=1, arm_ax=1, arm_az=1,
            hdc=1,  # MP.HDC with the estimated object: the arm's reaction pitch moment about the CoM is -hdc
            cex=1, cez=1,  # CoM of the UAM with a point object of the estimated mass at the tip (the reference point)
            obj_rate=3,  # diagonal of d/dt of that composite's inertia minus J's I-dot: the estimated object's share
            singular=1)  # 1.0 when G_C could not be inverted (the caller then falls back to numpy)


@njit(cache=True)
def pivot_rows(m, c, n):
    """Partial pivoting for column c of the n-row matrix m: swap the row (of c..n-1) with the largest |m[r, c]|
    into row c (all columns). False if that pivot is zero or not finite (m unchanged then)."""
    p = c
    big = abs(m[c, c])
    for r in range(c + 1, n):
        v = abs(m[r, c])
        if v > big:
            p = r
            big = v
    if big == 0.0 or not math.isfinite(big):
        return False
    if p != c:
        for j in range(m.shape[1]):
            t = m[c, j]
            m[c, j] = m[p, j]
            m[p, j] = t
    return True


@njit(cache=True)
def inv_gauss_jordan(a: np.ndarray, out: np.ndarray) -> bool:
    """out = a^-1 for a small square matrix (Gauss-Jordan, partial pivoting). False if singular."""
    n = a.shape[0]
    m = np.empty((n, 2 * n))
    for i in range(n):
        for j in range(n):
            m[i, j] = a[i, j]
            m[i, n + j] = 1.0 if i == j else 0.0
    for c in range(n):
        if not pivot_rows(m, c, n):
            return False
        piv = m[c, c]
        for j in range(2 * n):
            m[c, j] /= piv
        for r in range(n):
            if r != c:
                f = m[r, c]
                if f != 0.0:
                    for j in range(2 * n):
                        m[r, j] -= f * m[c, j]
    for i in range(n):
        for j in range(n):
            out[i, j] = m[i, n + j]
    return True


_N_BODY_ACC = 15  # sum m x, m z, m xd, m zd, m xdd, m zdd; J11 J22 J33 J13 about O; their rates; h' about O


@njit(cache=True)
def _add_body(acc, m, x, z, xd, zd, xdd, zdd, o11, o22, o33, o13, r11, r22, r33, r13, oh):
    """Add one arm body of mass m at (x, 0, z) FRD (with its velocity and acceleration) to the accumulators acc:
    its first moments, its inertia about O (own inertia o.. about its CoM + parallel axis) and that inertia's
    rate (own rate r.. + the moving point's), and its share of d/dt of the pitch angular momentum about O with
    the body not rotating: m (r x r'')_y + oh (oh = own I_yy theta'')."""
    acc[0] += m * x
    acc[1] += m * z
    acc[2] += m * xd
    acc[3] += m * zd
    acc[4] += m * xdd
    acc[5] += m * zdd
    acc[6] += o11 + m * z * z
    acc[7] += o22 + m * (x * x + z * z)
    acc[8] += o33 + m * x * x
    acc[9] += o13 - m * x * z
    acc[10] += r11 + 2.0 * m * z * zd
    acc[11] += r22 + 2.0 * m * (x * xd + z * zd)
    acc[12] += r33 + 2.0 * m * x * xd
    acc[13] += r13 - m * (xd * z + x * zd)
    acc[14] += m * (z * xdd - x * zdd) + oh  # (r x r'')_y = z x'' - x z''


@njit(cache=True)
def mass_props(q, qd, qdd, object_mass_kg, geo, inertia, rate, mp):
    """Composite mass properties of UAV + 3 links (+ the object) at the arm state (q, q-dot, q-ddot) (notes 3.1-3.2).

    Planar arm in the body x-z plane through O (mount y = 0): link k's centre r_k = joint_k + L/2 e(theta_k),
    e = [sin, 0, cos]; rod inertia Ia (E - e e^T) about its centre; the object (object_mass_kg > 0) a point at
    geo[OBJ_OFFSET] beyond the tip along link 3 with sphere inertia 0.4 m r^2. Writes inertia (3x3, about the
    composite CoM) and rate (its time derivative about the moving CoM, Eq. 22's I-dot), and mp (MP layout).
    """
    L, ml, ia = geo[GEO.LINK_LEN], geo[GEO.LINK_MASS], geo[GEO.LINK_INERTIA]
    th = thd = thdd = 0.0
    jx, jz, jvx, jvz, jax, jaz = geo[GEO.MOUNT_X], geo[GEO.MOUNT_Z], 0.0, 0.0, 0.0, 0.0
    acc = np.zeros(_N_BODY_ACC)  # first moments, inertia about O and its rate of the arm bodies (_BA_*)
    s = c = 0.0
    h = 0.5 * L
    for i in range(3):
        th += q[i]
        thd += qd[i]
        thdd += qdd[i]
        s, c = math.sin(th), math.cos(th)
        # d/dt e = thd e', e' = [cos, 0, -sin]; d2/dt2 e = thdd e' - thd^2 e
        vx, vz = thd * c, -thd * s
        ax, az = thdd * c - thd * thd * s, -thdd * s - thd * thd * c
        x, z = jx + h * s, jz + h * c
        xd, zd = jvx + h * vx, jvz + h * vz
        xdd, zdd = jax + h * ax, jaz + h * az
        s2, c2 = 2.0 * s * c, c * c - s * s
        # own inertia of the rod (about its CoM, in the x-z plane) and its rate
        _add_body(acc, ml, x, z, xd, zd, xdd, zdd, ia * c * c, ia, ia * s * s, -ia * s * c,
                  -ia * s2 * thd, 0.0, ia * s2 * thd, -ia * c2 * thd, ia * thdd)
        jx, jz = jx + L * s, jz + L * c
        jvx, jvz = jvx + L * vx, jvz + L * vz
        jax, jaz = jax + L * ax, jaz + L * az
    m = geo[GEO.UAM_MASS]
    mo = object_mass_kg
    if mo > 0.0:
        d = geo[GEO.OBJ_OFFSET]
        io = 0.4 * mo * geo[GEO.OBJ_RADIUS] * geo[GEO.OBJ_RADIUS]
        x, z = jx + d * s, jz + d * c
        xd, zd = jvx + d * thd * c, jvz - d * thd * s
        xdd, zdd = jax + d * (thdd * c - thd * thd * s), jaz + d * (-thdd * s - thd * thd * c)
        _add_body(acc, mo, x, z, xd, zd, xdd, zdd, io, io, io, 0.0, 0.0, 0.0, 0.0, 0.0, io * thdd)  # isotropic
        m = m + mo
    s1, s1z, v1x, v1z, a1x, a1z, j11, j22, j33, j13, d11, d22, d33, d13, hd = (
        acc[0], acc[1], acc[2], acc[3], acc[4], acc[5], acc[6], acc[7], acc[8], acc[9], acc[10], acc[11], acc[12],
        acc[13], acc[14])
    cx, cz = s1 / m, s1z / m
    cxd, czd = v1x / m, v1z / m
    # Parallel-axis theorem from O to the CoM (c_y = 0): I_c = I_O - m (|c|^2 E - c c^T), and its rate.
    inertia[:, :] = 0.0
    rate[:, :] = 0.0
    inertia[0, 0] = geo[GEO.J11] + j11 - m * cz * cz
    inertia[1, 1] = geo[GEO.J22] + j22 - m * (cx * cx + cz * cz)
    inertia[2, 2] = geo[GEO.J33] + j33 - m * cx * cx
    i13 = geo[GEO.J13] + j13 + m * cx * cz
    inertia[0, 2] = i13
    inertia[2, 0] = i13
    rate[0, 0] = d11 - 2.0 * m * cz * czd
    rate[1, 1] = d22 - 2.0 * m * (cx * cxd + cz * czd)
    rate[2, 2] = d33 - 2.0 * m * cx * cxd
    r13 = d13 + m * (cxd * cz + cx * czd)
    rate[0, 2] = r13
    rate[2, 0] = r13
    mp[MP.MASS] = m
    mp[MP.CX] = cx
    mp[MP.CZ] = cz
    mp[MP.MA_X] = a1x
    mp[MP.MA_Z] = a1z
    mp[MP.TIP_AX] = jax
    mp[MP.TIP_AZ] = jaz
    mp[MP.OBJ_X] = jx + geo[GEO.OBJ_OFFSET] * s
    # about the CoM: sum m (r - c) x (r'' - c'') = sum m r x r'' - m c x c''
    mp[MP.HDC] = hd - (s1z * a1x - s1 * a1z) / m
    mp[MP.OBJ_Z] = jz + geo[GEO.OBJ_OFFSET] * c
    mp[MP.JO] = geo[GEO.J11] + j11
    mp[MP.JO + 1] = geo[GEO.J22] + j22
    mp[MP.JO + 2] = geo[GEO.J33] + j33
    mp[MP.JO + 3] = geo[GEO.J13] + j13


@njit(cache=True)
def gc_about(f, m0, cx, cz, gc):
    """G_C (Eq. 2) about the point c = (cx, 0, cz): rows [L, M, N, Fx, Fz] from the per-input force f (3x5) and
    moment about O m0 (3x5), M_c = M_O - c x F (notes 2.5); c x F with c_y = 0 is [-cz Fy, cz Fx - cx Fz, cx Fy]."""
    for j in range(5):
        gc[0, j] = m0[0, j] + cz * f[1, j]
        gc[1, j] = m0[1, j] - (cz * f[0, j] - cx * f[2, j])
        gc[2, j] = m0[2, j] - cx * f[1, j]
        gc[3, j] = f[0, j]
        gc[4, j] = f[2, j]


@njit(cache=True)
def gc_inv_about(f, m0, cx, cz, gc, gc_inv):
    """G_C about c = (cx, 0, cz) (gc_about) and its inverse into gc, gc_inv; False when G_C is singular."""
    gc_about(f, m0, cx, cz, gc)
    return inv_gauss_jordan(gc, gc_inv)


@njit(cache=True)
def uam_model(q, qd, qdd, object_mass_kg, geo, f, m0, inertia, rate, gc, gc_inv, uo):
    """The controller's model of the UAM without object at the arm state: mass_props, G_C about the UAM CoM and
    its inverse, and the arm's CoM-acceleration term sum_k m_k r''_k / m with a point object of object_mass_kg
    (the estimate) at the tip (notes 3.3 option b). Writes inertia, rate (3x3), gc, gc_inv (5x5) and uo (UO)."""
    mp = np.empty(_N_MP)
    mass_props(q, qd, qdd, 0.0, geo, inertia, rate, mp)
    m, cx, cz = mp[MP.MASS], mp[MP.CX], mp[MP.CZ]
    mo = max(object_mass_kg, 0.0)
    m_tot = m + mo
    uo[UO.MASS] = m
    uo[UO.CX] = cx
    uo[UO.CZ] = cz
    uo[UO.ARM_AX] = (mp[MP.MA_X] + mo * mp[MP.TIP_AX]) / m_tot
    uo[UO.ARM_AZ] = (mp[MP.MA_Z] + mo * mp[MP.TIP_AZ]) / m_tot
    uo[UO.CEX] = (m * cx + mo * mp[MP.OBJ_X]) / m_tot
    if mo > 0.0:  # the reaction and inertia with the estimated object (G_C, G_I above stay those without it)
        mp2 = np.empty(_N_MP)
        ic_rate = np.empty((3, 3))
        mass_props(q, qd, qdd, mo, geo, np.empty((3, 3)), ic_rate, mp2)
        uo[UO.HDC] = mp2[MP.HDC]
        for i in range(3):
            uo[UO.OBJ_RATE + i] = ic_rate[i, i] - rate[i, i]
    else:
        uo[UO.HDC] = mp[MP.HDC]
        for i in range(3):
            uo[UO.OBJ_RATE + i] = 0.0
    uo[UO.CEZ] = (m * cz + mo * mp[MP.OBJ_Z]) / m_tot
    gc_about(f, m0, cx, cz, gc)
    uo[UO.SINGULAR] = 0.0 if inv_gauss_jordan(gc, gc_inv) else 1.0



# Attitude (quaternions [w, x, y, z] rotate body FRD into NED; Euler ZYX). navig8_fc.core.rotation wraps these
# for Python callers.


@njit(cache=True)
def quat_mul(aw, ax, ay, az, bw, bx, by, bz):
    """a (x) b (Hamilton product)."""
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


@njit(cache=True)
def quat_to_dcm(w, x, y, z):
    """R (body -> NED), row-major (9 values)."""
    return (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))


@njit(cache=True)
def euler_to_quat(roll, pitch, yaw):
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy)


@njit(cache=True)
def quat_to_euler(w, x, y, z):
    """(roll, pitch, yaw) in rad, ZYX."""
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    s = max(-1.0, min(1.0, 2 * (w * y - z * x)))
    return roll, math.asin(s), math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


@njit(cache=True)
def attitude_error_rotvec(mw, mx, my, mz, cw, cx, cy, cz):
    """Rotation vector (body frame, rad) from the measured attitude m to the command c: rotvec(conj(m) (x) c),
    the shortest rotation (sign of the error quaternion's w), so 359 deg of yaw error is -1 deg."""
    ew, ex, ey, ez = quat_mul(mw, -mx, -my, -mz, cw, cx, cy, cz)
    sgn = 1.0 if ew >= 0.0 else -1.0
    vn = math.sqrt(ex * ex + ey * ey + ez * ez)
    if vn < 1e-12:
        return 0.0, 0.0, 0.0
    k = sgn * (2.0 * math.atan2(vn, abs(ew))) / vn
    return k * ex, k * ey, k * ez


# Outer loops: config, setpoint, feed-forward and output vectors (outer_loop)
OC = layout("OC", pos_k=1, vel_k=1, vel_max=1, acc_max=1, att_k=1, rate_k=1, rate_max=1, gravity=1)
OSP = layout("OSP", pos=3, pitch=1, yaw=1)  # p_cmd N, E, D (m); pitch, yaw (rad)
# Feed-forward of a shaped reference (outer_loop.shape_reference; all zero: the paper's stateless loop):
# velocity and acceleration (NED), body rate and angular acceleration of the reference attitude (its own FRD axes)
OFF = layout("OFF", vel=3, acc=3, rate=3, ang_acc=3)
OO = layout("OO", accel_cmd_ned=3, specific_force_cmd_ned=3, att_cmd_quat=4, roll_cmd=1, rate_cmd=3,
            accel_cmd=5)  # accel_cmd = [Pdot, Qdot, Rdot, a_x, a_z] for INDI


@njit(cache=True)
def _clip_norm3(v, limit):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if n > limit > 0.0:
        k = limit / n
        v[0] *= k
        v[1] *= k
        v[2] *= k


@njit(cache=True)
def roll_for_force(f0, f1, f2, pitch, yaw):
    """The roll that nulls the body-y component of the specific force f (NED) at the given pitch and yaw (the ducts
    act in x-z only): with f' = R_y(pitch)^T R_z(yaw)^T f, roll = atan2(f'_y, -f'_z)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    fx1 = cy * f0 + sy * f1
    fy1 = -sy * f0 + cy * f1
    fz2 = math.sin(pitch) * fx1 + math.cos(pitch) * f2
    return math.atan2(fy1, -fz2)


@njit(cache=True)
def _rotate_quat(w, x, y, z, v0, v1, v2):
    """R(q) v for the unit quaternion q (the frame q rotates into: R(q) maps q's axes into the reference's)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = quat_to_dcm(w, x, y, z)
    return (r00 * v0 + r01 * v1 + r02 * v2, r10 * v0 + r11 * v1 + r12 * v2, r20 * v0 + r21 * v1 + r22 * v2)


@njit(cache=True)
def outer_loop(cfg, sp, ff, pos, vel, quat, gyro, out):
    """One step of the outer loops (P cascade of [29], notes 6.5); cfg: OC, sp: OSP, ff: OFF, out: OO.

    v_cmd = sat(K_p (p_cmd - p), v_max) + v_ff (the sum limited to v_max when v_ff != 0);
    a_cmd = K_v (v_cmd - v) + a_ff, |a_cmd| <= a_max; f_cmd = a_cmd - g (NED). Pitch and yaw follow the setpoint;
    roll nulls the body-y part of f_cmd (roll_for_force). omega_cmd = sat(K_att rotvec(q^-1 q_cmd), rate_max) +
    omega_ff; [Pdot, Qdot, Rdot] = K_rate (omega_cmd - omega) + omega-dot_ff, the feed-forwards rotated from the
    command's axes into the measured body's; body a_x, a_z = f_cmd rotated with the measured attitude. With ff = 0
    this is the paper's stateless loop, bit for bit (PX4's PositionControl adds the same velocity/acceleration
    feed-forwards of its trajectory; docs/model.md "Command shaping").
    """
    v = np.empty(3)
    for i in range(3):
        v[i] = cfg[OC.POS_K] * (sp[OSP.POS + i] - pos[i])
    _clip_norm3(v, cfg[OC.VEL_MAX])
    if ff[OFF.VEL] != 0.0 or ff[OFF.VEL + 1] != 0.0 or ff[OFF.VEL + 2] != 0.0:
        for i in range(3):
            v[i] += ff[OFF.VEL + i]
        _clip_norm3(v, cfg[OC.VEL_MAX])
    a = np.empty(3)
    for i in range(3):
        a[i] = cfg[OC.VEL_K] * (v[i] - vel[i]) + ff[OFF.ACC + i]
    _clip_norm3(a, cfg[OC.ACC_MAX])
    f0, f1, f2 = a[0], a[1], a[2] - cfg[OC.GRAVITY]
    pitch, yaw = sp[OSP.PITCH], sp[OSP.YAW]
    roll = roll_for_force(f0, f1, f2, pitch, yaw)
    qw, qx, qy, qz = euler_to_quat(roll, pitch, yaw)
    # f in body axes with the measured attitude: R^T f
    r00, _, r02, r10, _, r12, r20, _, r22 = quat_to_dcm(quat[0], quat[1], quat[2], quat[3])
    fb0 = r00 * f0 + r10 * f1 + r20 * f2
    fb2 = r02 * f0 + r12 * f1 + r22 * f2
    err = np.empty(3)
    err[0], err[1], err[2] = attitude_error_rotvec(quat[0], quat[1], quat[2], quat[3], qw, qx, qy, qz)
    for i in range(3):
        err[i] = cfg[OC.ATT_K] * err[i]
    _clip_norm3(err, cfg[OC.RATE_MAX])
    dw = np.zeros(3)  # angular-acceleration feed-forward in the measured body axes
    if (ff[OFF.RATE] != 0.0 or ff[OFF.RATE + 1] != 0.0 or ff[OFF.RATE + 2] != 0.0 or ff[OFF.ANG_ACC] != 0.0
            or ff[OFF.ANG_ACC + 1] != 0.0 or ff[OFF.ANG_ACC + 2] != 0.0):
        # the command's axes -> the measured body's: conj(q_meas) (x) q_cmd
        ew, ex, ey, ez = quat_mul(quat[0], -quat[1], -quat[2], -quat[3], qw, qx, qy, qz)
        w0, w1, w2 = _rotate_quat(ew, ex, ey, ez, ff[OFF.RATE], ff[OFF.RATE + 1], ff[OFF.RATE + 2])
        err[0] += w0
        err[1] += w1
        err[2] += w2
        dw[0], dw[1], dw[2] = _rotate_quat(ew, ex, ey, ez, ff[OFF.ANG_ACC], ff[OFF.ANG_ACC + 1],
                                           ff[OFF.ANG_ACC + 2])
    for i in range(3):
        out[OO.ACCEL_CMD_NED + i] = a[i]
    out[OO.SPECIFIC_FORCE_CMD_NED] = f0
    out[OO.SPECIFIC_FORCE_CMD_NED + 1] = f1
    out[OO.SPECIFIC_FORCE_CMD_NED + 2] = f2
    out[OO.ATT_CMD_QUAT] = qw
    out[OO.ATT_CMD_QUAT + 1] = qx
    out[OO.ATT_CMD_QUAT + 2] = qy
    out[OO.ATT_CMD_QUAT + 3] = qz
    out[OO.ROLL_CMD] = roll
    for i in range(3):
        out[OO.RATE_CMD + i] = err[i]
        out[OO.ACCEL_CMD + i] = cfg[OC.RATE_K] * (err[i] - gyro[i]) + dw[i]
    out[OO.ACCEL_CMD + 3] = fb0
    out[OO.ACCEL_CMD + 4] = fb2


# INDI (IndiController owns these vectors): filter state, configuration and the output of indi_step
ST = layout("ST", gyro_f=3,  # low-passed gyro
            gyro_prev=3,  # previous low-passed gyro (backward difference)
            acc_f=2,  # low-passed specific force x, z
            u0_f=5,  # low-passed U0
            init=1,  # 1.0 once the filters have had their first sample
            # INDI_U0_SRC = 1: the actuator estimate (alpha1, alpha3, w1, w2, w3 positions, then their rates), the
            # last command sent (clipped actuators) and 1.0 when that command was flown (the previous tick engaged)
            act_x=10, act_cmd=5, act_ok=1,
            act_n=1)  # ticks since the estimate restarted at the measurement
IC = layout("IC", alpha=1, inv_dt=1, tilt_min=1, tilt_max=1, duct_speed_max=1, tail_speed_max=1,
            u_duct_sq_max=1,  # (w_duct_max^2)^2: bound on U_c^2 + U_s^2 of a duct
            u_tail_max=1,  # w_tail_max^2: bound on |U5|
            u0_src=1,  # INDI_U0_SRC: 0 U0 from the measured actuators (under Eq. 6), 1 model + measurement
            u0_gain=1,  # the complementary filter's correction gain toward the measurement (INDI_U0_TAU)
            # the actuator model's exact discretisation (actuator_model.actuator_discretisation), per group: the duct
            # tilts (alpha1, alpha3), then the propeller speeds (w1, w2, w3); Ad as [a00, a01, a10, a11], Bd [b0, b1]
            act_ad=8, act_bd=4)
IO = layout("IO", acc_f=5, u0=5, dacc=5, du=5, u=5, scale=3, fallback=1,
            act=5)  # alpha1, alpha3, w1, w2, w3 (clipped)


@njit(cache=True)
def actuators_to_u(alpha1, alpha3, w1, w2, w3, out, at):
    """U = [cos a1 w1^2, sin a1 w1^2, cos a3 w3^2, sin a3 w3^2, sign(w2) w2^2] (Sec. 3) into out[at:at + 5]."""
    out[at] = math.cos(alpha1) * w1 * w1
    out[at + 1] = math.sin(alpha1) * w1 * w1
    out[at + 2] = math.cos(alpha3) * w3 * w3
    out[at + 3] = math.sin(alpha3) * w3 * w3
    out[at + 4] = math.copysign(w2 * w2, w2)


@njit(cache=True)
def u_to_actuators(u, out, at):
    """(alpha1, alpha3, w1, w2, w3) from U (Sec. 3) into out[at:at + 5]: alpha = atan2, w = (U_c^2 + U_s^2)^(1/4)."""
    out[at] = math.atan2(u[1], u[0])
    out[at + 1] = math.atan2(u[3], u[2])
    out[at + 2] = math.hypot(u[0], u[1]) ** 0.5
    out[at + 3] = math.copysign(abs(u[4]) ** 0.5, u[4])
    out[at + 4] = math.hypot(u[2], u[3]) ** 0.5


@njit(cache=True)
def actuator_model_step(x, xo, ad, bd, cmd, co):
    """The five actuators' state x[xo:xo + 5] (positions), x[xo + 5:xo + 10] (rates) advanced one period under
    the held command cmd[co:co + 5]: [p, r] <- Ad [p, r] + Bd u (Eq. 10's second-order lag, exact ZOH;
    per group g (0: the tilts alpha1, alpha3; 1: the speeds w1, w2, w3) ad[4 g:4 g + 4] = [a00, a01, a10, a11],
    bd[2 g:2 g + 2] = [b0, b1] from actuator_model.actuator_discretisation)."""
    for i in range(5):
        g = 0 if i < 2 else 1
        p, r, u = x[xo + i], x[xo + 5 + i], cmd[co + i]
        x[xo + i] = ad[4 * g] * p + ad[4 * g + 1] * r + bd[2 * g] * u
        x[xo + 5 + i] = ad[4 * g + 2] * p + ad[4 * g + 3] * r + bd[2 * g + 1] * u


@njit(cache=True)
def actuator_estimate(st, ic, tilt1, tilt3, w1, w2, w3):
    """INDI_U0_SRC = 1: the actuators' positions in st[ACT_X:ACT_X + 5] from the command flown last tick through
    the FC's actuator model, corrected toward the measurement by the complementary gain: the model carries the
    fast part (no sensor noise), the measurement the slow part (model errors, disturbances). Without a flown
    command (first tick, after disengaging) the estimate restarts at the measurement, at rest; the gain is then
    1/(n + 1) on the n-th tick until it reaches the complementary gain (the running mean of the model-measurement
    gap, as a Kalman filter's gain falls from its start): otherwise the first sample's noise (20 rad/s on the
    speeds) would stay in U0 for ~INDI_U0_TAU and fly as a moment that long."""
    meas = (tilt1, tilt3, w1, w2, w3)
    if st[ST.ACT_OK] != 0.0:
        actuator_model_step(st, ST.ACT_X, ic[IC.ACT_AD:IC.ACT_AD + 8], ic[IC.ACT_BD:IC.ACT_BD + 4], st, ST.ACT_CMD)
        n = st[ST.ACT_N] + 1.0
        st[ST.ACT_N] = n
        g = max(ic[IC.U0_GAIN], 1.0 / (n + 1.0))
        for i in range(5):
            st[ST.ACT_X + i] += g * (meas[i] - st[ST.ACT_X + i])
    else:
        st[ST.ACT_N] = 0.0
        for i in range(5):
            st[ST.ACT_X + i] = meas[i]
            st[ST.ACT_X + 5 + i] = 0.0


@njit(cache=True)
def indi_measure(st, ic, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, out):
    """Filters of IndiController.measure: writes acc_f (out[0:5]) and u0 (out[5:10]). U0 before its low-pass:
    the measured actuators (INDI_U0_SRC = 0, as defined under Eq. 6) or their estimate (1, actuator_estimate)."""
    u = np.empty(5)
    if ic[IC.U0_SRC] != 0.0:
        actuator_estimate(st, ic, tilt1, tilt3, w1, w2, w3)
        actuators_to_u(st[ST.ACT_X], st[ST.ACT_X + 1], st[ST.ACT_X + 2], st[ST.ACT_X + 3], st[ST.ACT_X + 4], u, 0)
    else:
        actuators_to_u(tilt1, tilt3, w1, w2, w3, u, 0)
    if st[ST.INIT] == 0.0:
        for i in range(3):
            st[ST.GYRO_F + i] = gyro[i]
            st[ST.GYRO_PREV + i] = gyro[i]
            out[IO.ACC_F + i] = 0.0
        st[ST.ACC_F] = sf_x
        st[ST.ACC_F + 1] = sf_z
        for i in range(5):
            st[ST.U0_F + i] = u[i]
        st[ST.INIT] = 1.0
    else:
        a, k = ic[IC.ALPHA], ic[IC.INV_DT]
        for i in range(3):
            y = st[ST.GYRO_F + i]
            y = y + a * (gyro[i] - y)
            out[IO.ACC_F + i] = (y - st[ST.GYRO_PREV + i]) * k
            st[ST.GYRO_F + i] = y
            st[ST.GYRO_PREV + i] = y
        y = st[ST.ACC_F]
        st[ST.ACC_F] = y + a * (sf_x - y)
        y = st[ST.ACC_F + 1]
        st[ST.ACC_F + 1] = y + a * (sf_z - y)
        for i in range(5):
            y = st[ST.U0_F + i]
            st[ST.U0_F + i] = y + a * (u[i] - y)
    out[IO.ACC_F + 3] = st[ST.ACC_F]
    out[IO.ACC_F + 4] = st[ST.ACC_F + 1]
    for i in range(5):
        out[IO.U0 + i] = st[ST.U0_F + i]


@njit(cache=True)
def _feasible(ic, u0, u1, u2, u3, u4):
    if not (math.isfinite(u0) and math.isfinite(u1) and math.isfinite(u2) and math.isfinite(u3)
            and math.isfinite(u4)):
        return False
    if u0 * u0 + u1 * u1 > ic[IC.U_DUCT_SQ_MAX] or u2 * u2 + u3 * u3 > ic[IC.U_DUCT_SQ_MAX]:
        return False
    if abs(u4) > ic[IC.U_TAIL_MAX]:
        return False
    if u0 * u0 + u1 * u1 > 1e-6:
        a = math.atan2(u1, u0)
        if a < ic[IC.TILT_MIN] or a > ic[IC.TILT_MAX]:
            return False
    if u2 * u2 + u3 * u3 > 1e-6:
        a = math.atan2(u3, u2)
        if a < ic[IC.TILT_MIN] or a > ic[IC.TILT_MAX]:
            return False
    return True


@njit(cache=True)
def _feasible_v(ic, u):
    return _feasible(ic, u[0], u[1], u[2], u[3], u[4])


@njit(cache=True)
def _max_scale(ic, base, part):
    if not _feasible_v(ic, base):
        return 0.0
    lo, hi = 0.0, 1.0
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        if _feasible(ic, base[0] + mid * part[0], base[1] + mid * part[1], base[2] + mid * part[2],
                     base[3] + mid * part[3], base[4] + mid * part[4]):
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def indi_increment(st, ic, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, accel_cmd, gc_inv, gi_hat, out, m, d, u0, du,
                   u):
    """The unconstrained INDI increment: filters, M = G_C^-1 G_hat_I into m, Delta Acc = v - Acc_f into d (and
    out's DACC), Delta U = M Delta Acc (Eq. 5) into du, U0 into u0 and U = U0 + Delta U (Eq. 6) into u."""
    indi_measure(st, ic, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, out)
    for i in range(5):
        for j in range(5):
            acc = 0.0
            for k in range(5):
                acc += gc_inv[i, k] * gi_hat[k, j]
            m[i, j] = acc
    for i in range(5):
        d[i] = accel_cmd[i] - out[IO.ACC_F + i]
        out[IO.DACC + i] = d[i]
        u0[i] = out[IO.U0 + i]
    for i in range(5):
        acc = 0.0
        for k in range(5):
            acc += m[i, k] * d[k]
        du[i] = acc
        u[i] = u0[i] + acc
    out[IO.SCALE] = 1.0
    out[IO.SCALE + 1] = 1.0
    out[IO.SCALE + 2] = 1.0


@njit(cache=True)
def indi_finish(ic, u0, du, u, out):
    """Non-finite fallback to U0, then DU, U and the actuators (U -> alpha, w, clipped into the limits) into out."""
    fallback = False
    for i in range(5):
        if not math.isfinite(u[i]):
            fallback = True
    if fallback:
        for i in range(5):
            u[i] = u0[i]
            du[i] = 0.0
    out[IO.FALLBACK] = 1.0 if fallback else 0.0
    for i in range(5):
        out[IO.DU + i] = du[i]
        out[IO.U + i] = u[i]
    u_to_actuators(u, out, IO.ACT)  # then clipped into the limits
    out[IO.ACT] = min(max(out[IO.ACT], ic[IC.TILT_MIN]), ic[IC.TILT_MAX])
    out[IO.ACT + 1] = min(max(out[IO.ACT + 1], ic[IC.TILT_MIN]), ic[IC.TILT_MAX])
    out[IO.ACT + 2] = min(out[IO.ACT + 2], ic[IC.DUCT_SPEED_MAX])
    out[IO.ACT + 3] = min(max(out[IO.ACT + 3], -ic[IC.TAIL_SPEED_MAX]), ic[IC.TAIL_SPEED_MAX])
    out[IO.ACT + 4] = min(out[IO.ACT + 4], ic[IC.DUCT_SPEED_MAX])


@njit(cache=True)
def group_scaling(ic, m, d, u0, du, u, out):
    """The paper-faithful saturation handling (INDI_ALLOC = 0): the increment du = M d is scaled back axis group
    by axis group, lowest priority first (a_x, then Rdot, then roll/pitch/a_z together; bisection on a scale
    per group, into out's SCALE slots) until U0 + du is feasible; du and u are updated."""
    rest = du.copy()
    part = np.empty(5)
    base = np.empty(5)
    tmp = np.empty(5)
    for g in range(3):
        for i in range(5):
            if g == 0:
                part[i] = m[i, 3] * d[3]
            elif g == 1:
                part[i] = m[i, 2] * d[2]
            else:
                part[i] = m[i, 0] * d[0] + m[i, 1] * d[1] + m[i, 4] * d[4]
            base[i] = rest[i] - part[i]
            tmp[i] = u0[i] + base[i] + part[i]
        if _feasible_v(ic, tmp):
            break
        for i in range(5):
            tmp[i] = u0[i] + base[i]
        s = _max_scale(ic, tmp, part)
        out[IO.SCALE + g] = s
        for i in range(5):
            rest[i] = base[i] + s * part[i]
            tmp[i] = u0[i] + rest[i]
        if _feasible_v(ic, tmp):
            break
    for i in range(5):
        du[i] = rest[i]
        u[i] = u0[i] + du[i]


@njit(cache=True)
def indi_step(st, ic, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, accel_cmd, gc_inv, gi_hat, out):
    """IndiController.step with the paper's group scaling (INDI_ALLOC = 0): filters, Delta U = G_C^-1 G_hat_I
    Delta Acc (Eq. 5), saturation by groups (a_x, then Rdot, then roll/pitch/a_z), non-finite fallback to U0,
    U -> clipped actuators."""
    m = np.empty((5, 5))
    d = np.empty(5)
    u0 = np.empty(5)
    du = np.empty(5)
    u = np.empty(5)
    indi_increment(st, ic, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, accel_cmd, gc_inv, gi_hat, out, m, d, u0, du,
                   u)
    if not _feasible_v(ic, u):
        group_scaling(ic, m, d, u0, du, u, out)
    indi_finish(ic, u0, du, u, out)


# ---------------------------------------------------------------------------------------------
# Box projection glue around the clarabel solve (ckf.BoxProjector.solve_lists is the reference)
# ---------------------------------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# Controller front end: joint observer, differentiators, UAM model, Acc_m and U0 (one call per tick)
# ---------------------------------------------------------------------------------------------

# The tick's input vector (FlightControllerCore packs FcSensors into it): the sensors fc_front reads, then the
# outer loops' inputs (packed only when engaged).
TIN = layout("TIN", gyro=3, accel=3,  # specific force at O
             tilt=2, speed=3, jpos=3, jrate=3,  # alpha1, alpha3; w1, w2, w3; joint angles and rates
             pos=3, vel=3, quat=4, sp=5)  # pos_ned, vel_ned, quat_wxyz, setpoint (OSP layout)
# Front-end state `fst` and output `fo`
FST = layout("FST", qest=3,  # joint-angle estimate
             qd_prev=3, gyro_prev=3,  # previous joint rate and gyro (backward differences)
             init=1)  # 1.0 after the first sample
FO = layout("FO", qest=3, qdd=3,
            acc_m=5,  # [P_dot, Q_dot, R_dot, a_x + arm, a_z + arm] (Eq. 23)
            arm_hdc=1,  # UO.HDC: minus the arm's reaction pitch moment about the CoM (CKF_ARM_WRENCH)
            u_meas=5)  # U0 from the measured actuators


@njit(cache=True)
def com_accel_offset(p, q, r, qdot, cx, cz):
    """(x, z) of a_c - a_O for a rigid body: omega-dot x c + omega x (omega x c) with c = (cx, 0, cz) the composite
    CoM (FRD, from O) and omega-dot = (., qdot, .) (the planar arm keeps c_y = 0, so only Q-dot enters x and z).
    (omega-dot x c)_x = Qdot c_z, _z = -Qdot c_x; omega x (omega x c) = omega (omega . c) - c |omega|^2."""
    wc = p * cx + r * cz  # omega . c
    w2 = p * p + q * q + r * r
    return qdot * cz + p * wc - cx * w2, -qdot * cx + r * wc - cz * w2


@njit(cache=True)
def fc_front(fst, dt, obs_gain, inv_dt, sens, object_mass_kg, geo, f, m0, inertia, rate, gc, gc_inv, uo, fo,
             acc_ref=0.0):
    """FlightControllerCore's per-tick front end: the complementary joint observer (q_est), backward
    differences of the joint rates (q-ddot) and of the gyro (omega-dot), uam_model at (q_est, q-dot, q-ddot),
    Acc_m (Eq. 23) and U0 = actuators_to_u(measured). All state in fst; first sample: q_est = q, zeros out of
    the differences. sens: TIN (only its sensor part is read).

    acc_ref = 0 (the paper): Acc_m's force rows are the specific force at O plus the arm's c-ddot_rel.
    acc_ref = 1 (INDI_ACC_REF): they are the acceleration of the estimated composite CoM c
    (uo CEX, CEZ): a_c = f_O + omega-dot x c + omega x (omega x c) + c-ddot_rel (the Coriolis term
    2 omega x c-dot_rel is left out), the point G_C's force rows and the flown loop refer to."""
    q = np.empty(3)
    qd = sens[TIN.JRATE:TIN.JRATE + 3]
    qdd = np.empty(3)
    if fst[FST.INIT] == 0.0:
        for i in range(3):
            fst[FST.QEST + i] = sens[TIN.JPOS + i]
            qdd[i] = 0.0
            fo[FO.ACC_M + i] = 0.0
        fst[FST.INIT] = 1.0
    else:
        for i in range(3):
            pred = fst[FST.QEST + i] + dt * qd[i]
            fst[FST.QEST + i] = pred + obs_gain * (sens[TIN.JPOS + i] - pred)
            qdd[i] = (qd[i] - fst[FST.QD_PREV + i]) * inv_dt
            fo[FO.ACC_M + i] = (sens[TIN.GYRO + i] - fst[FST.GYRO_PREV + i]) * inv_dt
    for i in range(3):
        fst[FST.QD_PREV + i] = qd[i]
        fst[FST.GYRO_PREV + i] = sens[TIN.GYRO + i]
        q[i] = fst[FST.QEST + i]
        fo[FO.QEST + i] = q[i]
        fo[FO.QDD + i] = qdd[i]
    uam_model(q, qd, qdd, object_mass_kg, geo, f, m0, inertia, rate, gc, gc_inv, uo)
    fo[FO.ARM_HDC] = uo[UO.HDC]
    fo[FO.ACC_M + 3] = sens[TIN.ACCEL] + uo[UO.ARM_AX]
    fo[FO.ACC_M + 4] = sens[TIN.ACCEL + 2] + uo[UO.ARM_AZ]
    if acc_ref != 0.0:
        dx, dz = com_accel_offset(sens[TIN.GYRO], sens[TIN.GYRO + 1], sens[TIN.GYRO + 2], fo[FO.ACC_M + 1],
                                  uo[UO.CEX], uo[UO.CEZ])
        fo[FO.ACC_M + 3] += dx
        fo[FO.ACC_M + 4] += dz
    actuators_to_u(sens[TIN.TILT], sens[TIN.TILT + 1], sens[TIN.SPEED], sens[TIN.SPEED + 1], sens[TIN.SPEED + 2],
                   fo, FO.U_MEAS)


@njit(cache=True)
def ghat_ginv_eigs(gi_hat: np.ndarray, gc_uam: np.ndarray, gc_true: np.ndarray, gi_true: np.ndarray,
                   out_re: np.ndarray, out_im: np.ndarray) -> None:
    """Eigenvalues of G_hat G^-1 = (G_hat_I^-1 G_C,UAM)(G_C,true^-1 G_I,true) (Eq. 14), sorted by real part.

    K Xi can have complex pairs (~1 % of poses): real eigvals first, complex arithmetic when that fails.
    tests/unit/test_vehicle.py checks it against scipy.linalg.eigvals."""
    a = np.linalg.solve(gi_hat, gc_uam) @ np.linalg.solve(gc_true, gi_true)
    if _real_eigvals_sorted(a, out_re):  # the usual case, ~3x cheaper than the complex path
        out_im[:] = 0.0
        return
    lam = np.linalg.eigvals(a.astype(np.complex128))
    order = np.argsort(lam.real)
    for i in range(lam.size):
        out_re[i] = lam[order[i]].real
        out_im[i] = lam[order[i]].imag


@njit(cache=True)
def _real_eigvals_sorted(a: np.ndarray, out_re: np.ndarray) -> bool:
    """Sorted eigenvalues of `a` into out_re when all are real; False (out_re untouched) when some are not:
    numba's real eigvals raises on a complex result."""
    try:
        lam = np.linalg.eigvals(a)
    except Exception:  # noqa: BLE001 - complex pair: the caller takes the complex path
        return False
    lam.sort()
    out_re[:] = lam
    return True
