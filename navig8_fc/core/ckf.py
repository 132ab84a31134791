"""Constrained Kalman filter for G_hat_I and the adaptive law around it (paper Sec. 3.3, Fig. 3).

State and models
----------------
x = [I_hat_xx, I_hat_yy, I_hat_zz, m_hat] (kg m^2, kg m^2, kg m^2, kg).

- Motion model, Eq. 22: x[k] = x[k-1] + dt [I_dot_11, I_dot_22, I_dot_33, 0] + eps, with I_dot the rate of
  the UAM (no object) inertia tensor from the measured arm q, q_dot (the caller computes it), and a random
  walk for the mass. Q = diag(CKF_Q_*) is the process-noise covariance *per control step*.
- Measurement model, Eq. 23-24: z = Delta U = G_C,UAM^-1 G_hat_I Delta Acc_m + nu = H(Delta Acc_m) x + nu with
  H = G_C,UAM^-1 [v_xx v_yy v_zz v_m] (5x4), v_xx = [a1, 0, rho_x a1, 0, 0], v_yy = [0, a2, 0, 0, 0],
  v_zz = [rho_z a3, 0, a3, 0, 0], v_m = [0, 0, 0, a4, a5], rho_x = J13/J11, rho_z = J13/J33 of the UAM
  inertia (notes 2.4). This is Eq. 24 with m_hat in place of the printed m_UAM (with m_UAM the mass would
  be unobservable), written with a generic 5x5 G_C,UAM^-1 instead of the paper's symmetry-reduced rows.
- Constraint, Eq. 21: I_UAM / K_max <= x <= I_UAM / K_min component-wise (Eq. 20: 0.5 <= K <= 1). The box
  moves with the arm pose; the caller supplies it every step.

Constrained filter (estimate projection, Simon 2010; notes 5)
--------------------------------------------------------------
Predict, correct (Joseph form, symmetric P), then project the corrected estimate x_hat onto the box:

    x_tilde = argmin (x - x_hat)^T W (x - x_hat)  s.t.  lower <= x <= upper

with W = P^-1 (minimum-variance projection, default) or W = I (Euclidean: exactly component-wise clipping).
x_tilde is fed into the next predict. P is kept unreduced: the projection moves the mean only. Reducing P
on the active set (P - P D^T (D P D^T)^-1 D P) would claim that the bound is a perfect measurement and make
the filter over-confident and slow to leave a bound; the paper does not say which it does (notes 5).

The QP is solved by clarabel: one persistent solver built once, its P values and b vector updated in place
every step (clarabel's data-updating API; presolve off, structural zeros kept). The problem is posed in
scaled offset variables y = diag(sqrt(W_ii)) (x - x_hat) so the quadratic has a unit diagonal and q = 0;
only P (10 upper-triangular values) and b (8 bounds) change. Clarabel's interior-point answer is then
polished: the active set it identifies is held and the equality-constrained projection solved exactly
(a weakly active bound is settled by up to n primal-dual active-set updates), so results sit exactly on
the bounds and pass a KKT check. If clarabel reports anything but Solved (or polishing fails), the exact
active-set solver `project_box_exact` answers and the fallback is counted. When x_hat is already inside
the box the projection is x_hat itself and no QP is solved (exact, and the common case).

Cost per ConstrainedKalmanFilter.step on the 2-core development VM (CPython 3.11, clarabel 0.11): ~30 us
median inside the box; ~100 us median when the projection is active, of which the clarabel solve is
~30 us (about 11 interior-point iterations, no iterative refinement) and the update ~3 us.

Increments (our reading of Eq. 23)
----------------------------------
The adaptive law low-passes U0 (from the measured actuators) and Acc_m with the *same* first-order filter
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

Pure core: numpy, scipy.sparse (to hand clarabel its CSC matrices) and clarabel; no I/O, no clocks.
Time comes in as t_s from the caller.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import IntEnum
from itertools import product
from typing import Literal

import clarabel
import numpy as np
from scipy import sparse
from scipy.linalg.lapack import dgesv as _dgesv

from navig8_fc.core import _kernels as _kern
from navig8_fc.core.filters import LowPass1

__all__ = [
    "CKF_PARAM_NAMES",
    "AdaptiveLaw",
    "AdaptiveLawInputs",
    "AdaptiveLawStatus",
    "BoxProjector",
    "CkfConfig",
    "CkfMode",
    "CkfStepInputs",
    "CkfStepResult",
    "ConstrainedKalmanFilter",
    "ProjectionResult",
    "inertia_ratios",
    "inv_small",
    "measurement_matrix",
    "project_box_exact",
]

N_STATE = 4
N_MEAS = 5

ProjectionWeight = Literal["inv_p", "identity"]

CKF_PARAM_NAMES: tuple[str, ...] = (
    "CKF_MODE", "CKF_LPF_TAU", "CKF_START_DLY",
    "CKF_Q_IXX", "CKF_Q_IYY", "CKF_Q_IZZ", "CKF_Q_M",
    "CKF_R_U1", "CKF_R_U2", "CKF_R_U3", "CKF_R_U4", "CKF_R_U5",
    "CKF_P0_SCALE", "CKF_PROJ_W",
)


class CkfMode(IntEnum):
    """CKF_MODE: 0 fixed G_I,UAM (K = 1), 1 unconstrained KF (previous-work proxy), 2 proposed constrained KF."""

    FIXED = 0
    UNCONSTRAINED = 1
    CONSTRAINED = 2


def _floats(values: Sequence[float], n: int, name: str) -> tuple[float, ...]:
    out = tuple(float(v) for v in values)
    if len(out) != n:
        raise ValueError(f"{name} needs {n} values, got {len(out)}")
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must be finite, got {out}")
    return out


@dataclass(frozen=True)
class CkfConfig:
    """Configuration of the constrained KF and the adaptive law. Defaults are the paper's Sec. 4 settings.

    q_diag: process-noise variances per control step of [I_xx, I_yy, I_zz, m] (Eq. 22; notes 6.3 item 12).
    r_diag: measurement-noise variances of Delta U1..U5 (Eq. 24), (rad/s)^4.
    p0_scale: P0 = p0_scale * diag(q_diag) [A].
    projection_weight: "inv_p" (W = P^-1, minimum variance) or "identity" (W = I, i.e. clipping).
    mode: fixed / unconstrained / constrained (CKF_MODE).
    lpf_tau_s: time constant of the adaptive law's low-pass filters on U0 and Acc_m.
    start_delay_s: the estimator starts this long after the first sample (Sec. 4: 0.5 s).
    dt_s: control period (filters and the predict step use it).
    """

    q_diag: tuple[float, ...] = (1.0e-4, 5.0e-5, 1.0e-4, 5.0e-4)
    r_diag: tuple[float, ...] = (1500.0**2, 2000.0**2, 1500.0**2, 2000.0**2, 10000.0**2)
    p0_scale: float = 100.0
    projection_weight: ProjectionWeight = "inv_p"
    mode: CkfMode = CkfMode.CONSTRAINED
    lpf_tau_s: float = 0.7
    start_delay_s: float = 0.5
    dt_s: float = 0.01

    def __post_init__(self) -> None:
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
        for name in ("p0_scale", "lpf_tau_s", "start_delay_s"):
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
        """True when the KF runs at all (CKF_MODE 1 or 2)."""
        return self.mode != CkfMode.FIXED

    @staticmethod
    def from_params(values: Mapping[str, float | int], dt_s: float) -> CkfConfig:
        """Build from the parameter set (params/fc_params.yaml). Every name in CKF_PARAM_NAMES is required."""
        missing = [n for n in CKF_PARAM_NAMES if n not in values]
        if missing:
            raise KeyError(f"missing CKF parameters: {', '.join(missing)}")
        proj = int(values["CKF_PROJ_W"])
        if proj not in (0, 1):
            raise ValueError(f"CKF_PROJ_W must be 0 (P^-1) or 1 (identity), got {proj}")
        mode = int(values["CKF_MODE"])
        if mode not in (0, 1, 2):
            raise ValueError(f"CKF_MODE must be 0, 1 or 2, got {mode}")
        return CkfConfig(
            q_diag=tuple(float(values[n]) for n in ("CKF_Q_IXX", "CKF_Q_IYY", "CKF_Q_IZZ", "CKF_Q_M")),
            r_diag=tuple(float(values[f"CKF_R_U{i}"]) for i in range(1, 6)),
            p0_scale=float(values["CKF_P0_SCALE"]),
            projection_weight="inv_p" if proj == 0 else "identity",
            mode=CkfMode(mode),
            lpf_tau_s=float(values["CKF_LPF_TAU"]),
            start_delay_s=float(values["CKF_START_DLY"]),
            dt_s=float(dt_s),
        )


_EYES: dict[int, np.ndarray] = {}


def inv_small(a: np.ndarray) -> np.ndarray:
    """np.linalg.inv(a) of a small float64 matrix, same values, ~2 us instead of ~5 us.

    np.linalg.inv solves A X = I with LAPACK dgesv behind ~3 us of Python wrapper; this calls dgesv directly
    (scipy's binding; the same OpenBLAS routine, bit-identical results) and returns X in C order like
    np.linalg.inv (later BLAS products take the same kernels). A singular matrix goes to np.linalg.inv, which
    raises LinAlgError as before.
    """
    n = a.shape[0]
    eye = _EYES.get(n)
    if eye is None:
        eye = _EYES[n] = np.eye(n)
    x, info = _dgesv(a, eye)[2:]
    if info != 0:
        return np.linalg.inv(a)
    return np.ascontiguousarray(x)


# --------------------------------------------------------------------------------------------------
# Measurement model (Eq. 24)
# --------------------------------------------------------------------------------------------------


def inertia_ratios(inertia_uam: np.ndarray) -> tuple[float, float]:
    """(rho_x, rho_z) = (J13/J11, J13/J33) of the UAM inertia tensor (notes 2.4, Eq. 24)."""
    j13 = float(inertia_uam[0, 2])
    return j13 / float(inertia_uam[0, 0]), j13 / float(inertia_uam[2, 2])


def measurement_matrix(
    gc_uam_inv: np.ndarray, delta_acc: Sequence[float] | np.ndarray, rho_x: float, rho_z: float
) -> np.ndarray:
    """H (5x4) with Delta U = H x, x = [I_xx, I_yy, I_zz, m] (Eq. 24, notes 2.4).

    H = G_C,UAM^-1 [v_xx v_yy v_zz v_m]; equals G_C,UAM^-1 @ estimated_gi(J, x) @ Delta Acc for every x.
    """
    a1, a2, a3, a4, a5 = (float(v) for v in delta_acc)
    v = np.zeros((N_MEAS, N_STATE))
    _fill_regressor(v, a1, a2, a3, a4, a5, rho_x, rho_z)
    return gc_uam_inv @ v


def _fill_regressor(v: np.ndarray, a1: float, a2: float, a3: float, a4: float, a5: float, rho_x: float,
                    rho_z: float) -> None:
    """The non-zero entries of [v_xx v_yy v_zz v_m] (5x4) in place (notes 2.4); the zeros never change."""
    v[0, 0] = a1
    v[2, 0] = rho_x * a1
    v[1, 1] = a2
    v[0, 2] = rho_z * a3
    v[2, 2] = a3
    v[3, 3] = a4
    v[4, 3] = a5


# --------------------------------------------------------------------------------------------------
# Box projection: exact enumeration and the persistent clarabel solver
# --------------------------------------------------------------------------------------------------


def _check_box(x_hat: np.ndarray, w: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> None:
    n = x_hat.shape[0]
    if x_hat.shape != (n,) or w.shape != (n, n) or lower.shape != (n,) or upper.shape != (n,):
        raise ValueError(f"shape mismatch: x {x_hat.shape}, W {w.shape}, lower {lower.shape}, upper {upper.shape}")
    if not bool((lower <= upper).all()):
        raise ValueError(f"empty box (or NaN bound): lower {lower}, upper {upper}")


def _inside(x: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> bool:
    return bool((x >= lower).all() and (x <= upper).all())


class _ActiveSet:
    """One assignment free (0) / at lower (-1) / at upper (+1) per variable."""

    __slots__ = ("state", "n_active", "fixed", "free")

    def __init__(self, state: tuple[int, ...]) -> None:
        self.state = state
        self.n_active = sum(1 for v in state if v)
        self.fixed = tuple(i for i, v in enumerate(state) if v)
        self.free = tuple(i for i, v in enumerate(state) if not v)


_ACTIVE_SETS: dict[int, tuple[tuple[_ActiveSet, ...], dict[tuple[int, ...], _ActiveSet]]] = {}


def _active_sets(n: int) -> tuple[tuple[_ActiveSet, ...], dict[tuple[int, ...], _ActiveSet]]:
    """All 3^n active sets ordered by the number of active bounds (cached; immutable after creation)."""
    cached = _ACTIVE_SETS.get(n)
    if cached is None:
        sets = sorted((_ActiveSet(s) for s in product((0, -1, 1), repeat=n)), key=lambda a: a.n_active)
        cached = (tuple(sets), {a.state: a for a in sets})
        _ACTIVE_SETS[n] = cached
    return cached


def _gauss_solve(a: list[list[float]], b: list[float]) -> list[float]:
    """Solve a small dense system by Gaussian elimination with partial pivoting (pure Python, n <= ~6)."""
    n = len(b)
    m = [row[:] + [bi] for row, bi in zip(a, b, strict=True)]
    for c in range(n):
        p = c
        big = abs(m[c][c])
        for r in range(c + 1, n):
            v = abs(m[r][c])
            if v > big:
                p, big = r, v
        piv = m[p][c]
        if piv == 0.0 or not math.isfinite(piv):
            raise np.linalg.LinAlgError("singular face system")
        if p != c:
            m[c], m[p] = m[p], m[c]
        rc = m[c]
        for r in range(c + 1, n):
            f = m[r][c] / piv
            if f != 0.0:
                rr = m[r]
                for k in range(c, n + 1):
                    rr[k] -= f * rc[k]
    y = [0.0] * n
    for c in range(n - 1, -1, -1):
        rc = m[c]
        acc = rc[n]
        for k in range(c + 1, n):
            acc -= rc[k] * y[k]
        y[c] = acc / rc[c]
    return y


def _face_point(
    xh: list[float], w: list[list[float]], lo: list[float], hi: list[float], aset: _ActiveSet
) -> list[float]:
    """Minimise (x - x_hat)^T W (x - x_hat) with the bounds of `aset` held and the other variables free."""
    x = xh[:]
    state = aset.state
    for i in aset.fixed:
        x[i] = hi[i] if state[i] > 0 else lo[i]
    free = aset.free
    if free and aset.fixed:
        # Stationarity in the free variables: W_FF d_F = -W_FA d_A.
        d_fixed = [(j, x[j] - xh[j]) for j in aset.fixed]
        rhs = [-sum(w[i][j] * dj for j, dj in d_fixed) for i in free]
        y = _gauss_solve([[w[i][k] for k in free] for i in free], rhs)
        for i, yi in zip(free, y, strict=True):
            x[i] = xh[i] + yi
    return x


def _face_point_cov(
    xh: list[float], pl: list[list[float]], lo: list[float], hi: list[float], aset: _ActiveSet
) -> list[float]:
    """The same face minimiser from P = W^-1: x = x_hat + P[:, A] P_AA^-1 (x_A - x_hat_A).

    Cheaper than the free-variable form when few bounds are active (one active bound: no solve at all).
    """
    fixed = aset.fixed
    state = aset.state
    d = [(hi[i] if state[i] > 0 else lo[i]) - xh[i] for i in fixed]
    if len(fixed) == 1:
        j = fixed[0]
        piv = pl[j][j]
        if not (piv > 0.0 and math.isfinite(piv)):
            raise np.linalg.LinAlgError("singular face system")
        nu = d[0] / piv
        x = [xk + pk[j] * nu for xk, pk in zip(xh, pl, strict=True)]
    else:
        lam = _gauss_solve([[pl[i][j] for j in fixed] for i in fixed], d)
        x = [xk + sum(pk[j] * lj for j, lj in zip(fixed, lam, strict=True)) for xk, pk in zip(xh, pl, strict=True)]
    for i, di in zip(fixed, d, strict=True):
        x[i] = xh[i] + di  # held components exactly on their bounds
    return x


def _kkt_next_state(
    x: list[float], xh: list[float], w: list[list[float]], lo: list[float], hi: list[float],
    state: tuple[int, ...], tol: float,
) -> tuple[int, ...]:
    """KKT check of an active-set candidate; returns `state` itself iff the candidate is optimal.

    Free components must lie inside the box (a violated one is held at the violated bound in the returned
    state). The free components' gradient is zero by construction; the multipliers are the gradient
    components g = W (x - x_hat) at the held bounds: g_i = lambda_i >= 0 at a lower bound and
    g_i = -mu_i <= 0 at an upper bound, judged against the rounding scale tol * sum_j |W_ij (x_j - x_hat_j)|
    (a wrong sign releases the bound in the returned state). This is one primal-dual active-set update.
    """
    n = len(x)
    d = [x[j] - xh[j] for j in range(n)]
    new: list[int] | None = None
    for i, s in enumerate(state):
        if s == 0:
            slack = tol * (1.0 + max(abs(lo[i]), abs(hi[i])))
            v = 1 if x[i] > hi[i] + slack else (-1 if x[i] < lo[i] - slack else 0)
        else:
            wi = w[i]
            g = 0.0
            scale = 0.0
            for j in range(n):
                t = wi[j] * d[j]
                g += t
                scale += abs(t)
            gtol = tol * scale
            v = 0 if (s < 0 and g < -gtol) or (s > 0 and g > gtol) else s
        if v != s:
            if new is None:
                new = list(state)
            new[i] = v
    return state if new is None else tuple(new)


def _kkt_ok(
    x: list[float], xh: list[float], w: list[list[float]], lo: list[float], hi: list[float],
    state: tuple[int, ...], tol: float,
) -> bool:
    return _kkt_next_state(x, xh, w, lo, hi, state, tol) is state


def _cost(x: list[float], xh: list[float], w: list[list[float]]) -> float:
    d = [a - b for a, b in zip(x, xh, strict=True)]
    return sum(di * sum(wij * dj for wij, dj in zip(wi, d, strict=True)) for di, wi in zip(d, w, strict=True))


def project_box_exact(
    x_hat: Sequence[float] | np.ndarray,
    w: np.ndarray,
    lower: Sequence[float] | np.ndarray,
    upper: Sequence[float] | np.ndarray,
    tol: float = 1e-9,
) -> np.ndarray:
    """Exact solution of min (x - x_hat)^T W (x - x_hat) s.t. lower <= x <= upper (W symmetric positive definite).

    Active-set enumeration: each variable is free, at its lower or at its upper bound (3^n cases, 81 for
    n = 4). Each case is the equality-constrained minimiser on that face; the first one that satisfies the
    KKT conditions (free part feasible, multiplier signs right) is the unique optimum of the strictly convex
    QP. The "clipping" face (the violated bounds held) is tried first, then all faces by the number of
    active bounds. If rounding defeats every KKT check, the feasible candidate of lowest cost is returned
    (the optimum is always among the candidates). The result is clipped into the box (rounding level).
    """
    xh_a = np.asarray(x_hat, dtype=float)
    w_a = np.asarray(w, dtype=float)
    lo_a = np.asarray(lower, dtype=float)
    hi_a = np.asarray(upper, dtype=float)
    _check_box(xh_a, w_a, lo_a, hi_a)
    if _inside(xh_a, lo_a, hi_a):
        return xh_a.copy()
    xh, wl, lo, hi = xh_a.tolist(), w_a.tolist(), lo_a.tolist(), hi_a.tolist()
    sets, by_state = _active_sets(len(xh))
    clip_state = tuple(1 if a > u else (-1 if a < lo_i else 0) for a, lo_i, u in zip(xh, lo, hi, strict=True))
    best: list[float] | None = None
    best_cost = math.inf
    for aset in (by_state[clip_state], *sets[1:]):  # sets[0] (nothing held) is x_hat itself, outside
        try:
            x = _face_point(xh, wl, lo, hi, aset)
        except np.linalg.LinAlgError:
            continue
        if _kkt_ok(x, xh, wl, lo, hi, aset.state, tol):
            return np.clip(np.array(x), lo_a, hi_a)
        if _kkt_ok(x, xh, wl, lo, hi, (0,) * len(x), 1e-7):  # feasible (free-part check on every component)
            cost = _cost(x, xh, wl)
            if cost < best_cost:
                best, best_cost = x, cost
    if best is None:  # cannot happen for SPD W and a non-empty box: the all-held corners are candidates
        raise np.linalg.LinAlgError("box projection: no feasible candidate (is W positive definite?)")
    return np.clip(np.array(best), lo_a, hi_a)


@dataclass(frozen=True)
class ProjectionResult:
    """Outcome of one box projection; `x` is inside the box."""

    x: np.ndarray
    projected: bool  # False: x_hat was inside, x = x_hat
    used_fallback: bool  # True: clarabel did not solve (or polishing failed), project_box_exact was used
    solver_iterations: int


class BoxProjector:
    """min (x - x_hat)^T W (x - x_hat) s.t. lower <= x <= upper, by one persistent clarabel solver.

    Built once for dimension n; each call updates the objective values and the bound vector in place.
    Variables are the scaled offsets y = s * (x - x_hat), s = sqrt(diag W), so the QP is
    min (1/2) y^T C y, C = W / (s s^T) (unit diagonal), s.t. [I; -I] y <= [s (upper - x_hat); s (x_hat - lower)].
    The interior-point answer is polished: the active set it shows (dual > slack) is held and the
    equality-constrained projection solved exactly; if that fails the KKT check, or clarabel's status is not
    Solved, project_box_exact answers and the call counts as a fallback.
    """

    def __init__(self, n: int = N_STATE, max_iter: int = 50) -> None:
        self.n = int(n)
        n = self.n
        # Upper triangle of a dense n x n matrix in CSC order: column j holds rows 0..j.
        rows = [i for j in range(n) for i in range(j + 1)]
        cols = [j for j in range(n) for _ in range(j + 1)]
        self._rows = np.array(rows, dtype=np.intp)
        self._cols = np.array(cols, dtype=np.intp)
        self._pairs = tuple(zip(rows, cols, strict=True))
        indptr = np.concatenate([[0], np.cumsum(np.arange(1, n + 1))])
        p0 = sparse.csc_matrix((np.eye(n)[self._rows, self._cols], self._rows, indptr), shape=(n, n))
        a = sparse.csc_matrix(np.vstack([np.eye(n), -np.eye(n)]))
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        settings.presolve_enable = False  # data updates need presolve off
        settings.input_sparse_dropzeros = False  # keep structural zeros of P (W may have exact zeros)
        settings.max_iter = int(max_iter)
        # The answer is polished to the exact face solution (see _polish), so clarabel only has to identify
        # the active set; iterative refinement of the 12x12 KKT solves buys nothing here and costs ~20% of the
        # solve time (polished results bit-identical on the paper run). Looser tolerances would save a few
        # more iterations but leave weakly active bounds ambiguous (polishing fails, exact fallback).
        settings.iterative_refinement_enable = False
        settings.equilibrate_enable = False  # the QP is already scaled to a unit-diagonal objective
        self._solver = clarabel.DefaultSolver(
            p0, np.zeros(n), a, np.ones(2 * n), [clarabel.NonnegativeConeT(2 * n)], settings
        )
        if not self._solver.is_data_update_allowed():
            raise RuntimeError("clarabel refuses data updates with these settings")
        self._solved = clarabel.SolverStatus.Solved
        self._by_state = _active_sets(n)[1]
        self._w, self._pl = np.empty((n, n)), np.empty((n, n))  # work arrays of solve_kf
        self._c, self._b, self._xo = np.empty(n * (n + 1) // 2), np.empty(2 * n), np.empty(n)
        self._m = 2 * n  # constraint rows
        self.n_calls = 0
        self.n_fallbacks = 0
        self.last_status: str = "none"

    def project(
        self,
        x_hat: Sequence[float] | np.ndarray,
        w: np.ndarray,
        lower: Sequence[float] | np.ndarray,
        upper: Sequence[float] | np.ndarray,
        skip_inside: bool = True,
        w_inv: np.ndarray | None = None,
    ) -> ProjectionResult:
        """Project x_hat onto the box in the W-norm. With skip_inside, a point inside is returned as is.

        w_inv, if given, must be W^-1 (the KF passes P); it only makes the polishing step cheaper.
        The small-vector arithmetic is done on Python floats: for n = 4 that is several times cheaper
        than numpy's per-call overhead.
        """
        n = self.n
        xh = np.asarray(x_hat, dtype=float).tolist()
        wl = np.asarray(w, dtype=float).tolist()
        lo = np.asarray(lower, dtype=float).tolist()
        hi = np.asarray(upper, dtype=float).tolist()
        if len(xh) != n or len(lo) != n or len(hi) != n or len(wl) != n or any(len(r) != n for r in wl):
            raise ValueError(f"BoxProjector({n}): wrong input sizes")
        if not all(a <= b for a, b in zip(lo, hi, strict=True)):
            raise ValueError(f"empty box (or NaN bound): lower {lo}, upper {hi}")
        if skip_inside and all(a <= x <= b for a, x, b in zip(lo, xh, hi, strict=True)):
            return ProjectionResult(np.array(xh), False, False, 0)
        pl = None if w_inv is None else np.asarray(w_inv, dtype=float).tolist()
        x, used_fallback, iterations = self.solve_lists(xh, wl, lo, hi, pl)
        return ProjectionResult(np.array(x), True, used_fallback, iterations)

    def solve_lists(
        self, xh: list[float], wl: list[list[float]], lo: list[float], hi: list[float],
        pl: list[list[float]] | None = None,
    ) -> tuple[list[float], bool, int]:
        """The QP on plain lists, inputs already checked (sizes, lower <= upper): (x, used_fallback, iterations).

        project() without its conversions and checks; the KF calls it directly. pl is W^-1 or None.
        """
        n = self.n
        self.n_calls += 1
        iterations = 0
        diag = [wl[i][i] for i in range(n)]
        finite = math.isfinite(sum(xh) + sum(map(sum, wl)))  # NaN/inf propagate (overflow -> exact fallback)
        if finite and all(d > 0.0 for d in diag):
            sc = [math.sqrt(d) for d in diag]
            c = [wl[i][j] / (sc[i] * sc[j]) for i, j in self._pairs]  # unit-diagonal C, CSC upper triangle
            b = [sc[i] * (hi[i] - xh[i]) for i in range(n)] + [sc[i] * (xh[i] - lo[i]) for i in range(n)]
            self._solver.update(P=c, b=b)
            sol = self._solver.solve()
            iterations = int(sol.iterations)
            self.last_status = str(sol.status)
            if sol.status == self._solved:
                x = self._polish(xh, wl, lo, hi, sol.z, sol.s, pl)
                if x is not None:
                    return x, False, iterations
        else:
            self.last_status = "bad_input"
        self.n_fallbacks += 1
        return project_box_exact(xh, np.array(wl), lo, hi).tolist(), True, iterations

    def solve_kf(
        self, xh: np.ndarray, p: np.ndarray, lo: np.ndarray, hi: np.ndarray, identity: bool
    ) -> tuple[list[float], bool, int]:
        """The KF's projection, W = P^-1 (identity=False) or I: (x, used_fallback, iterations).

        solve_lists(xh, W, lo, hi, W^-1) with the arithmetic around the clarabel solve (W, the scaled data,
        the polish) in numba kernels (_kernels.proj_setup, _kernels.polish); the same clarabel solver and
        data updates. A singular P gives W = I as before. Inputs checked by the caller (n = self.n, lo <= hi).
        """
        self.n_calls += 1
        iterations = 0
        w, pl, x = self._w, self._pl, self._xo
        code = _kern.proj_setup(xh, p, lo, hi, identity, w, pl, self._c, self._b)
        if code:
            solver = self._solver
            # The same values handed over as lists: clarabel's update converts a list ~2 us faster than an array.
            solver.update(P=self._c.tolist(), b=self._b.tolist())
            sol = solver.solve()
            iterations = int(sol.iterations)
            status = sol.status
            self.last_status = str(status)
            if status == self._solved:
                zs, m = np.array(sol.z + sol.s), self._m  # z and s (m = 2n each) in one conversion
                if _kern.polish(xh, w, pl, code == 1, lo, hi, zs[:m], zs[m:], x):
                    return x.tolist(), False, iterations
        else:
            self.last_status = "bad_input"
        self.n_fallbacks += 1
        return project_box_exact(xh, w.copy(), lo, hi).tolist(), True, iterations

    def _polish(
        self, xh: list[float], wl: list[list[float]], lo: list[float], hi: list[float],
        z: Sequence[float], s: Sequence[float], pl: list[list[float]] | None = None,
    ) -> list[float] | None:
        """Hold the active set the interior-point solution shows and solve that face exactly."""
        n = self.n
        # Row i is x_i <= upper_i, row n + i is x_i >= lower_i. Per variable, look at the row with the
        # smaller slack (both cannot be active unless lower = upper) and call it active when its dual
        # exceeds its slack (complementarity: s z -> 0 along the central path).
        state = tuple(
            (1 if z[i] > s[i] else 0) if s[i] <= s[n + i] else (-1 if z[n + i] > s[n + i] else 0)
            for i in range(n)
        )
        if not any(state):  # nothing active: right only if x_hat is inside (skip_inside=False)
            inside = all(a <= x <= b for a, x, b in zip(lo, xh, hi, strict=True))
            return xh[:] if inside else None
        # Clarabel's guess is almost always right; when a bound is only weakly active (multiplier ~ slack)
        # a few primal-dual active-set updates (hold violated bounds, release wrong-sign ones) settle it.
        for _ in range(n):
            aset = self._by_state[state]
            try:
                if pl is not None and 2 * aset.n_active <= n:
                    x = _face_point_cov(xh, pl, lo, hi, aset)
                else:
                    x = _face_point(xh, wl, lo, hi, aset)
            except np.linalg.LinAlgError:
                return None
            nxt = _kkt_next_state(x, xh, wl, lo, hi, state, 1e-7)
            if nxt is state:
                return [min(max(v, a), b) for v, a, b in zip(x, lo, hi, strict=True)]
            state = nxt
        return None


# --------------------------------------------------------------------------------------------------
# The constrained Kalman filter
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CkfStepInputs:
    """One CKF step: increments (Eq. 23), the UAM model at the current pose, I_dot, and the Eq. 21 box."""

    delta_u: np.ndarray  # (5,) Delta U
    delta_acc: np.ndarray  # (5,) Delta Acc_m
    gc_uam_inv: np.ndarray  # (5, 5) G_C,UAM^-1
    rho_x: float  # J13 / J11 (UAM)
    rho_z: float  # J13 / J33 (UAM)
    inertia_rate_diag: np.ndarray  # (3,) [I_dot_11, I_dot_22, I_dot_33] of the UAM (Eq. 22)
    lower: np.ndarray  # (4,) Eq. 21
    upper: np.ndarray  # (4,) Eq. 21


@dataclass(frozen=True)
class CkfStepResult:
    x_hat: np.ndarray  # (4,) estimate after the step (projected when constrained)
    x_unconstrained: np.ndarray  # (4,) corrected estimate before projection
    innovation: np.ndarray  # (5,) Delta U - H x_prior
    p_diag: np.ndarray  # (4,) diagonal of the (unreduced) posterior covariance
    projected: bool  # the projection moved the estimate
    used_fallback: bool  # the exact solver replaced clarabel this step


class ConstrainedKalmanFilter:
    """KF on x = [I_xx, I_yy, I_zz, m] with Eq. 22 (predict), Eq. 24 (correct) and the Eq. 21 projection."""

    def __init__(self, config: CkfConfig) -> None:
        self.config = config
        self._q = np.array(config.q_diag)
        self._r = np.array(config.r_diag)
        self._r_mat = np.diag(self._r)
        self._q_mat = np.diag(self._q)
        self._eye = np.eye(N_STATE)
        self._identity_weight = config.projection_weight == "identity"
        self._eye_list = self._eye.tolist()
        self._projector = BoxProjector(N_STATE)
        self._v = np.zeros((N_MEAS, N_STATE))  # scratch for H's sparse factor (measurement_matrix's v)
        self._x = np.zeros(N_STATE)
        self._p = np.diag(config.p0_scale * self._q)
        self._initialised = False
        self.n_updates = 0
        self.n_projection_fallbacks = 0

    # --- state access ------------------------------------------------------------------------------
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

    def reset(self) -> None:
        """Back to the uninitialised state (the clarabel solver is kept); initialise() starts again."""
        self._initialised = False
        self.n_updates = 0
        self.n_projection_fallbacks = 0

    # --- the three stages -----------------------------------------------------------------------------
    def predict(self, inertia_rate_diag: Sequence[float] | np.ndarray) -> None:
        """Eq. 22: x- = x + dt [I_dot_11, I_dot_22, I_dot_33, 0];  P- = P + Q."""
        d = np.asarray(inertia_rate_diag, dtype=float)
        if d.shape != (3,):
            raise ValueError(f"inertia_rate_diag needs 3 components, got shape {d.shape}")
        self._x[:3] += self.config.dt_s * d
        self._p += self._q_mat

    def correct(
        self,
        delta_u: Sequence[float] | np.ndarray,
        delta_acc: Sequence[float] | np.ndarray,
        gc_uam_inv: np.ndarray,
        rho_x: float,
        rho_z: float,
    ) -> np.ndarray:
        """Measurement update with z = Delta U, H(Delta Acc_m) of Eq. 24 (Joseph form). Returns the innovation."""
        a1, a2, a3, a4, a5 = (float(v) for v in delta_acc)
        return self._correct(delta_u, a1, a2, a3, a4, a5, gc_uam_inv, rho_x, rho_z)

    def _correct(
        self, delta_u: Sequence[float] | np.ndarray, a1: float, a2: float, a3: float, a4: float, a5: float,
        gc_uam_inv: np.ndarray, rho_x: float, rho_z: float,
    ) -> np.ndarray:
        """The update in one numba kernel (_kernels.kf_correct); `_correct_reference` is the numpy original
        (tests compare them; they agree to rounding). A singular S goes to the reference, which raises."""
        innovation = np.empty(N_MEAS)
        if _kern.kf_correct(self._x, self._p, self._r, np.asarray(gc_uam_inv, dtype=float),
                            np.asarray(delta_u, dtype=float), a1, a2, a3, a4, a5, rho_x, rho_z, innovation):
            self.n_updates += 1
            return innovation
        return self._correct_reference(delta_u, a1, a2, a3, a4, a5, gc_uam_inv, rho_x, rho_z)

    def _correct_reference(
        self, delta_u: Sequence[float] | np.ndarray, a1: float, a2: float, a3: float, a4: float, a5: float,
        gc_uam_inv: np.ndarray, rho_x: float, rho_z: float,
    ) -> np.ndarray:
        # H = measurement_matrix(...), filling a persistent v (its zeros never change): same product, no alloc.
        v = self._v
        _fill_regressor(v, a1, a2, a3, a4, a5, rho_x, rho_z)
        dot = np.dot  # np.dot on these tiny 2-D arrays: the same BLAS products as @, less call overhead
        h = dot(gc_uam_inv, v)
        p = self._p
        pht = dot(p, h.T)  # 4x5
        s = dot(h, pht)
        s += self._r_mat  # S = H P H^T + R
        # K = P H^T S^-1 by a solve, no explicit inverse (S symmetric): LAPACK dgesv called directly, the
        # routine np.linalg.solve runs, without its ~3 us of wrapper; np.linalg.solve reports a failure.
        gain_t, info = _dgesv(s, pht.T)[2:]
        # C order like np.linalg.solve's result: the later products then take the same BLAS kernels (the
        # transposed-layout gemv sums in another order), keeping the results bit-identical.
        gain = (np.ascontiguousarray(gain_t) if info == 0 else np.linalg.solve(s, pht.T)).T
        innovation = np.asarray(delta_u, dtype=float) - dot(h, self._x)
        self._x = self._x + dot(gain, innovation)
        ikh = self._eye - dot(gain, h)
        p = dot(dot(ikh, p), ikh.T) + dot(gain * self._r, gain.T)  # Joseph form: stays PSD under rounding
        self._p = 0.5 * (p + p.T)
        self.n_updates += 1
        return innovation

    def _project_lists(self, lo: Sequence[float], hi: Sequence[float]) -> tuple[list[float], bool, bool]:
        """project() on plain lists: (x after the step, projected, used_fallback); x <- x_tilde."""
        return self._project_xl(self._x.tolist(), lo, hi)

    def _project_xl(
        self, xl: list[float], lo: Sequence[float], hi: Sequence[float]
    ) -> tuple[list[float], bool, bool]:
        """_project_lists with xl = self._x.tolist() already made (N_STATE = 4 components unrolled)."""
        x0, x1, x2, x3 = xl
        l0, l1, l2, l3 = lo
        h0, h1, h2, h3 = hi
        if l0 <= x0 <= h0 and l1 <= x1 <= h1 and l2 <= x2 <= h2 and l3 <= x3 <= h3:
            return xl, False, False  # inside: x_tilde = x_hat, W not needed
        if not (l0 <= h0 and l1 <= h1 and l2 <= h2 and l3 <= h3):
            raise ValueError(f"empty box (or NaN bound): lower {list(lo)}, upper {list(hi)}")
        x, used_fallback, _ = self._projector.solve_kf(self._x, self._p, np.array(lo), np.array(hi),
                                                       self._identity_weight)
        if used_fallback:
            self.n_projection_fallbacks += 1
        self._x = np.array(x)
        return x, True, used_fallback

    def project(self, lower: np.ndarray, upper: np.ndarray) -> ProjectionResult:
        """Eq. 21 by estimate projection; x <- x_tilde, P unchanged (see module docstring)."""
        x = self._x
        if bool((x >= lower).all() and (x <= upper).all()):
            return ProjectionResult(x.copy(), False, False, 0)  # inside: x_tilde = x_hat, W not needed
        if self._identity_weight:
            res = self._projector.project(x, self._eye, lower, upper, w_inv=self._eye)
        else:
            w = self._weight_inv_p()
            res = self._projector.project(x, w, lower, upper, w_inv=None if w is self._eye else self._p)
        if res.used_fallback:
            self.n_projection_fallbacks += 1
        self._x = res.x.copy()
        return res

    def _weight_inv_p(self) -> np.ndarray:
        """W = P^-1 (minimum-variance projection). A singular P (possible only with Q = 0 and P0 = 0, when
        the filter cannot move anyway) falls back to W = I."""
        try:
            w = inv_small(self._p)
        except np.linalg.LinAlgError:
            return self._eye
        return w if bool(np.isfinite(w).all()) else self._eye

    def step(self, inputs: CkfStepInputs, predict: bool = True) -> CkfStepResult:
        """predict (unless predict=False, e.g. on the initialisation tick), correct, then project if constrained."""
        if not self._initialised:
            raise RuntimeError("ConstrainedKalmanFilter.step before initialise()")
        if predict:
            self.predict(inputs.inertia_rate_diag)
        innovation = self.correct(inputs.delta_u, inputs.delta_acc, inputs.gc_uam_inv, inputs.rho_x, inputs.rho_z)
        x_unc = self._x.copy()
        projected = used_fallback = False
        if self.config.constrained:
            lo = np.asarray(inputs.lower, dtype=float).tolist()
            hi = np.asarray(inputs.upper, dtype=float).tolist()
            _, projected, used_fallback = self._project_lists(lo, hi)
        return CkfStepResult(
            x_hat=self._x.copy(),
            x_unconstrained=x_unc,
            innovation=innovation,
            p_diag=np.diag(self._p).copy(),
            projected=projected,
            used_fallback=used_fallback,
        )

    def _step_lists(
        self, du: list[float], da: list[float], gc_uam_inv: np.ndarray, rho_x: float, rho_z: float,
        idot: tuple[float, float, float] | None, lo: list[float], hi: list[float],
    ) -> tuple[list[float], list[float], np.ndarray]:
        """step() for the adaptive law: plain lists in, (x_hat, x_unconstrained, innovation) out; idot None
        skips the predict. Same arithmetic as predict/correct/project, without their conversions and checks."""
        if idot is not None:
            x, dt = self._x, self.config.dt_s
            x[0] += dt * idot[0]  # element-wise, as predict's x[:3] += dt * d
            x[1] += dt * idot[1]
            x[2] += dt * idot[2]
            self._p += self._q_mat
        a1, a2, a3, a4, a5 = da
        innovation = self._correct(np.array(du), a1, a2, a3, a4, a5, gc_uam_inv, rho_x, rho_z)
        if self.config.constrained:
            x_unc = self._x.tolist()
            x_hat = self._project_lists(lo, hi)[0]
        else:
            x_unc = x_hat = self._x.tolist()
        return x_hat, x_unc, innovation


# --------------------------------------------------------------------------------------------------
# The adaptive law (Fig. 3)
# --------------------------------------------------------------------------------------------------


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
    k_min: float  # Eq. 20
    k_max: float


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
    delta_u: tuple[float, ...] = (0.0,) * N_MEAS  # increments fed to the KF (Eq. 23)
    delta_acc: tuple[float, ...] = (0.0,) * N_MEAS


_ZERO4 = (0.0,) * N_STATE
_ZERO5 = (0.0,) * N_MEAS
_ONES4 = (1.0,) * N_STATE
_FALSE4 = (False,) * N_STATE


class AdaptiveLaw:
    """Fig. 3's adaptive law: filters, increments (Eq. 23), the constrained KF, and G_hat_I (Eq. 4).

    The start delay counts from the first sample after construction or reset(); the shell resets the law
    when the controller engages. Before the start, and always in mode FIXED, G_I,UAM (K = 1) is returned.
    The filters run from the first sample in every mode, so the increments are settled when the KF starts.
    """

    def __init__(self, config: CkfConfig) -> None:
        self.config = config
        self._lpf_u = LowPass1(config.lpf_tau_s, config.dt_s, N_MEAS)
        self._lpf_a = LowPass1(config.lpf_tau_s, config.dt_s, N_MEAS)
        self._kf = ConstrainedKalmanFilter(config)
        self._alpha = self._lpf_u.alpha  # the compiled path (_kernels.adapt_step) runs the same filters
        self._ast = np.zeros(_kern.N_AST)
        self._out = np.zeros(_kern.N_AO)
        # Constants of the tick, looked up once: the config is frozen.
        self._adaptive = config.adaptive
        self._constrained = config.constrained
        self._start_delay_tol = config.start_delay_s - 1e-9
        self._dt = config.dt_s
        self.reset()

    @property
    def kf(self) -> ConstrainedKalmanFilter:
        return self._kf

    def reset(self) -> None:
        self._lpf_u.reset()
        self._lpf_a.reset()
        self._prev_u: list[float] | None = None
        self._prev_a: list[float] | None = None
        self._ast[:] = 0.0
        self._t0: float | None = None
        self._running = False
        self._kf.reset()  # re-initialised at the next start; its clarabel solver is reused

    @property
    def mass_estimate_kg(self) -> float | None:
        """x_hat[3] (the estimated mass) while the KF runs, else None; cheaper than kf.x[3] (no copy)."""
        return float(self._kf._x[3]) if self._kf.initialised else None

    def step(self, inp: AdaptiveLawInputs) -> tuple[np.ndarray, AdaptiveLawStatus]:
        """Returns (G_hat_I 5x5, status).

        Per-tick bookkeeping on plain floats (the vectors have 4-5 components: numpy's per-call overhead
        would dominate); the values equal those of vehicle.estimate_bounds / estimated_gi / k_from_estimate
        and inertia_ratios exactly (same IEEE operations, tests compare them bit for bit).
        """
        g, _, status = self._step(
            inp.t_s, np.asarray(inp.u_meas, dtype=float), np.asarray(inp.acc_m, dtype=float),
            np.asarray(inp.gc_uam_inv, dtype=float), np.asarray(inp.inertia_uam, dtype=float),
            float(inp.mass_uam_kg), np.asarray(inp.inertia_rate_uam, dtype=float), inp.k_min, inp.k_max,
        )
        return g, status

    def _step(
        self, t_s: float, u_meas: np.ndarray, acc_m: np.ndarray, gc_inv: np.ndarray, inertia: np.ndarray,
        m: float, inertia_rate: np.ndarray, k_min: float, k_max: float,
    ) -> tuple[np.ndarray, tuple[float, ...], AdaptiveLawStatus]:
        """step() on float64 arrays (u_meas, acc_m (5,), gc_inv (5, 5), inertia and inertia_rate (3, 3)), m a float;
        also returns G_hat_I row-major as a tuple (the same floats as the array). The controller's tick."""
        (j11, _, j13), (_, j22, _), (_, _, j33) = inertia.tolist()
        base = (j11, j22, j33, m)
        lower = (j11 / k_max, j22 / k_max, j33 / k_max, m / k_max)  # Eq. 21 (estimate_bounds)
        upper = (j11 / k_min, j22 / k_min, j33 / k_min, m / k_min)
        t_s = float(t_s)
        if self._t0 is None:
            self._t0 = t_s
        # 1e-9 s guards the comparison against time accumulated in floating point.
        started = self._adaptive and (t_s - self._t0) >= self._start_delay_tol
        kf = self._kf
        first = False
        id0 = id1 = id2 = 0.0
        if started:
            first = not self._running
            if first:
                kf.initialise(base)  # K = 1 at the start (Sec. 4)
                self._running = True
            id0, id1, id2 = inertia_rate.item(0), inertia_rate.item(4), inertia_rate.item(8)
        # Filters, one-step increments (Eq. 23), predict (skipped on the first KF tick: x0 already describes
        # the current pose) and correct in one kernel; `_step_lists` and the LowPass1 filters are the reference.
        rho_x, rho_z = j13 / j11, j13 / j33  # inertia_ratios
        out = self._out
        code = _kern.adapt_step(self._ast, self._alpha, u_meas, acc_m, started, started and not first,
                                self._dt, id0, id1, id2, kf._x, kf._p, kf._q, kf._r, gc_inv, rho_x, rho_z, out)
        o = tuple(out.tolist())
        du, da = o[0:5], o[5:10]
        if not started:
            g, gl = _gi_hat_flat(j11, j13, j33, base)
            return g, gl, AdaptiveLawStatus(
                running=False, x_hat=base, x_unconstrained=base, k=_ONES4,
                lower=lower, upper=upper, active_lower=_FALSE4, active_upper=_FALSE4,
                innovation=_ZERO5, p_diag=_ZERO4, n_updates=0, n_projection_fallbacks=0,
                delta_u=du, delta_acc=da,
            )

        if code == 1:
            kf.n_updates += 1
            innovation = o[10:15]
        else:  # singular S: the reference update (raises or propagates NaN as before)
            innovation = tuple(kf._correct_reference(np.array(du), *da, gc_inv, rho_x, rho_z).tolist())
        x_unc = kf._x.tolist()
        x = kf._project_xl(x_unc, lower, upper)[0] if self._constrained else x_unc
        x0, x1, x2, x3 = x
        g, gl = _gi_hat_flat(j11, j13, j33, x)
        return g, gl, AdaptiveLawStatus(
            running=True,
            x_hat=(x0, x1, x2, x3),
            x_unconstrained=tuple(x_unc),
            k=(j11 / x0, j22 / x1, j33 / x2, m / x3),  # k_from_estimate
            lower=lower,
            upper=upper,
            active_lower=(x0 <= lower[0], x1 <= lower[1], x2 <= lower[2], x3 <= lower[3]),
            active_upper=(x0 >= upper[0], x1 >= upper[1], x2 >= upper[2], x3 >= upper[3]),
            innovation=innovation,
            p_diag=tuple(kf._p.diagonal().tolist()),
            n_updates=kf.n_updates,
            n_projection_fallbacks=kf.n_projection_fallbacks,
            delta_u=du,
            delta_acc=da,
        )


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
