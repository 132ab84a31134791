"""Outer loops of the cascade of [29] (paper Sec. 4) (notes §6.5): position/velocity -> specific-force command,
attitude -> body rate -> angular-acceleration command. Pure; one numba kernel (`outer_loop`).

- Position: a_cmd = K_v (sat(K_p (p_cmd - p), v_max) - v) (NED), |a_cmd| <= a_max;
  the specific force to produce is f_cmd = a_cmd - g (NED).
- Attitude: pitch and yaw follow their commands (the paper hovers at 45 deg pitch); roll is chosen to
  null the body-y component of f_cmd, which the vehicle cannot produce (the ducts only act in x-z):
  with f' = R_y(theta)^T R_z(psi)^T f_cmd, phi_cmd = atan2(f'_y, -f'_z).
- Body-frame x, z specific-force commands come from f_cmd rotated with the measured attitude, so the
  INDI loop asks for the force the body can make now.
- Rate: omega_cmd = K_att * rotvec(q_meas^-1 q_cmd), limited; Pdot/Qdot/Rdot_cmd = K_rate (omega_cmd - omega).

Command shaping (OL_JERK_MAX, OL_ATT_ACC_REF > 0; off by default, the paper's loop): `shape_reference` turns the
raw setpoint into a smooth reference (position with a jerk limit, pitch/yaw with rate and acceleration limits)
and its feed-forwards (velocity, acceleration, body rate, angular acceleration), which `outer_loop`
adds, as PX4's trajectory generator and position controller do (docs/model.md "Command shaping"). A position
step then tilts the commanded attitude at most at ~OL_JERK_MAX/g rad/s instead of in one tick.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from navig8_fc.core import arm_preview, rotation
from navig8_fc.core.arm_preview import servo_model_accel
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.layout import layout
from navig8_fc.core.records import frozen_record
from navig8_fc.core.rotation import (
    attitude_error_rotvec_kernel,
    euler_to_quat_kernel,
    quat_mul_kernel,
    quat_to_dcm_kernel,
    quat_to_euler_kernel,
)

# Outer loops: config, setpoint, feed-forward and output vectors (outer_loop)
OC = layout("OC", pos_k=1, vel_k=1, vel_max=1, acc_max=1, att_k=1, rate_k=1, rate_max=1, gravity=1)
OSP = layout("OSP", pos=3, pitch=1, yaw=1)  # p_cmd N, E, D (m); pitch, yaw (rad)
# Feed-forward of a shaped reference (shape_reference; all zero: the paper's stateless loop):
# velocity and acceleration (NED), body rate and angular acceleration of the reference attitude (its own FRD axes)
OFF = layout("OFF", vel=3, acc=3, rate=3, ang_acc=3)
OO = layout("OO", accel_cmd_ned=3, specific_force_cmd_ned=3, att_cmd_quat=4, roll_cmd=1, rate_cmd=3,
            accel_cmd=5)  # accel_cmd = [Pdot, Qdot, Rdot, a_x, a_z] for INDI

# The slices of the kernel's output the status reads (module constants: no enum lookups per tick)
_OO_ACCEL_NED, _OO_FORCE_NED, _OO_QUAT, _OO_RATE, _OO_ACCEL = (
    m.sl for m in (OO.ACCEL_CMD_NED, OO.SPECIFIC_FORCE_CMD_NED, OO.ATT_CMD_QUAT, OO.RATE_CMD,
                   OO.ACCEL_CMD))
_OO_ROLL, _OO_SIZE = int(OO.ROLL_CMD), int(OO.SIZE)


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
    # command shaping (shape_reference); 0 = off: the setpoint goes to the loop as it is (the paper)
    jerk_max_m_s3: float = 0.0  # OL_JERK_MAX: the position reference's jerk limit
    ref_acc_max_m_s2: float = 2.0  # OL_ACC_REF: the position reference's acceleration limit
    err_max_m: float = 0.0  # OL_ERR_MAX: the reference waits for a vehicle this far behind (0 = never)
    att_rate_ref_rad_s: float = 1.0  # OL_ATT_RATE_REF: pitch/yaw reference's rate limit
    att_acc_ref_rad_s2: float = 0.0  # OL_ATT_ACC_REF: pitch/yaw reference's acceleration limit
    ff_level: int = 1  # OL_FF: angular feed-forward of the reference: 0 none, 1 body rate, 2 + angular accel.

    @property
    def shaping(self) -> bool:
        return self.jerk_max_m_s3 > 0.0 or self.att_acc_ref_rad_s2 > 0.0

    @staticmethod
    def from_params(values: Mapping[str, float], gravity_m_s2: float) -> OuterLoopConfig:
        kw = {name: float(values[param]) for name, param in _PARAM_OF.items()}
        return OuterLoopConfig(**kw, gravity_m_s2=gravity_m_s2, ff_level=int(values["OL_FF"]))  # type: ignore[arg-type]


# OuterLoopConfig's fields and the parameters they come from (OL_FF, an integer, apart)
_PARAM_OF = {"pos_k": "OL_POS_K", "vel_k": "OL_VEL_K", "vel_max_m_s": "OL_VEL_MAX", "acc_max_m_s2": "OL_ACC_MAX",
             "att_k": "OL_ATT_K", "rate_k": "OL_RATE_K", "rate_max_rad_s": "OL_RATE_MAX",
             "jerk_max_m_s3": "OL_JERK_MAX", "ref_acc_max_m_s2": "OL_ACC_REF", "err_max_m": "OL_ERR_MAX",
             "att_rate_ref_rad_s": "OL_ATT_RATE_REF", "att_acc_ref_rad_s2": "OL_ATT_ACC_REF"}


@dataclass(frozen=True)
class Setpoint:
    """Position (NED, m), pitch and yaw (rad). Roll is the outer loop's choice."""

    pos_ned_m: tuple[float, float, float]
    pitch_rad: float = 0.0
    yaw_rad: float = 0.0


