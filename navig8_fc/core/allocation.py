"""Prioritised weighted least-squares control allocation over the real actuators (INDI_ALLOC = 1).

The paper's INDI (Eq. 5-6) inverts G_C,UAM^-1 G_hat_I exactly; when the resulting U leaves the feasible set the
paper-faithful option (INDI_ALLOC = 0, `indi.indi_step`) scales the increment back group by group, which
holds the forward force a_x fixed and so discards the tilt lever (common duct tilt x the ducts' vertical offset),
the largest source of pitch moment at hover (docs/results.md, "Authority bound"). This module replaces that
step, only on the ticks where the exact increment is infeasible (elsewhere both options fly the same U):

    min_dx  sum_i (w_i (A dx - Delta Acc)_i)^2 + EPS_REG |dx|^2     s.t.  lo <= dx <= hi

over the real actuators x = [alpha1, alpha3, t1, t3, t5] (duct tilts in rad; duct thrust t = w^2 / w_max^2 and
the reversible tail's signed t5 = sign(w2) w2^2 / w2_max^2, both in [0, 1] resp. [-1, 1]: monotonic in the
speeds, so the speed limits are exact box bounds, and linear in U, so only the tilts are linearised). A = M^-1 J
with M = G_C^-1 G_hat_I (the INDI's own inverse model, Eq. 5: Delta Acc = M^-1 Delta U) and J = dU/dx at the
actuators of the (low-passed) U0. The box is the actuator position limits intersected, for the tilts, with
a per-tick step INDI_ALLOC_DTILT (a rate limit, and the trust region of the tilt linearisation). The weights
w = [W_RP, W_RP, W_YAW, W_AX, W_AZ] set the priorities roll/pitch >> vertical force >> yaw >> forward force:
the weighted-LS form of a prioritised allocation, as Paparazzi's rotorcraft INDI does it (stabilization_indi.c
calling sw/airborne/math/wls/wls_alloc.h, Haerkegaard's active-set WLS; Smeur, Hoeppener & De Wagter, IMAV
2017); its default Wv = {1000, 1000, 1, 100} for roll, pitch, yaw, thrust has our roll/pitch : thrust ratio.
The small regulariser keeps the problem strictly convex when a column of A vanishes (a duct at zero thrust
has no tilt effect). The tilt linearisation is refined by GN_PASSES damped Gauss-Newton passes.

wls_box solves each pass with a primal active-set method on the residual form (its docstring);
tests/unit/test_allocation.py checks it against scipy.optimize.lsq_linear (BVLS). box_qp's projection in the
H-norm (the KF's solver) was tried first and certified wrong faces on ill-conditioned problems.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navig8_fc.core import box_qp, linalg
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.layout import layout

__all__ = ["AL", "ALLOC_GROUP_SCALING", "ALLOC_WLS", "AllocationConfig", "EPS_REG", "allocate_actuators",
           "within_tilt_step", "wls_box"]

ALLOC_GROUP_SCALING = 0  # INDI_ALLOC = 0: the paper's increment with group scaling on saturation
ALLOC_WLS = 1  # INDI_ALLOC = 1: this module on saturation

GN_PASSES = 3  # Gauss-Newton passes (damped): the later ones correct the first's tilt linearisation
EPS_REG = 1e-6  # regulariser on the normalised actuator increment (|dx| ~ 1 is full range)

# Allocation configuration vector: weights of Delta Acc = [Pdot, Qdot, Rdot, a_x, a_z], the tilt step per tick,
# and the actuator limits the allocation keeps to (the INDI's: duct tilt range, duct speed, w_tail_max^2 on |U5|).
AL = layout("AL", w_acc=5, tilt_step=1, tilt_min=1, tilt_max=1, duct_speed_max=1, u_tail_max=1)

# Return codes of wls_box
WLS_INTERIOR = 0  # the unconstrained minimiser is inside the box
WLS_ACTIVE_SET = 1  # the optimum holds some bounds (KKT certified)
WLS_FAILED = 2  # no certificate within WLS_MAX_ITER (x feasible, maybe not optimal); not seen in the tests
WLS_MAX_ITER = 40  # active-set iterations (each adds or releases one bound)
WLS_KKT_TOL = 1e-9  # multiplier sign test, relative to the rounding scale of the gradient component


@dataclass(frozen=True)
class AllocationConfig:
    """INDI_ALLOC and its weights (params/fc_params.yaml); `vector(...)` is the kernels' AL vector."""

    mode: int = ALLOC_GROUP_SCALING
    w_rp: float = 100.0  # roll and pitch angular acceleration, per rad/s^2
    w_az: float = 10.0  # vertical specific force, per m/s^2
    w_yaw: float = 0.3  # yaw angular acceleration, per rad/s^2
    w_ax: float = 0.03  # forward specific force, per m/s^2
    tilt_step_rad: float = 0.3  # largest duct-tilt change per tick relative to the low-passed tilt

    def __post_init__(self) -> None:
        if self.mode not in (ALLOC_GROUP_SCALING, ALLOC_WLS):
            raise ValueError(f"INDI_ALLOC must be 0 or 1, got {self.mode}")
        for name in ("w_rp", "w_az", "w_yaw", "w_ax", "tilt_step_rad"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"allocation {name} must be finite and > 0, got {v}")

    def vector(self, tilt_min_rad: float, tilt_max_rad: float, duct_speed_max: float, tail_speed_max: float
               ) -> np.ndarray:
        """The AL vector: these weights and tilt step with the actuators' limits (rad, rad/s)."""
        return AL.pack(w_acc=(self.w_rp, self.w_rp, self.w_yaw, self.w_ax, self.w_az), tilt_step=self.tilt_step_rad,
                       tilt_min=tilt_min_rad, tilt_max=tilt_max_rad, duct_speed_max=duct_speed_max,
                       u_tail_max=tail_speed_max**2)


