"""Attitude helpers with plain floats (hot path: numpy is overhead-bound on 3-vectors).

Quaternions are [w, x, y, z] and rotate body FRD vectors into NED: v_ned = R(q) v_frd.
Euler angles are the aerospace ZYX sequence (yaw psi, pitch theta, roll phi).
Frames change here and at the ENU/NED edge (`enu_to_ned`), nowhere else.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def quat_normalize(q: Sequence[float]) -> Quat:
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not n > 0.0 or not math.isfinite(n):
        raise ValueError(f"cannot normalise quaternion {tuple(q)}")
    return (w / n, x / n, y / n, z / n)


def quat_mul(a: Sequence[float], b: Sequence[float]) -> Quat:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_conj(q: Sequence[float]) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


def quat_to_dcm(q: Sequence[float]) -> tuple[Vec3, Vec3, Vec3]:
    """Rows of R (body -> NED)."""
    w, x, y, z = q
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


def rotate_body_to_ned(q: Sequence[float], v: Sequence[float]) -> Vec3:
    r = quat_to_dcm(q)
    return tuple(r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2] for i in range(3))  # type: ignore[return-value]


def rotate_ned_to_body(q: Sequence[float], v: Sequence[float]) -> Vec3:
    r = quat_to_dcm(q)
    return tuple(r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2] for i in range(3))  # type: ignore[return-value]


def euler_to_quat(roll: float, pitch: float, yaw: float) -> Quat:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def quat_to_euler(q: Sequence[float]) -> Vec3:
    """(roll, pitch, yaw) in rad, ZYX."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    s = max(-1.0, min(1.0, 2 * (w * y - z * x)))
    pitch = math.asin(s)
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return (roll, pitch, yaw)


def attitude_error_rotvec(q_meas: Sequence[float], q_cmd: Sequence[float]) -> Vec3:
    """Small-angle rotation vector (body frame, rad) that takes the measured attitude to the command.

    Uses the shortest rotation (sign of the error quaternion's w) so 359 deg of yaw error is -1 deg.
    """
    e = quat_mul(quat_conj(q_meas), q_cmd)
    w = e[0]
    s = 1.0 if w >= 0.0 else -1.0
    vn = math.sqrt(e[1] * e[1] + e[2] * e[2] + e[3] * e[3])
    if vn < 1e-12:
        return (0.0, 0.0, 0.0)
    angle = 2.0 * math.atan2(vn, abs(w))
    k = s * angle / vn
    return (k * e[1], k * e[2], k * e[3])


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
