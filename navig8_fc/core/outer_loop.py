"""Outer loops of the cascade of [28] (notes §6.5): position/velocity -> specific-force command,
attitude -> body rate -> angular-acceleration command. Pure, plain floats.

- Position: a_cmd = K_v (sat(K_p (p_cmd - p), v_max) - v) (NED), |a_cmd| <= a_max;
  the specific force to produce is f_cmd = a_cmd - g (NED).
- Attitude: pitch and yaw follow their commands (the paper hovers at 45 deg pitch); roll is chosen to
  null the body-y component of f_cmd, which the vehicle cannot produce (the ducts only act in x-z):
  with f' = R_y(theta)^T R_z(psi)^T f_cmd, phi_cmd = atan2(f'_y, -f'_z).
- Body-frame x, z specific-force commands come from f_cmd rotated with the measured attitude, so the
  INDI loop asks for the force the body can make now.
- Rate: omega_cmd = K_att * rotvec(q_meas^-1 q_cmd), limited; Pdot/Qdot/Rdot_cmd = K_rate (omega_cmd - omega).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from navig8_fc.core import _kernels as _k
from navig8_fc.core.rotation import attitude_error_rotvec, euler_to_quat, rotate_ned_to_body


@dataclass(frozen=True)
class OuterLoopConfig:
    pos_k: float
    vel_k: float
    vel_max_m_s: float
    acc_max_m_s2: float
    att_k: float
    rate_k: float
    rate_max_rad_s: float
    gravity_m_s2: float

    @staticmethod
    def from_params(values: Mapping[str, float], gravity_m_s2: float) -> OuterLoopConfig:
        return OuterLoopConfig(
            pos_k=float(values["OL_POS_K"]),
            vel_k=float(values["OL_VEL_K"]),
            vel_max_m_s=float(values["OL_VEL_MAX"]),
            acc_max_m_s2=float(values["OL_ACC_MAX"]),
            att_k=float(values["OL_ATT_K"]),
            rate_k=float(values["OL_RATE_K"]),
            rate_max_rad_s=float(values["OL_RATE_MAX"]),
            gravity_m_s2=gravity_m_s2,
        )


@dataclass(frozen=True)
class Setpoint:
    """Position (NED, m), pitch and yaw (rad). Roll is the outer loop's choice."""

    pos_ned: tuple[float, float, float]
    pitch_rad: float = 0.0
    yaw_rad: float = 0.0


@dataclass(frozen=True)
class OuterLoopStatus:
    accel_cmd_ned: tuple[float, float, float]
    specific_force_cmd_ned: tuple[float, float, float]
    att_cmd_quat: tuple[float, float, float, float]
    roll_cmd_rad: float
    rate_cmd_frd: tuple[float, float, float]
    accel_cmd: tuple[float, float, float, float, float]  # [Pdot, Qdot, Rdot, a_x, a_z] for INDI


def outer_loop_config_array(cfg: OuterLoopConfig) -> np.ndarray:
    """The config as the float64 vector `_kernels.outer_loop` takes."""
    return np.array([cfg.pos_k, cfg.vel_k, cfg.vel_max_m_s, cfg.acc_max_m_s2, cfg.att_k, cfg.rate_k,
                     cfg.rate_max_rad_s, cfg.gravity_m_s2])


def outer_loop_step_compiled(
    cfg_array: np.ndarray,
    sp: Setpoint,
    pos_ned: Sequence[float],
    vel_ned: Sequence[float],
    quat_wxyz: Sequence[float],
    gyro_frd: Sequence[float],
) -> OuterLoopStatus:
    """outer_loop_step in one numba kernel (same maths, same status; tests compare the two)."""
    return _outer_loop_arrays(cfg_array,
                              np.array((sp.pos_ned[0], sp.pos_ned[1], sp.pos_ned[2], sp.pitch_rad, sp.yaw_rad)),
                              np.asarray(pos_ned, dtype=float), np.asarray(vel_ned, dtype=float),
                              np.asarray(quat_wxyz, dtype=float), np.asarray(gyro_frd, dtype=float))[0]