@frozen_record
@dataclass(frozen=True)
class OuterLoopStatus:
    accel_cmd_ned_m_s2: tuple[float, float, float]
    specific_force_cmd_ned_m_s2: tuple[float, float, float]
    att_cmd_quat: tuple[float, float, float, float]
    roll_cmd_rad: float
    rate_cmd_frd_rad_s: tuple[float, float, float]
    accel_cmd: tuple[float, float, float, float, float]  # [Pdot, Qdot, Rdot, a_x, a_z] for INDI


def outer_loop_config_array(cfg: OuterLoopConfig) -> np.ndarray:
    """The config as the float64 vector `outer_loop` takes (OC layout)."""
    return OC.pack(pos_k=cfg.pos_k, vel_k=cfg.vel_k, vel_max=cfg.vel_max_m_s, acc_max=cfg.acc_max_m_s2,
                   att_k=cfg.att_k, rate_k=cfg.rate_k, rate_max=cfg.rate_max_rad_s, gravity=cfg.gravity_m_s2)


def outer_loop_step(
    cfg: OuterLoopConfig | np.ndarray,
    sp: Setpoint,
    pos_ned_m: Sequence[float],
    vel_ned_m_s: Sequence[float],
    quat_wxyz: Sequence[float],
    gyro_frd_rad_s: Sequence[float],
    ff: np.ndarray | None = None,
) -> OuterLoopStatus:
    """One step of the outer loops (the `outer_loop` kernel); stateless. cfg: the config or its OC vector; ff: the
    reference's feed-forwards (OFF layout; None: none, the paper's loop)."""
    cfg_array = outer_loop_config_array(cfg) if isinstance(cfg, OuterLoopConfig) else cfg
    return _outer_loop_arrays(cfg_array, OSP.pack(pos=sp.pos_ned_m, pitch=sp.pitch_rad, yaw=sp.yaw_rad),
                              np.asarray(pos_ned_m, dtype=float), np.asarray(vel_ned_m_s, dtype=float),
                              np.asarray(quat_wxyz, dtype=float), np.asarray(gyro_frd_rad_s, dtype=float),
                              OFF.zeros() if ff is None else ff)[0]


