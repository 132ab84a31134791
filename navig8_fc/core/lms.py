"""LMS estimator of G_hat_I with clipping: the adaptive INDI of Smeur, Chu & de Croon (JGCD 2016) as Paparazzi flies
it, mapped onto the paper's parameterisation (CKF_MODE 4, a published baseline beside the constrained KF).

What Smeur et al. adapt, and how (read in paparazzi/paparazzi, sw/airborne/firmwares/rotorcraft/stabilization/)
------------------------------------------------------------------------------------------------------------
Smeur, Chu & de Croon, "Adaptive Incremental Nonlinear Dynamic Inversion for Attitude Control of Micro Air
Vehicles", J. Guid. Control Dyn. 39(3), 2016 (the paper's ref. [18]), estimate the control effectiveness G (angular
acceleration per actuator input, G1, plus the rotor-inertia term G2 in yaw) online with a least-mean-squares filter
on the incremental model Delta omega-dot = G Delta u, both sides low-passed by the same filter and differenced:

    G <- G - mu (G Delta u_f - Delta omega-dot_f) Delta u_f^T        (mu: one learning rate per output axis)

- `stabilization_indi.c` at commit 0001342e (line numbers counted in the stored copy): `calc_g1_element` (l. 643-646) is
  `g1_est[i][j] -= du_estimation[j] * mu * ddx_error`, with `ddx_error = sum_j g1_est[i][j] du_estimation[j] (+ g2
  term in yaw) - ddx_estimation[i]` formed in `lms_estimation` (l. 667-741, the loop l. 700-728); the learning
  rates are per output axis, `mu1 = {1e-5, 1e-5, 3e-6, 2e-6}` for roll, pitch, yaw, thrust (l. 152-153, mu2 = 0.002
  for G2, l. 155). The regressors are first differences of second-order Butterworth-filtered signals times the
  rate: `actuator_state_filt_vectd` of the actuator state (l. 516-520) and `estimation_rate_dd`, the difference of
  the differentiated filtered gyro (l. 387-391); both go through the same filter (`init_filters`, l. 287-315,
  cut-off STABILIZATION_INDI_ESTIMATION_FILT_CUTOFF). du is multiplied by a constant `adaptive_mu_lr` (0.001 by
  default, l. 684-692) "to avoid numerical errors": a fixed scaling that makes the rates of the axes comparable.
  The thrust row's error is zeroed when the filtered jerk exceeds 60 m/s^3 (l. 717-721). The estimate starts
  from the airframe's G (`g1_est = g1`, remembered as `g1_init`, l. 248-253) and runs only in flight
  (`if (in_flight && indi_use_adaptive)`, l. 523-526). After every update `bound_g_mat` (l. 820-864) clips each
  entry of G1 and G2 to [g_init / 2, 2 g_init] (INDI_ALLOWED_G_FACTOR = 2, l. 48-49): element-wise clipping,
  no sign change.
- `stabilization_indi_simple.c` at commit 01a59beb (`lms_estimation`, the last function of the file): the
  diagonal version of the paper, g1.p, g1.q, g1.r and g2 adapted with one mu (STABILIZATION_INDI_ADAPTIVE_MU; mu/3
  in yaw) on 4 Hz Butterworth-filtered signals (STABILIZATION_INDI_ESTIMATION_FILT_CUTOFF), the G's scaled by
  INDI_EST_SCALE = 0.001, and clipped from below only: `if (est->g1.p < 0.01) est->g1.p = 0.01` ("the g values
  should be larger than zero, otherwise there is positive feedback"), a minimum magnitude with no sign change.
  It runs only while the thrust command is >= 300.

How it maps onto this controller (and why this form)
----------------------------------------------------
Our G = G_I^-1 G_C (paper Eq. 3-4): G_C (geometry, from the arm pose) is computed, G_I is estimated through
x = [I_xx, I_yy, I_zz, m] (kg m^2, kg m^2, kg m^2, kg). The law adapts x, the same state the constrained KF
(kalman.py) estimates, on the same data: the regressor H(Delta Acc_m) of Eq. 24 (kalman._regressor), z = Delta U,
the increments, windows and gates of adaptive_law.py, the Eq. 22 drift. Only the estimator differs:

    e = z - H x                                    (equation error, z = Delta U, Eq. 24)
    x_i <- x_i + mu_i s_i^2 sum_j H_ji e_j / r_j   (one LMS step on sum_j e_j^2 / (2 r_j), per-state rate mu_i)
    x <- clip(x, lower, upper)                     (the Eq. 21 box; Paparazzi's bound_g_mat)

- *Equation-error space.* Paparazzi's error G Delta u - Delta omega-dot is the incremental model's equation error
  in acceleration space, linear in the entries it adapts. Our unknowns enter the same model as G_I Delta Acc =
  G_C Delta U: linear in x on the input side (Eq. 24), whereas in acceleration space they would enter as 1/I,
  with I_xx and I_zz coupled through J13 (Eq. 4). So the LMS step is taken on the input-side equation error, where
  the model is linear in the adapted parameters, as it is in Paparazzi's form for its parameters. The state is the
  paper's, so the Eq. 21 box, the stability floor and the logs apply unchanged.
- *Scaling* (Paparazzi's INDI_EST_SCALE / adaptive_mu_lr). The raw gradient mixes kg m^2, kg and (rad/s)^2 and
  entries 10^4 apart; as Paparazzi scales its inputs and G's so that one mu per axis means the same on every axis,
  the step is taken in normalised coordinates: each state relative to its value at the start (s_i = x0_i, i.e.
  relative to K = 1) and each row's error relative to its noise level (r_j = CKF_R_U1..5, the variances the KF
  weights with). In those coordinates the update is the plain LMS theta <- theta + mu_i H~^T e~, mu_i dimensionless
  (CKF_LMS_MU1..4, one per state as Paparazzi has one per axis: I_xx <-> roll, I_yy <-> pitch, I_zz <-> yaw,
  m <-> thrust). A constant scaling, not a normalised LMS (no division by |H|^2): that is what Paparazzi flies.
  It converges when mu_i |H~|^2 < 2; the clipping keeps it bounded when a large manoeuvre breaks that.
- *Clipping.* The Eq. 21 box lower = I_UAM / K_max <= x <= I_UAM / K_min is the analogue of bound_g_mat's
  factor-2 box: with K in [0.5, 1] it allows x in [x0, 2 x0], i.e. the effectiveness in [g0 / 2, g0]. It is applied
  component-wise (exactly Paparazzi's element-wise clip; the KF's minimum-variance projection needs a covariance the
  LMS does not have) every step, since the box moves with the arm pose.
- *Initialisation.* x0 = [J11, J22, J33, m_UAM] (K = 1, the model without object), as Paparazzi starts from the
  airframe's G; the law starts it after CKF_START_DLY (our in-flight condition: the FC resets the law on arming).
- *Not taken.* G2 (rotor inertia: our G has none; the tail's torque reaction is in G_C). The jerk gate of the thrust
  row (the law's saturation and excitation gates, CKF_SAT_GATE / CKF_EXC_*, apply to both estimators).
- No covariance: p_diag is reported as zeros; the Eq. 22 drift x += dt [I_dot_11, I_dot_22, I_dot_33, 0] is applied
  as in the KF's predict (it is known from the arm, not estimated). A non-finite step is not taken (x is held).

Pure core: numpy and numba; no I/O, no clocks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from navig8_fc.core import ckf_config, kalman
from navig8_fc.core.ckf_config import N_MEAS, N_STATE, CkfConfig
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.kalman import (
    SO_CORRECTED,
    SO_EXCITED,
    SO_INNOV,
    SO_P_DIAG,
    SO_X_HAT,
    SO_X_UNC,
    STEP_OUT,
    KfStepResult,
)

__all__ = ["LmsEstimator", "lms_step"]

# Return codes of lms_step
CLIP_INSIDE = 0  # the estimate was inside the box
CLIP_MOVED = 1  # the clipping moved it
CLIP_EMPTY_BOX = -1  # lower > upper (or a NaN bound)


@njit_cached(kalman, ckf_config)
def lms_step(x, scale2, mu, r_diag, dt, do_predict, id0, id1, id2, do_correct, exc_rot, exc_lin, gc_inv, du, da,
             rho_x, rho_z, lo, hi, out):
    """Drift (Eq. 22, if do_predict), one LMS step on the Eq. 24 equation error (if do_correct and some state passes
    the excitation gate; the others held), then the clip onto [lo, hi] (Eq. 21), on x in place; results into out
    (kalman.STEP_OUT, p_diag zeros). scale2 = s_i^2 (module docstring), mu the per-state rates. Returns a CLIP_*
    code."""
    if do_predict:
        x[0] += dt * id0
        x[1] += dt * id1
        x[2] += dt * id2
    mask = out[SO_EXCITED:SO_EXCITED + N_STATE]
    innovation = out[SO_INNOV:SO_INNOV + N_MEAS]
    n_exc = kalman.excitation_mask(da, exc_rot, exc_lin, mask) if do_correct else 0
    corrected = False
    if n_exc > 0:
        h = np.empty((N_MEAS, N_STATE))
        kalman._regressor(gc_inv, da, rho_x, rho_z, h)
        for j in range(N_MEAS):  # e = z - H x (the prior, as the KF's innovation)
            acc = 0.0
            for i in range(N_STATE):
                acc += h[j, i] * x[i]
            innovation[j] = du[j] - acc
        step = np.empty(N_STATE)
        finite = True
        for i in range(N_STATE):
            g = 0.0
            for j in range(N_MEAS):
                g += h[j, i] * innovation[j] / r_diag[j]  # gradient of sum_j e_j^2 / (2 r_j), sign: descent
            step[i] = mask[i] * mu[i] * scale2[i] * g
            if not math.isfinite(step[i]):
                finite = False
        if finite:  # a NaN/inf increment is not learned from (x held, as by the gates)
            for i in range(N_STATE):
                x[i] += step[i]
            corrected = True
    if not corrected:
        mask[:] = 0.0
        innovation[:] = 0.0
    out[SO_CORRECTED] = 1.0 if corrected else 0.0
    for i in range(N_STATE):
        out[SO_X_UNC + i] = x[i]
    code = CLIP_INSIDE
    for i in range(N_STATE):
        if not (lo[i] <= hi[i]):
            return CLIP_EMPTY_BOX
        if x[i] < lo[i]:  # element-wise, as Paparazzi's bound_g_mat: the Euclidean projection onto a box
            x[i] = lo[i]
            code = CLIP_MOVED
        elif x[i] > hi[i]:
            x[i] = hi[i]
            code = CLIP_MOVED
    for i in range(N_STATE):
        out[SO_X_HAT + i] = x[i]
        out[SO_P_DIAG + i] = 0.0
    return code


_ZERO3 = (0.0, 0.0, 0.0)


class LmsEstimator:
    """LMS with clipping on x = [I_xx, I_yy, I_zz, m] (CKF_MODE 4; module docstring). The interface the adaptive law
    uses from ConstrainedKalmanFilter: initialise, reset, step -> KfStepResult, n_updates, n_projection_fallbacks."""

    def __init__(self, config: CkfConfig) -> None:
        self.config = config
        self._mu = np.array(config.lms_mu)
        self._r = np.array(config.r_diag)
        self._dt = config.dt_s
        self._exc_rot, self._exc_lin = config.exc_rot_rad_s2, config.exc_lin_m_s2
        self._x = np.zeros(N_STATE)
        self._scale2 = np.ones(N_STATE)
        self._out = STEP_OUT.zeros()
        self._initialised = False
        self.n_updates = 0
        self.n_projection_fallbacks = 0  # always 0: the clip has no fallback (kept for the law's status)

    @property
    def initialised(self) -> bool:
        return self._initialised

    @property
    def x(self) -> np.ndarray:
        return self._x.copy()

    @property
    def p(self) -> np.ndarray:
        """No covariance: zeros (the law reports p_diag from it)."""
        return np.zeros((N_STATE, N_STATE))

    def initialise(self, x0: Sequence[float] | np.ndarray, p0: np.ndarray | None = None) -> None:
        """Start from x0 (normally [J11, J22, J33, m_UAM], K = 1); the normalisation s_i = x0_i is fixed here.
        p0 is accepted for the KF's signature and ignored."""
        x = np.array(x0, dtype=float)
        if x.shape != (N_STATE,):
            raise ValueError(f"x0 must have {N_STATE} components, got shape {x.shape}")
        if not np.all(np.isfinite(x)) or np.any(x <= 0.0):
            raise ValueError(f"x0 must be finite and > 0 (it scales the LMS step), got {x.tolist()}")
        self._x = x
        self._scale2 = x * x
        self._initialised = True
        self.n_updates = 0
        self.n_projection_fallbacks = 0

    def forget(self, x_new: Sequence[float] | np.ndarray | None = None) -> None:
        """A known change of the truth (the law's CKF_GRIP_RST): the estimate moves to x_new when given. LMS keeps no
        covariance, so there is nothing else to forget; the counters keep counting."""
        if not self._initialised:
            raise RuntimeError("LMS estimator not initialised")
        if x_new is not None:
            x = np.array(x_new, dtype=float)
            if x.shape != (N_STATE,) or not np.all(np.isfinite(x)):
                raise ValueError(f"x_new must be {N_STATE} finite values, got {x_new!r}")
            self._x[:] = x

    def reset(self) -> None:
        """Back to the uninitialised state; initialise() starts again."""
        self._initialised = False
        self.n_updates = 0
        self.n_projection_fallbacks = 0

    def step(
        self,
        delta_u: Sequence[float] | np.ndarray,
        delta_acc: Sequence[float] | np.ndarray,
        gc_uam_inv: np.ndarray,
        rho_x: float,
        rho_z: float,
        inertia_rate_diag: Sequence[float] | None,
        lower: Sequence[float],
        upper: Sequence[float],
        correct: bool = True,
        arm_moving: bool = False,
    ) -> KfStepResult:
        """Drift (skipped when inertia_rate_diag is None), one LMS step (when `correct`; the states that pass the
        excitation gate of the config), the clip onto [lower, upper], in one compiled call. Arguments as
        ConstrainedKalmanFilter.step (arm_moving, CKF_R_MOVE's, has no noise to scale here: ignored); n_updates counts
        the steps taken."""
        if not self._initialised:
            raise RuntimeError("LmsEstimator.step before initialise()")
        do_predict = inertia_rate_diag is not None
        i0, i1, i2 = inertia_rate_diag if do_predict else _ZERO3  # type: ignore[misc]
        code = lms_step(self._x, self._scale2, self._mu, self._r, self._dt, do_predict, i0, i1, i2, bool(correct),
                        self._exc_rot, self._exc_lin, np.ascontiguousarray(gc_uam_inv, dtype=float),
                        np.asarray(delta_u, dtype=float), np.asarray(delta_acc, dtype=float), float(rho_x),
                        float(rho_z), lower, upper, self._out)
        if code == CLIP_EMPTY_BOX:
            raise ValueError(f"empty box (or NaN bound): lower {list(lower)}, upper {list(upper)}")
        o = self._out.tolist()
        corrected = o[SO_CORRECTED] != 0.0
        self.n_updates += corrected
        exc = o[SO_EXCITED:SO_EXCITED + 4]
        return KfStepResult(tuple(o[SO_X_HAT:SO_X_HAT + 4]), tuple(o[SO_X_UNC:SO_X_UNC + 4]),
                            tuple(o[SO_INNOV:SO_INNOV + 5]), tuple(o[SO_P_DIAG:SO_P_DIAG + 4]),
                            code == CLIP_MOVED, False, corrected,
                            (exc[0] != 0.0, exc[1] != 0.0, exc[2] != 0.0, exc[3] != 0.0))
