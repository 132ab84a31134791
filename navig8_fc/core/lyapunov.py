"""Common quadratic Lyapunov functions of a finite family of discrete-time matrices (an SDP solved with clarabel).

Pure math (numpy/scipy/clarabel): no I/O, no clocks, no prints.

The question: is there one P = P^T > 0 with

    A_i^T P A_i <= rho^2 P      for every vertex A_i                                         (*)

If so, V(x) = x^T P x decreases by the factor rho^2 each step for x+ = A(k) x with A(k) ANY sequence in the convex
hull of the A_i (the set {A : A^T P A <= rho^2 P} is convex in A: by a Schur complement it is the linear matrix
inequality [[rho^2 P, A^T P], [P A, P]] >= 0), so the switched or slowly or quickly varying system is exponentially
stable with ||x_k|| <= sqrt(cond P) rho^k ||x_0||. Frozen-time stability (every spectral radius < 1) is necessary
for (*) with rho < 1 but not sufficient.

Method.
- Feasibility ("is there a common P at all"): min trace(P) s.t. P >= I, A_i^T P A_i - P <= -I for all i. (*) with
  some rho < 1 holds for a finite family iff this SDP is feasible (scale P up), so a clarabel infeasibility
  certificate is the answer "no common quadratic Lyapunov function".
- Decay rate: the P found is checked on every vertex with plain linear algebra (rho_P = max_i ||L^T A_i L^-T||_2,
  P = L L^T), so the reported rate never rests on the solver's tolerances; then bisection on rho in
  [max_i spectral radius, rho_P] with the SDP min trace(P) s.t. P >= I, A_i^T P A_i <= rho^2 P.
- Many vertices: constraint generation. The SDP is solved on a working subset; the P found is checked on all
  vertices; the most violated ones join the subset. Infeasibility on a subset is infeasibility of the family (fewer
  constraints), so both answers are exact for the full set.
- Scaling: one common similarity transform x = S z (S from the Lyapunov equation of the mean vertex) makes the
  problem well conditioned; (*) is invariant under it (P -> S^T P S).
- PSD cones: clarabel's PSDTriangleConeT takes the upper triangle, column by column, off-diagonal entries scaled by
  sqrt(2) (svec below).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import clarabel
import numpy as np
from scipy import linalg, sparse

_SQRT2 = math.sqrt(2.0)


# --------------------------------------------------------------------------------------
# svec: the symmetric-matrix vectorisation clarabel's PSD triangle cone uses
# --------------------------------------------------------------------------------------


def _triu_cols(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the upper triangle, column by column: (0,0), (0,1), (1,1), (0,2), ..."""
    cols = np.concatenate([np.full(j + 1, j) for j in range(n)])
    rows = np.concatenate([np.arange(j + 1) for j in range(n)])
    return rows, cols


def svec(m: np.ndarray) -> np.ndarray:
    """Upper triangle of the symmetric m, column by column, off-diagonal entries times sqrt(2) (<X, Y> = svec.svec)."""
    n = m.shape[0]
    r, c = _triu_cols(n)
    return np.where(r == c, 1.0, _SQRT2) * m[r, c]


def smat(v: np.ndarray, n: int) -> np.ndarray:
    """Inverse of svec."""
    r, c = _triu_cols(n)
    out = np.zeros((n, n))
    vals = np.where(r == c, 1.0, 1.0 / _SQRT2) * np.asarray(v, dtype=float)
    out[r, c] = vals
    out[c, r] = vals
    return out


def _svec_maps(n: int) -> tuple[sparse.csr_matrix, sparse.csr_matrix]:
    """(to_svec (N x n^2), from_svec (n^2 x N)) for row-major vec, N = n(n+1)/2."""
    r, c = _triu_cols(n)
    big = r * n + c
    w = np.where(r == c, 1.0, _SQRT2)
    nn, nt = n * n, r.size
    to_svec = sparse.csr_matrix((w, (np.arange(nt), big)), shape=(nt, nn))
    # P[i, j] = P[j, i] = svec_k / w_k
    rows = np.concatenate([r * n + c, (c * n + r)[r != c]])
    cols = np.concatenate([np.arange(nt), np.arange(nt)[r != c]])
    vals = np.concatenate([1.0 / w, (1.0 / w)[r != c]])
    from_svec = sparse.csr_matrix((vals, (rows, cols)), shape=(nn, nt))
    return to_svec, from_svec


