"""The constrained Kalman filter's projection step (paper Sec. 3.3, Eq. 21; estimate projection, Simon 2010):

    x_tilde = argmin (x - x_hat)^T W (x - x_hat)  s.t.  lower <= x <= upper,   W symmetric positive definite.

The KF projects its corrected estimate with W = P^-1 (minimum variance) or W = I (then exactly clipping);
see kalman.py. n = 4 here, so everything is plain loops in numba kernels over small float64 arrays.

One solver: a primal-dual active-set iteration started on the clip face (the violated bounds held). Each
iteration solves the equality-constrained problem on the current face exactly (`_face_point`), then checks
the KKT conditions (`_kkt_next_state`): a free component outside the box is held at the bound it violates,
a held bound whose multiplier has the wrong sign is released. For W = I (and a diagonal W) the clip face is
already optimal: one iteration. In the paper scenario (seed 1) the KF projected on 1724 ticks: 1670 took one
iteration, 54 two, none the fallback. The answer lies exactly on the held bounds and passes the KKT check, which is
the optimality certificate of the strictly convex QP.

Checked fallback: if the iteration does not certify a face within MAX_ITER (active-set methods can cycle for
a general W) or a face system is singular, `enumerate_faces` answers: it tries the clip face, then all 3^n
faces by the number of held bounds (81 for n = 4), and returns the first that passes the KKT check (exact).

Measured on 2000 random problems with x_hat outside the box (W = P^-1, cond(P) up to 1e4; 2-core VM,
compiled): the active-set iteration 1.3 us per problem, certifying 99.5 % (1-8 iterations, median 2); the
enumeration 9.8 us, always exact; the persistent clarabel interior-point solver plus the polish to the same
face that this module replaced 26 us, with 70 of the 2000 needing the exact fallback. So the enumeration is
the fallback and clarabel is gone. The plain-Python path of every kernel is its `py_func`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from navig8_fc.core import linalg
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.linalg import pivot_rows

__all__ = [
    "KKT_TOL",
    "MAX_ITER",
    "ProjectionResult",
    "active_set_solve",
    "enumerate_faces",
    "project_box",
    "project_box_exact",
    "solve",
]

KKT_TOL = 1e-7  # relative rounding scale of the KKT check (see _kkt_next_state)
EXACT_TOL = 1e-9  # the enumeration's first pass: tighter, so a weakly active bound picks the better face
MAX_ITER = 8  # active-set iterations before the enumeration answers (2n; the KF's projections need <= 2)

# Return codes of `solve` (> 0: active-set iterations used)
SOLVED_BY_ENUMERATION = 0
NO_SOLUTION = -1  # cannot happen for SPD W and a non-empty box: every corner is a feasible candidate


@njit_cached(linalg)
def gauss_solve_inplace(m, n):
    """Solve A Y = B for the augmented m = [A | B] (n x (n + k)), Y into m[:, n:]. Gaussian elimination with
    partial pivoting; False (m partly eliminated) if a pivot is zero or not finite."""
    n_cols = m.shape[1]
    for c in range(n):
        if not pivot_rows(m, c, n):
            return False
        piv = m[c, c]
        for r in range(c + 1, n):
            f = m[r, c] / piv
            if f != 0.0:
                for k in range(c, n_cols):
                    m[r, k] -= f * m[c, k]
    y = np.empty(n)
    for j in range(n, n_cols):
        for c in range(n - 1, -1, -1):
            acc = m[c, j]
            for k in range(c + 1, n):
                acc -= m[c, k] * y[k]
            y[c] = acc / m[c, c]
        for c in range(n):
            m[c, j] = y[c]
    return True


@njit_cached(linalg)
def _face_point(xh, w, pl, use_pl, lo, hi, state, x):
    """Minimiser of (x - x_hat)^T W (x - x_hat) on the face `state` (-1 at lower, +1 at upper, 0 free), into x.

    Two exact forms: from P = W^-1 (use_pl), x = x_hat + P[:, A] P_AA^-1 (x_A - x_hat_A), cheaper when at most
    half the bounds are held (one held bound: no solve); else stationarity in the free variables,
    W_FF d_F = -W_FA d_A. Held components land exactly on their bounds. False if the face system is singular.
    """
    n = xh.shape[0]
    n_act = 0
    for i in range(n):
        if state[i] != 0:
            n_act += 1
    for i in range(n):
        x[i] = xh[i]
    if use_pl and 2 * n_act <= n:
        fixed = np.empty(n_act, dtype=np.int64)
        d = np.empty(n_act)
        k = 0
        for i in range(n):
            if state[i] != 0:
                fixed[k] = i
                d[k] = (hi[i] if state[i] > 0 else lo[i]) - xh[i]
                k += 1
        if n_act == 1:
            j = fixed[0]
            piv = pl[j, j]
            if not (piv > 0.0 and math.isfinite(piv)):
                return False
            nu = d[0] / piv
            for i in range(n):
                x[i] = xh[i] + pl[i, j] * nu
        elif n_act > 1:
            m = np.empty((n_act, n_act + 1))
            for a in range(n_act):
                for bb in range(n_act):
                    m[a, bb] = pl[fixed[a], fixed[bb]]
                m[a, n_act] = d[a]
            if not gauss_solve_inplace(m, n_act):
                return False
            for i in range(n):
                acc = 0.0
                for a in range(n_act):
                    acc += pl[i, fixed[a]] * m[a, n_act]
                x[i] = xh[i] + acc
        for a in range(n_act):
            x[fixed[a]] = xh[fixed[a]] + d[a]
        return True
    for i in range(n):
        if state[i] != 0:
            x[i] = hi[i] if state[i] > 0 else lo[i]
    n_free = n - n_act
    if n_free > 0 and n_act > 0:
        free = np.empty(n_free, dtype=np.int64)
        k = 0
        for i in range(n):
            if state[i] == 0:
                free[k] = i
                k += 1
        m = np.empty((n_free, n_free + 1))
        for a in range(n_free):
            i = free[a]
            for bb in range(n_free):
                m[a, bb] = w[i, free[bb]]
            acc = 0.0
            for j in range(n):
                if state[j] != 0:
                    acc += w[i, j] * (x[j] - xh[j])
            m[a, n_free] = -acc
        if not gauss_solve_inplace(m, n_free):
            return False
        for a in range(n_free):
            x[free[a]] = xh[free[a]] + m[a, n_free]
    return True


@njit_cached(linalg)
def _kkt_next_state(x, xh, w, lo, hi, state, tol, new):
    """KKT check of the face point x of `state`; the next active set into `new`; True iff x is optimal.

    Free components must lie inside the box (one outside is held at the bound it violates). The free
    components' gradient is zero by construction; at a held bound the gradient g = W (x - x_hat) is the
    multiplier: g_i >= 0 at a lower, g_i <= 0 at an upper bound, judged against the rounding scale
    tol * sum_j |W_ij (x_j - x_hat_j)| (a wrong sign releases the bound). One primal-dual active-set update.
    """
    n = x.shape[0]
    same = True
    for i in range(n):
        s = state[i]
        if s == 0:
            slack = tol * (1.0 + max(abs(lo[i]), abs(hi[i])))
            v = 1 if x[i] > hi[i] + slack else (-1 if x[i] < lo[i] - slack else 0)
        else:
            g = 0.0
            scale = 0.0
            for j in range(n):
                t = w[i, j] * (x[j] - xh[j])
                g += t
                scale += abs(t)
            gtol = tol * scale
            v = 0 if (s < 0 and g < -gtol) or (s > 0 and g > gtol) else s
        new[i] = v
        if v != s:
            same = False
    return same


@njit_cached(linalg)
def _clip_into(x, lo, hi):
    for i in range(x.shape[0]):
        x[i] = min(max(x[i], lo[i]), hi[i])


@njit_cached(linalg)
def active_set_solve(xh, w, pl, use_pl, lo, hi, x, max_iter):
    """The active-set iteration from the clip face. Returns the iterations used (x = the certified optimum,
    clipped to the box at rounding level) or 0 (no certificate within max_iter, or a singular face)."""
    n = xh.shape[0]
    state = np.empty(n, dtype=np.int64)
    new = np.empty(n, dtype=np.int64)
    for i in range(n):
        state[i] = 1 if xh[i] > hi[i] else (-1 if xh[i] < lo[i] else 0)
    for it in range(1, max_iter + 1):
        if not _face_point(xh, w, pl, use_pl, lo, hi, state, x):
            return 0
        if _kkt_next_state(x, xh, w, lo, hi, state, KKT_TOL, new):
            _clip_into(x, lo, hi)
            return it
        for i in range(n):
            state[i] = new[i]
    return 0


@njit_cached(linalg)
def _cost(x, xh, w):
    n = x.shape[0]
    c = 0.0
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += w[i, j] * (x[j] - xh[j])
        c += (x[i] - xh[i]) * acc
    return c


@njit_cached(linalg)
def enumerate_faces(xh, w, lo, hi, x):
    """Exact solution by enumeration: the clip face, then every face (3^n) by the number of held bounds; the
    first one passing the KKT check (EXACT_TOL) is the unique optimum of the strictly convex QP. If rounding
    defeats every check, the feasible candidate of lowest cost (the optimum is among them). x is clipped into
    the box (rounding level). False only if no candidate is feasible (W not positive definite)."""
    n = xh.shape[0]
    state = np.empty(n, dtype=np.int64)
    new = np.empty(n, dtype=np.int64)
    free = np.zeros(n, dtype=np.int64)
    cand = np.empty(n)
    best = np.empty(n)
    best_cost = math.inf
    found = False
    for i in range(n):
        state[i] = 1 if xh[i] > hi[i] else (-1 if xh[i] < lo[i] else 0)
    if _face_point(xh, w, w, False, lo, hi, state, cand) and _kkt_next_state(cand, xh, w, lo, hi, state,
                                                                              EXACT_TOL, new):
        for i in range(n):
            x[i] = cand[i]
        _clip_into(x, lo, hi)
        return True
    n_faces = 3**n
    for n_held in range(1, n + 1):  # no bound held is x_hat itself, which is outside
        for code in range(n_faces):
            # Digit of variable i (variable 0 most significant): 0 free, 1 lower, 2 upper.
            rest = code
            held = 0
            for i in range(n - 1, -1, -1):
                dgt = rest % 3
                rest //= 3
                state[i] = 0 if dgt == 0 else (-1 if dgt == 1 else 1)
                if dgt != 0:
                    held += 1
            if held != n_held or not _face_point(xh, w, w, False, lo, hi, state, cand):
                continue
            if _kkt_next_state(cand, xh, w, lo, hi, state, EXACT_TOL, new):
                for i in range(n):
                    x[i] = cand[i]
                _clip_into(x, lo, hi)
                return True
            if _kkt_next_state(cand, xh, w, lo, hi, free, KKT_TOL, new):  # feasible (all components in box)
                c = _cost(cand, xh, w)
                if c < best_cost:
                    best_cost = c
                    found = True
                    for i in range(n):
                        best[i] = cand[i]
    if not found:
        return False
    for i in range(n):
        x[i] = best[i]
    _clip_into(x, lo, hi)
    return True


@njit_cached(linalg)
def solve(xh, w, pl, use_pl, lo, hi, x):
    """The projection of x_hat (outside the box) into x: the active-set iteration, checked; the enumeration
    when it gives no certificate. pl = W^-1 if use_pl (only makes face solves cheaper). Returns the
    iterations (> 0), SOLVED_BY_ENUMERATION or NO_SOLUTION."""
    it = active_set_solve(xh, w, pl, use_pl, lo, hi, x, MAX_ITER)
    if it > 0:
        return it
    return SOLVED_BY_ENUMERATION if enumerate_faces(xh, w, lo, hi, x) else NO_SOLUTION


# --------------------------------------------------------------------------------------------------
# Python front end (checks and conversions; the KF calls the kernels directly)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ProjectionResult:
    """Outcome of one box projection; `x` is inside the box."""

    x: np.ndarray
    projected: bool  # False: x_hat was inside, x = x_hat
    used_fallback: bool  # True: the active-set iteration gave no certificate, the enumeration answered
    iterations: int  # active-set iterations (0 when inside or when the enumeration answered)


def _as_problem(
    x_hat: Sequence[float] | np.ndarray, w: np.ndarray, lower: Sequence[float] | np.ndarray,
    upper: Sequence[float] | np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    xh = np.array(x_hat, dtype=float)
    wa = np.ascontiguousarray(w, dtype=float)
    lo = np.array(lower, dtype=float)
    hi = np.array(upper, dtype=float)
    n = xh.shape[0]
    if xh.shape != (n,) or wa.shape != (n, n) or lo.shape != (n,) or hi.shape != (n,):
        raise ValueError(f"shape mismatch: x {xh.shape}, W {wa.shape}, lower {lo.shape}, upper {hi.shape}")
    if not bool((lo <= hi).all()):
        raise ValueError(f"empty box (or NaN bound): lower {lo}, upper {hi}")
    return xh, wa, lo, hi


def project_box(
    x_hat: Sequence[float] | np.ndarray,
    w: np.ndarray,
    lower: Sequence[float] | np.ndarray,
    upper: Sequence[float] | np.ndarray,
    w_inv: np.ndarray | None = None,
) -> ProjectionResult:
    """min (x - x_hat)^T W (x - x_hat) s.t. lower <= x <= upper (W SPD); x_hat itself when inside.

    w_inv, if given, must be W^-1 (the KF has P); it only makes the face solves cheaper.
    Raises ValueError on mismatched shapes or an empty box, LinAlgError if no candidate is feasible.
    """
    xh, wa, lo, hi = _as_problem(x_hat, w, lower, upper)
    if bool(((xh >= lo) & (xh <= hi)).all()):
        return ProjectionResult(xh, False, False, 0)
    use_pl = w_inv is not None
    pl = np.ascontiguousarray(w_inv, dtype=float) if use_pl else wa
    x = np.empty_like(xh)
    code = solve(xh, wa, pl, use_pl, lo, hi, x)
    if code == NO_SOLUTION:
        raise np.linalg.LinAlgError("box projection: no feasible candidate (is W positive definite?)")
    return ProjectionResult(x, True, code == SOLVED_BY_ENUMERATION, max(code, 0))


def project_box_exact(
    x_hat: Sequence[float] | np.ndarray,
    w: np.ndarray,
    lower: Sequence[float] | np.ndarray,
    upper: Sequence[float] | np.ndarray,
) -> np.ndarray:
    """The fallback alone (`enumerate_faces`): the exact projection by enumerating the faces."""
    xh, wa, lo, hi = _as_problem(x_hat, w, lower, upper)
    if bool(((xh >= lo) & (xh <= hi)).all()):
        return xh
    x = np.empty_like(xh)
    if not enumerate_faces(xh, wa, lo, hi, x):
        raise np.linalg.LinAlgError("box projection: no feasible candidate (is W positive definite?)")
    return x
