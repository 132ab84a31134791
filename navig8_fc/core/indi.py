"""INDI inner loop (paper Sec. 2.2 and 3, Eq. 5-6) with saturation handling.

Each control step:
- angular acceleration from differentiating the low-passed gyro; body specific force x, z low-passed
  with the same filter (tau = INDI_LPF_TAU): Acc_f = [Pdot, Qdot, Rdot, a_x, a_z] filtered;
- U0 from the measured duct angles and propeller speeds (INDI_U0_SRC = 0, the paper's U0 under Eq. 6), or (1) from the
  command flown last tick through the FC's actuator model (Eq. 10, ACT_WN, ACT_ZETA) corrected toward the
  measurement by a complementary filter (time constant INDI_U0_TAU), which keeps the 20 rad/s speed-sensor noise
  out of the increment (docs/model.md, "Hover sway"); either is passed through the same low-pass as the
  feedback so the increment is unbiased by the filter lag (notes §4, Paparazzi's synchronisation);
- Delta Acc = v - Acc_f; Delta U = G_C,UAM^-1 G_hat_I Delta Acc (Eq. 5); U = U0 + Delta U (Eq. 6);
- U -> (alpha1, alpha3, w1, w2, w3) (Sec. 3), respecting the actuator limits.

Saturation (INDI_ALLOC): when U would leave the feasible set,
- 0 (the paper-faithful baseline): the increment is scaled back axis group by axis group, lowest priority
  first: (1) forward force a_x, (2) yaw Rdot, (3) roll, pitch and vertical force, which are kept as long as
  possible (bisection on a scale factor per group; `group_scaling`);
- 1: prioritised weighted least squares over the real actuators (allocation.py), which gives up a_x first
  but keeps the duct tilts free, so the tilt lever still produces pitch moment.
The result is then clipped into the limits, and a non-finite U falls back to U0 (never NaN to the actuators).

The tick is one numba kernel (`indi_step`, or `indi_step_wls` with INDI_ALLOC = 1), at the end of this module with
the filters and saturation handling it calls; IndiController above it holds the flat float64 vectors (ST, IC, IO).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from navig8_fc.core import actuator_model, allocation, box_qp, g_c, linalg
from navig8_fc.core.actuator_model import (
    AID,
    actuator_identify,
    actuator_model_step,
    group_discretisation,
    id_grid,
    id_state,
)
from navig8_fc.core.allocation import ALLOC_WLS, AllocationConfig, allocate_actuators, within_tilt_step
from navig8_fc.core.arm_preview import ArmPreviewConfig
from navig8_fc.core.filters import lpf_alpha
from navig8_fc.core.g_c import actuators_to_u, u_to_actuators
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.layout import layout
from navig8_fc.core.records import frozen_record
from navig8_fc.core.vehicle import VehicleConfig

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


# The slices of indi_step's output the status reads (module constants: no enum lookups per tick)
_IO_ACC_F, _IO_U0, _IO_DACC, _IO_DU, _IO_U, _IO_SCALE, _IO_ACT = (
    m.sl for m in (IO.ACC_F, IO.U0, IO.DACC, IO.DU, IO.U, IO.SCALE, IO.ACT))
_IO_FALLBACK = int(IO.FALLBACK)
_ST_ACT_CMD, _ST_ACT_OK = ST.ACT_CMD.sl, int(ST.ACT_OK)
_IC_U0_GAIN, _IC_ACT_AD, _IC_ACT_BD = int(IC.U0_GAIN), IC.ACT_AD.sl, IC.ACT_BD.sl

U0_MEASURED, U0_MODEL = 0, 1  # INDI_U0_SRC
# Commands remembered for a link that reports which one the actuators flew (Indi.fly_applied): 160 ms at 100 Hz,
# over any link delay that still flies
CMD_HISTORY = 16

# Axis groups of Delta Acc = [Pdot, Qdot, Rdot, a_x, a_z], scaled back in this order on saturation.
SATURATION_ORDER: tuple[tuple[int, ...], ...] = ((3,), (2,), (0, 1, 4))


@dataclass(frozen=True)
class ActuatorLimits:
    tilt_min_rad: float
    tilt_max_rad: float
    duct_speed_max: float
    tail_speed_max: float

    @staticmethod
    def from_vehicle(cfg: VehicleConfig) -> ActuatorLimits:
        return ActuatorLimits(cfg.tilt_min_rad, cfg.tilt_max_rad, cfg.duct_speed_max, cfg.tail_speed_max)


@dataclass(frozen=True)
class IndiConfig:
    dt_s: float
    lpf_tau_s: float
    limits: ActuatorLimits
    alloc: AllocationConfig = AllocationConfig()  # INDI_ALLOC and its weights (default: the paper's scaling)
    # INDI_ARM_FF (FlightControllerCore applies it): 0 none (the paper), 1 the measured arm reaction not yet through
    # the filter, 2 the reaction predicted INDI_ARM_LEAD ahead from the arm's commanded trajectory (arm_preview.py)
    arm_ff: int = 0
    arm_preview: ArmPreviewConfig = ArmPreviewConfig()
    # INDI_U0_SRC (U0_MEASURED: the paper; U0_MODEL: the command through the actuator model, complemented by the
    # measurement with time constant INDI_U0_TAU) and the FC's actuator model (ACT_WN, ACT_ZETA; Eq. 10)
    u0_src: int = U0_MEASURED
    u0_tau_s: float = 0.2
    act_wn_rad_s: float = 120.0
    act_zeta: float = 1.0
    # INDI_U0_SRC = 1's checks (docs/model.md, "Feed-forward that cannot hurt"): identify the actuators' bandwidth
    # online (ACT_ID) and distrust the model, flying the measured U0, while its innovation RMS exceeds ACT_CHK_TILT
    # (rad) or ACT_CHK_SPD (rad/s)
    act_identify: bool = False
    act_check_tilt_rad: float = 0.25
    act_check_speed_rad_s: float = 60.0
    # The flown loop gain (FlightControllerCore applies it; k_xi.flown_k): the INDI's G_hat_I is built from
    # K_flown,i = max(lam_ref K_hat,i, k_flown_min) on the rotational axes (INDI_LAM_REF, INDI_KFL_MIN), K4 as
    # estimated; 1 and 0 fly K_hat itself (the paper)
    lam_ref: float = 1.0
    k_flown_min: float = 0.0


@dataclass(frozen=True)
class IndiInputs:
    gyro_frd_rad_s: Sequence[float]  # measured
    specific_force_frd_m_s2: Sequence[float]  # accelerometer (specific force at O)
    duct_tilt_rad: Sequence[float]  # measured alpha1, alpha3
    prop_speed_rad_s: Sequence[float]  # measured w1, w2 (signed), w3
    accel_cmd: Sequence[float]  # v = [Pdot, Qdot, Rdot, a_x, a_z] commanded
    gc: np.ndarray  # G_C,UAM (5x5)
    gi_hat: np.ndarray  # G_hat_I (5x5)
    gc_inv: np.ndarray | None = None  # G_C,UAM^-1 if the caller already has it (saves a solve per tick)


@frozen_record
@dataclass(frozen=True)
class IndiOutput:
    tilt_cmd_rad: tuple[float, float]
    speed_cmd_rad_s: tuple[float, float, float]  # w1, w2 (signed), w3
    u_cmd: tuple[float, ...]


@frozen_record
@dataclass(frozen=True)
class IndiStatus:
    acc_filtered: tuple[float, ...]  # [Pdot, Qdot, Rdot, a_x, a_z] after the LPF
    u0_filtered: tuple[float, ...]
    delta_acc: tuple[float, ...]
    delta_u: tuple[float, ...]  # increment actually applied (after saturation handling)
    # per group in SATURATION_ORDER, 1 = untouched: the group's scale (INDI_ALLOC = 0) or the fraction of the
    # group's Delta Acc the allocation delivers to first order (INDI_ALLOC = 1)
    saturation_scale: tuple[float, float, float]
    saturated: bool
    fallback_to_u0: bool
    # INDI_U0_SRC = 1: the actuator model's bandwidth in use (rad/s, tilts and speeds: ACT_WN, or identified), its
    # innovation RMS against the measurement (rad, rad/s) and whether it is trusted (False: the measured U0 is flown)
    act_wn_rad_s: tuple[float, float] = (0.0, 0.0)
    act_innov_rms: tuple[float, float] = (0.0, 0.0)
    u0_model_trusted: bool = True


class IndiController:
    """Incremental nonlinear dynamic inversion on [Pdot, Qdot, Rdot, a_x, a_z]; the tick is one numba kernel
    (`indi_step`, `indi_step_wls`), its filter state a flat float64 vector (ST layout)."""

    def __init__(self, cfg: IndiConfig) -> None:
        self.cfg = cfg
        lim = cfg.limits
        self._st = ST.zeros()
        if cfg.u0_src not in (U0_MEASURED, U0_MODEL):
            raise ValueError(f"INDI_U0_SRC must be {U0_MEASURED} or {U0_MODEL}, got {cfg.u0_src}")
        ad, bd = group_discretisation(cfg.act_wn_rad_s, cfg.act_wn_rad_s, cfg.act_zeta, cfg.dt_s)
        self._ic = IC.pack(alpha=lpf_alpha(cfg.lpf_tau_s, cfg.dt_s), inv_dt=1.0 / cfg.dt_s,
                           tilt_min=lim.tilt_min_rad, tilt_max=lim.tilt_max_rad, duct_speed_max=lim.duct_speed_max,
                           tail_speed_max=lim.tail_speed_max, u_duct_sq_max=(lim.duct_speed_max**2)**2,
                           u_tail_max=lim.tail_speed_max**2, u0_src=float(cfg.u0_src),
                           u0_gain=lpf_alpha(cfg.u0_tau_s, cfg.dt_s),
                           act_ad=ad, act_bd=bd)
        self._out = IO.zeros()
        self._al = cfg.alloc.vector(lim.tilt_min_rad, lim.tilt_max_rad, lim.duct_speed_max, lim.tail_speed_max)
        self._wls = cfg.alloc.mode == ALLOC_WLS
        self._u0_gain = float(self._ic[_IC_U0_GAIN])
        # the actuator-bandwidth identification (actuator_model.actuator_identify) and the model's trust
        self._id_on = cfg.u0_src == U0_MODEL and cfg.act_identify
        self._id_grid = id_grid(cfg.act_wn_rad_s, cfg.act_zeta, cfg.dt_s)
        self._id = id_state(self._id_grid, cfg.act_wn_rad_s)
        self._id_meas = np.zeros(5)
        self._wn = (cfg.act_wn_rad_s, cfg.act_wn_rad_s)
        self._innov = (0.0, 0.0)
        self._u0_trusted = True
        self._u0_ok_ticks = 0
        # the commands of the last ticks by their sample's time (us), for a link that reports which one was flown
        self._cmd_hist = np.zeros((CMD_HISTORY, 5))
        self._cmd_hist_t_us = [-1] * CMD_HISTORY
        self._cmd_hist_next = 0
        self._cmd_record_t_us = -1  # this tick's time when fly_applied announced it (-1: no link's report)

    def fly_applied(self, applied_t_s: float, t_s: float) -> None:
        """Before the tick at t_s: the actuator model (the model-based U0 and ACT_ID) advances on the command the link
        says the actuators flew up to this sample (the answer to the sample at applied_t_s), not on the last tick's.
        Over a real-time link the answer reaches the actuators one or more periods late, and a model fed the last
        command reads that delay as actuator lag. A command no longer remembered (or never sent): the last tick's.
        This tick's command is remembered under t_s."""
        self._cmd_record_t_us = round(t_s * 1e6)
        try:
            row = self._cmd_hist_t_us.index(round(applied_t_s * 1e6))
        except ValueError:
            return
        self._st[_ST_ACT_CMD] = self._cmd_hist[row]

    def _remember_command(self) -> None:
        """After a tick fly_applied announced: its command, under its sample's time."""
        i = self._cmd_hist_next
        self._cmd_hist[i] = self._st[_ST_ACT_CMD]
        self._cmd_hist_t_us[i] = self._cmd_record_t_us
        self._cmd_hist_next = (i + 1) % CMD_HISTORY
        self._cmd_record_t_us = -1

    def reset(self) -> None:
        self._st[:] = 0.0
        self._id[AID.OK] = 0.0  # the bank restarts at the measurement; its estimate is kept
        self._id[AID.J.sl] = 0.0  # the last flight's innovations (a crash, a landing) judge nothing of this one
        self._id[AID.TICKS] = 0.0
        self._u0_trusted, self._u0_ok_ticks = True, 0
        self._ic[_IC_U0_GAIN] = self._u0_gain

    def measure(self, inp: IndiInputs) -> tuple[list[float], list[float]]:
        """Filtered acceleration feedback and filtered U0 (also used while disarmed, to stay warm)."""
        sf, (a1, a3), (w1, w2, w3) = inp.specific_force_frd_m_s2, inp.duct_tilt_rad, inp.prop_speed_rad_s
        self._st[_ST_ACT_OK] = 0.0  # no command flown: the actuator estimate restarts at the measurement
        indi_measure(self._st, self._ic, np.asarray(inp.gyro_frd_rad_s, dtype=float), float(sf[0]), float(sf[2]),
                        float(a1), float(a3), float(w1), float(w2), float(w3), self._out)
        o = self._out.tolist()
        return o[_IO_ACC_F], o[_IO_U0]

    def step(self, inp: IndiInputs) -> tuple[IndiOutput, IndiStatus]:
        sf, (a1, a3), (w1, w2, w3) = inp.specific_force_frd_m_s2, inp.duct_tilt_rad, inp.prop_speed_rad_s
        gc_inv = inp.gc_inv if inp.gc_inv is not None else np.linalg.inv(inp.gc)
        return self._step(np.asarray(inp.gyro_frd_rad_s, dtype=float), float(sf[0]), float(sf[2]), float(a1), float(a3),
                          float(w1), float(w2), float(w3), np.asarray(inp.accel_cmd, dtype=float), gc_inv, inp.gi_hat)

    def _step(
        self, gyro: np.ndarray, sf_x: float, sf_z: float, a1: float, a3: float, w1: float, w2: float, w3: float,
        accel_cmd: np.ndarray, gc_inv: np.ndarray, gi_hat: np.ndarray,
    ) -> tuple[IndiOutput, IndiStatus]:
        """step() on its inputs already converted (float64 arrays, Python floats); the controller's tick."""
        out = self._out
        if self._id_on:
            self._check_actuator_model(a1, a3, w1, w2, w3)
        if self._wls:
            indi_step_wls(self._st, self._ic, self._al, gyro, sf_x, sf_z, a1, a3, w1, w2, w3, accel_cmd, gc_inv,
                          gi_hat, out)
        else:
            indi_step(self._st, self._ic, gyro, sf_x, sf_z, a1, a3, w1, w2, w3, accel_cmd, gc_inv, gi_hat, out)
        st = self._st
        st[_ST_ACT_CMD] = out[_IO_ACT]  # what the actuators fly until the next tick: the model's input
        st[_ST_ACT_OK] = 1.0
        if self._cmd_record_t_us >= 0:
            self._remember_command()
        o = tuple(out.tolist())
        s0, s1, s2 = scales = o[_IO_SCALE]
        act = o[_IO_ACT]
        res = IndiOutput(act[0:2], act[2:5], o[_IO_U])
        status = IndiStatus(
            acc_filtered=o[_IO_ACC_F],
            u0_filtered=o[_IO_U0],
            delta_acc=o[_IO_DACC],
            delta_u=o[_IO_DU],
            saturation_scale=scales,
            saturated=s0 < 1.0 or s1 < 1.0 or s2 < 1.0,
            fallback_to_u0=o[_IO_FALLBACK] != 0.0,
            act_wn_rad_s=self._wn,
            act_innov_rms=self._innov,
            u0_model_trusted=self._u0_trusted,
        )
        return res, status

    def _check_actuator_model(self, a1: float, a3: float, w1: float, w2: float, w3: float) -> None:
        """INDI_U0_SRC = 1 with ACT_ID: the bank's tick on the command flown last tick (before the INDI's own estimate
        advances), a moved estimate re-discretised into the U0 model, and the model's trust: distrusted (the
        complementary gain 1: the measured U0) while a group's innovation RMS exceeds its ACT_CHK_*, trusted again
        after one J time constant below 70 % of it."""
        st = self._st
        if st[_ST_ACT_OK] == 0.0:
            self._id[AID.OK] = 0.0
            return
        m = self._id_meas
        m[0], m[1], m[2], m[3], m[4] = a1, a3, w1, w2, w3
        ic = self._ic
        if actuator_identify(self._id, self._id_grid, st[_ST_ACT_CMD], m, self._u0_gain, self.cfg.dt_s):
            g = self._id_grid
            it, isp = int(self._id[AID.IDX]), int(self._id[AID.IDX + 1])
            ic[_IC_ACT_AD] = np.concatenate([g[it, 0:4], g[isp, 0:4]])
            ic[_IC_ACT_BD] = np.concatenate([g[it, 4:6], g[isp, 4:6]])
            self._wn = (float(g[it, 6]), float(g[isp, 6]))
        j = self._id[AID.J.sl].tolist()
        rms_t, rms_s = math.sqrt(max(j[1], 0.0) / 2.0), math.sqrt(max(j[4], 0.0) / 3.0)
        self._innov = (rms_t, rms_s)
        cfg = self.cfg
        bad = rms_t > cfg.act_check_tilt_rad or rms_s > cfg.act_check_speed_rad_s
        if bad:
            self._u0_ok_ticks = 0
            if self._u0_trusted:
                self._u0_trusted = False
                ic[_IC_U0_GAIN] = 1.0
        elif not self._u0_trusted:
            if rms_t < 0.7 * cfg.act_check_tilt_rad and rms_s < 0.7 * cfg.act_check_speed_rad_s:
                self._u0_ok_ticks += 1
                if self._u0_ok_ticks * cfg.dt_s >= 2.0:
                    self._u0_trusted = True
                    ic[_IC_U0_GAIN] = self._u0_gain
            else:
                self._u0_ok_ticks = 0