def congruence_operator(a: np.ndarray, to_svec: sparse.csr_matrix, from_svec: sparse.csr_matrix) -> np.ndarray:
    """The N x N matrix of svec(P) -> svec(A^T P A) (row-major vec(A^T P A) = (A^T kron A^T) vec(P))."""
    k = np.kron(a.T, a.T)
    return np.asarray(to_svec @ (from_svec.T @ k.T).T)


# --------------------------------------------------------------------------------------
# One SDP
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SdpOutcome:
    status: str  # clarabel's status string ("Solved", "PrimalInfeasible", ...)
    feasible: bool | None  # None: the solver could not tell (numerical trouble, iteration limit)
    p: np.ndarray | None  # the P found (scaled coordinates), when feasible
    solve_time_s: float  # clarabel's own solve time
    z: np.ndarray | None = None  # the dual vector (the infeasibility certificate when infeasible)


_FEASIBLE = {"Solved", "AlmostSolved"}
_INFEASIBLE = {"PrimalInfeasible", "AlmostPrimalInfeasible"}


def _solve_sdp(ops: Sequence[np.ndarray], rho: float, strict: bool, n: int) -> SdpOutcome:
    """min trace(P) s.t. P >= I and, per operator L_i = svec(A_i^T . A_i), rho^2 P - A_i^T P A_i >= (I if strict)."""
    nt = n * (n + 1) // 2
    eye = svec(np.eye(n))
    blocks_a = [-sparse.identity(nt, format="csc")]
    blocks_b = [-eye]
    for op in ops:
        # s = b - A x = svec(rho^2 P - A^T P A - mu I) in the PSD cone
        blocks_a.append(sparse.csc_matrix(-(rho**2 * np.eye(nt) - op)))
        blocks_b.append(-eye if strict else np.zeros(nt))
    a_mat = sparse.vstack(blocks_a, format="csc")
    b_vec = np.concatenate(blocks_b)
    cones = [clarabel.PSDTriangleConeT(n) for _ in range(len(ops) + 1)]
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_iter = 300
    solver = clarabel.DefaultSolver(sparse.csc_matrix((nt, nt)), eye, a_mat, b_vec, cones, settings)
    sol = solver.solve()
    status = str(sol.status)
    feasible = True if status in _FEASIBLE else (False if status in _INFEASIBLE else None)
    p = smat(np.asarray(sol.x), n) if feasible else None
    return SdpOutcome(status, feasible, p, float(sol.solve_time), np.asarray(sol.z))


def certificate_residual(matrices: np.ndarray, z: np.ndarray) -> float:
    """How far clarabel's infeasibility certificate is from an exact one, relative to its size.

    By Farkas' lemma for the strict LMI, no P > 0 with A_i^T P A_i < P exists iff there are Z_i >= 0, not all zero,
    with D = sum_i (A_i Z_i A_i^T - Z_i) >= 0 (the dual of the P >= I cone absorbs D). z holds [Z_0, Z_1, ...] in
    svec form. Returns max(0, -lambda_min(D)) / sum_i tr Z_i after projecting each Z_i onto the PSD cone: 0 is an
    exact certificate; a small value says any common P would need cond(P) >= (1 - rho^2) / (n * residual)."""
    m, n = matrices.shape[0], matrices.shape[1]
    nt = n * (n + 1) // 2
    d = np.zeros((n, n))
    total = 0.0
    for i in range(m):
        zi = smat(z[nt * (i + 1) : nt * (i + 2)], n)
        w, v = np.linalg.eigh(zi)
        zi = (v * np.clip(w, 0.0, None)) @ v.T
        d += matrices[i] @ zi @ matrices[i].T - zi
        total += float(np.trace(zi))
    if total <= 0.0:
        return math.inf
    return max(0.0, -float(np.linalg.eigvalsh(0.5 * (d + d.T))[0])) / total


# --------------------------------------------------------------------------------------
# The family
# --------------------------------------------------------------------------------------


