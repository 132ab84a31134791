"""The flight controller's core: outer loops -> INDI inner loop, with the adaptive law (paper Fig. 3).

One `step(sensors, setpoint, engaged) -> (command, status)` per control tick, on the sensor bundle's
time (lockstep: no clock of its own). Configuration is a frozen dataclass built from parameters;
everything observable leaves through `ControllerStatus`.

Signal flow per tick:
1. Joint-state observer: the joint angles are very noisy (sigma 0.08 rad, paper §4) while the rates
   are clean (0.01 rad/s), so q is estimated by a complementary filter (integrate q-dot, correct
   toward q with time constant JOINT_OBS_TAU_S); q-ddot is the difference of the measured rate.
2. UAM model without object at (q_est, q-dot): mass, CoM, inertia, I-dot (Eq. 22), G_C,UAM (Eq. 2).
3. Adaptive law (constrained KF): G_hat_I (Eq. 4), from U0 and Acc_m = [omega-dot, f_O + c-ddot_arm].
4. Outer loops: [Pdot, Qdot, Rdot, a_x, a_z] commands.
5. INDI: Delta U = G_C^-1 G_hat_I Delta Acc (Eq. 5), U = U0 + Delta U (Eq. 6) -> actuators; on saturation the
   group scaling (INDI_ALLOC = 0) or the prioritised WLS allocation (INDI_ALLOC = 1, allocation.py).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from navig8_fc.core import k_xi, rotation
from navig8_fc.core.actuator_model import DeliveredU
from navig8_fc.core.adaptive_law import AdaptiveLaw, AdaptiveLawConfig, AdaptiveLawStatus
from navig8_fc.core.allocation import AllocationConfig
from navig8_fc.core.arm_preview import (
    PS,
    ArmPreviewConfig,
    arm_preview_step,
    hold_plan,
    preview_ahead,
    preview_supervise,
    reference_advance,
)
from navig8_fc.core.ckf_config import CkfConfig
from navig8_fc.core.filters import lpf_alpha
from navig8_fc.core.front_end import FO, FST, TIN, com_accel_offset, fc_front
from navig8_fc.core.g_c import UO, actuators_to_u, gc_inv_about
from navig8_fc.core.indi import (
    ActuatorLimits,
    IndiConfig,
    IndiController,
    IndiInputs,
    IndiStatus,
)
from navig8_fc.core.outer_loop import (
    OFF,
    OO,
    OSP,
    SH,
    OuterLoopConfig,
    OuterLoopStatus,
    Setpoint,
    _outer_loop_arrays,
    outer_loop_config_array,
    shape_reference,
    shaper_config_array,
)
from navig8_fc.core.records import frozen_record
from navig8_fc.core.vehicle import N_LINKS, UamModel, VehicleConfig, ghat_ginv_eig_record

# Slots of the front-end kernel's outputs the tick reads (module constants: no enum lookups per tick).
_UO_MASS, _UO_SINGULAR = int(UO.MASS), int(UO.SINGULAR)
_UO_CEX, _UO_CEZ = int(UO.CEX), int(UO.CEZ)
_UO_OBJ_RATE, _UO_OBJ_IXZ, _UO_OBJ_IXZ_DM = int(UO.OBJ_RATE), int(UO.OBJ_IXZ), int(UO.OBJ_IXZ_DM)
_UO_CE_DM = int(UO.CE_DM)
_NO_SLOPE = (0.0, 0.0)  # the law's reference point does not follow the mass estimate (CKF_CZ_DM's slope)
# The tick's input vector (front_end.TIN): the sensors, then pos_ned, vel_ned, quat_wxyz and the setpoint
# (the outer loops' inputs, packed only when engaged). struct packs float64 exactly as np.array(..., dtype=float)
# converts, into a persistent array (no per-tick allocation).
_PACK_SENSORS = struct.Struct(f"={int(TIN.POS)}d").pack_into
_PACK_ENGAGED = struct.Struct(f"={int(TIN.SIZE)}d").pack_into
_IN_ACCEL, _IN_TILT, _IN_SPEED = int(TIN.ACCEL), int(TIN.TILT), int(TIN.SPEED)
_IN_JRATE = int(TIN.JRATE)
_FO_QEST, _FO_QDD, _OO_ACCEL = FO.QEST.sl, FO.QDD.sl, OO.ACCEL_CMD.sl
_FO_ARM_HDC = int(FO.ARM_HDC)
_SH_PITCH, _SH_YAW = int(SH.PITCH), int(SH.YAW)
_PS_TRUST, _PS_ERR, _PS_V_HAT, _PS_A_HAT = int(PS.TRUST), int(PS.ERR), int(PS.V_HAT), int(PS.A_HAT)
_PS_DROPS, _PS_IDENTS = int(PS.DROPS), int(PS.IDENTS)

assert N_LINKS == 3  # the tick's arm buffers and kernels are laid out for three joints

JOINT_OBS_TAU_S = 1.0  # complementary-filter time constant for the joint angles (docs/model.md)
# The shaped reference's feed-forward assumes the vehicle follows the reference. While the vehicle's attitude is more
# than SHAPING_FF_ATT_RAD off the reference's (the actuators cannot follow it), the feed-forward is halved each tick
# (the feedback alone flies: a demand the vehicle cannot meet only adds to the error); it comes back over
# SHAPING_FF_RISE_S once they agree again. (Halving it also on every saturated tick was measured: the same peaks and a
# 7 % worse attitude RMS on the paper scenario, so saturation alone does not withdraw it.)
SHAPING_FF_ATT_RAD = 0.35
SHAPING_FF_RISE_S = 0.3

PARAMS_USED = (
    "INDI_RATE_HZ", "INDI_LPF_TAU", "INDI_K_MIN", "INDI_K_MAX",
    "OL_POS_K", "OL_VEL_K", "OL_VEL_MAX", "OL_ACC_MAX", "OL_ATT_K", "OL_RATE_K", "OL_RATE_MAX",
    "OL_JERK_MAX", "OL_ACC_REF", "OL_ERR_MAX", "OL_ATT_RATE_REF", "OL_ATT_ACC_REF", "OL_FF",
    "CKF_MODE", "CKF_LPF_TAU", "CKF_START_DLY", "CKF_Q_IXX", "CKF_Q_IYY", "CKF_Q_IZZ", "CKF_Q_M",
    "CKF_R_U1", "CKF_R_U2", "CKF_R_U3", "CKF_R_U4", "CKF_R_U5", "CKF_P0_SCALE", "CKF_PROJ_W",
    "INDI_ACC_REF", "CKF_ARM_WRENCH",
    "INDI_ARM_FF", "INDI_ALLOC", "INDI_ALLOC_W_RP", "INDI_ALLOC_W_AZ", "INDI_ALLOC_W_YAW", "INDI_ALLOC_W_AX",
    "INDI_ALLOC_DTILT", "CKF_INC_N", "CKF_EXC_ROT", "CKF_EXC_LIN", "CKF_SAT_GATE", "CKF_U_SRC", "CKF_ACC_REF",
    "INDI_ARM_LEAD", "ARM_SERVO_HZ", "ARM_SERVO_VMAX", "ARM_SERVO_AMAX",
    "INDI_U0_SRC", "INDI_U0_TAU", "ACT_WN", "ACT_ZETA",
    "ARM_CHK_TOL", "ARM_TRUST_RISE", "ARM_SERVO_ID", "ACT_ID", "ACT_CHK_TILT", "ACT_CHK_SPD",
    "INDI_LAM_REF", "INDI_KFL_MIN",
)


@frozen_record
@dataclass(frozen=True)
class FcSensors:
    """One sensor bundle as the flight controller sees it (body FRD, NED, SI)."""

    t_s: float
    gyro_frd_rad_s: tuple[float, float, float]
    accel_frd_m_s2: tuple[float, float, float]  # specific force at O
    pos_ned_m: tuple[float, float, float]
    vel_ned_m_s: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    duct_tilt_rad: tuple[float, float]  # measured alpha1, alpha3
    prop_speed_rad_s: tuple[float, float, float]  # measured w1, w2 (signed), w3
    joint_pos_rad: tuple[float, float, float]
    joint_rate_rad_s: tuple[float, float, float]
    gripper_closed: bool = False  # the gripper's reported state (NAVIG8_ARM_STATE); CKF_GRIP_RST forgets on it
    # the time of the sample whose command drove the actuators up to this one (the link's echo,
    # NAVIG8_ACTUATOR_STATE.cmd_time_usec); None: the command of the last tick (lockstep, in process)
    cmd_applied_t_s: float | None = None


@frozen_record
@dataclass(frozen=True)
class ActuatorCommand:
    tilt_rad: tuple[float, float]
    speed_rad_s: tuple[float, float, float]


MOTORS_OFF = ActuatorCommand((0.0, 0.0), (0.0, 0.0, 0.0))


@dataclass(frozen=True)
class ControllerConfig:
    dt_s: float
    k_min: float
    k_max: float
    indi: IndiConfig
    outer: OuterLoopConfig
    ckf: CkfConfig
    acc_ref: int = 0  # INDI_ACC_REF: 0 specific force at O (the paper), 1 acceleration of the estimated CoM
    arm_wrench: bool = False  # CKF_ARM_WRENCH: the arm's reaction moment in the adaptive law's measurement

    @staticmethod
    def from_params(values: Mapping[str, float | int], vehicle: VehicleConfig) -> ControllerConfig:
        missing = [n for n in PARAMS_USED if n not in values]
        if missing:
            raise KeyError(f"controller parameters missing: {missing}")
        dt = 1.0 / float(values["INDI_RATE_HZ"])
        return ControllerConfig(
            dt_s=dt,
            k_min=float(values["INDI_K_MIN"]),
            k_max=float(values["INDI_K_MAX"]),
            indi=IndiConfig(dt, float(values["INDI_LPF_TAU"]), ActuatorLimits.from_vehicle(vehicle),
                            AllocationConfig(int(values["INDI_ALLOC"]), float(values["INDI_ALLOC_W_RP"]),
                                             float(values["INDI_ALLOC_W_AZ"]), float(values["INDI_ALLOC_W_YAW"]),
                                             float(values["INDI_ALLOC_W_AX"]), float(values["INDI_ALLOC_DTILT"])),
                            int(values["INDI_ARM_FF"]),
                            ArmPreviewConfig(float(values["INDI_ARM_LEAD"]), float(values["ARM_SERVO_HZ"]),
                                             float(values["ARM_SERVO_VMAX"]), float(values["ARM_SERVO_AMAX"]),
                                             check_tol_rad_s=float(values["ARM_CHK_TOL"]),
                                             trust_rise_s=float(values["ARM_TRUST_RISE"]),
                                             identify=bool(int(values["ARM_SERVO_ID"]))),
                            u0_src=int(values["INDI_U0_SRC"]), u0_tau_s=float(values["INDI_U0_TAU"]),
                            act_wn_rad_s=float(values["ACT_WN"]), act_zeta=float(values["ACT_ZETA"]),
                            act_identify=bool(int(values["ACT_ID"])),
                            act_check_tilt_rad=float(values["ACT_CHK_TILT"]),
                            act_check_speed_rad_s=float(values["ACT_CHK_SPD"]),
                            lam_ref=float(values["INDI_LAM_REF"]), k_flown_min=float(values["INDI_KFL_MIN"])),
            outer=OuterLoopConfig.from_params(values, vehicle.gravity_m_s2),  # type: ignore[arg-type]
            ckf=CkfConfig.from_params(values, dt),
            acc_ref=int(values["INDI_ACC_REF"]),
            arm_wrench=bool(int(values["CKF_ARM_WRENCH"])),
        )


@frozen_record
@dataclass(frozen=True)
class FeedForwardStatus:
    """The model-based feed-forwards' checks against what is measured (docs/model.md, "Feed-forward that cannot
    hurt"). Arm preview (INDI_ARM_FF = 2): the trust in the servo model (0: the measured reaction is flown, 1: the
    preview), its last consistency error, the servo limits identified online, and how many times trust was
    withdrawn and the limits re-identified (counters: a change is an event)."""

    arm_trust: float
    arm_err_rad_s: float
    arm_v_hat_rad_s: float
    arm_a_hat_rad_s2: float
    arm_drops: int
    arm_idents: int
    # command shaping (OL_JERK_MAX / OL_ATT_ACC_REF): the share of the reference's feed-forward flown (1: all; less
    # while the vehicle's attitude is far off the reference's: SHAPING_FF_*)
    shaping_ff_scale: float = 1.0


@frozen_record
@dataclass(frozen=True)
class ControllerStatus:
    t_s: float
    engaged: bool
    q_est_rad: tuple[float, float, float]
    qdd_est_rad_s2: tuple[float, float, float]
    mass_uam_kg: float
    inertia_uam_diag: tuple[float, float, float]
    gi_hat: tuple[float, ...]  # 5x5 row-major
    gc_uam: tuple[float, ...]  # G_C,UAM(q_est) this tick used (Eq. 4), 5x5 row-major
    outer: OuterLoopStatus | None
    indi: IndiStatus | None
    adapt: AdaptiveLawStatus
    # the point (FRD, m) whose acceleration the INDI force rows and Acc_m refer to when INDI_ACC_REF = 1 (the
    # estimated composite CoM); None: the paper's specific force at O
    ref_frd_m: tuple[float, float, float] | None = None
    ff: FeedForwardStatus | None = None  # the feed-forwards' supervision (None: no model-based feed-forward flown)


class FlightControllerCore:
    """Outer loops + INDI + adaptive law for the Navig8-UAM."""

    _tick_io: tuple | None = None  # the tick's persistent input vector and views (tick_buffers)
    _indi_saturated = False  # the last INDI step's IndiStatus.saturated (the adaptive law's saturation gate)
    _u_cmd_ok = False  # _u_cmd holds U of the last actuator command (the adaptive law's CKF_U_SRC = 1)

    def __init__(self, vehicle: VehicleConfig, config: ControllerConfig) -> None:
        self.vehicle, self.config, self._model = vehicle, config, UamModel(vehicle)
        self._indi = IndiController(config.indi)
        self._adapt = AdaptiveLaw(AdaptiveLawConfig(config.ckf, config.k_min, config.k_max, config.arm_wrench))
        self._obs_gain = config.dt_s / (JOINT_OBS_TAU_S + config.dt_s)
        self._outer_cfg = outer_loop_config_array(config.outer)
        # Command shaping: configuration, state (SH; INIT = 0: seed at the next engaged tick), setpoint, feed-forwards
        self._shape_cfg = shaper_config_array(config.outer, config.dt_s)
        self._shape_st = SH.zeros()
        self._shape_sp = OSP.zeros()
        self._shape_ff = OFF.zeros()  # stays zero while shaping is off: the paper's loop
        self._shape_ff_scale = 1.0  # the feed-forward's check (shaping_ff_scale of FeedForwardStatus)
        self._shape_rise = config.dt_s / SHAPING_FF_RISE_S
        self._uo = UO.zeros()
        self._fst = FST.zeros()  # joint observer + differentiator state (front_end.fc_front)
        self._fo = FO.zeros()
        self._inv_dt = 1.0 / config.dt_s
        # INDI_ARM_FF: the arm's h' low-passed like the INDI's feedback (None until the first tick)
        self._ff_alpha = lpf_alpha(config.indi.lpf_tau_s, config.dt_s)
        self._hdc_f: float | None = None
        # INDI_ARM_FF = 2: the arm's commanded trajectory (arm_preview plan rows, sim time; None: hold the measured
        # joints, i.e. no preview) and the servo model's scratch state
        self._arm_plan: np.ndarray | None = None
        self._arm_ref = np.zeros(10)  # the servo reference model's state (arm_preview_step), invalid until set
        self._arm_ahead = np.zeros(9)
        pv = config.indi.arm_preview
        self._arm_sup_cfg = pv.supervisor_config()
        self._arm_sup = pv.supervisor_state()  # kept across resets: the identified servo stays identified
        self._u_cmd = np.zeros(5)  # CKF_U_SRC 2: U of the command through the actuator model (DeliveredU)
        ind = config.indi
        self._u_act = DeliveredU(ind.act_wn_rad_s, ind.act_zeta, config.dt_s) if config.ckf.u_delivered else None
        self._gc_law, self._gc_law_inv = np.empty((5, 5)), np.empty((5, 5))  # CKF_ACC_REF: G_C about the est. CoM
        # the flown loop gain, or None: K_hat, bit for bit
        self._flown_gain = (ind.lam_ref, ind.k_flown_min) if ind.lam_ref != 1.0 or ind.k_flown_min > 0.0 else None

    def update_gains(self, outer: OuterLoopConfig, k_min: float, k_max: float) -> None:
        """New outer-loop gains and K bounds from the next tick on; filters and estimator keep their state.
        (A change of rate, filter or estimator settings needs a new core: its filters depend on them.)"""
        self.config = replace(self.config, outer=outer, k_min=k_min, k_max=k_max)
        self._outer_cfg = outer_loop_config_array(outer)  # what the tick reads: rebuilt with the gains
        self._shape_cfg = shaper_config_array(outer, self.config.dt_s)
        self._shape_ff[:] = 0.0  # shaping switched off flies the plain loop; switched on, it starts afresh
        self._shape_st[SH.INIT] = 0.0
        self._adapt.set_k_bounds(k_min, k_max)

    def set_flown_floor(self, k_flown_min: float) -> None:
        """A new floor on the rotational axes' flown K (IndiConfig.k_flown_min) from the next tick on; filters and
        estimator keep their state (the automatic link floor raised in flight: navig8_fc/params/link_floor.py)."""
        self.config = replace(self.config, indi=replace(self.config.indi, k_flown_min=float(k_flown_min)))
        ind = self.config.indi
        self._flown_gain = (ind.lam_ref, ind.k_flown_min) if ind.lam_ref != 1.0 or ind.k_flown_min > 0.0 else None

    def set_arm_plan(self, plan: np.ndarray | None) -> None:
        """The arm's commanded joint trajectory (arm_preview plan rows in sim time), which INDI_ARM_FF = 2 previews:
        the scenario's arm plan, or `arm_preview.hold_plan(target)` after an arm-joint command."""
        self._arm_plan = None if plan is None else np.ascontiguousarray(plan, dtype=np.float64)
        self._arm_ref[9] = 0.0  # the reference model starts again from the measured joints

    def reset(self) -> None:
        """Forget filter and estimator state (e.g. on arming); the start delay counts again."""
        self._indi.reset()
        self._adapt.reset()
        self._fst[:] = 0.0
        self._hdc_f = None
        self._arm_ref[9] = 0.0
        self._indi_saturated = False
        self._shape_ff_scale = 1.0
        self._u_cmd_ok = False
        self._shape_st[SH.INIT] = 0.0
        # The arm preview's trust is earned again in the new flight (docs/model.md); the identified servo limits
        # (V_HAT, A_HAT) stay identified.
        sup = self._arm_sup
        for f in (PS.TRUST, PS.MOVING, PS.BAD_MOVE, PS.REST_TICKS, PS.QD_OK):
            sup[f] = 0.0

    @property
    def reference_accel_ned(self) -> tuple[float, float, float]:
        """The command shaper's position-reference acceleration (m/s^2, NED), which a mode change keeps; zero when
        the position is not shaped or the reference is not running."""
        st = self._shape_st
        if st[SH.INIT] == 0.0 or not self.config.outer.jerk_max_m_s3 > 0.0:
            return (0.0, 0.0, 0.0)
        return (float(st[SH.ACC]), float(st[SH.ACC + 1]), float(st[SH.ACC + 2]))

    def resync_reference(self) -> None:
        """Mode changes: the command shaper's position reference continues from the measured position and velocity
        at the next tick (never a reference left over from the last mode), its acceleration and pitch/yaw
        reference from where they are (no attitude-command step). Arming and disengaging seed it afresh."""
        if self._shape_st[SH.INIT] != 0.0:
            self._shape_st[SH.INIT] = 2.0

    def step(
        self, s: FcSensors, sp: Setpoint, engaged: bool = True
    ) -> tuple[ActuatorCommand, ControllerStatus]:
        """One control tick: the front end, the adaptive law, the arm's feed-forward, then the outer loops and the
        INDI when engaged (the INDI's filters kept warm when not); the module docstring's signal flow."""
        io = self._tick_io
        if io is None:
            io = self._tick_io = tick_buffers(self._fo, self.vehicle.uam_mass_kg)
        sens, _, _, _, _, _, u_meas, acc_m, uam_mass = io
        # The arm term uses a point object of the estimated extra mass at the tip (notes §3.3 option b).
        m_obj_est = 0.0
        m_hat = self._adapt.mass_estimate_kg
        if m_hat is not None:
            m_obj_est = max(m_hat - uam_mass, 0.0)
        inertia, rate, gc, gc_inv, ul = self._front_end(s, sp, engaged, m_obj_est, sens)
        mass = ul[_UO_MASS]
        acc_law, gc_law_inv = self._law_inputs(s, ul, gc_inv, m_obj_est, acc_m)
        fo = self._fo
        gi_hat, gi_flat, adapt_status = self._adapt.step_arrays(
            s.t_s, u_meas, acc_law, gc_law_inv, inertia, mass, rate, fo.item(_FO_ARM_HDC), self._indi_saturated,
            self._u_cmd if self._u_cmd_ok else None, s.gripper_closed, tuple(ul[_UO_OBJ_RATE:_UO_OBJ_RATE + 3]),
            ul[_UO_OBJ_IXZ] if s.gripper_closed else 0.0,  # the object's I_xz only while one is held, as its CoM
            ul[_UO_OBJ_IXZ_DM] if s.gripper_closed else 0.0,
            (ul[_UO_CE_DM], ul[_UO_CE_DM + 1]) if s.gripper_closed and self.config.ckf.gc_at_com else _NO_SLOPE,
            s.gyro_frd_rad_s)
        if self._flown_gain is not None:  # the INDI, the status and the eigenvalue monitor fly K_flown, not K_hat
            gi_hat, gi_flat = k_xi.flown_gi_hat(gi_flat, adapt_status.k, *self._flown_gain)
        ref: tuple[float, float, float] | None = None
        sf_x = sf_z = 0.0  # the INDI's force-row feedback: f_O's (read from the sensors) or, here, the CoM's
        if self.config.acc_ref:
            # the INDI force rows feed back the CoM's acceleration (Acc_m's, before its low-pass) instead of f_O
            ref = (ul[_UO_CEX], 0.0, ul[_UO_CEZ])
            am = acc_m.tolist()
            sf_x, sf_z = am[3], am[4]
        ff_q = 0.0
        ff_status: FeedForwardStatus | None = None
        if self.config.indi.arm_ff:
            ff_q, ff_status = self._arm_feedforward(s, m_obj_est, gi_hat, sens)
        outer: OuterLoopStatus | None = None
        indi_status: IndiStatus | None = None
        if engaged:
            if s.cmd_applied_t_s is not None:  # a link that reports which command the actuators flew
                self._indi.fly_applied(s.cmd_applied_t_s, s.t_s)
            cmd, outer, indi_status, ff_status = self._fly(io, sf_x, sf_z, gc_inv, gi_hat, ff_q, ff_status)
        else:
            cmd = self._idle(s, sf_x, sf_z, gc, gi_hat)
        ft = tuple(fo.tolist())
        status = ControllerStatus(
            t_s=s.t_s,
            engaged=engaged,
            q_est_rad=ft[_FO_QEST],
            qdd_est_rad_s2=ft[_FO_QDD],
            mass_uam_kg=mass,
            inertia_uam_diag=(inertia.item(0), inertia.item(4), inertia.item(8)),
            gi_hat=gi_flat,
            gc_uam=tuple(gc.ravel().tolist()),
            outer=outer,
            indi=indi_status,
            adapt=adapt_status,
            ref_frd_m=ref,
            ff=ff_status,
        )
        return cmd, status

    def _front_end(
        self, s: FcSensors, sp: Setpoint, engaged: bool, m_obj_est: float, sens: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[float]]:
        """The sensors into the input vector, then the front end's kernel: joint observer (complementary filter,
        JOINT_OBS_TAU_S), q-ddot and omega-dot by backward differences, the UAM model (UamModel.evaluate) with G_C
        and G_C^-1, Acc_m (Eq. 23: Delta Acc_m = Delta Acc_UAV + Delta Acc_ARM) and U0 from the measured actuators.
        Returns (inertia, inertia rate, G_C, G_C^-1, the UO outputs as a list): fresh arrays each tick (callers of
        the reference APIs may keep them)."""
        cfg = self.config
        inertia, rate = np.empty((3, 3)), np.empty((3, 3))
        gc, gc_inv = np.empty((5, 5)), np.empty((5, 5))
        # The sensor values packed as float64 into the persistent input vector (TIN's sensor part is all fc_front
        # reads); when engaged the outer loops' inputs follow, read through views.
        if engaged:
            sp_pos = sp.pos_ned_m
            _PACK_ENGAGED(sens, 0, *s.gyro_frd_rad_s, *s.accel_frd_m_s2, *s.duct_tilt_rad, *s.prop_speed_rad_s,
                          *s.joint_pos_rad,
                          *s.joint_rate_rad_s, *s.pos_ned_m, *s.vel_ned_m_s, *s.quat_wxyz,
                          sp_pos[0], sp_pos[1], sp_pos[2], sp.pitch_rad, sp.yaw_rad)
        else:
            _PACK_SENSORS(sens, 0, *s.gyro_frd_rad_s, *s.accel_frd_m_s2, *s.duct_tilt_rad, *s.prop_speed_rad_s,
                          *s.joint_pos_rad,
                          *s.joint_rate_rad_s)
        model = self._model
        fc_front(self._fst, cfg.dt_s, self._obs_gain, self._inv_dt, sens, m_obj_est, model.geometry,
                 model.force_per_input, model.moment_o_per_input, inertia, rate, gc, gc_inv, self._uo, self._fo,
                 float(cfg.acc_ref), float(cfg.ckf.lpf_mean_start))  # CKF_LPF_SEED: the joint observer's start too
        ul = self._uo.tolist()
        if ul[_UO_SINGULAR]:
            gc_inv = np.linalg.inv(gc)  # raises LinAlgError as before
        return inertia, rate, gc, gc_inv, ul

    def _law_inputs(
        self, s: FcSensors, ul: list[float], gc_inv: np.ndarray, m_obj_est: float, acc_m: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The adaptive law's Acc_m and G_C^-1: the INDI's, or referred to the estimated CoM (CKF_ACC_REF: the
        force rows; CKF_GC_REF: the moment rows)."""
        cfg = self.config
        acc_law = acc_m
        gc_law_inv = gc_inv
        if cfg.ckf.acc_at_com and not cfg.acc_ref:  # CKF_ACC_REF: the law's force rows at the estimated CoM (the
            am = acc_m.tolist()  # INDI's already are with INDI_ACC_REF = 1)
            dx, dz = com_accel_offset(*s.gyro_frd_rad_s, am[1], ul[_UO_CEX], ul[_UO_CEZ])
            acc_law = np.array((am[0], am[1], am[2], am[3] + dx, am[4] + dz))
        if cfg.ckf.gc_at_com and s.gripper_closed:  # CKF_GC_REF: the law's moment rows about the estimated CoM
            # (an object at the gripper only while it reports closed: with it open, a mass estimate above m_UAM is
            # not an object there, and a CoM moved toward the tip on it made the estimate, and the flight, wander:
            # a cancelled reposition in SITL overshot by 1.8 m in half the runs)
            if m_obj_est > 0.0:
                # and its moment rows: the body turns about the composite CoM, so G_C's moments are taken about it
                # (M_c = M_O - c x F). About the UAM's CoM, a force increment (the ducts tilting to hold position
                # through a pitch doublet) made a pitch moment the model did not have, correlated with Delta Q-dot:
                # K2 stayed at 0.9 against a true 0.63 with a 0.5 kg object (docs/model.md, "Estimator").
                gc_law_inv = self._gc_law_inv
                model = self._model
                if not gc_inv_about(model.force_per_input, model.moment_o_per_input, ul[_UO_CEX], ul[_UO_CEZ],
                                    self._gc_law, gc_law_inv):
                    gc_law_inv = gc_inv
        return acc_law, gc_law_inv

    def _arm_feedforward(
        self, s: FcSensors, m_obj_est: float, gi_hat: np.ndarray, sens: np.ndarray
    ) -> tuple[float, FeedForwardStatus | None]:
        """INDI_ARM_FF: the pitch-acceleration feed-forward of the arm's reaction (ff_q, added to the outer loops'
        Q-dot command) and, with the preview (INDI_ARM_FF = 2 and a plan), its supervision's status."""
        # The INDI feeds back the low-passed Q-dot, which carries the arm's reaction -h'/I_yy with the filter's
        # lag; the part of h' the filter has not passed yet is fed forward: Delta Q-dot += (h' - h'_f) / I_yy
        # (pitch row of G_C U = G_I Acc + [0, h', 0, 0, 0], adaptive_law.py), with I_yy = G_hat_I[1, 1].
        cfg = self.config
        fo = self._fo
        ff_status: FeedForwardStatus | None = None
        hdc = fo.item(_FO_ARM_HDC)
        hf = hdc if self._hdc_f is None else self._hdc_f + self._ff_alpha * (hdc - self._hdc_f)
        self._hdc_f = hf
        plan = self._arm_plan
        if cfg.indi.arm_ff == 2 and plan is not None:
            # The INDI delivers I_yy v + LPF(h') after the actuators' lag; commanding I_yy v + h'(t + lead) instead
            # has the counter-moment there when the arm's reaction is (arm_preview.py; G_C U = G_I Acc + h' e_M).
            # The servo model is checked against the measured joints every tick (preview_supervise): the preview
            # is blended in by the trust it has earned, the measured h' (INDI_ARM_FF = 1) flies the rest.
            pv = cfg.indi.arm_preview
            sup = self._arm_sup
            h_s = 1.0 / pv.servo_hz
            v_hat, a_hat = sup.item(_PS_V_HAT), sup.item(_PS_A_HAT)
            qd_meas = sens[_IN_JRATE:_IN_JRATE + 3]
            err = reference_advance(plan, s.t_s, cfg.dt_s, fo[_FO_QEST], qd_meas, h_s, a_hat, v_hat, self._arm_ref)
            preview_supervise(sup, self._arm_sup_cfg, err, qd_meas, self._arm_ref, cfg.dt_s)
            trust = sup.item(_PS_TRUST)
            if trust > 0.0:
                hp = preview_ahead(plan, s.t_s, pv.lead_s, h_s, a_hat, v_hat, m_obj_est, self._model.geometry,
                                   self._arm_ref, self._arm_ahead)
                hdc = trust * hp + (1.0 - trust) * hdc
            su = sup.tolist()
            ff_status = FeedForwardStatus(su[_PS_TRUST], su[_PS_ERR], su[_PS_V_HAT], su[_PS_A_HAT],
                                          int(su[_PS_DROPS]), int(su[_PS_IDENTS]), self._shape_ff_scale)
        return (hdc - hf) / gi_hat.item(6), ff_status

    def _fly(
        self, io: tuple, sf_x: float, sf_z: float, gc_inv: np.ndarray, gi_hat: np.ndarray, ff_q: float,
        ff_status: FeedForwardStatus | None,
    ) -> tuple[ActuatorCommand, OuterLoopStatus, IndiStatus, FeedForwardStatus | None]:
        """Engaged: the command shaper (when on), the outer loops, the INDI (sf_x, sf_z: the CoM's force-row
        feedback with INDI_ACC_REF = 1, else read here from the sensors). Returns (command, outer loop status, INDI
        status, the feed-forwards' status with the shaper's scale)."""
        cfg = self.config
        sens, gyro, pos, vel, quat, spv, _, _, _ = io
        sl = sens.tolist()
        if not cfg.acc_ref:
            sf_x, sf_z = sl[_IN_ACCEL], sl[_IN_ACCEL + 2]
        ffv = self._shape_ff
        if cfg.outer.shaping:
            shape_reference(self._shape_cfg, self._shape_st, spv, pos, vel, quat, self._shape_sp, ffv)
            spv = self._shape_sp
            scale = self._shape_ff_scale = shaping_ff_check(self._shape_st, quat, self._shape_ff_scale,
                                                            self._shape_rise)
            ffv = ffv if scale >= 1.0 else ffv * scale
            if ff_status is None:
                ff_status = FeedForwardStatus(0.0, 0.0, 0.0, 0.0, 0, 0, self._shape_ff_scale)
            else:
                ff_status = replace(ff_status, shaping_ff_scale=self._shape_ff_scale)
        outer, ol_out = _outer_loop_arrays(self._outer_cfg, spv, pos, vel, quat, gyro, ffv)
        v_cmd = ol_out[_OO_ACCEL]
        if ff_q != 0.0:
            v_cmd = v_cmd.copy()
            v_cmd[1] += ff_q
        out, indi_status = self._indi._step(gyro, sf_x, sf_z, sl[_IN_TILT], sl[_IN_TILT + 1], sl[_IN_SPEED],
                                            sl[_IN_SPEED + 1], sl[_IN_SPEED + 2], v_cmd, gc_inv, gi_hat)
        self._indi_saturated = indi_status.saturated
        if self._u_act is None:
            actuators_to_u(*out.tilt_cmd_rad, *out.speed_cmd_rad_s, self._u_cmd, 0)
        else:  # seeded afresh by the first command after an idle tick
            self._u_act.step(out.tilt_cmd_rad, out.speed_cmd_rad_s, self._u_cmd, not self._u_cmd_ok)
        self._u_cmd_ok = True
        return ActuatorCommand(out.tilt_cmd_rad, out.speed_cmd_rad_s), outer, indi_status, ff_status

    def _idle(self, s: FcSensors, sf_x: float, sf_z: float, gc: np.ndarray, gi_hat: np.ndarray) -> ActuatorCommand:
        """Disengaged: motors off; the INDI's filters are kept warm so engaging does not start from a transient, and
        the command shaper seeds afresh at the next engaged tick."""
        self._indi_saturated = False
        self._u_cmd_ok = False
        self._shape_st[SH.INIT] = 0.0
        acc = s.accel_frd_m_s2 if not self.config.acc_ref else (sf_x, s.accel_frd_m_s2[1], sf_z)
        self._indi.measure(IndiInputs(s.gyro_frd_rad_s, acc, s.duct_tilt_rad, s.prop_speed_rad_s, (0.0,) * 5, gc,
                                      gi_hat))
        return MOTORS_OFF