def _outer_loop_arrays(
    cfg_array: np.ndarray, sp: np.ndarray, pos: np.ndarray, vel: np.ndarray, quat: np.ndarray, gyro: np.ndarray,
    ff: np.ndarray,
) -> tuple[OuterLoopStatus, np.ndarray]:
    """outer_loop_step on float64 vectors (cfg: OC, sp: OSP, ff: OFF); also returns the kernel's output vector (OO),
    whose ACCEL_CMD slice is the INDI command as an array."""
    out = np.empty(_OO_SIZE)
    outer_loop(cfg_array, sp, ff, pos, vel, quat, gyro, out)
    o = tuple(out.tolist())
    return OuterLoopStatus(
        accel_cmd_ned_m_s2=o[_OO_ACCEL_NED],
        specific_force_cmd_ned_m_s2=o[_OO_FORCE_NED],
        att_cmd_quat=o[_OO_QUAT],
        roll_cmd_rad=o[_OO_ROLL],
        rate_cmd_frd_rad_s=o[_OO_RATE],
        accel_cmd=o[_OO_ACCEL],
    ), out


# --- The loop's kernel -----------------------------------------------------------------------------------------


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


@njit_cached(rotation)
def _rotate_quat(w, x, y, z, v0, v1, v2):
    """R(q) v for the unit quaternion q (the frame q rotates into: R(q) maps q's axes into the reference's)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = quat_to_dcm_kernel(w, x, y, z)
    return (r00 * v0 + r01 * v1 + r02 * v2, r10 * v0 + r11 * v1 + r12 * v2, r20 * v0 + r21 * v1 + r22 * v2)


@njit_cached(rotation)
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
    qw, qx, qy, qz = euler_to_quat_kernel(roll, pitch, yaw)
    # f in body axes with the measured attitude: R^T f
    r00, _, r02, r10, _, r12, r20, _, r22 = quat_to_dcm_kernel(quat[0], quat[1], quat[2], quat[3])
    fb0 = r00 * f0 + r10 * f1 + r20 * f2
    fb2 = r02 * f0 + r12 * f1 + r22 * f2
    err = np.empty(3)
    err[0], err[1], err[2] = attitude_error_rotvec_kernel(quat[0], quat[1], quat[2], quat[3], qw, qx, qy, qz)
    for i in range(3):
        err[i] = cfg[OC.ATT_K] * err[i]
    _clip_norm3(err, cfg[OC.RATE_MAX])
    dw = np.zeros(3)  # angular-acceleration feed-forward in the measured body axes
    if (ff[OFF.RATE] != 0.0 or ff[OFF.RATE + 1] != 0.0 or ff[OFF.RATE + 2] != 0.0 or ff[OFF.ANG_ACC] != 0.0
            or ff[OFF.ANG_ACC + 1] != 0.0 or ff[OFF.ANG_ACC + 2] != 0.0):
        # the command's axes -> the measured body's: conj(q_meas) (x) q_cmd
        ew, ex, ey, ez = quat_mul_kernel(quat[0], -quat[1], -quat[2], -quat[3], qw, qx, qy, qz)
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


# --- Command shaping -------------------------------------------------------------------------------------------
# Configuration and state of shape_reference (layouts live beside the kernel that uses them: numba's cache).
SHC = layout("SHC", pos_k=1, vel_k=1, vel_max=1, acc_max=1, jerk_max=1, jerk_k=1, err_max=1, att_rate=1, att_acc=1,
             ff=1, dt=1, gravity=1)
SH = layout("SH", pos=3, vel=3, acc=3, jerk=3,  # the position reference (NED) and its derivatives
            pitch=1, pitch_rate=1, yaw=1, yaw_rate=1,  # the pitch/yaw reference
            prev=5,  # acc (3), pitch, yaw of the previous tick's reference attitude (the rate feed-forward)
            rate_prev=3,  # the previous tick's body-rate feed-forward (the angular-acceleration one)
            init=1)  # 0: seed from the measured state at the next call; 2: resync position, velocity; 1: running
JERK_K_PER_VEL_K = 3.0  # the jerk stage's gain per OL_VEL_K: a triple pole at OL_VEL_K when OL_POS_K = OL_VEL_K / 3


def shaper_config_array(cfg: OuterLoopConfig, dt_s: float) -> np.ndarray:
    """The shaper's configuration vector (SHC layout) from the outer loop's configuration and the tick."""
    return SHC.pack(pos_k=cfg.pos_k, vel_k=cfg.vel_k, vel_max=cfg.vel_max_m_s, acc_max=cfg.ref_acc_max_m_s2,
                    jerk_max=cfg.jerk_max_m_s3, jerk_k=JERK_K_PER_VEL_K * cfg.vel_k, err_max=cfg.err_max_m,
                    att_rate=cfg.att_rate_ref_rad_s, att_acc=cfg.att_acc_ref_rad_s2, ff=float(cfg.ff_level),
                    dt=dt_s, gravity=cfg.gravity_m_s2)


@njit(cache=True)
def _wrap_pi(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit_cached(rotation)
def _ref_quat(st, at, pitch, yaw, g):
    """The reference attitude: the roll that flies the acceleration st[at:at + 3] (roll_for_force) at pitch, yaw."""
    roll = roll_for_force(st[at], st[at + 1], st[at + 2] - g, pitch, yaw)
    return euler_to_quat_kernel(roll, pitch, yaw)


@njit_cached(rotation, arm_preview)
def shape_reference(shc, st, sp, pos, vel, quat, sp_out, ff_out):
    """One tick of the command shaper (docs/model.md "Command shaping"); shc: SHC, st: SH (state), sp: the raw
    setpoint (OSP); writes the shaped setpoint into sp_out (OSP) and its feed-forwards into ff_out (OFF).

    Position (jerk_max > 0): a virtual vehicle flown by the outer loop's own cascade with a jerk stage,
    v_d = sat(K_p (p_sp - p_r), v_max), a_d = sat(K_v (v_d - v_r), a_ref), j_d = sat(K_j (a_d - a_r), j_max),
    the jerk rate-limited to K_j j_max (so the attitude feed-forward has no impulses), integrated exactly over the
    tick; as j_max and K_j grow it becomes the paper's loop on an ideal vehicle. Its time runs slower while the
    vehicle is behind it (by 1 - |p_r - p| / err_max, PX4's MPC_XY_ERR_MAX time stretch). Pitch and yaw
    (att_acc > 0): the time-optimal rate- and acceleration-limited tracker of arm_preview.servo_model_accel (yaw
    the short way round). Feed-forwards: v_r, a_r; the body rate of the reference attitude (a_r's roll at the
    reference pitch, yaw) from its change over the tick and (ff = 2) the angular acceleration from the rate's
    change. Seeded from the measured position, velocity and attitude when st[INIT] == 0."""
    dt, g = shc[SHC.DT], shc[SHC.GRAVITY]
    shape_pos = shc[SHC.JERK_MAX] > 0.0
    shape_att = shc[SHC.ATT_ACC] > 0.0
    if st[SH.INIT] == 0.0:
        _r, pitch_m, yaw_m = quat_to_euler_kernel(quat[0], quat[1], quat[2], quat[3])
        for i in range(3):
            st[SH.POS + i] = pos[i]
            st[SH.VEL + i] = vel[i]
            st[SH.ACC + i] = 0.0
            st[SH.JERK + i] = 0.0
            st[SH.RATE_PREV + i] = 0.0
        st[SH.PITCH] = pitch_m
        st[SH.YAW] = yaw_m
        st[SH.PITCH_RATE] = 0.0
        st[SH.YAW_RATE] = 0.0
        st[SH.INIT] = 1.0
        first = True
    else:
        first = False
        if st[SH.INIT] == 2.0:  # resync (a mode change): position and velocity from the measurement, the rest kept
            for i in range(3):
                st[SH.POS + i] = pos[i]
                st[SH.VEL + i] = vel[i]
            st[SH.INIT] = 1.0
    for i in range(3):
        st[SH.PREV + i] = st[SH.ACC + i]
    st[SH.PREV + 3] = st[SH.PITCH]
    st[SH.PREV + 4] = st[SH.YAW]
    h = dt
    if shape_pos:
        emax = shc[SHC.ERR_MAX]
        if emax > 0.0:
            d0, d1, d2 = st[SH.POS] - pos[0], st[SH.POS + 1] - pos[1], st[SH.POS + 2] - pos[2]
            if d0 * st[SH.VEL] + d1 * st[SH.VEL + 1] + d2 * st[SH.VEL + 2] > 0.0:  # behind and pulling away
                h = dt * (1.0 - min(math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / emax, 1.0))
    if shape_pos and h > 0.0:
        vd = np.empty(3)
        for i in range(3):
            vd[i] = shc[SHC.POS_K] * (sp[OSP.POS + i] - st[SH.POS + i])
        _clip_norm3(vd, shc[SHC.VEL_MAX])
        ad = np.empty(3)
        for i in range(3):
            ad[i] = shc[SHC.VEL_K] * (vd[i] - st[SH.VEL + i])
        _clip_norm3(ad, shc[SHC.ACC_MAX])
        jd = np.empty(3)
        for i in range(3):
            jd[i] = shc[SHC.JERK_K] * (ad[i] - st[SH.ACC + i])
        _clip_norm3(jd, shc[SHC.JERK_MAX])
        for i in range(3):
            jd[i] -= st[SH.JERK + i]
        _clip_norm3(jd, shc[SHC.JERK_K] * shc[SHC.JERK_MAX] * h)  # snap limit
        for i in range(3):
            j = st[SH.JERK + i] + jd[i]
            a = st[SH.ACC + i]
            v = st[SH.VEL + i]
            st[SH.POS + i] += h * (v + h * (0.5 * a + h * j / 6.0))
            st[SH.VEL + i] = v + h * (a + 0.5 * h * j)
            st[SH.ACC + i] = a + h * j
            st[SH.JERK + i] = j
    elif not shape_pos:
        for i in range(3):
            st[SH.POS + i] = sp[OSP.POS + i]
            st[SH.VEL + i] = 0.0
            st[SH.ACC + i] = 0.0
            st[SH.JERK + i] = 0.0
    if shape_att:
        amax, vmax = shc[SHC.ATT_ACC], shc[SHC.ATT_RATE]
        for k in range(2):  # pitch, then yaw (the short way round)
            at = SH.PITCH if k == 0 else SH.YAW
            e = sp[OSP.PITCH + k] - st[at]
            if k == 1:
                e = _wrap_pi(e)
            w = st[at + 1]
            acc = servo_model_accel(e, w, dt, amax, vmax)
            st[at] += dt * (w + 0.5 * acc * dt)
            st[at + 1] = w + acc * dt
        st[SH.YAW] = _wrap_pi(st[SH.YAW])
    else:
        st[SH.PITCH] = sp[OSP.PITCH]
        st[SH.YAW] = sp[OSP.YAW]
        st[SH.PITCH_RATE] = 0.0
        st[SH.YAW_RATE] = 0.0
        st[SH.PREV + 3] = st[SH.PITCH]  # a step that is not shaped gives no rate feed-forward
        st[SH.PREV + 4] = st[SH.YAW]
    for i in range(3):
        sp_out[OSP.POS + i] = st[SH.POS + i]
        ff_out[OFF.VEL + i] = st[SH.VEL + i]
        ff_out[OFF.ACC + i] = st[SH.ACC + i]
    sp_out[OSP.PITCH] = st[SH.PITCH]
    sp_out[OSP.YAW] = st[SH.YAW]
    level = shc[SHC.FF]
    w0 = w1 = w2 = 0.0
    if level >= 1.0 and not first:
        pw, px, py, pz = _ref_quat(st, SH.PREV, st[SH.PREV + 3], st[SH.PREV + 4], g)
        cw, cx, cy, cz = _ref_quat(st, SH.ACC, st[SH.PITCH], st[SH.YAW], g)
        w0, w1, w2 = attitude_error_rotvec_kernel(pw, px, py, pz, cw, cx, cy, cz)
        w0, w1, w2 = w0 / dt, w1 / dt, w2 / dt
    ff_out[OFF.RATE] = w0
    ff_out[OFF.RATE + 1] = w1
    ff_out[OFF.RATE + 2] = w2
    for i in range(3):
        ff_out[OFF.ANG_ACC + i] = 0.0
    if level >= 2.0 and not first:
        ff_out[OFF.ANG_ACC] = (w0 - st[SH.RATE_PREV]) / dt
        ff_out[OFF.ANG_ACC + 1] = (w1 - st[SH.RATE_PREV + 1]) / dt
        ff_out[OFF.ANG_ACC + 2] = (w2 - st[SH.RATE_PREV + 2]) / dt
    st[SH.RATE_PREV] = w0
    st[SH.RATE_PREV + 1] = w1
    st[SH.RATE_PREV + 2] = w2
