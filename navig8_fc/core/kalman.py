"""Constrained Kalman filter for G_hat_I (paper Sec. 3.3, Fig. 3): predict (Eq. 22), correct (Eq. 23-24),
project onto the Eq. 21 box.

State and models
----------------
x = [I_hat_xx, I_hat_yy, I_hat_zz, m_hat] (kg m^2, kg m^2, kg m^2, kg).

- Motion model, Eq. 22: x[k] = x[k-1] + dt [I_dot_11, I_dot_22, I_dot_33, 0] + eps, with I_dot the rate of
  the UAM (no object) inertia tensor from the measured arm q, q_dot (the caller computes it), and a random
  walk for the mass. Q = diag(CKF_Q_*) is the process-noise covariance *per control step*.
- Measurement model, Eq. 23-24: z = Delta U = G_C,UAM^-1 G_hat_I Delta Acc_m + nu = H(Delta Acc_m) x + nu with
  the regressor H = G_C,UAM^-1 [v_xx v_yy v_zz v_m] (5x4), v_xx = [a1, 0, rho_x a1, 0, 0], v_yy = [0, a2, 0, 0, 0],
  v_zz = [rho_z a3, 0, a3, 0, 0], v_m = [0, 0, 0, a4, a5], rho_x = J13/J11, rho_z = J13/J33 of the UAM
  inertia (notes 2.4). This is Eq. 24 with m_hat in place of the printed m_UAM (with m_UAM the mass would
  be unobservable), written with a generic 5x5 G_C,UAM^-1 instead of the paper's symmetry-reduced rows.
- Constraint, Eq. 21: I_UAM / K_max <= x <= I_UAM / K_min component-wise (Eq. 20: 0.5 <= K <= 1). The box
  moves with the arm pose; the caller (adaptive_law.py) supplies it every step.
- Nuisance states (kf_nuisance.py), each with a prior while an object is held: the pitch row's CoM-height error
  (CKF_CZ_SIG, kf_correct_pitch) and the roll and yaw rows' I_xz error (CKF_IXZ_SIG, a fifth state of kf_correct).

Constrained filter (estimate projection, Simon 2010; notes 5)
--------------------------------------------------------------
Predict, correct (Joseph form, symmetric P), then project the corrected estimate x_hat onto the box
(box_qp.py): x_tilde = argmin (x - x_hat)^T W (x - x_hat) s.t. lower <= x <= upper, with W = P^-1
(minimum-variance projection, default) or W = I (Euclidean: exactly component-wise clipping). x_tilde is fed
into the next predict. P is kept unreduced: the projection moves the mean only. Reducing P on the active set
(P - P D^T (D P D^T)^-1 D P) would claim that the bound is a perfect measurement and make the filter
over-confident and slow to leave a bound; the paper does not say which it does (notes 5). When x_hat is
already inside the box the projection is x_hat itself and no QP is solved (exact, and the common case).

One API: `predict`, `correct`, `project` and `step` (all three in one compiled call, the adaptive law's
tick). Each stage is one numba kernel; `step`'s kernel calls the same three. The kernels that reach
box_qp's kernels or linalg.inv_gauss_jordan (and kf_step, which reads ckf_config's vector sizes) are cached by
jit.njit_cached, so that numba's on-disk cache follows changes in those modules. The configuration (CkfConfig,
CkfMode, the CKF_* parameters) is ckf_config.py's.

Pure core: numpy and numba; no I/O, no clocks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numba import njit

from navig8_fc.core import box_qp, ckf_config, kf_nuisance, linalg
from navig8_fc.core.box_qp import ProjectionResult
from navig8_fc.core.ckf_config import N_MEAS, N_STATE, CkfConfig
from navig8_fc.core.force_balance import correct_mass
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.kf_nuisance import NZ_COV, NZ_SIZE, NZ_VAR, NZ_X, augment, ixz_column, unaugment
from navig8_fc.core.kf_nuisance import mul as _mul
from navig8_fc.core.layout import layout

__all__ = [
    "ConstrainedKalmanFilter",
    "KfStepResult",
    "ProjectionResult",
    "eq22_drift",
    "inertia_ratios",
    "measurement_matrix",
]


def inertia_ratios(j11: float, j13: float, j33: float) -> tuple[float, float]:
    """(rho_x, rho_z) = (J13/J11, J13/J33) of the UAM inertia tensor J (notes 2.4, Eq. 24)."""
    return j13 / j11, j13 / j33


def eq22_drift(
    j_diag: tuple[float, float, float], inertia_rate: np.ndarray,
    object_inertia_rate: tuple[float, float, float] | None, j_prev: tuple[float, float, float] | None, inv_dt: float,
) -> tuple[float, float, float]:
    """Eq. 22's drift [I_dot_11, I_dot_22, I_dot_33]: the model's I-dot (j_prev None), or (CKF_PRED_DJ) the tick's
    change of J's diagonal from j_prev plus the estimated object's I-dot."""
    # CKF_PRED_DJ: the drift is the tick's own change of J plus the estimated object's I-dot (it moves with the
    # arm), so that x follows the model exactly where it is right. The model's I-dot of J from the measured joint
    # rates integrates to less or more than J's change, because J is evaluated at the joint observer's q, which
    # also moves by its correction toward the measured q: each 40 deg arm reversal of the paper scenario moved K3
    # by -0.05 (K3 0.74 at 23 s with no object); and it leaves out the held object, whose inertia changes most
    # with the arm's pose. The object's share is its rate at the estimated mass (a change of the mass estimate
    # itself moves no inertia).
    if j_prev is not None:
        j11, j22, j33 = j_diag
        ob = object_inertia_rate or (0.0, 0.0, 0.0)
        return ((j11 - j_prev[0]) * inv_dt + ob[0], (j22 - j_prev[1]) * inv_dt + ob[1],
                (j33 - j_prev[2]) * inv_dt + ob[2])
    return (inertia_rate.item(0), inertia_rate.item(4), inertia_rate.item(8))


# --------------------------------------------------------------------------------------------------
# Kernels: regressor (Eq. 24), predict (Eq. 22), correct, project (Eq. 21), and the three in one step
# --------------------------------------------------------------------------------------------------


@njit(cache=True)
def _regressor(gc_inv, da, rho_x, rho_z, h):
    """H = G_C,UAM^-1 [v_xx v_yy v_zz v_m] (5x4) into h, from Delta Acc_m = da (Eq. 24; only the non-zero
    entries of the v's enter the products)."""
    a1, a2, a3, a4, a5 = da[0], da[1], da[2], da[3], da[4]
    for i in range(5):
        h[i, 0] = gc_inv[i, 0] * a1 + gc_inv[i, 2] * (rho_x * a1)
        h[i, 1] = gc_inv[i, 1] * a2
        h[i, 2] = gc_inv[i, 0] * (rho_z * a3) + gc_inv[i, 2] * a3
        h[i, 3] = gc_inv[i, 3] * a4 + gc_inv[i, 4] * a5


@njit(cache=True)
def kf_predict(x, p, q_diag, dt, id0, id1, id2):
    """Eq. 22: x- = x + dt [I_dot_11, I_dot_22, I_dot_33, 0]; P- = P + diag(Q). In place."""
    x[0] += dt * id0
    x[1] += dt * id1
    x[2] += dt * id2
    for i in range(4):
        p[i, i] += q_diag[i]


@njit_cached(box_qp, linalg, kf_nuisance)
def kf_correct(x, p, r_diag, gc_inv, du, da, rho_x, rho_z, mask, innovation, pitch_r=0.0, nz=None, hm=None,
               pitch_y=math.nan, nx=None, com_dm_x=0.0, com_dm_z=0.0):
    """Measurement update z = Delta U = H(Delta Acc_m) x + nu (Eq. 24): K = P H^T S^-1, S = H P H^T + R
    (a solve, no inverse), x += K (z - H x), P = (I - K H) P (I - K H)^T + K R K^T (Joseph form: PSD under
    rounding), symmetrised. x (4,), p (4, 4) in place; innovation (5,) written.

    mask (4,): row i of K is multiplied by mask[i]; 0 holds state i (a Schmidt "consider" state: H still predicts
    with it, and the Joseph form gives the exact covariance of the masked, suboptimal gain), 1 is the KF.

    S >= R > 0 for finite inputs, so it always factorises; a non-finite S (a NaN/inf measurement) cannot, and
    x and P become NaN, as the LAPACK solve's result was. Returns False then.

    pitch_r > 0 (CKF_R_PITCH, (N m)^2): I_yy is held in the Delta U update above and corrected instead from the pitch
    row of Eq. 24 taken back to moment space, G_C[M, :] Delta U = I_yy Delta Q-dot (G_I's pitch row has I_yy alone),
    a scalar update with noise variance pitch_r (kf_correct_pitch); pitch_r < 0: I_yy held (not corrected).
    nz (NZ_SIZE,): the pitch row's nuisance state, the CoM-height error of a held object (kf_correct_pitch); its
    cross-covariance with x follows this update too. None: no nuisance state.
    hm (5,): added to H's mass column, the rows' linearised dependence on m beyond Eq. 24's force rows (the modelled
    object's I_xz in the roll and yaw rows, CKF_IXZ_MOD 2; the caller adds hm m_hat to du, so the innovation is the
    one without it). None: Eq. 24's H. pitch_y: the pitch row's moment increment when given (CKF_MOM_LPF; nan:
    G_C[M, :] Delta U). nx (NZ_SIZE,): the roll and yaw rows' I_xz nuisance (CKF_IXZ_SIG, kf_nuisance); with a
    variance > 0 it is a fifth state of this update (H's fifth column kf_nuisance.ixz_column, never masked; its
    covariance with the pitch nuisance taken as zero). com_dm_x, com_dm_z: the pitch row's mass column (CKF_CZ_DM,
    kf_correct_pitch)."""
    na = 4
    if nx is not None:
        if nx[NZ_VAR] > 0.0:
            na = 5
    h = np.zeros((5, na))
    _regressor(gc_inv, da, rho_x, rho_z, h)
    if hm is not None:
        for i in range(5):
            h[i, 3] += hm[i]
    xa = x
    pa = p
    if nx is not None:
        if na == 5:
            ixz_column(gc_inv, da, h, 4)
            xa = np.empty(5)
            pa = np.empty((5, 5))
            augment(x, p, nx, xa, pa)
    pht = np.empty((na, 5))
    _mul(pa, h.T, pht)
    for i in range(5):
        acc = 0.0
        for k in range(na):
            acc += h[i, k] * xa[k]
        innovation[i] = du[i] - acc
    # [S | P H^T^T] -> [. | K^T] by Gaussian elimination (S K^T = H P).
    aug = np.empty((5, 5 + na))
    _mul(h, pht, aug[:, :5])
    for i in range(5):
        aug[i, i] += r_diag[i]
        for j in range(na):
            aug[i, 5 + j] = pht[j, i]
    if not box_qp.gauss_solve_inplace(aug, 5):
        x[:] = np.nan
        p[:, :] = np.nan
        return False
    gain = aug[:, 5:].T  # K (na x 5), a view
    m1 = mask[1]
    if pitch_r != 0.0:
        m1 = 0.0  # I_yy: the pitch-moment row below (pitch_r > 0), or held (< 0)
    for i in range(4):
        mi = m1 if i == 1 else mask[i]
        for k in range(5):
            gain[i, k] *= mi
    for i in range(na):
        acc = 0.0
        for k in range(5):
            acc += gain[i, k] * innovation[k]
        xa[i] += acc
    ikh = np.empty((na, na))
    _mul(gain, h, ikh)
    for i in range(na):
        for j in range(na):
            ikh[i, j] = (1.0 if i == j else 0.0) - ikh[i, j]
    t1 = np.empty((na, na))
    _mul(ikh, pa, t1)
    pn = np.empty((na, na))
    _mul(t1, ikh.T, pn)
    gr = np.empty((na, 5))
    for i in range(na):
        for k in range(5):
            gr[i, k] = gain[i, k] * r_diag[k]
    krk = np.empty((na, na))
    _mul(gr, gain.T, krk)
    for i in range(na):
        for j in range(na):
            pn[i, j] += krk[i, j]
    for i in range(na):
        for j in range(na):
            pa[i, j] = 0.5 * (pn[i, j] + pn[j, i])
    if nx is not None:
        if na == 5:
            unaugment(xa, pa, x, p, nx)
    if nz is not None:  # cov(x, c) <- (I - K H) cov(x, c): c is not measured by this update
        kf_nuisance.cov_transform(ikh, nz)
    if pitch_r > 0.0 and mask[1] != 0.0:
        return kf_nuisance.kf_correct_pitch(x, p, pitch_r, gc_inv, du, da[1], nz, pitch_y, nx, com_dm_x, com_dm_z)
    return True


# Return codes of kf_project
PROJ_INSIDE = 0
PROJ_SOLVED = 1
PROJ_FALLBACK = 2  # box_qp's enumeration answered
PROJ_EMPTY_BOX = -1
PROJ_FAILED = -2  # no feasible candidate (cannot happen for SPD W and a non-empty box)


@njit_cached(box_qp, linalg)
def kf_project(x, p, identity, lo, hi):
    """Eq. 21: x <- argmin (x' - x)^T W (x' - x) over the box (box_qp.solve), W = P^-1 or I (identity, or
    when P is singular). P is not touched. Returns a PROJ_* code."""
    n = x.shape[0]
    inside = True
    for i in range(n):
        if not (lo[i] <= hi[i]):
            return PROJ_EMPTY_BOX
        if not (lo[i] <= x[i] <= hi[i]):
            inside = False
    if inside:
        return PROJ_INSIDE
    w = np.empty((n, n))
    pl = np.empty((n, n))  # W^-1 = P, or I: makes the face solves cheaper
    use_pl = True
    if not identity:
        if linalg.inv_gauss_jordan(p, w):
            for i in range(n):
                for j in range(n):
                    if not math.isfinite(w[i, j]):
                        use_pl = False
        else:
            use_pl = False
    if use_pl and not identity:
        pl[:, :] = p
    else:  # W = I: asked for, or P singular (possible only with Q = 0 and P0 = 0, when x cannot move anyway)
        for i in range(n):
            for j in range(n):
                w[i, j] = 1.0 if i == j else 0.0
                pl[i, j] = w[i, j]
    xh = x.copy()
    usable = True
    for i in range(n):
        if not (math.isfinite(xh[i]) and w[i, i] > 0.0):
            usable = False
    if usable:
        code = box_qp.solve(xh, w, pl, use_pl, lo, hi, x)
    else:  # a non-finite estimate or a W that is not positive definite: the enumeration (a fallback)
        code = box_qp.SOLVED_BY_ENUMERATION if box_qp.enumerate_faces(xh, w, lo, hi, x) else box_qp.NO_SOLUTION
    if code == box_qp.NO_SOLUTION:
        x[:] = xh
        return PROJ_FAILED
    return PROJ_FALLBACK if code == box_qp.SOLVED_BY_ENUMERATION else PROJ_SOLVED


# Output of kf_step
STEP_OUT = layout("STEP_OUT", x_hat=N_STATE, x_unconstrained=N_STATE, innovation=N_MEAS, p_diag=N_STATE,
                  excited=N_STATE, corrected=1)
SO_X_HAT = STEP_OUT.X_HAT
SO_X_UNC = STEP_OUT.X_UNCONSTRAINED
SO_INNOV = STEP_OUT.INNOVATION
SO_P_DIAG = STEP_OUT.P_DIAG
SO_EXCITED = STEP_OUT.EXCITED  # 1.0 per state whose regressor passed the excitation gate (0 when not correcting)
SO_CORRECTED = STEP_OUT.CORRECTED  # 1.0 when a measurement update ran (some state excited)


@njit(cache=True)
def excitation_mask(da, exc_rot, exc_lin, mask):
    """The excitation gate (CkfConfig.exc_*): mask[i] = 1.0 when state i's regressor increment is at least the
    threshold (|da[0]|, |da[1]|, |da[2]| >= exc_rot for I_xx, I_yy, I_zz; |(da[3], da[4])| >= exc_lin for m), else
    0.0. Returns the number of excited states. Zero thresholds pass everything (the paper)."""
    n = 0
    for i in range(3):
        mask[i] = 1.0 if abs(da[i]) >= exc_rot else 0.0
        n += int(mask[i])
    mask[3] = 1.0 if math.sqrt(da[3] * da[3] + da[4] * da[4]) >= exc_lin else 0.0
    return n + int(mask[3])


@njit_cached(box_qp, linalg, ckf_config, kf_nuisance)
def kf_step(x, p, q_diag, r_diag, dt, do_predict, id0, id1, id2, do_correct, exc_rot, exc_lin, gc_inv, du, da,
            rho_x, rho_z, constrained, identity, lo, hi, out, pitch_r=0.0, nz=None, hm=None, pitch_y=math.nan,
            nx=None, com_dm_x=0.0, com_dm_z=0.0, apart=-1):
    """predict (if do_predict), correct (if do_correct and some state passes the excitation gate; the others
    held), project (if constrained) on x, p in place; results into out (STEP_OUT). Returns the PROJ_* code.
    apart >= 0 (CKF_PROJ_IYY: I_yy, 1): that state's covariances with the others are left out of the projection's
    weight (project_apart)."""
    if do_predict:
        kf_predict(x, p, q_diag, dt, id0, id1, id2)
    mask = out[SO_EXCITED:SO_EXCITED + N_STATE]
    innovation = out[SO_INNOV:SO_INNOV + N_MEAS]
    n_exc = excitation_mask(da, exc_rot, exc_lin, mask) if do_correct else 0
    if n_exc > 0:
        kf_correct(x, p, r_diag, gc_inv, du, da, rho_x, rho_z, mask, innovation, pitch_r, nz, hm, pitch_y, nx, com_dm_x,
                   com_dm_z)
        out[SO_CORRECTED] = 1.0
    else:
        mask[:] = 0.0
        innovation[:] = 0.0
        out[SO_CORRECTED] = 0.0
    for i in range(N_STATE):
        out[SO_X_UNC + i] = x[i]
    code = PROJ_INSIDE
    if constrained:
        code = kf_project(x, p, identity, lo, hi) if apart < 0 else project_apart(x, p, identity, lo, hi, apart)
    for i in range(N_STATE):
        out[SO_X_HAT + i] = x[i]
        out[SO_P_DIAG + i] = p[i, i]
    return code


@njit_cached(box_qp, linalg)
def project_apart(x, p, identity, lo, hi, apart):
    """kf_project (Eq. 21) with the state `apart`'s covariances with the others zeroed in the weight's P (P itself not
    touched): W = P^-1 is then block-diagonal, that state is clipped to its own bounds and the others are projected
    among themselves. Why for I_yy with the moment-space pitch row (CKF_PROJ_IYY): the Delta U rows do not correct
    I_yy (Schmidt, kf_correct) but leave it correlated with the mass through its prediction in their innovation, and
    their pitch component carries the trim's move as the arm shifts the CoM (docs/model.md, "Estimator" item 13), which
    can take the mass out of its box by 3 sigma in one window; W = P^-1 then moved I_yy by P_ym / P_mm of that
    violation (0.03 kg m^2, K2 -0.06, back at the next window), inertia information the pitch row never gave."""
    pw = p.copy()
    for j in range(x.shape[0]):
        if j != apart:
            pw[apart, j] = 0.0
            pw[j, apart] = 0.0
    return kf_project(x, pw, identity, lo, hi)


def measurement_matrix(
    gc_uam_inv: np.ndarray, delta_acc: Sequence[float] | np.ndarray, rho_x: float, rho_z: float
) -> np.ndarray:
    """The regressor H (5x4) with Delta U = H x, x = [I_xx, I_yy, I_zz, m] (Eq. 24, notes 2.4); equals
    G_C,UAM^-1 @ estimated_gi(J, x) @ Delta Acc for every x. The kernel kf_correct uses."""
    h = np.empty((N_MEAS, N_STATE))
    _regressor(np.ascontiguousarray(gc_uam_inv, dtype=float), np.asarray(delta_acc, dtype=float), float(rho_x),
               float(rho_z), h)
    return h


# --------------------------------------------------------------------------------------------------
# The filter
# --------------------------------------------------------------------------------------------------


class KfStepResult(NamedTuple):
    """One step() of the filter, as plain floats (the adaptive law logs them as they are)."""

    x_hat: tuple[float, ...]  # (4,) estimate after the step (projected when constrained)
    x_unconstrained: tuple[float, ...]  # (4,) corrected estimate before projection
    innovation: tuple[float, ...]  # (5,) Delta U - H x_prior
    p_diag: tuple[float, ...]  # (4,) diagonal of the (unreduced) posterior covariance
    projected: bool  # the projection moved the estimate
    used_fallback: bool  # box_qp's enumeration answered the projection
    corrected: bool = True  # a measurement update ran (False: predict and project only, or nothing excited)
    excited: tuple[bool, ...] = (True,) * N_STATE  # the states the update corrected (the excitation gate)


_ZERO3 = (0.0, 0.0, 0.0)
_ONES4 = np.ones(N_STATE)


class ConstrainedKalmanFilter:
    """KF on x = [I_xx, I_yy, I_zz, m] with Eq. 22 (predict), Eq. 24 (correct) and the Eq. 21 projection
    (constrained mode; CkfConfig.mode)."""

    def __init__(self, config: CkfConfig) -> None:
        self.config = config
        self._q = np.array(config.q_diag)
        self._r = np.array(config.r_diag)
        self._dt = config.dt_s
        self._constrained = config.constrained
        self._identity_weight = config.projection_weight == "identity"
        self._exc_rot, self._exc_lin = config.exc_rot_rad_s2, config.exc_lin_m_s2
        self._pitch_r = config.pitch_r_nm2
        # CKF_R_MOVE: the noise variances while the arm moves (step's arm_moving), scaled once here, not every tick
        self._r_move = self._r * config.r_move_scale
        self._pitch_r_move = config.pitch_r_nm2 * config.r_move_scale
        # CKF_PROJ_IYY: I_yy (state 1) projected apart, with the moment-space pitch row only (its sole corrector)
        self._apart = 1 if config.iyy_projected_apart and config.pitch_r_nm2 > 0.0 else -1
        self._nz = np.zeros(NZ_SIZE)  # the pitch row's nuisance state (kf_correct_pitch): zero until an object is held
        self._nx = np.zeros(NZ_SIZE)  # the roll and yaw rows' I_xz nuisance (kf_nuisance): zero until an object is held
        self._x = np.zeros(N_STATE)
        self._p = np.diag(config.p0_scale * self._q)
        self._out = STEP_OUT.zeros()
        self._initialised = False
        self.n_updates = 0
        self.n_projection_fallbacks = 0

    @property
    def initialised(self) -> bool:
        return self._initialised

    @property
    def x(self) -> np.ndarray:
        return self._x.copy()

    @property
    def p(self) -> np.ndarray:
        return self._p.copy()

    def initialise(self, x0: Sequence[float] | np.ndarray, p0: np.ndarray | None = None) -> None:
        """Start from x0 (normally [J11, J22, J33, m_UAM], i.e. K = 1) and P0 = p0_scale * diag(Q)."""
        x = np.array(x0, dtype=float)
        if x.shape != (N_STATE,):
            raise ValueError(f"x0 must have {N_STATE} components, got shape {x.shape}")
        self._x = x
        self._p = np.diag(self.config.p0_scale * self._q) if p0 is None else np.array(p0, dtype=float)
        self._nz[:] = 0.0
        self._nx[:] = 0.0
        self._initialised = True
        self.n_updates = 0
        self.n_projection_fallbacks = 0

    def forget(self, x_new: Sequence[float] | np.ndarray | None = None) -> None:
        """Forget what was learned: P back to P0 = p0_scale * diag(Q), and the estimate moved to x_new when given
        (a known change of the truth, e.g. a released object). The counters keep counting."""
        self._require_initialised()
        if x_new is not None:
            x = np.array(x_new, dtype=float)
            if x.shape != (N_STATE,) or not np.all(np.isfinite(x)):
                raise ValueError(f"x_new must be {N_STATE} finite values, got {x_new!r}")
            self._x[:] = x
        self._p[:, :] = np.diag(self.config.p0_scale * self._q)
        self._nz[NZ_COV:] = 0.0
        self._nx[NZ_COV:] = 0.0

    def correct_mass(self, z_kg: float, r_kg2: float) -> None:
        """A direct measurement of the mass, z = m + v, var v = r_kg2 (force_balance.correct_mass)."""
        correct_mass(self._x, self._p, self._nz, self._nx, z_kg, r_kg2)

    def raise_variance(self, var_min: Sequence[float]) -> None:
        """P's diagonal raised to at least var_min (4,) (a prior wider than P0 after a known change of the truth)."""
        self._require_initialised()
        for i, v in enumerate(var_min):
            self._p[i, i] = max(self._p[i, i], float(v))

    def lower_variance(self, var_max: Sequence[float]) -> None:
        """P's diagonal lowered to at most var_max (4,) (a prior narrower than P0 where the truth is known better), as
        P <- D P D with D = diag(min(1, sqrt(var_max / P_ii))): the correlations are kept and P stays PSD."""
        self._require_initialised()
        d = np.ones(N_STATE)
        for i, v in enumerate(var_max):
            if 0.0 < float(v) < self._p[i, i]:
                d[i] = math.sqrt(float(v) / self._p[i, i])
        self._p[:, :] = d[:, None] * self._p * d[None, :]

    def object_held(self, held: bool, com_sigma_m: float, iyy_var_min: float) -> None:
        """The pitch row's prior on a grasp (held) or a release: while an object is held, the CoM-height error of the
        law's reference point is a nuisance state of prior N(0, com_sigma_m^2) (kf_correct_pitch) and I_yy's variance is
        raised to at least iyy_var_min (a held object may move I_yy anywhere in the box); with none held the nuisance
        is zero, with zero variance."""
        self._require_initialised()
        self._nz[:] = 0.0
        if held:
            self._nz[NZ_VAR] = com_sigma_m * com_sigma_m
            self._p[1, 1] = max(self._p[1, 1], iyy_var_min)

    def ixz_held(self, held: bool, ixz_sigma_kgm2: float) -> None:
        """The roll and yaw rows' prior on a grasp (held) or a release: while an object is held, the error of the
        modelled I_xz is a nuisance state of prior N(0, ixz_sigma_kgm2^2) (kf_nuisance, kf_correct's nx); with none
        held it is zero, with zero variance (the UAM's I_xz is known)."""
        self._require_initialised()
        self._nx[:] = 0.0
        if held:
            self._nx[NZ_VAR] = ixz_sigma_kgm2 * ixz_sigma_kgm2

    def move_pitch_reference(self, dz_m: float) -> None:
        """CKF_CZ_FOLLOW: the pitch row's reference point moved down by dz_m (m, body z) with the mass estimate while
        that row's CoM error is its nuisance alone (no mass column): the nuisance, the true CoM's height less the
        point's (kf_correct_pitch), moves by -dz_m, a known shift (its variance and covariances unchanged). Nothing
        while no object is held (the nuisance is zero then)."""
        if self._nz[NZ_VAR] > 0.0:
            self._nz[NZ_X] -= dz_m

    @property
    def ixz_offset_kgm2(self) -> float:
        """The I_xz nuisance estimate (kg m^2): the true I_xz minus the modelled one (0: none held)."""
        return float(self._nx[NZ_X])

    @property
    def pitch_com_offset_m(self) -> float:
        """The pitch row's nuisance estimate (m): the CoM-height error of the law's reference point (0: none held)."""
        return float(self._nz[NZ_X])

    def reset(self) -> None:
        """Back to the uninitialised state; initialise() starts again."""
        self._initialised = False
        self.n_updates = 0
        self.n_projection_fallbacks = 0

    def _account(self, code: int, lower: Sequence[float], upper: Sequence[float]) -> None:
        """Count a fallback, raise on a failed projection (kf_project's PROJ_* code)."""
        if code == PROJ_FALLBACK:
            self.n_projection_fallbacks += 1
        elif code == PROJ_EMPTY_BOX:
            raise ValueError(f"empty box (or NaN bound): lower {list(lower)}, upper {list(upper)}")
        elif code == PROJ_FAILED:
            raise np.linalg.LinAlgError("box projection: no feasible candidate")

    def _require_initialised(self) -> None:
        if not self._initialised:
            raise RuntimeError("ConstrainedKalmanFilter used before initialise()")

    def predict(self, inertia_rate_diag: Sequence[float] | np.ndarray) -> None:
        """Eq. 22: x- = x + dt [I_dot_11, I_dot_22, I_dot_33, 0];  P- = P + Q."""
        self._require_initialised()
        d = np.asarray(inertia_rate_diag, dtype=float)
        if d.shape != (3,):
            raise ValueError(f"inertia_rate_diag needs 3 components, got shape {d.shape}")
        kf_predict(self._x, self._p, self._q, self._dt, float(d[0]), float(d[1]), float(d[2]))

    def correct(
        self,
        delta_u: Sequence[float] | np.ndarray,
        delta_acc: Sequence[float] | np.ndarray,
        gc_uam_inv: np.ndarray,
        rho_x: float,
        rho_z: float,
    ) -> np.ndarray:
        """Measurement update with z = Delta U and the regressor H(Delta Acc_m) of Eq. 24 (Joseph form).
        Returns the innovation z - H x_prior."""
        self._require_initialised()
        innovation = np.empty(N_MEAS)
        kf_correct(self._x, self._p, self._r, np.ascontiguousarray(gc_uam_inv, dtype=float),
                   np.asarray(delta_u, dtype=float), np.asarray(delta_acc, dtype=float), float(rho_x),
                   float(rho_z), _ONES4, innovation, self._pitch_r, self._nz, None, math.nan, self._nx, 0.0, 0.0)
        self.n_updates += 1
        return innovation

    def project(self, lower: Sequence[float] | np.ndarray, upper: Sequence[float] | np.ndarray) -> ProjectionResult:
        """Eq. 21 by estimate projection; x <- x_tilde, P unchanged (module docstring). Any mode."""
        self._require_initialised()
        lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        code = kf_project(self._x, self._p, self._identity_weight, lo, hi)
        self._account(code, lo, hi)
        return ProjectionResult(self._x.copy(), code != PROJ_INSIDE, code == PROJ_FALLBACK, 0)

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
        pitch: bool = True,
        h_mass: np.ndarray | None = None,
        pitch_y: float = math.nan,
        com_dm: tuple[float, float] = (0.0, 0.0),
        arm_moving: bool = False,
    ) -> KfStepResult:
        """predict (skipped when inertia_rate_diag is None, e.g. on the first tick: x0 already describes the
        current pose), correct (when `correct`; only the states that pass the excitation gate of the config),
        then project onto [lower, upper] if constrained, in one compiled call.

        delta_u, delta_acc: float64 arrays (5,); gc_uam_inv (5, 5) float64; lower/upper: 4 floats each, ignored
        unless constrained. n_updates counts the
        corrections that ran. pitch False: with the moment-space pitch row (CKF_R_PITCH > 0), I_yy is not corrected
        this step (held, as the gate holds a state). h_mass (5,) float64: added to H's mass column (kf_correct's hm),
        delta_u then carrying h_mass m_hat. pitch_y: the pitch row's moment increment (kf_correct_pitch; nan: from
        delta_u). com_dm: (dc_x/dm, dc_z/dm) (m/kg), the slope of the pitch row's reference point in the mass estimate
        (CKF_CZ_DM, kf_correct_pitch; zeros: none). arm_moving: the noise variances are CKF_R_MOVE times R (the Delta U
        rows' and the pitch row's) this step.
        """
        if not self._initialised:
            raise RuntimeError("ConstrainedKalmanFilter.step before initialise()")
        do_predict = inertia_rate_diag is not None
        i0, i1, i2 = inertia_rate_diag if do_predict else _ZERO3  # type: ignore[misc]
        # the box as arrays, as project() and box_qp's callers pass it: one compilation of the projection's kernels
        r, pitch_r = (self._r_move, self._pitch_r_move) if arm_moving else (self._r, self._pitch_r)
        code = kf_step(self._x, self._p, self._q, r, self._dt, do_predict, i0, i1, i2, bool(correct),
                       self._exc_rot, self._exc_lin, gc_uam_inv, delta_u, delta_acc, rho_x, rho_z, self._constrained,
                       self._identity_weight, np.array(lower, dtype=float), np.array(upper, dtype=float), self._out,
                       pitch_r if pitch or pitch_r <= 0.0 else -1.0, self._nz, h_mass, pitch_y, self._nx,
                       com_dm[0], com_dm[1], self._apart)
        self._account(code, lower, upper)
        o = self._out.tolist()
        corrected = o[SO_CORRECTED] != 0.0
        self.n_updates += corrected
        exc = o[SO_EXCITED:SO_EXCITED + 4]
        return KfStepResult(tuple(o[SO_X_HAT:SO_X_HAT + 4]), tuple(o[SO_X_UNC:SO_X_UNC + 4]),
                            tuple(o[SO_INNOV:SO_INNOV + 5]), tuple(o[SO_P_DIAG:SO_P_DIAG + 4]),
                            code != PROJ_INSIDE, code == PROJ_FALLBACK, corrected,
                            (exc[0] != 0.0, exc[1] != 0.0, exc[2] != 0.0, exc[3] != 0.0))