def tick_buffers(fo: np.ndarray, uam_mass_kg: float) -> tuple:
    """Built on a core's first step and kept (`FlightControllerCore._tick_io`): the input vector the sensors are
    packed into, the views of it the outer loop and INDI kernels take (gyro, pos, vel, quat, setpoint), the views of
    the front end's output `fo` the adaptive law takes (U0, Acc_m; its kernel only reads them) and the UAM mass.
    The arrays are never replaced, so the views stay valid."""
    sens = TIN.zeros()
    t = TIN.views(sens)
    f = FO.views(fo)
    return (sens, t.gyro, t.pos, t.vel, t.quat, t.sp, f.u_meas, f.acc_m, uam_mass_kg)


def shaping_ff_check(shape_st: np.ndarray, quat: np.ndarray, scale: float, rise: float) -> float:
    """The check of the shaped reference's feed-forward (SHAPING_FF_*): its scale (shaping_ff_scale of
    FeedForwardStatus) halved while the measured attitude is more than SHAPING_FF_ATT_RAD off the shaper's reference
    (shape_st: SH), raised by `rise` up to 1 while they agree."""
    sh = shape_st.tolist()
    cp, sp_, cy, sy = math.cos(sh[_SH_PITCH]), math.sin(sh[_SH_PITCH]), math.cos(sh[_SH_YAW]), math.sin(sh[_SH_YAW])
    # the reference attitude's body x axis against the measured one (roll is the outer loop's choice: not
    # compared); both in NED: x_ref = (cos pitch cos yaw, cos pitch sin yaw, -sin pitch)
    w, x, y, z = quat.tolist()
    bx = (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y))
    c = max(-1.0, min(1.0, bx[0] * cp * cy + bx[1] * cp * sy - bx[2] * sp_))
    off = math.acos(c) > SHAPING_FF_ATT_RAD
    if off:
        scale *= 0.5
    else:
        scale = min(1.0, scale + rise)
    return scale


