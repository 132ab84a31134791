"""Numba hot path of the controller tick: UAM model + G_C^-1, KF correct, outer loops, INDI increment.

Plain float maths on flat float64 arrays (the same style as sim_bridge/_kernels.py): the controller's
vectors have 3-5 components, where numpy's per-call overhead dominates. Each kernel here has a
plain-Python / numpy reference (UamModel.evaluate + inv_small, ConstrainedKalmanFilter._correct_reference,
outer_loop_step, IndiControllerReference) and tests/unit/test_fc_kernels.py compares them; results
agree to rounding (different summation order than BLAS / LAPACK). Pure: no I/O, no clocks.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Layout of the UAM-model output vector `uo` (uam_model)
UO_MASS = 0
UO_CX = 1
UO_CZ = 2
UO_ARM_AX = 3
UO_ARM_AZ = 4
UO_SINGULAR = 5  # 1.0 when G_C could not be inverted (the caller then falls back to numpy)
N_UO = 6


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
            for j in range(2 * n):
                t = m[c, j]
                m[c, j] = m[p, j]
                m[p, j] = t
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


@njit(cache=True)
def uam_model(q, qd, qdd, object_mass_kg, geo, f, m0, inertia, rate, gc, gc_inv, uo):
    """UamModel.evaluate + G_C about the CoM + its inverse, into preallocated arrays.

    geo = [L, m_link, I_link, mount_x, mount_z, m_uam, jb11, jb22, jb33, jb13]; f, m0: (3, 5) force and
    moment-about-O rows per input. Writes inertia (3x3), rate (3x3), gc (5x5), gc_inv (5x5) and uo.
    """
    L, ml, ia, mx, mz = geo[0], geo[1], geo[2], geo[3], geo[4]
    th = thd = thdd = 0.0
    jx, jz, jvx, jvz, jax, jaz = mx, mz, 0.0, 0.0, 0.0, 0.0
    s1 = s1z = 0.0
    v1x = v1z = a1x = a1z = 0.0
    j11 = j22 = j33 = j13 = 0.0
    d11 = d22 = d33 = d13 = 0.0
    h = 0.5 * L
    for i in range(3):
        th += q[i]
        thd += qd[i]
        thdd += qdd[i]
        s, c = math.sin(th), math.cos(th)
        vx, vz = thd * c, -thd * s
        ax, az = thdd * c - thd * thd * s, -thdd * s - thd * thd * c
        x, z = jx + h * s, jz + h * c
        xd, zd = jvx + h * vx, jvz + h * vz
        xdd, zdd = jax + h * ax, jaz + h * az
        s1 += ml * x
        s1z += ml * z
        v1x += ml * xd
        v1z += ml * zd
        a1x += ml * xdd
        a1z += ml * zdd
        j11 += ia * c * c + ml * z * z
        j22 += ia + ml * (x * x + z * z)
        j33 += ia * s * s + ml * x * x
        j13 += -ia * s * c - ml * x * z
        s2, c2 = 2.0 * s * c, c * c - s * s
        d11 += -ia * s2 * thd + 2.0 * ml * z * zd
        d22 += 2.0 * ml * (x * xd + z * zd)
        d33 += ia * s2 * thd + 2.0 * ml * x * xd
        d13 += -ia * c2 * thd - ml * (xd * z + x * zd)
        jx, jz = jx + L * s, jz + L * c
        jvx, jvz = jvx + L * vx, jvz + L * vz
        jax, jaz = jax + L * ax, jaz + L * az
    m = geo[5]
    cx, cz = s1 / m, s1z / m
    cxd, czd = v1x / m, v1z / m
    inertia[:, :] = 0.0
    rate[:, :] = 0.0
    inertia[0, 0] = geo[6] + j11 - m * cz * cz
    inertia[1, 1] = geo[7] + j22 - m * (cx * cx + cz * cz)
    inertia[2, 2] = geo[8] + j33 - m * cx * cx
    i13 = geo[9] + j13 + m * cx * cz
    inertia[0, 2] = i13
    inertia[2, 0] = i13
    rate[0, 0] = d11 - 2.0 * m * cz * czd
    rate[1, 1] = d22 - 2.0 * m * (cx * cxd + cz * czd)
    rate[2, 2] = d33 - 2.0 * m * cx * cxd
    r13 = d13 + m * (cxd * cz + cx * czd)
    rate[0, 2] = r13
    rate[2, 0] = r13
    mo = max(object_mass_kg, 0.0)
    m_tot = m + mo
    uo[UO_MASS] = m
    uo[UO_CX] = cx
    uo[UO_CZ] = cz
    uo[UO_ARM_AX] = (a1x + mo * jax) / m_tot
    uo[UO_ARM_AZ] = (a1z + mo * jaz) / m_tot
    for j in range(5):
        gc[0, j] = m0[0, j] + cz * f[1, j]
        gc[1, j] = m0[1, j] - (cz * f[0, j] - cx * f[2, j])
        gc[2, j] = m0[2, j] - cx * f[1, j]
        gc[3, j] = f[0, j]
        gc[4, j] = f[2, j]
    uo[UO_SINGULAR] = 0.0 if inv_gauss_jordan(gc, gc_inv) else 1.0


@njit(cache=True)
def _clip_norm3(v, limit):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if n > limit > 0.0:
        k = limit / n
        v[0] *= k
        v[1] *= k
        v[2] *= k


@njit(cache=True)
def outer_loop(cfg, sp, pos, vel, quat, gyro, out):
    """outer_loop_step on arrays. cfg = [pos_k, vel_k, vel_max, acc_max, att_k, rate_k, rate_max, g];
    sp = [n, e, d, pitch, yaw]. out (19,) = a_cmd(3), f_cmd(3), q_cmd(4), roll, w_cmd(3), accel_cmd(5)."""
    v = np.empty(3)
    for i in range(3):
        v[i] = cfg[0] * (sp[i] - pos[i])
    _clip_norm3(v, cfg[2])
    a = np.empty(3)
    for i in range(3):
        a[i] = cfg[1] * (v[i] - vel[i])
    _clip_norm3(a, cfg[3])
    f0, f1, f2 = a[0], a[1], a[2] - cfg[7]
    pitch, yaw = sp[3], sp[4]
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, spp = math.cos(pitch), math.sin(pitch)
    fx1 = cy * f0 + sy * f1
    fy1 = -sy * f0 + cy * f1
    fz2 = spp * fx1 + cp * f2
    roll = math.atan2(fy1, -fz2)
    # euler_to_quat
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp2, sp2 = math.cos(pitch / 2), math.sin(pitch / 2)
    cy2, sy2 = math.cos(yaw / 2), math.sin(yaw / 2)
    qw = cr * cp2 * cy2 + sr * sp2 * sy2
    qx = sr * cp2 * cy2 - cr * sp2 * sy2
    qy = cr * sp2 * cy2 + sr * cp2 * sy2
    qz = cr * cp2 * sy2 - sr * sp2 * cy2
    # rotate_ned_to_body(quat, f): R^T f with R = quat_to_dcm(quat)
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    r00 = 1 - 2 * (y * y + z * z)
    r02 = 2 * (x * z + w * y)
    r10 = 2 * (x * y + w * z)
    r12 = 2 * (y * z - w * x)
    r20 = 2 * (x * z - w * y)
    r22 = 1 - 2 * (x * x + y * y)
    fb0 = r00 * f0 + r10 * f1 + r20 * f2
    fb2 = r02 * f0 + r12 * f1 + r22 * f2
    # attitude_error_rotvec(quat, q_cmd): e = conj(quat) * q_cmd
    aw, ax, ay, az = w, -x, -y, -z
    ew = aw * qw - ax * qx - ay * qy - az * qz
    ex = aw * qx + ax * qw + ay * qz - az * qy
    ey = aw * qy - ax * qz + ay * qw + az * qx
    ez = aw * qz + ax * qy - ay * qx + az * qw
    sgn = 1.0 if ew >= 0.0 else -1.0
    vn = math.sqrt(ex * ex + ey * ey + ez * ez)
    err = np.zeros(3)
    if vn >= 1e-12:
        k = sgn * (2.0 * math.atan2(vn, abs(ew))) / vn
        err[0] = k * ex
        err[1] = k * ey
        err[2] = k * ez
    for i in range(3):
        err[i] = cfg[4] * err[i]
    _clip_norm3(err, cfg[6])
    out[0] = a[0]
    out[1] = a[1]
    out[2] = a[2]
    out[3] = f0
    out[4] = f1
    out[5] = f2
    out[6] = qw
    out[7] = qx
    out[8] = qy
    out[9] = qz
    out[10] = roll
    for i in range(3):
        out[11 + i] = err[i]
        out[14 + i] = cfg[5] * (err[i] - gyro[i])
    out[17] = fb0
    out[18] = fb2


# INDI: state vector `st` and config `ic` layouts (IndiController owns them)
ST_GYRO_F = 0  # 0:3 low-passed gyro
ST_GYRO_PREV = 3  # 3:6 previous low-passed gyro (backward difference)
ST_ACC_F = 6  # 6:8 low-passed specific force x, z
ST_U0_F = 8  # 8:13 low-passed U0
ST_INIT = 13  # 1.0 once the filters have had their first sample
N_ST = 14
# ic = [alpha, 1/dt, tilt_min, tilt_max, duct_speed_max, tail_speed_max, (w_duct_max^2)^2, w_tail_max^2]
# Output vector of indi_step
IO_ACC_F = 0
IO_U0 = 5
IO_DACC = 10
IO_DU = 15
IO_U = 20
IO_SCALE = 25
IO_FALLBACK = 28
IO_ACT = 29  # alpha1, alpha3, w1, w2, w3 (clipped)
N_IO = 34


@njit(cache=True)
def indi_measure(st, ic, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, out):
    """Filters of IndiController.measure: writes acc_f (out[0:5]) and u0 (out[5:10])."""
    u = np.empty(5)
    u[0] = math.cos(tilt1) * w1 * w1
    u[1] = math.sin(tilt1) * w1 * w1
    u[2] = math.cos(tilt3) * w3 * w3
    u[3] = math.sin(tilt3) * w3 * w3
    u[4] = math.copysign(w2 * w2, w2)
    if st[ST_INIT] == 0.0:
        for i in range(3):
            st[ST_GYRO_F + i] = gyro[i]
            st[ST_GYRO_PREV + i] = gyro[i]
            out[IO_ACC_F + i] = 0.0
        st[ST_ACC_F] = sf_x
        st[ST_ACC_F + 1] = sf_z
        for i in range(5):
            st[ST_U0_F + i] = u[i]
        st[ST_INIT] = 1.0
    else:
        a, k = ic[0], ic[1]
        for i in range(3):
            y = st[ST_GYRO_F + i]
            y = y + a * (gyro[i] - y)
            out[IO_ACC_F + i] = (y - st[ST_GYRO_PREV + i]) * k
            st[ST_GYRO_F + i] = y
            st[ST_GYRO_PREV + i] = y
        y = st[ST_ACC_F]
        st[ST_ACC_F] = y + a * (sf_x - y)
        y = st[ST_ACC_F + 1]
        st[ST_ACC_F + 1] = y + a * (sf_z - y)
        for i in range(5):
            y = st[ST_U0_F + i]
            st[ST_U0_F + i] = y + a * (u[i] - y)
    out[IO_ACC_F + 3] = st[ST_ACC_F]
    out[IO_ACC_F + 4] = st[ST_ACC_F + 1]
    for i in range(5):
        out[IO_U0 + i] = st[ST_U0_F + i]


@njit(cache=True)
def _feasible(ic, u0, u1, u2, u3, u4):
    if not (math.isfinite(u0) and math.isfinite(u1) and math.isfinite(u2) and math.isfinite(u3)
            and math.isfinite(u4)):
        return False
    if u0 * u0 + u1 * u1 > ic[6] or u2 * u2 + u3 * u3 > ic[6]:
        return False
    if abs(u4) > ic[7]:
        return False
    if u0 * u0 + u1 * u1 > 1e-6:
        a = math.atan2(u1, u0)
        if a < ic[2] or a > ic[3]:
            return False
    if u2 * u2 + u3 * u3 > 1e-6:
        a = math.atan2(u3, u2)
        if a < ic[2] or a > ic[3]:
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
def indi_step(st, ic, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, accel_cmd, gc_inv, gi_hat, out):
    """IndiController.step: filters, Delta U = G_C^-1 G_hat_I Delta Acc (Eq. 5), saturation by groups
    (a_x, then Rdot, then roll/pitch/a_z), non-finite fallback to U0, U -> clipped actuators."""
    indi_measure(st, ic, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, out)
    m = np.empty((5, 5))
    for i in range(5):
        for j in range(5):
            acc = 0.0
            for k in range(5):
                acc += gc_inv[i, k] * gi_hat[k, j]
            m[i, j] = acc
    d = np.empty(5)
    for i in range(5):
        d[i] = accel_cmd[i] - out[IO_ACC_F + i]
        out[IO_DACC + i] = d[i]
    u0 = out[IO_U0:IO_U0 + 5].copy()
    du = np.empty(5)
    u = np.empty(5)
    for i in range(5):
        acc = 0.0
        for k in range(5):
            acc += m[i, k] * d[k]
        du[i] = acc
        u[i] = u0[i] + acc
    out[IO_SCALE] = 1.0
    out[IO_SCALE + 1] = 1.0
    out[IO_SCALE + 2] = 1.0
    if not _feasible_v(ic, u):
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
            out[IO_SCALE + g] = s
            for i in range(5):
                rest[i] = base[i] + s * part[i]
                tmp[i] = u0[i] + rest[i]
            if _feasible_v(ic, tmp):
                break
        for i in range(5):
            du[i] = rest[i]
            u[i] = u0[i] + du[i]
    fallback = False
    for i in range(5):
        if not math.isfinite(u[i]):
            fallback = True
    if fallback:
        for i in range(5):
            u[i] = u0[i]
            du[i] = 0.0
    out[IO_FALLBACK] = 1.0 if fallback else 0.0
    for i in range(5):
        out[IO_DU + i] = du[i]
        out[IO_U + i] = u[i]
    a1 = math.atan2(u[1], u[0])
    a3 = math.atan2(u[3], u[2])
    w1c = math.hypot(u[0], u[1]) ** 0.5
    w3c = math.hypot(u[2], u[3]) ** 0.5
    w2c = math.copysign(abs(u[4]) ** 0.5, u[4])
    out[IO_ACT] = min(max(a1, ic[2]), ic[3])
    out[IO_ACT + 1] = min(max(a3, ic[2]), ic[3])
    out[IO_ACT + 2] = min(w1c, ic[4])
    out[IO_ACT + 3] = min(max(w2c, -ic[5]), ic[5])
    out[IO_ACT + 4] = min(w3c, ic[4])


# ---------------------------------------------------------------------------------------------
# Controller front end: joint observer, differentiators, UAM model, Acc_m and U0 (one call per tick)
# ---------------------------------------------------------------------------------------------

# Sensor vector `sens` (FlightControllerCore builds it from FcSensors)
S_GYRO = 0  # 0:3
S_ACCEL = 3  # 3:6 specific force at O
S_TILT = 6  # 6:8 alpha1, alpha3
S_SPEED = 8  # 8:11 w1, w2, w3
S_JPOS = 11  # 11:14
S_JRATE = 14  # 14:17
N_SENS = 17
# Front-end state `fst`
F_QEST = 0  # 0:3 joint-angle estimate
F_QD_PREV = 3  # 3:6 previous joint rate
F_GYRO_PREV = 6  # 6:9 previous gyro
F_INIT = 9  # 1.0 after the first sample
N_FST = 10
# Front-end output `fo`
FO_QEST = 0  # 0:3
FO_QDD = 3  # 3:6
FO_ACC_M = 6  # 6:11 [P_dot, Q_dot, R_dot, a_x + arm, a_z + arm] (Eq. 23)
FO_U_MEAS = 11  # 11:16 U0 from the measured actuators
N_FO = 16


@njit(cache=True)
def fc_front(fst, dt, obs_gain, inv_dt, sens, object_mass_kg, geo, f, m0, inertia, rate, gc, gc_inv, uo, fo):
    """FlightControllerCore's per-tick front end: the complementary joint observer (q_est), backward
    differences of the joint rates (q-ddot) and of the gyro (omega-dot), uam_model at (q_est, q-dot, q-ddot),
    Acc_m (Eq. 23) and U0 = actuators_to_u(measured). All state in fst; first sample: q_est = q, zeros out of
    the differences."""
    q = np.empty(3)
    qd = sens[S_JRATE:S_JRATE + 3]
    qdd = np.empty(3)
    if fst[F_INIT] == 0.0:
        for i in range(3):
            fst[F_QEST + i] = sens[S_JPOS + i]
            qdd[i] = 0.0
            fo[FO_ACC_M + i] = 0.0
        fst[F_INIT] = 1.0
    else:
        for i in range(3):
            pred = fst[F_QEST + i] + dt * qd[i]
            fst[F_QEST + i] = pred + obs_gain * (sens[S_JPOS + i] - pred)
            qdd[i] = (qd[i] - fst[F_QD_PREV + i]) * inv_dt
            fo[FO_ACC_M + i] = (sens[S_GYRO + i] - fst[F_GYRO_PREV + i]) * inv_dt
    for i in range(3):
        fst[F_QD_PREV + i] = qd[i]
        fst[F_GYRO_PREV + i] = sens[S_GYRO + i]
        q[i] = fst[F_QEST + i]
        fo[FO_QEST + i] = q[i]
        fo[FO_QDD + i] = qdd[i]
    uam_model(q, qd, qdd, object_mass_kg, geo, f, m0, inertia, rate, gc, gc_inv, uo)
    fo[FO_ACC_M + 3] = sens[S_ACCEL] + uo[UO_ARM_AX]
    fo[FO_ACC_M + 4] = sens[S_ACCEL + 2] + uo[UO_ARM_AZ]
    a1, a3 = sens[S_TILT], sens[S_TILT + 1]
    w1, w2, w3 = sens[S_SPEED], sens[S_SPEED + 1], sens[S_SPEED + 2]
    fo[FO_U_MEAS] = math.cos(a1) * w1 * w1
    fo[FO_U_MEAS + 1] = math.sin(a1) * w1 * w1
    fo[FO_U_MEAS + 2] = math.cos(a3) * w3 * w3
    fo[FO_U_MEAS + 3] = math.sin(a3) * w3 * w3
    fo[FO_U_MEAS + 4] = math.copysign(w2 * w2, w2)


@njit(cache=True)
def ghat_ginv_eigs(gi_hat: np.ndarray, gc_uam: np.ndarray, gc_true: np.ndarray, gi_true: np.ndarray,
                   out_re: np.ndarray, out_im: np.ndarray) -> None:
    """Eigenvalues of G_hat G^-1 = (G_hat_I^-1 G_C,UAM)(G_C,true^-1 G_I,true) (Eq. 14), sorted by real part.

    K Xi can have complex pairs (~1 % of poses): real eigvals first, complex arithmetic when that fails.
    Reference: vehicle.ghat_ginv_eig_record(..., compiled=False) (numpy)."""
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