def contraction_factors(matrices: np.ndarray, p: np.ndarray) -> np.ndarray:
    """rho_i = sqrt(lambda_max(P^-1 A_i^T P A_i)) = ||L^T A_i L^-T||_2 with P = L L^T, for every vertex (batched).

    V = x^T P x shrinks by at least rho_i^2 per step of A_i; a common P with every rho_i < 1 is the certificate."""
    chol = np.linalg.cholesky(p)
    lt = chol.T
    lt_inv = linalg.solve_triangular(chol, np.eye(p.shape[0]), lower=True)  # L^-1, so L^-T = lt_inv.T
    m = lt[None] @ matrices @ lt_inv.T[None]
    return np.linalg.norm(m, ord=2, axis=(-2, -1))


def _scaling(matrices: np.ndarray) -> np.ndarray:
    """S with S^-1 A S well conditioned: the inverse Cholesky factor of the mean vertex's Lyapunov solution
    (in z = S^-1 x the mean vertex contracts in the plain Euclidean norm). Identity if the mean is not stable."""
    mean = matrices.mean(axis=0)
    n = mean.shape[0]
    if np.max(np.abs(np.linalg.eigvals(mean))) >= 1.0:
        return np.eye(n)
    p0 = linalg.solve_discrete_lyapunov(mean.T, np.eye(n))
    p0 = 0.5 * (p0 + p0.T)
    chol = np.linalg.cholesky(p0)  # P0 = L L^T; z = L^T x, x = L^-T z
    return linalg.solve_triangular(chol, np.eye(n), lower=True).T


@dataclass(frozen=True)
class CommonLyapunovResult:
    """A common quadratic Lyapunov function for a family of one-step matrices, or why there is none."""

    feasible: bool | None  # None: undecided (the solver failed or the budget ran out)
    n_vertices: int
    state_dim: int
    max_spectral_radius: float  # max_i rho(A_i): a lower bound for any common rate
    max_spectral_radius_vertex: int
    rate: float | None  # verified contraction factor per step of V^(1/2): max_i rho_i for the best P found
    p: np.ndarray | None  # that P (original coordinates)
    rho_per_vertex: np.ndarray | None  # rho_i of that P
    active: tuple[int, ...]  # the vertices the last SDP held (the binding subset)
    unstable_vertices: tuple[int, ...]  # spectral radius >= 1: no P can exist while these are in the set
    conflict: tuple[int, ...]  # infeasible: a small subset of vertices that shares no P (greedy, see find_conflict)
    n_sdp: int  # SDPs solved
    sdp_time_s: float  # clarabel's time in them
    status: str  # the deciding SDP's status, or the reason it was not solved
    certificate_residual: float | None = None  # infeasible: certificate_residual of the conflict set (0 = exact)


def _generate(matrices: np.ndarray, ops_of, rho: float, strict: bool, active: list[int], max_rounds: int,
              add_per_round: int, n: int) -> tuple[SdpOutcome, list[int], int, float, np.ndarray | None]:
    """Constraint generation: SDP on `active`, check every vertex, add the worst violators, until none is violated.

    Returns (last outcome, active set, SDPs solved, solver time, rho_i of the final P or None)."""
    n_sdp, t_sdp = 0, 0.0
    # The strict SDP asks A^T P A - P <= -I; the check uses the factor it implies, rho_i < 1.
    target = rho if not strict else 1.0
    for _ in range(max_rounds):
        out = _solve_sdp([ops_of(i) for i in active], rho, strict, n)
        n_sdp += 1
        t_sdp += out.solve_time_s
        if out.feasible is not True:
            return out, active, n_sdp, t_sdp, None
        rho_i = contraction_factors(matrices, out.p)
        slack = 1e-9 if not strict else 0.0
        bad = [int(i) for i in np.argsort(-rho_i) if rho_i[i] >= target + slack and int(i) not in active]
        if not bad:
            # tolerance: a vertex of the active set may sit on the boundary at the solver's accuracy
            return out, active, n_sdp, t_sdp, rho_i
        active = active + bad[:add_per_round]
    return SdpOutcome("constraint generation did not converge", None, None, 0.0), active, n_sdp, t_sdp, None


