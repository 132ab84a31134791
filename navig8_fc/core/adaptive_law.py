"""The adaptive law of Fig. 3 (paper Sec. 3.3): low-passed increments (Eq. 23), the constrained KF
(kalman.py; Eq. 22-24) on the Eq. 21 box from the K bounds (Eq. 20), and G_hat_I (Eq. 4).

Increments (our reading of Eq. 23)
----------------------------------
The law low-passes U0 (from the measured actuators) and Acc_m with the *same* first-order filter
(tau = CKF_LPF_TAU, 0.7 s in Sec. 4) and uses one-step increments of the filtered signals,

    Delta U[k] = U_f[k] - U_f[k-1],   Delta Acc_m[k] = A_f[k] - A_f[k-1].

Why: Eq. 1 relates increments, Acc = G U + b(x) => Delta Acc = G Delta U + Delta b. One-step differences
cancel slowly varying b (gravity, accelerometer bias, aerodynamic terms) and, because the same linear
filter is applied to both sides, the static relation Delta U = G^-1 Delta Acc survives filtering exactly
(up to the variation of G within the filter memory). Paparazzi's LMS adaptation does the same (filtered
first differences, notes 4). The paper does not define the increment; alternatives we considered:
(a) N-step or since-start differences U_f[k] - U_f[k-N] (more signal per sample, but consecutive
measurements share noise and bias drift, breaking the white-noise assumption of the KF); (b) high-pass
increments U[k] - U_f[k] (the INDI-style "command minus filtered"), which are larger but carry the full
raw-sensor noise and the unfiltered disturbance. With one-step increments of tau = 0.7 s filtered signals
the per-step signal is small: a step change of size D arrives as increments alpha D (1 - alpha)^k with
alpha = 1 - exp(-0.01/0.7) = 0.0142, total squared size D^2 alpha / (2 - alpha) = 0.0071 D^2.
Caveat: H is built from the *measured* Delta Acc_m, which the KF treats as exact. Noise in it (differentiated
gyro, accelerometer) biases the estimate towards zero (errors-in-variables attenuation), i.e. towards
the lower bound K = 1 once constrained.

Windows (CKF_INC_N = N > 1, the default 25): the increments are y[k] - y[k-N], one correction every N
steps (predict and projection every step). Why: y[k] - y[k-1] = alpha (x[k] - y[k-1]) passes white noise and a
0.5 Hz doublet with the same gain (~alpha), so the regressor is as noisy as the raw signal and the estimate is
attenuated towards K = 1 (errors in variables); over N = 25 steps the doublet passes with gain ~0.6 and the
noise with ~sqrt(alpha). Non-overlapping windows share no noise samples, so the KF's white-noise assumption holds
much better than for option (a) above. With N = 1 everything is exactly the one-step law.

Forgetting (CKF_GRIP_RST, docs/model.md "Estimator"): the FC knows when its gripper closes or opens (the sensors
report it). A grasp resets P to P0, so the new object is learned at the filter's first speed rather than at the
speed Q allows after a long hover has shrunk P; a release puts the estimate back where it was before the grasp (the
object is gone, what was known of the vehicle holds) and resets P. The windows within the filter's time constant
after either event carry the step in U and Acc_m through the low-passes and are not corrected from.

Gates and sources (docs/model.md "Estimator"): a window in which the INDI saturated is not learned
from (CKF_SAT_GATE); states whose regressor increment is below a threshold are held (CKF_EXC_ROT, CKF_EXC_LIN);
U can be the INDI's previous actuator command instead of the measured actuators (CKF_U_SRC: the measured U's
noise is fed back by the INDI and correlates the regressor with the noise in z).

The filters and increments are one numba kernel (`law_filters.lpf_increments`) over a named state layout; the KF is
used through its public `step`. Pure core: no I/O, no clocks; time comes in as t_s from the caller.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from navig8_fc.core.ckf_config import N_MEAS, N_STATE, CkfConfig, CkfMode
from navig8_fc.core.filters import lpf_alpha
from navig8_fc.core.force_balance import ForceBalanceMass
from navig8_fc.core.gyroscopic import gyroscopic_moment
from navig8_fc.core.kalman import ConstrainedKalmanFilter, KfStepResult, eq22_drift, inertia_ratios
from navig8_fc.core.kf_nuisance import ixz_mass_column, known_ixz, refer_moment  # I_xz (CKF_IXZ_MOD), CKF_MOM_MREF
from navig8_fc.core.law_filters import (
    LAW_OUT,
    LAW_STATE,
    LO_DA,
    LO_DG,
    LO_DH,
    LO_DU,
    LO_READY,
    LO_SAT,
    LS_NSEEN,
    lpf_increments,
)
from navig8_fc.core.linalg import inv_gauss_jordan
from navig8_fc.core.lms import LmsEstimator
from navig8_fc.core.records import frozen_record

__all__ = [
    "AdaptiveLaw",
    "AdaptiveLawConfig",
    "AdaptiveLawInputs",
    "AdaptiveLawStatus",
]


@dataclass(frozen=True)
class AdaptiveLawConfig:
    """The law's settings: the CKF_* group (filter, low-pass, start delay, mode) and the K bounds of Eq. 20
    (INDI_K_MIN, INDI_K_MAX), which make the Eq. 21 box I_UAM / k_max <= x <= I_UAM / k_min."""

    ckf: CkfConfig = field(default_factory=CkfConfig)
    k_min: float = 0.5
    k_max: float = 1.0
    # CKF_ARM_WRENCH: take the arm's reaction pitch moment out of the measurement. The body's pitch
    # equation about the CoM is G_C U = G_I Acc + [0, h', 0, 0, 0] (h' = arm_hdc, the rate of the bodies'
    # angular momentum relative to the body); the paper's Eq. 24 drops h', which then acts as equation
    # error correlated with Delta Q-dot. With it: z = Delta U - G_C^-1[:, M] Delta h'. False: the paper.
    arm_wrench: bool = False

    def __post_init__(self) -> None:
        k_min, k_max = float(self.k_min), float(self.k_max)
        if not (0.0 < k_min <= k_max and math.isfinite(k_max)):
            raise ValueError(f"K bounds need 0 < k_min <= k_max < inf, got k_min {k_min}, k_max {k_max}")
        object.__setattr__(self, "k_min", k_min)
        object.__setattr__(self, "k_max", k_max)


@dataclass(frozen=True)
class AdaptiveLawInputs:
    """Per control step. Signals unfiltered; the law filters them itself."""

    t_s: float  # controller time (lockstep sim time), s
    u_meas: Sequence[float] | np.ndarray  # (5,) U0 from the measured actuators (Sec. 3 definition of U)
    acc_m: Sequence[float] | np.ndarray  # (5,) [P_dot, Q_dot, R_dot, a_x, a_z] incl. the arm term (Eq. 23), body FRD
    gc_uam_inv: np.ndarray  # (5, 5) G_C,UAM^-1 at the measured pose
    inertia_uam: np.ndarray  # (3, 3) UAM inertia tensor about the UAM CoM
    mass_uam_kg: float
    inertia_rate_uam: np.ndarray  # (3, 3) d/dt of inertia_uam (Eq. 22)
    arm_hdc: float = 0.0  # the arm's h' (CKF_ARM_WRENCH)
    indi_saturated: bool = False  # IndiStatus.saturated of the latest command (CKF_SAT_GATE)
    u_cmd: Sequence[float] | np.ndarray | None = None  # U of the latest actuator command (CKF_U_SRC = 1)
    gripper_closed: bool | None = None  # the gripper's reported state (CKF_GRIP_RST); None: not known


@frozen_record  # built every step: its fields straight into the instance dict (core/records.py)
@dataclass(frozen=True)
class AdaptiveLawStatus:
    """What the adaptive law did this step (tuples of floats/bools so it logs as plain JSON)."""

    running: bool
    x_hat: tuple[float, ...]  # [I_xx, I_yy, I_zz, m] used for G_hat_I
    x_unconstrained: tuple[float, ...]  # before projection
    k: tuple[float, ...]  # implied [K1..K4] (Eq. 4)
    lower: tuple[float, ...]  # Eq. 21 box
    upper: tuple[float, ...]
    active_lower: tuple[bool, ...]
    active_upper: tuple[bool, ...]
    innovation: tuple[float, ...]  # (5,)
    p_diag: tuple[float, ...]  # (4,)
    n_updates: int
    n_projection_fallbacks: int
    delta_u: tuple[float, ...] = (0.0,) * N_MEAS  # increments fed to the KF (Eq. 23); zeros between windows
    delta_acc: tuple[float, ...] = (0.0,) * N_MEAS
    corrected: bool = False  # a measurement update ran this step (a window closed, not gated)
    excited: tuple[bool, ...] = (False,) * N_STATE  # the states it corrected (excitation gate)
    saturated: bool = False  # the window that closed this step had INDI saturation (skipped when CKF_SAT_GATE)
    n_saturation_skips: int = 0  # windows skipped by the saturation gate since the start
    n_forgets: int = 0  # grasps and releases the estimator forgot on (CKF_GRIP_RST) since the start


PITCH_EVENT_HOLD_TAU = 3.0  # the moment-space pitch row's wait after a gripper event, in CKF_LPF_TAU
# CKF_CZ_DM's mass column only with the arm at rest: |I_yy-dot| of the arm's model below this (kg m^2/s) through the
# window and PITCH_EVENT_HOLD_TAU filter constants before it (and since the estimator's start). With the arm held the
# joint observer's noise gives at most 0.0033 (q1 60 deg); the paper scenario's arm moves at up to 0.45, and after it
# moved the pitch row carries the trim's move as the CoM shifted (0.69 N m RMS per window while it moves, against the
# row's sigma 0.1, docs/model.md "Estimator" item 13), which the mass column would read as mass
ARM_REST_IYY_DOT = 0.01
_ZERO4 = (0.0,) * N_STATE
_ZERO5 = (0.0,) * N_MEAS
_ONES4 = (1.0,) * N_STATE
_FALSE4 = (False,) * N_STATE
_NO_SLOPE = (0.0, 0.0)


class AdaptiveLaw:
    """Fig. 3's adaptive law: filters, increments (Eq. 23), the constrained KF, and G_hat_I (Eq. 4).

    The start delay counts from the first sample after construction or reset(); the shell resets the law
    when the controller engages. Before the start, and always in mode FIXED, G_I,UAM (K = 1) is returned.
    The filters run from the first sample in every mode, so the increments are settled when the KF starts.
    """

    def __init__(self, config: AdaptiveLawConfig) -> None:
        self.config = config
        ckf = config.ckf
        # CKF_MODE 4: the LMS baseline (lms.py) in the KF's place, same interface, same increments and gates
        self._kf = LmsEstimator(ckf) if ckf.mode == CkfMode.LMS else ConstrainedKalmanFilter(ckf)
        self._alpha = lpf_alpha(ckf.lpf_tau_s, ckf.dt_s)
        self._st = LAW_STATE.zeros()
        self._inc = LAW_OUT.zeros()
        inc = LAW_OUT.views(self._inc)
        self._du, self._da = inc.delta_u, inc.delta_acc  # what the KF step reads
        self._n_window = float(ckf.inc_window)
        self._sat_gate = ckf.sat_gate
        # the saturation gate also skips the filter time constant after a saturated step (the low-passed U and
        # Acc_m still carry it: measured on the paper scenario, the windows right after a reversal's saturation
        # moved m_hat by 2 kg)
        self._sat_hold = float(math.ceil(ckf.lpf_tau_s / ckf.dt_s)) if ckf.sat_gate else 0.0
        self._u_from_cmd = ckf.u_from_command
        self._mean_start = 1.0 if ckf.lpf_mean_start else 0.0  # CKF_LPF_SEED
        self._ixz_model = ckf.ixz_model  # CKF_IXZ_MOD (known_ixz)
        self._ixz_dm = ckf.ixz_mass_jacobian and isinstance(self._kf, ConstrainedKalmanFilter)  # CKF_IXZ_MOD 2
        self._grip_reset = ckf.grip_reset
        # CKF_M_SIG_OPEN: the mass variance (kg^2) with no object held, at the start and after a release (0: P0's)
        self._m_var_open = ckf.mass_sigma_open_kg ** 2 if isinstance(self._kf, ConstrainedKalmanFilter) else 0.0
        self._grip_sig = ckf.grip_sigma_w if isinstance(self._kf, ConstrainedKalmanFilter) else 0.0  # CKF_GRIP_SIG
        # CKF_IYY_GRIP_W: I_yy's prior at a grasp. Its mean stays the estimate before the grasp, so its weight pulls the
        # held estimate back there (docs/model.md, "Estimator" item 23): half a width by default; one width halved
        # that pull but let the arm's motion after a grasp of nothing move K2 to 0.053.
        self._iyy_grasp_w = ckf.iyy_grasp_w
        self._event_hold_s = ckf.lpf_tau_s  # no correction this long after a grasp / release (the low-passes carry it)
        self._pred_dj = ckf.predict_from_dj
        # the moment-space pitch row (CKF_R_PITCH; the KF only) and its prior while an object is held (CKF_CZ_SIG)
        self._pitch_row = ckf.pitch_r_nm2 > 0.0 and isinstance(self._kf, ConstrainedKalmanFilter)
        self._com_sigma = ckf.com_sigma_m if self._pitch_row else 0.0
        self._ixz_sigma = ckf.ixz_sigma_kgm2 if isinstance(self._kf, ConstrainedKalmanFilter) else 0.0  # CKF_IXZ_SIG
        self._cz_dm = ckf.com_mass_slope and self._pitch_row  # CKF_CZ_DM: the pitch row's mass column
        self._fbm = ForceBalanceMass(self._alpha, ckf.mass_balance_sigma_kg) if ckf.mass_balance_sigma_kg > 0.0 and \
            isinstance(self._kf, ConstrainedKalmanFilter) else None  # CKF_M_ABS_SIG: the held mass, force balance
        # CKF_GYRO: Euler's velocity term out of the moment rows (gyroscopic; lpf_increments filters it, zeros when off)
        self._gyro = ckf.gyroscopic
        self._gyro_m = np.zeros(3)
        # CKF_SYNC: last tick's U, Acc_m, gyroscopic moment and arm reaction (valid once _sync_started), and this
        # tick's half-tick-late values handed to the filters
        self._sync = ckf.half_tick_sync
        self._r_move = ckf.r_move_scale != 1.0 and isinstance(self._kf, ConstrainedKalmanFilter)  # CKF_R_MOVE
        self._u_prev, self._acc_prev, self._gyro_prev = np.zeros(N_MEAS), np.zeros(N_MEAS), np.zeros(3)
        self._hdc_prev = 0.0
        self._u_sync, self._acc_sync, self._gyro_sync = np.zeros(N_MEAS), np.zeros(N_MEAS), np.zeros(3)
        self._nuisance = self._pitch_row or self._ixz_sigma > 0.0  # a grasp / release moves a nuisance's prior
        # after a grasp or a release the pitch row waits PITCH_EVENT_HOLD_TAU filter time constants: the object's
        # weight moment steps in the commanded pitch moment with no pitch acceleration to match, and the low-passed
        # command carries the step's tail (exp(-1) of it after one constant, exp(-3) = 5 % after three)
        self._pitch_event_hold_s = PITCH_EVENT_HOLD_TAU * ckf.lpf_tau_s
        # the arm at rest this long before the mass column: as after a gripper event, the low-passed command carries the
        # trim's move as the arm shifted the CoM (exp(-3) = 5 % of it after three constants), then the window itself
        self._rest_s = self._pitch_event_hold_s + ckf.inc_window * ckf.dt_s
        self._inv_dt = 1.0 / ckf.dt_s
        # CKF_MOM_LPF: the pitch row's low-passed moment [value, value at the window's start] and G_C's scratch
        self._mom_lpf = ckf.moment_lpf and self._pitch_row
        self._mom_reref, self._mom_move = ckf.moment_reref and self._mom_lpf, ckf.moment_arm_moving and self._mom_lpf
        self._mom = [0.0] * 4
        self._gc = np.empty((5, 5))
        # CKF_CZ_FOLLOW: the pitch row's CoM nuisance follows the reference point's moves with the mass estimate
        self._cz_follow = ckf.com_follows_reference and self._mom_reref and self._com_sigma > 0.0
        self._j_prev = (0.0, 0.0, 0.0)  # J's diagonal at the previous tick (CKF_PRED_DJ; set before it is read)
        # Constants of the tick, looked up once: the config is frozen.
        self._adaptive = ckf.adaptive
        self._pinned = ckf.mode == CkfMode.PINNED
        self._start_delay_tol = ckf.start_delay_s - 1e-9
        self._k_min, self._k_max = config.k_min, config.k_max
        self.reset()

    @property
    def kf(self) -> ConstrainedKalmanFilter:
        return self._kf

    def set_k_bounds(self, k_min: float, k_max: float) -> None:
        """New K bounds (Eq. 20) from the next step on; the filters and the estimate keep their state."""
        self.config = replace(self.config, k_min=k_min, k_max=k_max)
        self._k_min, self._k_max = self.config.k_min, self.config.k_max

    def reset(self) -> None:
        self._st[:] = 0.0
        self._n_sat_skips = 0
        self._t0: float | None = None
        self._running = False
        self._mass_hat: float | None = None
        self._gripper_prev: bool | None = None  # the gripper's state at the last started tick that knew it
        self._pitch_hold_until_s = -math.inf
        self._k_before_grasp: tuple[float, ...] | None = None
        self._hold_until_s = -math.inf
        self._arm_seen_moving_s = -math.inf  # CKF_R_MOVE: the last tick the arm was seen moving (arm_moving)
        self._arm_moved_s: float | None = None  # the last tick the arm moved (|I_yy-dot| >= ARM_REST_IYY_DOT)
        self._n_forgets = 0
        self._mom, self._mom_obj_kg = [0.0] * 4, 0.0  # and the last tick's reference point's object mass (kg)
        self._ref_dz = 0.0  # the reference point's move down (m) with the mass estimate this tick (CKF_MOM_MREF)
        self._sync_started = False  # CKF_SYNC starts again
        self._kf.reset()  # re-initialised at the next start
        if self._fbm is not None:
            self._fbm.reset()

    @property
    def mass_estimate_kg(self) -> float | None:
        """The estimated mass x_hat[3] while the KF runs, else None."""
        return self._mass_hat

    def step(self, inp: AdaptiveLawInputs) -> tuple[np.ndarray, AdaptiveLawStatus]:
        """Returns (G_hat_I 5x5, status)."""
        g, _, status = self.step_arrays(
            inp.t_s, np.asarray(inp.u_meas, dtype=float), np.asarray(inp.acc_m, dtype=float),
            np.ascontiguousarray(inp.gc_uam_inv, dtype=float), np.asarray(inp.inertia_uam, dtype=float),
            float(inp.mass_uam_kg), np.asarray(inp.inertia_rate_uam, dtype=float), float(inp.arm_hdc),
            bool(inp.indi_saturated), None if inp.u_cmd is None else np.asarray(inp.u_cmd, dtype=float),
            inp.gripper_closed,
        )
        return g, status

    def step_arrays(
        self, t_s: float, u_meas: np.ndarray, acc_m: np.ndarray, gc_inv: np.ndarray, inertia: np.ndarray,
        m: float, inertia_rate: np.ndarray, arm_hdc: float = 0.0, indi_saturated: bool = False,
        u_cmd: np.ndarray | None = None, gripper_closed: bool | None = None,
        object_inertia_rate: tuple[float, float, float] | None = None, object_ixz: float = 0.0,
        object_ixz_dm: float = 0.0, object_com_dm: tuple[float, float] = (0.0, 0.0),
        rate_frd_rad_s: tuple[float, float, float] | None = None,
    ) -> tuple[np.ndarray, tuple[float, ...], AdaptiveLawStatus]:
        """step() on float64 arrays (u_meas, acc_m (5,), gc_inv (5, 5) C-contiguous, inertia and inertia_rate
        (3, 3)), m a float; also returns G_hat_I row-major as a tuple (the same floats). The controller's tick.
        indi_saturated: the INDI's saturation flag of the latest command (IndiStatus.saturated), for the gate.
        u_cmd: U of the latest actuator command (5,), used in place of u_meas when CKF_U_SRC = 1 (None: no
        command yet, u_meas is used). gripper_closed: the gripper's reported state, for CKF_GRIP_RST (None: unknown).
        object_inertia_rate: the diagonal of the rate of the modelled inertia of a point object of the estimated mass
        at the gripper (moving with the arm), added to Eq. 22's drift with CKF_PRED_DJ (None: no object).
        object_ixz: that object's share of the composite I_xz (kg m^2; 0: none held), for CKF_IXZ_MOD.
        object_ixz_dm: its slope in the object's mass (m^2; 0: none held), for CKF_IXZ_MOD 2.
        object_com_dm: the slope (m/kg) of the moment rows' reference point (the estimated CoM) in the object's mass,
        (x, z) (zeros: it does not follow the mass estimate), for CKF_CZ_DM.
        rate_frd_rad_s: the body rates (rad/s), for CKF_GYRO's gyroscopic moment (None: not taken out).

        Bookkeeping on plain floats (the vectors have 4-5 components: numpy's per-call overhead would
        dominate); the values equal those of vehicle.estimate_bounds / estimated_gi / k_from_estimate exactly
        (same IEEE operations; tests compare them bit for bit).
        """
        (j11, _, j13), (_, j22, _), (_, _, j33) = inertia.tolist()
        base = (j11, j22, j33, m)
        k_min, k_max = self._k_min, self._k_max
        lower = (j11 / k_max, j22 / k_max, j33 / k_max, m / k_max)  # Eq. 21 (estimate_bounds)
        upper = (j11 / k_min, j22 / k_min, j33 / k_min, m / k_min)
        t_s = float(t_s)
        if self._t0 is None:
            self._t0 = t_s
        # 1e-9 s guards the comparison against time accumulated in floating point.
        started = self._adaptive and (t_s - self._t0) >= self._start_delay_tol
        if u_cmd is not None and self._u_from_cmd:
            u_meas = u_cmd
        gyro = self._gyro and rate_frd_rad_s is not None
        if gyro:  # CKF_GYRO, with the inertia held this tick
            ix, iy, iz = (self._kf.x.item(0), self._kf.x.item(1), self._kf.x.item(2)) if self._running else base[:3]
            gm = self._gyro_m
            gm[0], gm[1], gm[2] = gyroscopic_moment(*rate_frd_rad_s, ix, iy, iz, j13 + object_ixz)
        u_lpf, acc_lpf, gyro_lpf, hdc_lpf = u_meas, acc_m, self._gyro_m, float(arm_hdc)
        if self._sync:
            u_lpf, acc_lpf, gyro_lpf, hdc_lpf = self._half_tick(u_meas, acc_m, hdc_lpf)
        lpf_increments(self._st, self._alpha, self._n_window, u_lpf, acc_lpf, hdc_lpf, gyro_lpf,
                       1.0 if indi_saturated else 0.0, self._sat_hold, self._inc, self._mean_start)
        inc = self._inc.tolist()
        du, da = tuple(inc[LO_DU:LO_DU + N_MEAS]), tuple(inc[LO_DA:LO_DA + N_MEAS])
        ready, window_sat = inc[LO_READY] != 0.0, inc[LO_SAT] != 0.0
        dgyro = (inc[LO_DG], inc[LO_DG + 1], inc[LO_DG + 2]) if gyro and ready else None
        gc_ok = (self._mom_lpf or self._fbm is not None) and inv_gauss_jordan(gc_inv, self._gc)  # G_C, once a tick
        dmom = self._moment_increment(gc_ok, u_lpf, ready, m, object_com_dm) if self._mom_lpf else None
        if not started:
            return self._not_started(base, j13, lower, upper, du, da, window_sat)
        kf = self._kf
        idot: tuple[float, float, float] | None = None  # no predict on the first KF tick: x0 is this pose
        if self._running:
            idot = eq22_drift((j11, j22, j33), inertia_rate, object_inertia_rate,
                              self._j_prev if self._pred_dj else None, self._inv_dt)
        else:
            kf.initialise(base)  # K = 1 at the start (Sec. 4)
            self._running = True
            if gripper_closed is False:
                narrow_mass_prior(kf, self._m_var_open)
        if gripper_closed is not None:  # a grasp or a release, detected here once for all that follow it
            closed, prev = bool(gripper_closed), self._gripper_prev
            self._gripper_prev = closed
            if prev is not None and closed != prev:
                if self._grip_reset:
                    self._on_gripper(closed, t_s, base, lower, upper)
                if self._fbm is not None:
                    self._fbm.restart()
            if self._nuisance and closed != prev:  # the first known state too: it sets the nuisances' priors
                self._held_changed(closed, prev, t_s, (self._iyy_grasp_w * (upper[1] - lower[1])) ** 2)
        correct = self._gate(ready, window_sat, t_s)
        if self._fbm is not None and gc_ok:  # CKF_M_ABS_SIG
            self._fbm.tick(self._gc, u_meas, acc_m, correct, gripper_closed, m, kf)
        self._j_prev = (j11, j22, j33)
        rho_x, rho_z = inertia_ratios(j11, j13, j33)
        du_kf, dhd = self._du, inc[LO_DH]
        if self.config.arm_wrench and dhd != 0.0:
            du_kf = self._du - gc_inv[:, 1] * dhd  # z = Delta U - G_C^-1 [0, Delta h', 0, 0, 0]
        if dgyro is not None:  # z = Delta U - G_C^-1 [Delta (w x I w), 0, 0]
            du_kf = du_kf - gc_inv[:, 0] * dgyro[0] - gc_inv[:, 1] * dgyro[1] - gc_inv[:, 2] * dgyro[2]
        h_mass = None
        if self._ixz_model:
            du_kf = known_ixz(du_kf, gc_inv, da, j13 + object_ixz)
            rho_x = rho_z = 0.0
            if self._ixz_dm and object_ixz_dm != 0.0:
                du_kf, h_mass = ixz_mass_column(du_kf, gc_inv, da, object_ixz_dm, kf.x.item(3))
        # CKF_R_MOVE: while the arm moves, the moments it makes that the rows do not model are measurement error
        moving = self._r_move and self.arm_moving(t_s, inertia_rate)
        if self._pitch_row or h_mass is not None:
            pitch_y, com_dm = self._pitch_inputs(t_s, inertia_rate, dmom, dhd, object_com_dm)
            if dgyro is not None:
                pitch_y -= dgyro[1]  # the moment-space pitch row likewise (NaN stays NaN: unread)
            r = kf.step(du_kf, self._da, gc_inv, rho_x, rho_z, idot, lower, upper, correct,
                        pitch=t_s >= self._pitch_hold_until_s, h_mass=h_mass, pitch_y=pitch_y, com_dm=com_dm,
                        arm_moving=moving)
        else:
            r = kf.step(du_kf, self._da, gc_inv, rho_x, rho_z, idot, lower, upper, correct, arm_moving=moving)
        self._mass_hat = r.x_hat[3]
        return estimated_status(r, base, j13, lower, upper, du, da, window_sat,
                                (kf.n_updates, kf.n_projection_fallbacks, self._n_sat_skips, self._n_forgets))

    def _half_tick(self, u: np.ndarray, acc: np.ndarray,
                   hdc: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """CKF_SYNC: the moment channels at the angular acceleration's instant. Acc_m's angular rows are the gyro's
        finite difference (w_k - w_k-1) / dt, the acceleration half a tick before U_k's moment, so U, the gyroscopic
        moment and the arm's reaction are averaged over this tick and the last (the same phase; gain cos(w dt / 2)
        against the difference's sin(w dt / 2) / (w dt / 2)), and Acc_m's force rows, read at tick k as U is, with
        them. The first tick averages with itself."""
        u_prev, acc_prev, gyro_prev, gm = self._u_prev, self._acc_prev, self._gyro_prev, self._gyro_m
        if not self._sync_started:
            u_prev[:], acc_prev[:], gyro_prev[:], self._hdc_prev = u, acc, gm, hdc
            self._sync_started = True
        us, accs, gs = self._u_sync, self._acc_sync, self._gyro_sync
        np.add(u, u_prev, out=us)
        us *= 0.5
        np.add(gm, gyro_prev, out=gs)
        gs *= 0.5
        accs[:] = acc
        accs[3] = 0.5 * (acc[3] + acc_prev[3])  # the force rows (Acc_m is [P', Q', R', a_x, a_z])
        accs[4] = 0.5 * (acc[4] + acc_prev[4])
        hdc_half = 0.5 * (hdc + self._hdc_prev)
        u_prev[:], acc_prev[:], gyro_prev[:], self._hdc_prev = u, acc, gm, hdc
        return us, accs, gs, hdc_half

    def _pitch_inputs(self, t_s: float, inertia_rate: np.ndarray, dmom: float | None, dhd: float,
                      object_com_dm: tuple[float, float]) -> tuple[float, tuple[float, float]]:
        """The pitch row's moment increment (NaN: unread) and its point's slope in the mass (CKF_CZ_FOLLOW: below)."""
        pitch_y = math.nan if (self._mom_move and self.arm_rested(t_s, inertia_rate)) or dmom is None \
            else dmom - dhd  # CKF_MOM_LPF: Delta M_f - Delta h' (CKF_MOM_MOVE: while the arm moves)
        com_dm = self.pitch_mass_slope(t_s, inertia_rate, object_com_dm)
        if self._cz_follow and com_dm == _NO_SLOPE and self._ref_dz != 0.0:
            self._kf.move_pitch_reference(self._ref_dz)  # no mass column: the nuisance is the whole error
        return pitch_y, com_dm

    def pitch_mass_slope(self, t_s: float, inertia_rate: np.ndarray, slope: tuple[float, float]) -> tuple[float, float]:
        """CKF_CZ_DM: the pitch row's reference-point slope in the mass while the arm has rested (arm_rested); else
        none (the mass held in that row)."""
        return slope if self._cz_dm and self.arm_rested(t_s, inertia_rate) else _NO_SLOPE

    def arm_rested(self, t_s: float, inertia_rate: np.ndarray) -> bool:
        """The arm at rest (the model's |I_yy-dot| < ARM_REST_IYY_DOT) through the window and PITCH_EVENT_HOLD_TAU
        filter constants before it, counted from the estimator's first tick (before it the motion is not known)."""
        if self._arm_moved_s is None or abs(inertia_rate.item(4)) >= ARM_REST_IYY_DOT:
            self._arm_moved_s = t_s
        return t_s - self._arm_moved_s >= self._rest_s

    def arm_moving(self, t_s: float, inertia_rate: np.ndarray) -> bool:
        """CKF_R_MOVE: the arm seen moving (the model's |I_yy-dot| >= ARM_REST_IYY_DOT) at this tick or within the pitch
        row's event wait and a window before it. Unlike arm_rested, an arm not yet seen moving is at rest: the gate
        raises the noise for motion the rows do not model, not for the estimator's start."""
        if abs(inertia_rate.item(4)) >= ARM_REST_IYY_DOT:
            self._arm_seen_moving_s = t_s
        return t_s - self._arm_seen_moving_s < self._rest_s

    def _held_changed(self, held: bool, held_before: bool | None, t_s: float, iyy_var_min: float) -> None:
        """A grasp or a release: the pitch row waits after a release; the pitch row's nuisance CoM error (CKF_CZ_SIG; at
        a grasp I_yy's variance at least iyy_var_min, the object's inertia being unknown within the box) and the roll
        and yaw rows' nuisance I_xz error (CKF_IXZ_SIG) are given their priors while held, zero otherwise."""
        if held_before and not held:  # a release
            self._pitch_hold_until_s = t_s + self._pitch_event_hold_s
        if self._com_sigma > 0.0:
            self._kf.object_held(held, self._com_sigma, iyy_var_min)
        if self._ixz_sigma > 0.0:
            self._kf.ixz_held(held, self._ixz_sigma)

    def _moment_increment(self, gc_ok: bool, u: np.ndarray, ready: bool, m: float,
                          com_dm: tuple[float, float]) -> float | None:
        """CKF_MOM_LPF: the increment over the window that closed (None between windows or with G_C^-1 singular,
        gc_ok False; else self._gc holds this tick's G_C) of the
        low-passed G_C[M, :] U with each tick's G_C, (Delta G_C) U_f included (docs/model.md, Estimator items 13, 17).
        CKF_MOM_MREF: the reference point's move with m_hat (com_dm (m/kg) x the object mass's change) re-refers it."""
        self._ref_dz = 0.0
        if not gc_ok:
            return None
        gc, st, n_seen = self._gc, self._mom, self._st.item(LS_NSEEN)
        mom = float(gc[1] @ u)
        a = 1.0 if n_seen <= 1.0 else max(self._alpha, 1.0 / n_seen) if self._mean_start else self._alpha
        if self._mom_reref:
            m_obj = max(self._mass_hat - m, 0.0) if self._mass_hat is not None else 0.0  # as the controller's
            dm, self._mom_obj_kg = m_obj - self._mom_obj_kg, m_obj
            refer_moment(st, float(gc[3] @ u), float(gc[4] @ u), a, com_dm[0] * dm, com_dm[1] * dm)
            self._ref_dz = com_dm[1] * dm  # the point's move down this tick (CKF_CZ_FOLLOW)
        if n_seen <= 1.0:
            st[0] = st[1] = mom
            return None
        st[0] += a * (mom - st[0])
        if not ready:
            return None
        d, st[1] = st[0] - st[1], st[0]
        return d

    def _not_started(
        self, base: tuple[float, float, float, float], j13: float, lower: tuple[float, ...],
        upper: tuple[float, ...], du: tuple[float, ...], da: tuple[float, ...], window_sat: bool,
    ) -> tuple[np.ndarray, tuple[float, ...], AdaptiveLawStatus]:
        """Before the start, and in the modes without an estimator: G_I,UAM (K = 1), or the pinned K's (PINNED)."""
        j11, j22, j33, m = base
        x_fixed, k_fixed = base, _ONES4
        if self._pinned:  # Eq. 4 with a constant K, clipped to the Eq. 20 box (the guarantee's K)
            k_min, k_max = self._k_min, self._k_max
            k_fixed = tuple(min(max(k, k_min), k_max) for k in self.config.ckf.k_pin)
            x_fixed = (j11 / k_fixed[0], j22 / k_fixed[1], j33 / k_fixed[2], m / k_fixed[3])
            self._mass_hat = x_fixed[3]  # the arm term's object: the constant model's extra mass
        g, gl = _gi_hat_flat(j11, j13, j33, x_fixed)
        return g, gl, AdaptiveLawStatus(
            running=False, x_hat=x_fixed, x_unconstrained=x_fixed, k=k_fixed,
            lower=lower, upper=upper, active_lower=_FALSE4, active_upper=_FALSE4,
            innovation=_ZERO5, p_diag=_ZERO4, n_updates=0, n_projection_fallbacks=0,
            delta_u=du, delta_acc=da, saturated=window_sat,
        )

    def _gate(self, ready: bool, window_sat: bool, t_s: float) -> bool:
        """Whether this step corrects: a window closed, outside the hold after a gripper event, and (CKF_SAT_GATE) no
        saturation in the window (counted as a skip)."""
        correct = ready and t_s >= self._hold_until_s
        if ready and window_sat and self._sat_gate:  # no learning from saturated steps (Paparazzi learns from
            correct = False  # the actuator state, which WLS keeps inside its limits; we skip such windows)
            self._n_sat_skips += 1
        return correct

    def _on_gripper(self, closed: bool, t_s: float, base: tuple[float, ...], lower: tuple[float, ...],
                    upper: tuple[float, ...]) -> None:
        """CKF_GRIP_RST, at a grasp (closed) or a release: forget on a grasp (P0) or a release (back to the estimate
        before the grasp, K = 1 when the flight started holding the object, and P0); then hold the corrections for the
        low-pass's time constant."""
        kf = self._kf
        x = kf.x
        if closed:
            self._k_before_grasp = tuple(b / v for b, v in zip(base, x.tolist(), strict=True))
            kf.forget()
            if self._grip_sig > 0.0:
                # CKF_GRIP_SIG: the object's I_xx, I_zz are unknown within the box, and the estimate restarts at its
                # edge (K = 1 is I's lower bound): the far edge is one width away, 2.5 sigma of P0 for I_zz at q1 60 deg
                # with 1 kg (it moves by 0.42 kg m^2, P0's sigma 0.17), which the prior then holds back through the
                # first held windows. I_yy has its own (CKF_CZ_SIG). Not the mass: the same prior on it identified K4
                # better but its faster first held windows, which the INDI's CoM and arm term follow, flew the
                # envelope worse (docs/model.md, "Estimator" item 12).
                w = self._grip_sig
                kf.raise_variance(((w * (upper[0] - lower[0])) ** 2, 0.0, (w * (upper[2] - lower[2])) ** 2, 0.0))
        else:
            k = self._k_before_grasp or _ONES4
            self._k_before_grasp = None
            kf.forget([min(max(b / ki, lo), hi) for b, ki, lo, hi in zip(base, k, lower, upper, strict=True)])
            narrow_mass_prior(kf, self._m_var_open)
        self._hold_until_s = t_s + self._event_hold_s
        self._n_forgets += 1


def estimated_status(
    r: KfStepResult, base: tuple[float, float, float, float], j13: float, lower: tuple[float, ...],
    upper: tuple[float, ...], du: tuple[float, ...], da: tuple[float, ...], window_sat: bool,
    counts: tuple[int, int, int, int],
) -> tuple[np.ndarray, tuple[float, ...], AdaptiveLawStatus]:
    """G_hat_I (Eq. 4) from the estimator's step r, and the law's status; counts: the estimator's updates and projection
    fallbacks, the law's saturation skips and forgets."""
    j11, j22, j33, m = base
    x = r.x_hat
    x0, x1, x2, x3 = x
    g, gl = _gi_hat_flat(j11, j13, j33, x)
    return g, gl, AdaptiveLawStatus(
        running=True,
        x_hat=x,
        x_unconstrained=r.x_unconstrained,
        k=(j11 / x0, j22 / x1, j33 / x2, m / x3),  # k_from_estimate
        lower=lower,
        upper=upper,
        active_lower=(x0 <= lower[0], x1 <= lower[1], x2 <= lower[2], x3 <= lower[3]),
        active_upper=(x0 >= upper[0], x1 >= upper[1], x2 >= upper[2], x3 >= upper[3]),
        innovation=r.innovation,
        p_diag=r.p_diag,
        n_updates=counts[0],
        n_projection_fallbacks=counts[1],
        delta_u=du,
        delta_acc=da,
        corrected=r.corrected,
        excited=r.excited,
        saturated=window_sat,
        n_saturation_skips=counts[2],
        n_forgets=counts[3],
    )


def narrow_mass_prior(kf: ConstrainedKalmanFilter | LmsEstimator, var_kg2: float) -> None:
    """CKF_M_SIG_OPEN (var_kg2 = its square; 0: nothing): with no object held the mass is the UAM's, which the model
    knows (K4 = 1, Eq. 4); one force-row window moved K4 by 0.05-0.07 with P0's sigma (docs/model.md, Estimator 14)."""
    if var_kg2 > 0.0 and isinstance(kf, ConstrainedKalmanFilter):
        kf.lower_variance((0.0, 0.0, 0.0, var_kg2))


def _gi_hat_flat(j11: float, j13: float, j33: float, x: Sequence[float]) -> tuple[np.ndarray, tuple[float, ...]]:
    """vehicle.estimated_gi(J, x) from J's three entries it uses (same operations, same values), as the 5x5
    array and as the row-major tuple of the same floats (the array is built from the tuple)."""
    ixx, iyy, izz, m = x
    flat = (
        ixx, 0.0, izz * j13 / j33, 0.0, 0.0,
        0.0, iyy, 0.0, 0.0, 0.0,
        ixx * j13 / j11, 0.0, izz, 0.0, 0.0,
        0.0, 0.0, 0.0, m, 0.0,
        0.0, 0.0, 0.0, 0.0, m,
    )
    return np.array(flat).reshape(5, 5), flat