@njit_cached(box_qp, linalg)
def _wls_gradient(a, d, w, eps, x, g, gscale):
    """g = A^T W^2 (A x - d) + eps x from the residual (no cancellation against a far unconstrained point),
    and the rounding scale of each component (sum of the magnitudes of its terms)."""
    n_out, n = a.shape
    r = np.empty(n_out)
    for k in range(n_out):
        acc = -d[k]
        for j in range(n):
            acc += a[k, j] * x[j]
        r[k] = w[k] * w[k] * acc
    for i in range(n):
        acc = eps * x[i]
        sc = abs(acc)
        for k in range(n_out):
            t = a[k, i] * r[k]
            acc += t
            sc += abs(t)
        g[i] = acc
        gscale[i] = sc


@njit_cached(box_qp, linalg)
def wls_box(a, d, w, eps, lo, hi, x):
    """x = argmin sum_i (w_i (A x - d)_i)^2 + eps |x|^2 s.t. lo <= x <= hi (A: n_out x n; lo <= 0 <= hi).

    The primal active-set method of Haerkegaard's WLS allocator (feasible iterates from x = 0): solve the
    equality-constrained problem on the free variables; if the step leaves the box, go to the first bound it
    hits and hold it; else, if a held bound's multiplier (the gradient, computed from the residual) has the
    wrong sign, release the worst one; else x is optimal (KKT). Every iterate is feasible, so even the
    (never observed) WLS_FAILED answer is inside the box. Returns WLS_INTERIOR (no bound held at the
    optimum), WLS_ACTIVE_SET or WLS_FAILED."""
    n_out, n = a.shape
    state = np.zeros(n, dtype=np.int64)  # -1 held at lo, +1 held at hi, 0 free
    h = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for k in range(n_out):
                acc += a[k, i] * w[k] * w[k] * a[k, j]
            h[i, j] = acc
        h[i, i] += eps
    for i in range(n):
        x[i] = min(max(0.0, lo[i]), hi[i])
    g = np.empty(n)
    gscale = np.empty(n)
    p = np.empty(n)
    free = np.empty(n, dtype=np.int64)
    for _ in range(WLS_MAX_ITER):
        _wls_gradient(a, d, w, eps, x, g, gscale)
        nf = 0
        for i in range(n):
            if state[i] == 0:
                free[nf] = i
                nf += 1
        for i in range(n):
            p[i] = 0.0
        if nf > 0:
            m = np.empty((nf, nf + 1))
            for r in range(nf):
                for c in range(nf):
                    m[r, c] = h[free[r], free[c]]
                m[r, nf] = -g[free[r]]
            if not box_qp.gauss_solve_inplace(m, nf):
                return WLS_FAILED
            for r in range(nf):
                p[free[r]] = m[r, nf]
        # the longest feasible fraction of the step, and the bound that stops it
        alpha = 1.0
        block = -1
        for r in range(nf):
            i = free[r]
            if p[i] > 0.0 and x[i] + p[i] > hi[i]:
                t = (hi[i] - x[i]) / p[i]
                if t < alpha:
                    alpha, block = t, i
            elif p[i] < 0.0 and x[i] + p[i] < lo[i]:
                t = (lo[i] - x[i]) / p[i]
                if t < alpha:
                    alpha, block = t, i
        if block >= 0:
            for i in range(n):
                x[i] = min(max(x[i] + alpha * p[i], lo[i]), hi[i])
            if p[block] > 0.0:
                x[block] = hi[block]
                state[block] = 1
            else:
                x[block] = lo[block]
                state[block] = -1
            continue
        for i in range(n):
            x[i] += p[i]
        _wls_gradient(a, d, w, eps, x, g, gscale)
        worst = -1
        worst_v = 0.0
        for i in range(n):
            s = state[i]
            if s == 0:
                continue
            v = -g[i] if s < 0 else g[i]  # > 0: pulling away from the held bound, into the box
            if v > WLS_KKT_TOL * gscale[i] and v > worst_v:
                worst, worst_v = i, v
        if worst < 0:
            for i in range(n):
                if state[i] != 0:
                    return WLS_ACTIVE_SET
            return WLS_INTERIOR
        state[worst] = 0
    return WLS_FAILED