def warm_up_kernels(vehicle: VehicleConfig, config: ControllerConfig, n_ticks: int = 8) -> None:
    """Run a throwaway core through every compiled path of the tick (disengaged, engaged, estimator on).

    numba loads a kernel from its on-disk cache at the kernel's first call (~0.2 s for the tick's kernels);
    without this, that load lands on the first control steps of a run: a stall at real time, and a tenth of
    a 30 s lockstep run at --speed 0. The inputs need only be finite; the results are discarded."""

    cfg = replace(config, ckf=replace(config.ckf, start_delay_s=0.0))
    core = FlightControllerCore(vehicle, cfg)
    w = 600.0
    sp = Setpoint((0.0, 0.0, -2.0), 0.0, 0.0)
    st: ControllerStatus | None = None
    for i in range(n_ticks):
        s = FcSensors(t_s=i * cfg.dt_s, gyro_frd_rad_s=(0.01, -0.02, 0.005), accel_frd_m_s2=(0.1, 0.0,
                                                                                             -vehicle.gravity_m_s2),
                      pos_ned_m=(0.0, 0.0, -2.0), vel_ned_m_s=(0.0, 0.0, 0.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0),
                      duct_tilt_rad=(0.1, 0.1), prop_speed_rad_s=(w, 50.0 * (i % 2), w), joint_pos_rad=(0.1 * i, 0.0,
                                                                                                        -0.1),
                      joint_rate_rad_s=(0.1, 0.0, -0.1))
        _, st = core.step(s, sp, engaged=i > 0)
    assert st is not None
    # INDI_ARM_FF = 2's preview kernel (runs only when selected; loaded here so selecting it does not stall a tick)
    arm_preview_step(hold_plan((0.1, 0.0, -0.1)), 0.0, cfg.dt_s, 0.05, np.zeros(3), np.zeros(3), 1e-3, 42.0, 4.0, 0.0,
                     core._model.geometry, np.zeros(10), np.zeros(9))
    pv = cfg.indi.arm_preview
    preview_supervise(pv.supervisor_state(), pv.supervisor_config(), 0.1, np.zeros(3), np.zeros(10), cfg.dt_s)
    # the command shaper (runs only when OL_JERK_MAX or OL_ATT_ACC_REF is on; loaded here so switching it on does not
    # stall a tick)
    shape_reference(shaper_config_array(replace(config.outer, jerk_max_m_s3=5.0, att_acc_ref_rad_s2=1.0), cfg.dt_s),
                    SH.zeros(), OSP.zeros(), np.zeros(3), np.zeros(3), np.array((1.0, 0.0, 0.0, 0.0)),
                    OSP.zeros(), OFF.zeros())
    # the attitude kernels Python code calls directly (rotation.py: telemetry, the plant's truth)
    q = rotation.euler_to_quat(0.1, 0.2, 0.3)
    rotation.quat_to_euler(rotation.quat_mul(q, q))
    rotation.attitude_error_rotvec(q, q)
    rotation.rotate_ned_to_body(q, (0.0, 0.0, 1.0))
    ghat_ginv_eig_record(core._model, st.q_est_rad, st.gi_hat, (0.0, 0.0, 0.05), vehicle.uav_inertia_array,
                         vehicle.uam_mass_kg, config.k_min, 0.1, st.gc_uam)
