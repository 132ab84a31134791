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
  possible (bisection on a scale factor per group; `_kernels.group_scaling`);
- 1: prioritised weighted least squares over the real actuators (allocation.py), which gives up a_x first
  but keeps the duct tilts free, so the tilt lever still produces pitch moment.
The result is then clipped into the limits, and a non-finite U falls back to U0 (never NaN to the actuators).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from navig8_fc.core import _kernels as _k
from navig8_fc.core.actuator_model import AID, actuator_identify, group_discretisation, id_grid, id_state
from navig8_fc.core.allocation import ALLOC_WLS, AllocationConfig, indi_step_wls
from navig8_fc.core.arm_preview import ArmPreviewConfig
from navig8_fc.core.filters import lpf_alpha
from navig8_fc.core.vehicle import VehicleConfig

# The slices of indi_step's output the status reads (module constants: no enum lookups per tick)
_IO_ACC_F, _IO_U0, _IO_DACC, _IO_DU, _IO_U, _IO_SCALE, _IO_ACT = (
    m.sl for m in (_k.IO.ACC_F, _k.IO.U0, _k.IO.DACC, _k.IO.DU, _k.IO.U, _k.IO.SCALE, _k.IO.ACT))
_IO_FALLBACK = int(_k.IO.FALLBACK)
_ST_ACT_CMD, _ST_ACT_OK = _k.ST.ACT_CMD.sl, int(_k.ST.ACT_OK)
_IC_U0_GAIN, _IC_ACT_AD, _IC_ACT_BD = int(_k.IC.U0_GAIN), _k.IC.ACT_AD.sl, _k.IC.ACT_BD.sl

U0_MEASURED, U0_MODEL = 0, 1  # INDI_U0_SRC

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


@dataclass(frozen=True)
class IndiInputs:
    gyro_frd: Sequence[float]  # rad/s, measured
    specific_force_frd: Sequence[float]  # m/s^2, accelerometer (specific force at O)
    tilt_rad: Sequence[float]  # measured alpha1, alpha3
    speed_rad_s: Sequence[float]  # measured w1, w2 (signed), w3
    accel_cmd: Sequence[float]  # v = [Pdot, Qdot, Rdot, a_x, a_z] commanded
    gc: np.ndarray  # G_C,UAM (5x5)
    gi_hat: np.ndarray  # G_hat_I (5x5)
    gc_inv: np.ndarray | None = None  # G_C,UAM^-1 if the caller already has it (saves a solve per tick)


@dataclass(frozen=True)
class IndiOutput:
    tilt_cmd_rad: tuple[float, float]
    speed_cmd_rad_s: tuple[float, float, float]  # w1, w2 (signed), w3
    u_cmd: tuple[float, ...]


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
    (_kernels.indi_step), its filter state a flat float64 vector (_kernels.ST layout)."""

    def __init__(self, cfg: IndiConfig) -> None:
        self.cfg = cfg
        lim = cfg.limits
        self._st = _k.ST.zeros()
        if cfg.u0_src not in (U0_MEASURED, U0_MODEL):
            raise ValueError(f"INDI_U0_SRC must be {U0_MEASURED} or {U0_MODEL}, got {cfg.u0_src}")
        ad, bd = group_discretisation(cfg.act_wn_rad_s, cfg.act_wn_rad_s, cfg.act_zeta, cfg.dt_s)
        self._ic = _k.IC.pack(alpha=lpf_alpha(cfg.lpf_tau_s, cfg.dt_s), inv_dt=1.0 / cfg.dt_s,
                              tilt_min=lim.tilt_min_rad, tilt_max=lim.tilt_max_rad, duct_speed_max=lim.duct_speed_max,
                              tail_speed_max=lim.tail_speed_max, u_duct_sq_max=(lim.duct_speed_max**2)**2,
                              u_tail_max=lim.tail_speed_max**2, u0_src=float(cfg.u0_src),
                              u0_gain=lpf_alpha(cfg.u0_tau_s, cfg.dt_s),
                              act_ad=ad, act_bd=bd)
        self._out = _k.IO.zeros()
        self._al = cfg.alloc.vector()
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

    def reset(self) -> None:
        self._st[:] = 0.0
        self._id[AID.OK] = 0.0  # the bank restarts at the measurement; its estimate is kept
        self._id[AID.J.sl] = 0.0  # the last flight's innovations (a crash, a landing) judge nothing of this one
        self._id[AID.TICKS] = 0.0
        self._u0_trusted, self._u0_ok_ticks = True, 0
        self._ic[_IC_U0_GAIN] = self._u0_gain

    def measure(self, inp: IndiInputs) -> tuple[list[float], list[float]]:
        """Filtered acceleration feedback and filtered U0 (also used while disarmed, to stay warm)."""
        sf, (a1, a3), (w1, w2, w3) = inp.specific_force_frd, inp.tilt_rad, inp.speed_rad_s
        self._st[_ST_ACT_OK] = 0.0  # no command flown: the actuator estimate restarts at the measurement
        _k.indi_measure(self._st, self._ic, np.asarray(inp.gyro_frd, dtype=float), float(sf[0]), float(sf[2]),
                        float(a1), float(a3), float(w1), float(w2), float(w3), self._out)
        o = self._out.tolist()
        return o[_IO_ACC_F], o[_IO_U0]

    def step(self, inp: IndiInputs) -> tuple[IndiOutput, IndiStatus]:
        sf, (a1, a3), (w1, w2, w3) = inp.specific_force_frd, inp.tilt_rad, inp.speed_rad_s
        gc_inv = inp.gc_inv if inp.gc_inv is not None else np.linalg.inv(inp.gc)
        return self._step(np.asarray(inp.gyro_frd, dtype=float), float(sf[0]), float(sf[2]), float(a1), float(a3),
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
            _k.indi_step(self._st, self._ic, gyro, sf_x, sf_z, a1, a3, w1, w2, w3, accel_cmd, gc_inv, gi_hat, out)
        st = self._st
        st[_ST_ACT_CMD] = out[_IO_ACT]  # what the actuators fly until the next tick: the model's input
        st[_ST_ACT_OK] = 1.0
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