@njit_cached(box_qp, linalg)
def _u_of_x(x, t_duct_max, u_tail_max, u):
    """U (Sec. 3) of the normalised actuators x = [alpha1, alpha3, t1, t3, t5]."""
    u[0] = t_duct_max * x[2] * math.cos(x[0])
    u[1] = t_duct_max * x[2] * math.sin(x[0])
    u[2] = t_duct_max * x[3] * math.cos(x[1])
    u[3] = t_duct_max * x[3] * math.sin(x[1])
    u[4] = u_tail_max * x[4]


@njit_cached(box_qp, linalg)
def _x_of_u(al, u, x):
    """The normalised actuators x = [alpha1, alpha3, t1, t3, t5] of U, clamped into the position limits."""
    t_max = al[AL.DUCT_SPEED_MAX] * al[AL.DUCT_SPEED_MAX]  # w_max^2
    tmin, tmax = al[AL.TILT_MIN], al[AL.TILT_MAX]
    x[0] = min(max(math.atan2(u[1], u[0]), tmin), tmax)
    x[1] = min(max(math.atan2(u[3], u[2]), tmin), tmax)
    x[2] = min(math.hypot(u[0], u[1]) / t_max, 1.0)
    x[3] = min(math.hypot(u[2], u[3]) / t_max, 1.0)
    x[4] = min(max(u[4] / al[AL.U_TAIL_MAX], -1.0), 1.0)


@njit_cached(box_qp, linalg)
def within_tilt_step(al, u0, u):
    """True if U's duct tilts are within INDI_ALLOC_DTILT of U0's (the per-tick tilt rate limit)."""
    x0 = np.empty(5)
    x = np.empty(5)
    _x_of_u(al, u0, x0)
    _x_of_u(al, u, x)
    step = al[AL.TILT_STEP]
    return abs(x[0] - x0[0]) <= step and abs(x[1] - x0[1]) <= step


