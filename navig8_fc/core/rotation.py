"""Attitude helpers with plain floats (hot path: numpy is overhead-bound on 3-vectors).

The maths is written once, as numba kernels in navig8_fc.core._kernels (the outer loop calls them there);
these functions give Python callers the same results on any sequence of floats.

Quaternions are [w, x, y, z] and rotate body FRD vectors into NED: v_ned = R(q) v_frd.
Euler angles are the aerospace ZYX sequence (yaw psi, pitch theta, roll phi).
Frames change here and at the ENU/NED edge (`enu_to_ned`), nowhere else.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from navig8_fc.core import _kernels as _k

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
    return _k.quat_mul(float(aw), float(ax), float(ay), float(az), float(bw), float(bx), float(by), float(bz))


def quat_conj(q: Sequence[float]) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


def quat_to_dcm(q: Sequence[float]) -> tuple[Vec3, Vec3, Vec3]:
    """Rows of R (body -> NED)."""
    w, x, y, z = q
    r = _k.quat_to_dcm(float(w), float(x), float(y), float(z))
    return (r[0:3], r[3:6], r[6:9])


def rotate_body_to_ned(q: Sequence[float], v: Sequence[float]) -> Vec3:
    r = quat_to_dcm(q)
    return tuple(r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2] for i in range(3))  # type: ignore[return-value]


def rotate_ned_to_body(q: Sequence[float], v: Sequence[float]) -> Vec3:
    r = quat_to_dcm(q)
    return tuple(r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2] for i in range(3))  # type: ignore[return-value]


def euler_to_quat(roll: float, pitch: float, yaw: float) -> Quat:
    return _k.euler_to_quat(float(roll), float(pitch), float(yaw))


def quat_to_euler(q: Sequence[float]) -> Vec3:
    """(roll, pitch, yaw) in rad, ZYX."""
    w, x, y, z = q
    return _k.quat_to_euler(float(w), float(x), float(y), float(z))


def attitude_error_rotvec(q_meas: Sequence[float], q_cmd: Sequence[float]) -> Vec3:
    """Small-angle rotation vector (body frame, rad) that takes the measured attitude to the command.

    Uses the shortest rotation (sign of the error quaternion's w) so 359 deg of yaw error is -1 deg.
    """
    mw, mx, my, mz = q_meas
    cw, cx, cy, cz = q_cmd
    return _k.attitude_error_rotvec(float(mw), float(mx), float(my), float(mz), float(cw), float(cx), float(cy),
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