def common_lyapunov(
    matrices: np.ndarray,
    bisection_steps: int = 6,
    initial: Sequence[int] = (),
    max_rounds: int = 40,
    add_per_round: int = 4,
    find_conflicting: bool = True,
) -> CommonLyapunovResult:
    """Is there P > 0 with A_i^T P A_i < P for every A_i in matrices (m, n, n)? And the best rate found (see above).

    initial: vertices the first SDP holds besides the one with the largest spectral radius. bisection_steps: SDPs
    spent on improving the rate after feasibility (0: report the rate of the feasibility SDP's P)."""
    mats = np.asarray(matrices, dtype=float)
    if mats.ndim != 3 or mats.shape[1] != mats.shape[2] or mats.shape[0] == 0:
        raise ValueError(f"need a non-empty (m, n, n) array, got shape {mats.shape}")
    m, n = mats.shape[0], mats.shape[1]
    spec = np.max(np.abs(np.linalg.eigvals(mats)), axis=-1)
    i_spec = int(np.argmax(spec))
    unstable = tuple(int(i) for i in np.nonzero(spec >= 1.0)[0])
    if unstable:
        return CommonLyapunovResult(False, m, n, float(spec[i_spec]), i_spec, None, None, None, (), unstable,
                                    (i_spec,), 0, 0.0, "a vertex is not stable on its own (spectral radius >= 1)")
    s = _scaling(mats)
    s_inv = np.linalg.inv(s)
    scaled = s_inv[None] @ mats @ s[None]
    to_svec, from_svec = _svec_maps(n)
    cache: dict[int, np.ndarray] = {}

    def ops_of(i: int) -> np.ndarray:
        if i not in cache:
            cache[i] = congruence_operator(scaled[i], to_svec, from_svec)
        return cache[i]

    active = list(dict.fromkeys([i_spec, *(int(i) for i in initial)]))
    out, active, n_sdp, t_sdp, rho_i = _generate(scaled, ops_of, 1.0, True, active, max_rounds, add_per_round, n)
    if out.feasible is not True:
        conflict: tuple[int, ...] = ()
        residual = None
        if out.feasible is False and out.z is not None:
            conflict, z = tuple(active), out.z
            if find_conflicting:
                conflict, k, t, z = find_conflict(scaled, active, ops_of, n, out.z)
                n_sdp += k
                t_sdp += t
            residual = certificate_residual(scaled[list(conflict)], z)
        return CommonLyapunovResult(out.feasible, m, n, float(spec[i_spec]), i_spec, None, None, None,
                                    tuple(active), (), conflict, n_sdp, t_sdp, out.status, residual)
    best_p = out.p
    lo, hi = float(spec[i_spec]), float(np.max(rho_i))
    for _ in range(bisection_steps):
        mid = 0.5 * (lo + hi)
        o, act, k, t, r_i = _generate(scaled, ops_of, mid, False, list(active), max_rounds, add_per_round, n)
        n_sdp += k
        t_sdp += t
        if o.feasible is True and r_i is not None and float(np.max(r_i)) < hi:
            best_p, active = o.p, act
            hi = float(np.max(r_i))
        elif o.feasible is False:
            lo = mid
        else:
            lo = mid  # undecided at this rate: do not claim it
    p_orig = s_inv.T @ best_p @ s_inv  # x^T P x = z^T P_s z with z = S^-1 x
    p_orig = 0.5 * (p_orig + p_orig.T)
    rho_orig = contraction_factors(mats, p_orig)
    return CommonLyapunovResult(True, m, n, float(spec[i_spec]), i_spec, float(np.max(rho_orig)), p_orig,
                                rho_orig, tuple(active), (), (), n_sdp, t_sdp, out.status)


def find_conflict(scaled: np.ndarray, active: Sequence[int], ops_of, n: int,
                  z_active: np.ndarray) -> tuple[tuple[int, ...], int, float, np.ndarray]:
    """A small subset of `active` (an infeasible set) that is still infeasible: drop one vertex at a time and keep
    the drop whenever the rest stays infeasible (deletion filter). Returns (subset, SDPs solved, solver time, the
    subset's infeasibility certificate z)."""
    keep = list(active)
    z_keep = z_active
    n_sdp, t_sdp = 0, 0.0
    # Try to drop the vertices with the smallest spectral radius first: they are the least likely to be needed.
    spec = np.max(np.abs(np.linalg.eigvals(scaled[list(active)])), axis=-1)
    for i in [active[j] for j in np.argsort(spec)]:
        if len(keep) <= 2:
            break
        trial = [j for j in keep if j != i]
        out = _solve_sdp([ops_of(j) for j in trial], 1.0, True, n)
        n_sdp += 1
        t_sdp += out.solve_time_s
        if out.feasible is False and out.z is not None:
            keep, z_keep = trial, out.z
    return tuple(keep), n_sdp, t_sdp, z_keep
