"""Attitude helpers with plain floats (hot path: numpy is overhead-bound on 3-vectors).

The maths is written once, as the numba kernels below (`*_kernel`, on scalar components; the outer loop's kernels
call them); the functions named without the suffix give Python callers the same results on any sequence of floats.

Quaternions are [w, x, y, z] and rotate body FRD vectors into NED: v_ned = R(q) v_frd.
Euler angles are the aerospace ZYX sequence (yaw psi, pitch theta, roll phi).
Frames change here and at the ENU/NED edge (`enu_to_ned`), nowhere else.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from numba import njit

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


@njit(cache=True)
def quat_mul_kernel(aw, ax, ay, az, bw, bx, by, bz):
    """a (x) b (Hamilton product)."""
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


@njit(cache=True)
def quat_to_dcm_kernel(w, x, y, z):
    """R (body -> NED), row-major (9 values)."""
    return (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))


@njit(cache=True)
def euler_to_quat_kernel(roll, pitch, yaw):
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy)


@njit(cache=True)
def quat_to_euler_kernel(w, x, y, z):
    """(roll, pitch, yaw) in rad, ZYX."""
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    s = max(-1.0, min(1.0, 2 * (w * y - z * x)))
    return roll, math.asin(s), math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


@njit(cache=True)
def attitude_error_rotvec_kernel(mw, mx, my, mz, cw, cx, cy, cz):
    """Rotation vector (body frame, rad) from the measured attitude m to the command c: rotvec(conj(m) (x) c),
    the shortest rotation (sign of the error quaternion's w), so 359 deg of yaw error is -1 deg."""
    ew, ex, ey, ez = quat_mul_kernel(mw, -mx, -my, -mz, cw, cx, cy, cz)
    sgn = 1.0 if ew >= 0.0 else -1.0
    vn = math.sqrt(ex * ex + ey * ey + ez * ez)
    if vn < 1e-12:
        return 0.0, 0.0, 0.0
    k = sgn * (2.0 * math.atan2(vn, abs(ew))) / vn
    return k * ex, k * ey, k * ez


def quat_normalize(q: Sequence[float]) -> Quat:
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not n > 0.0 or not math.isfinite(n):
        raise ValueError(f"cannot normalise quaternion {tuple(q)}")
    return (w / n, x / n, y / n, z / n)


def quat_mul(a: Sequence[float], b: Sequence[float]) -> Quat:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return quat_mul_kernel(float(aw), float(ax), float(ay), float(az), float(bw), float(bx), float(by), float(bz))


def quat_conj(q: Sequence[float]) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


def quat_to_dcm(q: Sequence[float]) -> tuple[Vec3, Vec3, Vec3]:
    """Rows of R (body -> NED)."""
    w, x, y, z = q
    r = quat_to_dcm_kernel(float(w), float(x), float(y), float(z))
    return (r[0:3], r[3:6], r[6:9])


def rotate_body_to_ned(q: Sequence[float], v: Sequence[float]) -> Vec3:
    r = quat_to_dcm(q)
    return tuple(r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2] for i in range(3))  # type: ignore[return-value]


def rotate_ned_to_body(q: Sequence[float], v: Sequence[float]) -> Vec3:
    r = quat_to_dcm(q)
    return tuple(r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2] for i in range(3))  # type: ignore[return-value]


def euler_to_quat(roll: float, pitch: float, yaw: float) -> Quat:
    return euler_to_quat_kernel(float(roll), float(pitch), float(yaw))


def quat_to_euler(q: Sequence[float]) -> Vec3:
    """(roll, pitch, yaw) in rad, ZYX."""
    w, x, y, z = q
    return quat_to_euler_kernel(float(w), float(x), float(y), float(z))


def attitude_error_rotvec(q_meas: Sequence[float], q_cmd: Sequence[float]) -> Vec3:
    """Small-angle rotation vector (body frame, rad) that takes the measured attitude to the command.

    Uses the shortest rotation (sign of the error quaternion's w) so 359 deg of yaw error is -1 deg.
    """
    mw, mx, my, mz = q_meas
    cw, cx, cy, cz = q_cmd
    return attitude_error_rotvec_kernel(float(mw), float(mx), float(my), float(mz), float(cw), float(cx), float(cy),
                                    float(cz))


def attitude_error_angle(q_meas: Sequence[float], q_cmd: Sequence[float]) -> float:
    ex, ey, ez = attitude_error_rotvec(q_meas, q_cmd)
    return math.sqrt(ex * ex + ey * ey + ez * ez)


def enu_to_ned(v_enu: Sequence[float]) -> Vec3:
    """The paper's ENU commands at the edge: E -> y, N -> x, U -> -z (DESIGN §3)."""
    e, n, u = v_enu
    return (n, e, -u)


def ned_to_enu(v_ned: Sequence[float]) -> Vec3:
    n, e, d = v_ned
    return (e, n, -d)
