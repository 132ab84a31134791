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
box_qp's kernels or linalg.inv_gauss_jordan are cached by jit.njit_cached, so that numba's on-disk cache
follows changes in those modules.

Pure core: numpy and numba; no I/O, no clocks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal, NamedTuple

import numpy as np
from numba import njit

from navig8_fc.core import box_qp, linalg
from navig8_fc.core.box_qp import ProjectionResult
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.layout import layout

__all__ = [
    "CKF_PARAM_NAMES",
    "CkfConfig",
    "CkfMode",
    "ConstrainedKalmanFilter",
    "KfStepResult",
    "ProjectionResult",
    "inertia_ratios",
    "measurement_matrix",
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
    "CKF_LMS_MU1", "CKF_LMS_MU2", "CKF_LMS_MU3", "CKF_LMS_MU4",
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
        for name in ("p0_scale", "lpf_tau_s", "start_delay_s", "exc_rot_rad_s2", "exc_lin_m_s2"):
            v = float(getattr(self, name))
            if not (v >= 0.0 and math.isfinite(v)):
                raise ValueError(f"{name} must be finite and >= 0, got {v}")
            object.__setattr__(self, name, v)
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
        for flag in ("CKF_SAT_GATE", "CKF_U_SRC", "CKF_ACC_REF", "CKF_GRIP_RST", "CKF_PRED_DJ", "CKF_GC_REF"):
            if int(values[flag]) not in (0, 1):
                raise ValueError(f"{flag} must be 0 or 1, got {values[flag]}")
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
            acc_at_com=bool(int(values["CKF_ACC_REF"])),
            k_pin=tuple(float(values[f"CKF_K_PIN{i}"]) for i in range(1, 5)),
            grip_reset=bool(int(values["CKF_GRIP_RST"])),
            predict_from_dj=bool(int(values["CKF_PRED_DJ"])),
            gc_at_com=bool(int(values["CKF_GC_REF"])),
            lms_mu=tuple(float(values[f"CKF_LMS_MU{i}"]) for i in range(1, 5)),
        )


def inertia_ratios(j11: float, j13: float, j33: float) -> tuple[float, float]:
    """(rho_x, rho_z) = (J13/J11, J13/J33) of the UAM inertia tensor J (notes 2.4, Eq. 24)."""
    return j13 / j11, j13 / j33


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
def _mul(a, b, out):
    """out = a @ b (plain loops: the summation order of every product here is fixed; b may be a transposed
    view)."""
    for i in range(a.shape[0]):
        for j in range(b.shape[1]):
            acc = 0.0
            for k in range(a.shape[1]):
                acc += a[i, k] * b[k, j]
            out[i, j] = acc


@njit(cache=True)
def kf_predict(x, p, q_diag, dt, id0, id1, id2):
    """Eq. 22: x- = x + dt [I_dot_11, I_dot_22, I_dot_33, 0]; P- = P + diag(Q). In place."""
    x[0] += dt * id0
    x[1] += dt * id1
    x[2] += dt * id2
    for i in range(4):
        p[i, i] += q_diag[i]


@njit_cached(box_qp, linalg)
def kf_correct(x, p, r_diag, gc_inv, du, da, rho_x, rho_z, mask, innovation):
    """Measurement update z = Delta U = H(Delta Acc_m) x + nu (Eq. 24): K = P H^T S^-1, S = H P H^T + R
    (a solve, no inverse), x += K (z - H x), P = (I - K H) P (I - K H)^T + K R K^T (Joseph form: PSD under
    rounding), symmetrised. x (4,), p (4, 4) in place; innovation (5,) written.

    mask (4,): row i of K is multiplied by mask[i]; 0 holds state i (a Schmidt "consider" state: H still predicts
    with it, and the Joseph form gives the exact covariance of the masked, suboptimal gain), 1 is the KF.

    S >= R > 0 for finite inputs, so it always factorises; a non-finite S (a NaN/inf measurement) cannot, and
    x and P become NaN, as the LAPACK solve's result was. Returns False then."""
    h = np.empty((5, 4))
    _regressor(gc_inv, da, rho_x, rho_z, h)
    pht = np.empty((4, 5))
    _mul(p, h.T, pht)
    for i in range(5):
        acc = 0.0
        for k in range(4):
            acc += h[i, k] * x[k]
        innovation[i] = du[i] - acc
    # [S | P H^T^T] -> [. | K^T] by Gaussian elimination (S K^T = H P).
    aug = np.empty((5, 9))
    _mul(h, pht, aug[:, :5])
    for i in range(5):
        aug[i, i] += r_diag[i]
        for j in range(4):
            aug[i, 5 + j] = pht[j, i]
    if not box_qp.gauss_solve_inplace(aug, 5):
        x[:] = np.nan
        p[:, :] = np.nan
        return False
    gain = aug[:, 5:].T  # K (4x5), a view
    for i in range(4):
        for k in range(5):
            gain[i, k] *= mask[i]
    for i in range(4):
        acc = 0.0
        for k in range(5):
            acc += gain[i, k] * innovation[k]
        x[i] += acc
    ikh = np.empty((4, 4))
    _mul(gain, h, ikh)
    for i in range(4):
        for j in range(4):
            ikh[i, j] = (1.0 if i == j else 0.0) - ikh[i, j]
    t1 = np.empty((4, 4))
    _mul(ikh, p, t1)
    pn = np.empty((4, 4))
    _mul(t1, ikh.T, pn)
    gr = np.empty((4, 5))
    for i in range(4):
        for k in range(5):
            gr[i, k] = gain[i, k] * r_diag[k]
    krk = np.empty((4, 4))
    _mul(gr, gain.T, krk)
    for i in range(4):
        for j in range(4):
            pn[i, j] += krk[i, j]
    for i in range(4):
        for j in range(4):
            p[i, j] = 0.5 * (pn[i, j] + pn[j, i])
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


