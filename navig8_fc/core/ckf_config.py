"""The estimator's configuration: the CKF_* parameters (CKF_PARAM_NAMES), CkfMode and CkfConfig, and the sizes
of the state and measurement vectors the filters share.

x = [I_hat_xx, I_hat_yy, I_hat_zz, m_hat] (N_STATE = 4: kg m^2, kg m^2, kg m^2, kg); z = Delta U (N_MEAS = 5,
Eq. 24). Q (q_diag) and P0 are per state, R (r_diag) per measurement. The filters that read it: the constrained
KF (kalman.py), the LMS baseline (lms.py) and the adaptive law around either (adaptive_law.py).

Pure core: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

__all__ = [
    "CKF_PARAM_NAMES",
    "N_MEAS",
    "N_STATE",
    "CkfConfig",
    "CkfMode",
]

N_STATE = 4
N_MEAS = 5

ProjectionWeight = Literal["inv_p", "identity"]
# CKF_LMS_MU1..4's defaults (lms.py; chosen on the ident scenario, seeds 1-2, docs/model.md "Estimator baselines")
LMS_MU_DEFAULT: tuple[float, ...] = (0.003, 0.05, 0.003, 0.001)

CKF_PARAM_NAMES: tuple[str, ...] = (
    "CKF_MODE", "CKF_LPF_TAU", "CKF_START_DLY",
    "CKF_Q_IXX", "CKF_Q_IYY", "CKF_Q_IZZ", "CKF_Q_M",
    "CKF_R_U1", "CKF_R_U2", "CKF_R_U3", "CKF_R_U4", "CKF_R_U5",
    "CKF_P0_SCALE", "CKF_PROJ_W",
    "CKF_INC_N", "CKF_EXC_ROT", "CKF_EXC_LIN", "CKF_SAT_GATE", "CKF_U_SRC", "CKF_ACC_REF",
    "CKF_K_PIN1", "CKF_K_PIN2", "CKF_K_PIN3", "CKF_K_PIN4", "CKF_GRIP_RST", "CKF_PRED_DJ", "CKF_GC_REF",
    "CKF_LMS_MU1", "CKF_LMS_MU2", "CKF_LMS_MU3", "CKF_LMS_MU4", "CKF_R_PITCH", "CKF_CZ_SIG",
    "CKF_LPF_SEED", "CKF_IXZ_MOD", "CKF_GRIP_SIG", "CKF_MOM_LPF", "CKF_M_SIG_OPEN", "CKF_IXZ_SIG", "CKF_CZ_DM",
    "CKF_MOM_MREF", "CKF_MOM_MOVE", "CKF_PROJ_IYY", "CKF_CZ_FOLLOW", "CKF_M_ABS_SIG", "CKF_GYRO", "CKF_IYY_GRIP_W",
    "CKF_SYNC", "CKF_R_MOVE",
)


class CkfMode(IntEnum):
    """CKF_MODE: 0 fixed G_I,UAM (K = 1), 1 unconstrained KF (previous-work proxy), 2 proposed constrained KF,
    3 pinned: a constant K vector (CKF_K_PIN1..4, inside the Eq. 20 box), the non-adaptive baseline a search over
    constant K can make as strong as it gets, 4 LMS with clipping to the Eq. 21 box (Smeur, Chu & de Croon 2016 as
    Paparazzi flies it; lms.py), the published adaptive baseline."""

    FIXED = 0
    UNCONSTRAINED = 1
    CONSTRAINED = 2
    PINNED = 3
    LMS = 4


def _floats(values: Sequence[float], n: int, name: str) -> tuple[float, ...]:
    out = tuple(float(v) for v in values)
    if len(out) != n:
        raise ValueError(f"{name} needs {n} values, got {len(out)}")
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must be finite, got {out}")
    return out


@dataclass(frozen=True)
class CkfConfig:
    """Configuration of the constrained KF and the adaptive law's filters (the CKF_* parameters). Defaults are
    the paper's Sec. 4 settings. The K bounds of Eq. 20-21 are the adaptive law's (AdaptiveLawConfig).

    q_diag: process-noise variances per control step of [I_xx, I_yy, I_zz, m] (Eq. 22; notes 6.3 item 12).
    r_diag: measurement-noise variances of Delta U1..U5 (Eq. 24), (rad/s)^4.
    p0_scale: P0 = p0_scale * diag(q_diag) [A].
    projection_weight: "inv_p" (W = P^-1, minimum variance) or "identity" (W = I, i.e. clipping).
    mode: fixed / unconstrained / constrained / pinned / lms (CKF_MODE).
    lpf_tau_s: time constant of the adaptive law's low-pass filters on U0 and Acc_m.
    start_delay_s: the estimator starts this long after the first sample (Sec. 4: 0.5 s).
    dt_s: control period (filters and the predict step use it).
    inc_window: CKF_INC_N, the increment window in control steps: the law corrects every inc_window steps with
        Delta = filtered[k] - filtered[k - inc_window] (1: one-step increments every step, our reading of the
        paper; adaptive_law.py explains why a longer window is the better band-pass). Predict runs every step.
    exc_rot_rad_s2, exc_lin_m_s2: CKF_EXC_ROT, CKF_EXC_LIN, excitation gate: a state is corrected only when its
        regressor's increment is at least this large (|Delta P-dot|, |Delta Q-dot|, |Delta R-dot| for I_xx,
        I_yy, I_zz; |(Delta a_x, Delta a_z)| for m); the others are held (Schmidt: their gain rows are zero).
        0: every state, every correction (the paper).
    sat_gate: CKF_SAT_GATE, skip the correction of a window in which the INDI saturated (no learning from
        saturated steps). False: the paper.
    u_from_command: CKF_U_SRC = 1, the law's U is the INDI's previous command (the actuators it commanded, as
        Paparazzi's estimator without RPM feedback); False (0): U0 from the measured actuators (the paper). Why:
        the measured U carries the actuator sensor noise, which the INDI feeds back into the next command, so the
        accelerations the regressor sees are correlated with the measurement noise in z (closed-loop bias).
    acc_at_com: CKF_ACC_REF = 1, the law's Acc_m force rows are the acceleration of the estimated composite CoM
        (a_c = f_O + omega-dot x c + omega x (omega x c) + c-ddot_rel, the point G_C's force rows refer to) whatever
        INDI_ACC_REF the INDI flies with; False (0): the INDI's Acc_m (the paper: f_O + c-ddot_rel, which puts
        Q-dot c_z into the mass equation as error correlated with the pitch excitation).
    """

    q_diag: tuple[float, ...] = (1.0e-4, 5.0e-5, 1.0e-4, 5.0e-4)
    r_diag: tuple[float, ...] = (1500.0**2, 2000.0**2, 1500.0**2, 2000.0**2, 10000.0**2)
    p0_scale: float = 100.0
    projection_weight: ProjectionWeight = "inv_p"
    mode: CkfMode = CkfMode.CONSTRAINED
    lpf_tau_s: float = 0.7
    start_delay_s: float = 0.5
    dt_s: float = 0.01
    inc_window: int = 1
    exc_rot_rad_s2: float = 0.0
    exc_lin_m_s2: float = 0.0
    sat_gate: bool = False
    u_from_command: bool = False
    acc_at_com: bool = False
    k_pin: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)  # CKF_K_PIN1..4: K of mode PINNED (Eq. 3's diagonal, K4 on mass)
    grip_reset: bool = False  # CKF_GRIP_RST: forget on the gripper's reported grasp / release (AdaptiveLaw)
    predict_from_dj: bool = False  # CKF_PRED_DJ: Eq. 22's drift from the tick's change of J, not the model's I-dot
    gc_at_com: bool = False  # CKF_GC_REF: the law's G_C moment rows about the estimated composite CoM (controller.py)
    # CKF_LMS_MU1..4: the per-state rates of mode LMS (dimensionless, in lms.py's normalised coordinates)
    lms_mu: tuple[float, ...] = LMS_MU_DEFAULT
    # CKF_R_PITCH: > 0, I_yy is corrected from the pitch row in moment space with this noise variance, (N m)^2
    # (kalman.kf_correct_pitch); 0: with the other states in Delta U space (the paper's Eq. 24 as written)
    pitch_r_nm2: float = 0.0
    # CKF_CZ_SIG: with pitch_r_nm2 > 0, the prior sigma (m) of the held object's CoM-height error in the pitch row, and
    # at a grasp I_yy's variance raised to (half the box's width)^2 (AdaptiveLaw, kalman.kf_correct_pitch); 0: neither
    com_sigma_m: float = 0.0
    # CKF_LPF_SEED: the law's low-passes start as the running mean of their samples (law_filters.lpf_increments),
    # not from the first sample alone; False: the first sample seeds them (the paper's first-order filter)
    lpf_mean_start: bool = False
    # CKF_IXZ_MOD: the product of inertia in the roll and yaw rows of Eq. 24 is the model's (J13, plus a point object
    # of the estimated mass at the gripper while it reports closed), not Eq. 24's I_zz J13 / J33 and I_xx J13 / J11
    ixz_model: bool = False
    # CKF_IXZ_MOD = 2: as 1, and the rows' dependence on the mass estimate through that object's I_xz enters the
    # filter's H (linearised at m_hat): a window read while m_hat was still off keeps its I_xx, I_zz correlated with m
    ixz_mass_jacobian: bool = False
    # CKF_U_SRC = 2: the command's U through the FC's actuator model (ACT_WN, ACT_ZETA; actuator_model.DeliveredU),
    # what the actuators deliver, rather than the command itself (u_from_command is True with it)
    u_delivered: bool = False
    # CKF_GRIP_SIG: with grip_reset, at a grasp the prior sigma of I_xx and I_zz is at least this many widths of their
    # Eq. 21 box (J / K_min - J / K_max); 0: P0 alone (AdaptiveLaw._on_gripper)
    grip_sigma_w: float = 0.0
    # CKF_IYY_GRIP_W: with the pitch row's CoM nuisance (com_sigma_m > 0), at a grasp the prior sigma of I_yy is at
    # least this many widths of its Eq. 21 box (AdaptiveLaw._held_changed)
    iyy_grasp_w: float = 0.5
    # CKF_MOM_LPF: the moment-space pitch row reads the increment of the low-passed pitch moment G_C[M, :] U (each
    # tick's G_C) less that of h', not G_C[M, :] Delta U (AdaptiveLaw)
    moment_lpf: bool = False
    # CKF_M_SIG_OPEN: the prior sigma of the mass (kg) when the estimator starts with the gripper reporting open, and
    # after a release (with grip_reset): no object is held, the mass is the UAM's (AdaptiveLaw); 0: P0's
    mass_sigma_open_kg: float = 0.0
    # CKF_IXZ_SIG: while an object is held, the prior sigma (kg m^2) of the modelled I_xz's error in the roll and yaw
    # rows, a nuisance state updated with x (kf_nuisance; AdaptiveLaw); 0: none, the model's I_xz taken as exact
    ixz_sigma_kgm2: float = 0.0
    # CKF_CZ_DM: with pitch_r_nm2 > 0, the pitch row's reference point (the estimated CoM, CKF_GC_REF) follows the mass
    # estimate, and its slope in m enters that row as a mass column (kf_nuisance.kf_correct_pitch's com_dm_x, com_dm_z):
    # the row's CoM error is c_z' (m - m_hat) plus the nuisance (CKF_CZ_SIG), and the row corrects m too
    com_mass_slope: bool = False
    # CKF_MOM_MREF: with moment_lpf, when the reference point moves with the mass estimate (the estimated CoM has a
    # point object of m_hat - m at the gripper) the low-passed moment is re-referred to it (kf_nuisance.refer_moment)
    moment_reref: bool = False
    # CKF_MOM_MOVE: with moment_lpf, the low-passed moment only while the arm moves or has not rested for the pitch
    # row's event wait and a window (AdaptiveLaw.arm_rested); at rest, G_C[M, :] Delta U as with moment_lpf off
    moment_arm_moving: bool = False
    # CKF_PROJ_IYY: with pitch_r_nm2 > 0, the Eq. 21 projection weighs I_yy apart from the other states (its
    # covariances with them left out of W = P^-1): I_yy is clipped to its own bounds and a projection of the Delta U
    # rows' states does not move it (kalman.kf_step)
    iyy_projected_apart: bool = False
    # CKF_CZ_FOLLOW: with com_sigma_m > 0 and moment_reref, while the pitch row has no mass column (com_mass_slope off,
    # or the arm not at rest) its CoM nuisance moves with the reference point when the mass estimate moves it
    # (ConstrainedKalmanFilter.move_pitch_reference; AdaptiveLaw)
    com_follows_reference: bool = False
    # CKF_M_ABS_SIG: while the gripper reports closed, the mass is also measured from the force balance F = m f,
    # calibrated on the UAM's mass while it reports open (force_balance), with this sigma (kg) per window; 0: off
    mass_balance_sigma_kg: float = 0.0
    # CKF_GYRO: the windows' increment of the gyroscopic moment w x (I w) (Euler's velocity term, which Eq. 24 leaves
    # out) taken out of the measurement, with the estimated inertia (gyroscopic)
    gyroscopic: bool = False
    # CKF_SYNC: the moment channels (U, the gyroscopic moment, the arm's reaction) and the specific force averaged
    # over this tick and the last, half a tick late as the angular acceleration's finite difference is (AdaptiveLaw)
    half_tick_sync: bool = False
    # CKF_R_MOVE: the filter's measurement noise variances (the Delta U rows' R and the pitch row's) times this while
    # the arm moves or was seen moving within the pitch row's event wait and a window (AdaptiveLaw.arm_moving); 1: none
    r_move_scale: float = 1.0

    def __post_init__(self) -> None:
        lms_mu = _floats(self.lms_mu, N_STATE, "lms_mu")
        if any(v < 0.0 for v in lms_mu):
            raise ValueError(f"lms_mu must be >= 0, got {lms_mu}")
        object.__setattr__(self, "lms_mu", lms_mu)
        k_pin = _floats(self.k_pin, N_STATE, "k_pin")
        if not all(v > 0.0 and math.isfinite(v) for v in k_pin):
            raise ValueError(f"k_pin must be finite and > 0, got {k_pin}")
        object.__setattr__(self, "k_pin", k_pin)
        q = _floats(self.q_diag, N_STATE, "q_diag")
        r = _floats(self.r_diag, N_MEAS, "r_diag")
        if any(v < 0.0 for v in q):
            raise ValueError(f"q_diag must be >= 0, got {q}")
        if any(v <= 0.0 for v in r):
            raise ValueError(f"r_diag must be > 0, got {r}")
        object.__setattr__(self, "q_diag", q)
        object.__setattr__(self, "r_diag", r)
        object.__setattr__(self, "mode", CkfMode(int(self.mode)))
        if self.projection_weight not in ("inv_p", "identity"):
            raise ValueError(f"projection_weight must be 'inv_p' or 'identity', got {self.projection_weight!r}")
        n = self.inc_window
        if isinstance(n, bool) or int(n) != n or int(n) < 1:
            raise ValueError(f"inc_window must be an integer >= 1, got {n!r}")
        object.__setattr__(self, "inc_window", int(n))
        object.__setattr__(self, "sat_gate", bool(self.sat_gate))
        object.__setattr__(self, "u_from_command", bool(self.u_from_command))
        object.__setattr__(self, "acc_at_com", bool(self.acc_at_com))
        object.__setattr__(self, "grip_reset", bool(self.grip_reset))
        object.__setattr__(self, "predict_from_dj", bool(self.predict_from_dj))
        object.__setattr__(self, "gc_at_com", bool(self.gc_at_com))
        object.__setattr__(self, "lpf_mean_start", bool(self.lpf_mean_start))
        object.__setattr__(self, "ixz_model", bool(self.ixz_model) or bool(self.ixz_mass_jacobian))
        object.__setattr__(self, "ixz_mass_jacobian", bool(self.ixz_mass_jacobian))
        object.__setattr__(self, "u_delivered", bool(self.u_delivered))
        object.__setattr__(self, "moment_lpf", bool(self.moment_lpf))
        object.__setattr__(self, "com_mass_slope", bool(self.com_mass_slope))
        object.__setattr__(self, "moment_reref", bool(self.moment_reref))
        object.__setattr__(self, "moment_arm_moving", bool(self.moment_arm_moving))
        object.__setattr__(self, "iyy_projected_apart", bool(self.iyy_projected_apart))
        object.__setattr__(self, "com_follows_reference", bool(self.com_follows_reference))
        object.__setattr__(self, "gyroscopic", bool(self.gyroscopic))
        object.__setattr__(self, "half_tick_sync", bool(self.half_tick_sync))
        for name in ("p0_scale", "lpf_tau_s", "start_delay_s", "exc_rot_rad_s2", "exc_lin_m_s2", "pitch_r_nm2",
                     "com_sigma_m", "grip_sigma_w", "iyy_grasp_w", "mass_sigma_open_kg", "ixz_sigma_kgm2",
                     "mass_balance_sigma_kg"):
            v = float(getattr(self, name))
            if not (v >= 0.0 and math.isfinite(v)):
                raise ValueError(f"{name} must be finite and >= 0, got {v}")
            object.__setattr__(self, name, v)
        r_move = float(self.r_move_scale)
        if not (r_move >= 1.0 and math.isfinite(r_move)):
            raise ValueError(f"r_move_scale must be finite and >= 1, got {r_move}")
        object.__setattr__(self, "r_move_scale", r_move)
        dt = float(self.dt_s)
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"dt_s must be finite and > 0, got {dt}")
        object.__setattr__(self, "dt_s", dt)

    @property
    def constrained(self) -> bool:
        """True when the estimate is projected onto the Eq. 21 box (CKF_MODE = 2)."""
        return self.mode == CkfMode.CONSTRAINED

    @property
    def adaptive(self) -> bool:
        """True when an estimator runs at all (CKF_MODE 1, 2: the KF; 4: the LMS)."""
        return self.mode in (CkfMode.UNCONSTRAINED, CkfMode.CONSTRAINED, CkfMode.LMS)

    @staticmethod
    def from_params(values: Mapping[str, float | int], dt_s: float) -> CkfConfig:
        """Build from the parameter set (params/fc_params.yaml). Every name in CKF_PARAM_NAMES is required."""
        missing = [n for n in CKF_PARAM_NAMES if n not in values]
        if missing:
            raise KeyError(f"missing CKF parameters: {', '.join(missing)}")
        if int(values["CKF_U_SRC"]) not in (0, 1, 2):
            raise ValueError(f"CKF_U_SRC must be 0, 1 or 2, got {values['CKF_U_SRC']}")
        for flag in ("CKF_SAT_GATE", "CKF_ACC_REF", "CKF_GRIP_RST", "CKF_PRED_DJ", "CKF_GC_REF",
                     "CKF_LPF_SEED", "CKF_MOM_LPF", "CKF_MOM_MREF",
                     "CKF_MOM_MOVE", "CKF_PROJ_IYY", "CKF_CZ_FOLLOW", "CKF_GYRO", "CKF_SYNC"):
            if int(values[flag]) not in (0, 1):
                raise ValueError(f"{flag} must be 0 or 1, got {values[flag]}")
        if int(values["CKF_IXZ_MOD"]) not in (0, 1, 2):
            raise ValueError(f"CKF_IXZ_MOD must be 0, 1 or 2, got {values['CKF_IXZ_MOD']}")
        proj = int(values["CKF_PROJ_W"])
        if proj not in (0, 1):
            raise ValueError(f"CKF_PROJ_W must be 0 (P^-1) or 1 (identity), got {proj}")
        mode = int(values["CKF_MODE"])
        if mode not in tuple(CkfMode):
            raise ValueError(f"CKF_MODE must be one of {[int(m) for m in CkfMode]}, got {mode}")
        return CkfConfig(
            q_diag=tuple(float(values[n]) for n in ("CKF_Q_IXX", "CKF_Q_IYY", "CKF_Q_IZZ", "CKF_Q_M")),
            r_diag=tuple(float(values[f"CKF_R_U{i}"]) for i in range(1, 6)),
            p0_scale=float(values["CKF_P0_SCALE"]),
            projection_weight="inv_p" if proj == 0 else "identity",
            mode=CkfMode(mode),
            lpf_tau_s=float(values["CKF_LPF_TAU"]),
            start_delay_s=float(values["CKF_START_DLY"]),
            dt_s=float(dt_s),
            inc_window=int(values["CKF_INC_N"]),
            exc_rot_rad_s2=float(values["CKF_EXC_ROT"]),
            exc_lin_m_s2=float(values["CKF_EXC_LIN"]),
            sat_gate=bool(int(values["CKF_SAT_GATE"])),
            u_from_command=bool(int(values["CKF_U_SRC"])),
            u_delivered=int(values["CKF_U_SRC"]) == 2,
            acc_at_com=bool(int(values["CKF_ACC_REF"])),
            k_pin=tuple(float(values[f"CKF_K_PIN{i}"]) for i in range(1, 5)),
            grip_reset=bool(int(values["CKF_GRIP_RST"])),
            predict_from_dj=bool(int(values["CKF_PRED_DJ"])),
            gc_at_com=bool(int(values["CKF_GC_REF"])),
            lms_mu=tuple(float(values[f"CKF_LMS_MU{i}"]) for i in range(1, 5)),
            pitch_r_nm2=float(values["CKF_R_PITCH"]),
            com_sigma_m=float(values["CKF_CZ_SIG"]),
            lpf_mean_start=bool(int(values["CKF_LPF_SEED"])),
            ixz_model=bool(int(values["CKF_IXZ_MOD"])),
            ixz_mass_jacobian=int(values["CKF_IXZ_MOD"]) == 2,
            grip_sigma_w=float(values["CKF_GRIP_SIG"]),
            iyy_grasp_w=float(values["CKF_IYY_GRIP_W"]),
            moment_lpf=bool(int(values["CKF_MOM_LPF"])),
            mass_sigma_open_kg=float(values["CKF_M_SIG_OPEN"]),
            ixz_sigma_kgm2=float(values["CKF_IXZ_SIG"]),
            com_mass_slope=bool(int(values["CKF_CZ_DM"])),
            moment_reref=bool(int(values["CKF_MOM_MREF"])),
            moment_arm_moving=bool(int(values["CKF_MOM_MOVE"])),
            iyy_projected_apart=bool(int(values["CKF_PROJ_IYY"])),
            com_follows_reference=bool(int(values["CKF_CZ_FOLLOW"])),
            mass_balance_sigma_kg=float(values["CKF_M_ABS_SIG"]),
            gyroscopic=bool(int(values["CKF_GYRO"])),
            half_tick_sync=bool(int(values["CKF_SYNC"])),
            r_move_scale=float(values["CKF_R_MOVE"]),
        )