def _outer_loop_arrays(
    cfg_array: np.ndarray, sp: np.ndarray, pos: np.ndarray, vel: np.ndarray, quat: np.ndarray, gyro: np.ndarray
) -> tuple[OuterLoopStatus, np.ndarray]:
    """outer_loop_step_compiled on float64 arrays (sp = [p_cmd N, E, D, pitch, yaw]); also returns the kernel's
    output vector (its [14:19] is accel_cmd as an array)."""
    out = np.empty(19)
    _k.outer_loop(cfg_array, sp, pos, vel, quat, gyro, out)
    o = tuple(out.tolist())
    return OuterLoopStatus(
        accel_cmd_ned=o[0:3],
        specific_force_cmd_ned=o[3:6],
        att_cmd_quat=o[6:10],
        roll_cmd_rad=o[10],
        rate_cmd_frd=o[11:14],
        accel_cmd=o[14:19],
    ), out


def _clip_norm(v: Sequence[float], limit: float) -> tuple[float, ...]:
    n = math.sqrt(sum(x * x for x in v))
    if n > limit > 0.0:
        k = limit / n
        return tuple(x * k for x in v)
    return tuple(v)


def outer_loop_step(
    cfg: OuterLoopConfig,
    sp: Setpoint,
    pos_ned: Sequence[float],
    vel_ned: Sequence[float],
    quat_wxyz: Sequence[float],
    gyro_frd: Sequence[float],
) -> OuterLoopStatus:
    """One step of the outer loops; stateless (pure P cascade, as [28]'s NDI loops)."""
    v_cmd = _clip_norm([cfg.pos_k * (sp.pos_ned[i] - pos_ned[i]) for i in range(3)], cfg.vel_max_m_s)
    a_cmd = _clip_norm([cfg.vel_k * (v_cmd[i] - vel_ned[i]) for i in range(3)], cfg.acc_max_m_s2)
    f_cmd = (a_cmd[0], a_cmd[1], a_cmd[2] - cfg.gravity_m_s2)  # specific force = a - g, g = +z NED
    # Roll that nulls the body-y force, given the commanded pitch and yaw.
    cy, sy = math.cos(sp.yaw_rad), math.sin(sp.yaw_rad)
    cp, spp = math.cos(sp.pitch_rad), math.sin(sp.pitch_rad)
    # R_z(psi)^T f, then R_y(theta)^T
    fx1 = cy * f_cmd[0] + sy * f_cmd[1]
    fy1 = -sy * f_cmd[0] + cy * f_cmd[1]
    fz1 = f_cmd[2]
    fy2 = fy1
    fz2 = spp * fx1 + cp * fz1
    roll_cmd = math.atan2(fy2, -fz2)
    q_cmd = euler_to_quat(roll_cmd, sp.pitch_rad, sp.yaw_rad)
    f_body = rotate_ned_to_body(quat_wxyz, f_cmd)
    err = attitude_error_rotvec(quat_wxyz, q_cmd)
    w_cmd = _clip_norm([cfg.att_k * e for e in err], cfg.rate_max_rad_s)
    wdot_cmd = [cfg.rate_k * (w_cmd[i] - gyro_frd[i]) for i in range(3)]
    return OuterLoopStatus(
        accel_cmd_ned=(a_cmd[0], a_cmd[1], a_cmd[2]),
        specific_force_cmd_ned=f_cmd,
        att_cmd_quat=q_cmd,
        roll_cmd_rad=roll_cmd,
        rate_cmd_frd=(w_cmd[0], w_cmd[1], w_cmd[2]),
        accel_cmd=(wdot_cmd[0], wdot_cmd[1], wdot_cmd[2], f_body[0], f_body[2]),
    )