@njit_cached(box_qp, linalg)
def _wls_pass(al, m, d, u0, x0, xl, radius, dacc_pred, x):
    """One Gauss-Newton pass: linearise U at the actuators xl, solve the box WLS for the increment that
    delivers d relative to U0, into x (absolute actuators, inside the box around x0) and its predicted
    Delta Acc; the tilts also stay within `radius` of xl (the pass's trust region). Returns wls_box's code, or
    -1 if M is singular."""
    t_max = al[AL.DUCT_SPEED_MAX] * al[AL.DUCT_SPEED_MAX]
    u_tail = al[AL.U_TAIL_MAX]
    ul = np.empty(5)
    _u_of_x(xl, t_max, u_tail, ul)
    # [M | J | U(xl) - U0]: A = M^-1 J and the offset M^-1 (U(xl) - U0)
    aug = np.zeros((5, 11))
    for i in range(5):
        for j in range(5):
            aug[i, j] = m[i, j]
        aug[i, 10] = ul[i] - u0[i]
    c1, s1, c3, s3 = math.cos(xl[0]), math.sin(xl[0]), math.cos(xl[1]), math.sin(xl[1])
    aug[0, 5] = -t_max * xl[2] * s1
    aug[1, 5] = t_max * xl[2] * c1
    aug[2, 6] = -t_max * xl[3] * s3
    aug[3, 6] = t_max * xl[3] * c3
    aug[0, 7] = t_max * c1
    aug[1, 7] = t_max * s1
    aug[2, 8] = t_max * c3
    aug[3, 8] = t_max * s3
    aug[4, 9] = u_tail
    if not box_qp.gauss_solve_inplace(aug, 5):
        return -1
    a = np.empty((5, 5))
    target = np.empty(5)
    for i in range(5):
        for j in range(5):
            a[i, j] = aug[i, 5 + j]
        target[i] = d[i] - aug[i, 10]
    tmin, tmax, step = al[AL.TILT_MIN], al[AL.TILT_MAX], al[AL.TILT_STEP]
    lo = np.empty(5)
    hi = np.empty(5)
    for i in range(2):
        lo[i] = max(max(tmin, x0[i] - step), xl[i] - radius) - xl[i]
        hi[i] = min(min(tmax, x0[i] + step), xl[i] + radius) - xl[i]
    for i in range(2, 4):
        lo[i] = -xl[i]
        hi[i] = 1.0 - xl[i]
    lo[4] = -1.0 - xl[4]
    hi[4] = 1.0 - xl[4]
    w = al[AL.W_ACC:AL.W_ACC + 5]
    dx = np.empty(5)
    code = wls_box(a, target, w, EPS_REG, lo, hi, dx)
    for i in range(5):
        acc = aug[i, 10]
        for j in range(5):
            acc += a[i, j] * dx[j]
        dacc_pred[i] = acc
        x[i] = xl[i] + dx[i]
    return code


@njit_cached(box_qp, linalg)
def allocate_actuators(al, m, d, u0, u, dacc_pred):
    """The WLS allocation of this module's docstring, GN_PASSES Gauss-Newton passes from the actuators of U0 (pass
    k's tilt trust region INDI_ALLOC_DTILT / 2^k around the previous pass's answer):
    U (inside the actuator limits) into u, the Delta Acc the last pass predicts into dacc_pred. Returns the
    last pass's wls_box code, or -1 if M is singular (u, dacc_pred untouched)."""
    t_max = al[AL.DUCT_SPEED_MAX] * al[AL.DUCT_SPEED_MAX]
    x0 = np.empty(5)
    _x_of_u(al, u0, x0)
    xl = x0.copy()
    x = np.empty(5)
    code = -1
    radius = al[AL.TILT_STEP]
    for _ in range(GN_PASSES):
        code = _wls_pass(al, m, d, u0, x0, xl, radius, dacc_pred, x)
        radius *= 0.5  # damped: each pass may move the tilts half as far as the one before
        if code < 0:
            return code
        for i in range(5):
            xl[i] = x[i]
    _u_of_x(x, t_max, al[AL.U_TAIL_MAX], u)
    return code