# --- The tick's kernels ---------------------------------------------------------------------------------------


@njit_cached(actuator_model)
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


@njit_cached(actuator_model, g_c)
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


@njit_cached(actuator_model, g_c)
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


@njit_cached(g_c)
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


@njit_cached(actuator_model, g_c)
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


@njit_cached()  # one compilation whatever constant indices a kernel passes (jit.py)
def _group_fraction(d, pred, i0, i1, i2):
    """How much of the group's Delta Acc the allocation delivers: <pred, d> / |d|^2 over the indices (i < 0:
    unused), clipped to [0, 1]; 1 when the group asks for nothing."""
    num = 0.0
    den = 0.0
    for i in (i0, i1, i2):
        if i >= 0:
            num += pred[i] * d[i]
            den += d[i] * d[i]
    if den == 0.0:
        return 1.0
    return min(max(num / den, 0.0), 1.0)


@njit_cached(actuator_model, g_c, allocation, box_qp, linalg)
def indi_step_wls(st, ic, al, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, accel_cmd, gc_inv, gi_hat, out):
    """IndiController.step with INDI_ALLOC = 1: the exact increment (Eq. 5-6) when feasible (and its tilts
    within INDI_ALLOC_DTILT of U0's), else
    allocate_actuators; the group scaling only if M is singular. out's SCALE slots hold, per group of
    SATURATION_ORDER, the fraction of the group's Delta Acc delivered (1 = untouched)."""
    m = np.empty((5, 5))
    d = np.empty(5)
    u0 = np.empty(5)
    du = np.empty(5)
    u = np.empty(5)
    indi_increment(st, ic, gyro, sf_x, sf_z, tilt1, tilt3, w1, w2, w3, accel_cmd, gc_inv, gi_hat, out, m, d, u0, du,
                   u)
    if not (_feasible_v(ic, u) and within_tilt_step(al, u0, u)):
        pred = np.empty(5)
        if allocate_actuators(al, m, d, u0, u, pred) >= 0:
            for i in range(5):
                du[i] = u[i] - u0[i]
            out[IO.SCALE] = _group_fraction(d, pred, 3, -1, -1)
            out[IO.SCALE + 1] = _group_fraction(d, pred, 2, -1, -1)
            out[IO.SCALE + 2] = _group_fraction(d, pred, 0, 1, 4)
        else:
            group_scaling(ic, m, d, u0, du, u, out)
    indi_finish(ic, u0, du, u, out)
