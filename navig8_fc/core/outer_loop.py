"""Outer loops of the cascade of [28] (notes §6.5): position/velocity -> specific-force command,
attitude -> body rate -> angular-acceleration command. Pure; one numba kernel (_kernels.outer_loop).

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

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from navig8_fc.core import _kernels as _k

# The slices of the kernel's output the status reads (module constants: no enum lookups per tick)
_OO_ACCEL_NED, _OO_FORCE_NED, _OO_QUAT, _OO_RATE, _OO_ACCEL = (
    m.sl for m in (_k.OO.ACCEL_CMD_NED, _k.OO.SPECIFIC_FORCE_CMD_NED, _k.OO.ATT_CMD_QUAT, _k.OO.RATE_CMD,
                   _k.OO.ACCEL_CMD))
_OO_ROLL, _OO_SIZE = int(_k.OO.ROLL_CMD), int(_k.OO.SIZE)


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
    """The config as the float64 vector `_kernels.outer_loop` takes (OC layout)."""
    return _k.OC.pack(pos_k=cfg.pos_k, vel_k=cfg.vel_k, vel_max=cfg.vel_max_m_s, acc_max=cfg.acc_max_m_s2,
                      att_k=cfg.att_k, rate_k=cfg.rate_k, rate_max=cfg.rate_max_rad_s, gravity=cfg.gravity_m_s2)


def outer_loop_step(
    cfg: OuterLoopConfig | np.ndarray,
    sp: Setpoint,
    pos_ned: Sequence[float],
    vel_ned: Sequence[float],
    quat_wxyz: Sequence[float],
    gyro_frd: Sequence[float],
) -> OuterLoopStatus:
    """One step of the outer loops (_kernels.outer_loop); stateless. cfg: the config or its OC vector."""
    cfg_array = outer_loop_config_array(cfg) if isinstance(cfg, OuterLoopConfig) else cfg
    return _outer_loop_arrays(cfg_array, _k.OSP.pack(pos=sp.pos_ned, pitch=sp.pitch_rad, yaw=sp.yaw_rad),
                              np.asarray(pos_ned, dtype=float), np.asarray(vel_ned, dtype=float),
                              np.asarray(quat_wxyz, dtype=float), np.asarray(gyro_frd, dtype=float))[0]


def _outer_loop_arrays(
    cfg_array: np.ndarray, sp: np.ndarray, pos: np.ndarray, vel: np.ndarray, quat: np.ndarray, gyro: np.ndarray
) -> tuple[OuterLoopStatus, np.ndarray]:
    """outer_loop_step on float64 vectors (cfg: OC, sp: OSP); also returns the kernel's output vector (OO), whose
    ACCEL_CMD slice is the INDI command as an array."""
    out = np.empty(_OO_SIZE)
    _k.outer_loop(cfg_array, sp, pos, vel, quat, gyro, out)
    o = tuple(out.tolist())
    return OuterLoopStatus(
        accel_cmd_ned=o[_OO_ACCEL_NED],
        specific_force_cmd_ned=o[_OO_FORCE_NED],
        att_cmd_quat=o[_OO_QUAT],
        roll_cmd_rad=o[_OO_ROLL],
        rate_cmd_frd=o[_OO_RATE],
        accel_cmd=o[_OO_ACCEL],
    ), out