@njit_cached(box_qp, linalg)
def kf_step(x, p, q_diag, r_diag, dt, do_predict, id0, id1, id2, do_correct, exc_rot, exc_lin, gc_inv, du, da,
            rho_x, rho_z, constrained, identity, lo, hi, out):
    """predict (if do_predict), correct (if do_correct and some state passes the excitation gate; the others
    held), project (if constrained) on x, p in place; results into out (STEP_OUT). Returns the PROJ_* code."""
    if do_predict:
        kf_predict(x, p, q_diag, dt, id0, id1, id2)
    mask = out[SO_EXCITED:SO_EXCITED + N_STATE]
    innovation = out[SO_INNOV:SO_INNOV + N_MEAS]
    n_exc = excitation_mask(da, exc_rot, exc_lin, mask) if do_correct else 0
    if n_exc > 0:
        kf_correct(x, p, r_diag, gc_inv, du, da, rho_x, rho_z, mask, innovation)
        out[SO_CORRECTED] = 1.0
    else:
        mask[:] = 0.0
        innovation[:] = 0.0
        out[SO_CORRECTED] = 0.0
    for i in range(N_STATE):
        out[SO_X_UNC + i] = x[i]
    code = kf_project(x, p, identity, lo, hi) if constrained else PROJ_INSIDE
    for i in range(N_STATE):
        out[SO_X_HAT + i] = x[i]
        out[SO_P_DIAG + i] = p[i, i]
    return code


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
                   float(rho_z), _ONES4, innovation)
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
    ) -> KfStepResult:
        """predict (skipped when inertia_rate_diag is None, e.g. on the first tick: x0 already describes the
        current pose), correct (when `correct`; only the states that pass the excitation gate of the config),
        then project onto [lower, upper] if constrained, in one compiled call.

        delta_u, delta_acc: float64 arrays (5,); gc_uam_inv (5, 5) float64; lower/upper: 4 floats each (a tuple
        is the cheap form: the kernel is compiled for it), ignored unless constrained. n_updates counts the
        corrections that ran.
        """
        if not self._initialised:
            raise RuntimeError("ConstrainedKalmanFilter.step before initialise()")
        do_predict = inertia_rate_diag is not None
        i0, i1, i2 = inertia_rate_diag if do_predict else _ZERO3  # type: ignore[misc]
        code = kf_step(self._x, self._p, self._q, self._r, self._dt, do_predict, i0, i1, i2, bool(correct),
                       self._exc_rot, self._exc_lin, gc_uam_inv, delta_u, delta_acc, rho_x, rho_z, self._constrained,
                       self._identity_weight, lower, upper, self._out)
        self._account(code, lower, upper)
        o = self._out.tolist()
        corrected = o[SO_CORRECTED] != 0.0
        self.n_updates += corrected
        exc = o[SO_EXCITED:SO_EXCITED + 4]
        return KfStepResult(tuple(o[SO_X_HAT:SO_X_HAT + 4]), tuple(o[SO_X_UNC:SO_X_UNC + 4]),
                            tuple(o[SO_INNOV:SO_INNOV + 5]), tuple(o[SO_P_DIAG:SO_P_DIAG + 4]),
                            code != PROJ_INSIDE, code == PROJ_FALLBACK, corrected,
                            (exc[0] != 0.0, exc[1] != 0.0, exc[2] != 0.0, exc[3] != 0.0))
