"""The loop flown while the estimate K varies: a common quadratic Lyapunov function over K corners x a pose/object grid.

Pure math (numpy/scipy/clarabel): no I/O, no clocks, no prints. docs/stability.md, "The loop flown while K varies".

Why. Sec. 3.1-3.2 (Eq. 9-20) is a frozen-time argument: for every FIXED G_hat G^-1 = K Xi (Eq. 14) the eigenvalues
lie where the decoupled H_i (Eq. 9) is stable. The constrained Kalman filter moves K every tick, and a loop whose
every frozen matrix is stable can still diverge when the matrix changes. A single P > 0 with A_i^T P A_i <= rho^2 P
for every vertex A_i (core.lyapunov) rules that out for any sequence inside the vertices' convex hull.

The vertices.
- The loop: stability.coupled_loop_parts, the five rows of Eq. 7 at the FC's rate with the actuator model, the
  feedback low-pass, the one-tick delay and the configured U0, coupled through (G_hat G^-1)^-1 in the increment:
  A = A_free - B Lambda^-1 C.
- K enters G_hat linearly (Eq. 3-4: G_hat_I = K G_I,UAM), so Lambda = K Xi is linear in K, but the loop holds
  Lambda^-1 = Xi^-1 K^-1. Lifting: the varying quantity is kappa = 1/K (diagonal), and A is affine in kappa. The
  box K_i in [k_min, k_max] is the box kappa_i in [1/k_max, 1/k_min], whose 16 corners are the K corners. So for a
  fixed pose and object, every A with K anywhere in the box, and every convex combination of such A, lies in the
  convex hull of the 16 corner matrices: the corners are genuine vertices and nothing between them is missed.
- The pose q and the object (mass, CoM offset) enter Xi nonlinearly: they are gridded, not a polytope. The statement
  is therefore "on the grid": arbitrary switching among the grid's (pose, object) cases and the K box. Between grid
  points it is an interpolation, not a proof.

The computation. Xi is block triangular in (lateral = rows/cols P_dot, R_dot; longitudinal = Q_dot, a_x, a_z)
order: the object sits in the longitudinal plane (Sec. 3.2), so the longitudinal rows do not see the lateral inputs
(stability.xi_block_coupling ~ 1e-16). Then every vertex is block upper triangular (the lateral channels receive the
longitudinal accelerations, not the converse), and
- the x_lateral subspace is invariant under every vertex, so a common P for all 35 states restricts to one for the
  lateral blocks: a lateral family without a common P means the whole family has none (the same holds for the
  longitudinal blocks through P^-1 and the transposed family);
- conversely, common P_lat and P_long give P = diag(P_lat, t P_long) for the whole family once t is large enough
  to dominate the coupling block.
So the SDPs run on the 14-state lateral and the 21-state longitudinal families (deduplicated: the lateral blocks see
K1, K3 only, the longitudinal K2, K4) and the assembled P is checked on every full 35-state vertex with plain linear
algebra; the rate reported is that check's. Without the block structure (a vehicle whose object leaves the plane)
the full family goes to the SDP directly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from navig8_fc.core import k_xi, sampled_loop
from navig8_fc.core.lyapunov import CommonLyapunovResult, common_lyapunov, contraction_factors
from navig8_fc.core.vehicle import VehicleConfig

# An extra object CoM offset beyond the link tip (m) in the default grid: the object held 10 cm further out.
EXTRA_OBJECT_OFFSET_M = 0.1
# Block coupling |Xi[longitudinal rows, lateral columns]| below this counts as exactly block triangular (round-off).
BLOCK_COUPLING_TOL = 1e-10
BLOCKS: tuple[tuple[str, tuple[int, ...]], ...] = (("lateral", k_xi.LATERAL_IDX),
                                                   ("longitudinal", k_xi.LONGITUDINAL_IDX))


@dataclass(frozen=True)
class LoopConfig:
    """The sampled loop of stability.coupled_loop_parts and the K box (from the FC's parameters)."""

    wn_rad_s: float  # ACT_WN
    zeta: float  # ACT_ZETA
    rate_hz: float  # INDI_RATE_HZ
    tl_s: float  # INDI_LPF_TAU
    k_min: float  # INDI_K_MIN
    k_max: float  # INDI_K_MAX
    u0_source: str = "model"  # INDI_U0_SRC 1 -> "model", 0 -> "measured"
    u0_tau_s: float = 0.2  # INDI_U0_TAU
    reference: str = "com"  # INDI_ACC_REF 1 -> "com" (the estimated CoM, T ~ I), 0 -> "o" (the paper's O)


@dataclass(frozen=True)
class VertexLabel:
    """What one vertex is: a K corner (None: any value, the block does not see it), a pose, an object."""

    k: tuple[float | None, float | None, float | None, float | None]  # (K1, K2, K3, K4)
    pose_deg: tuple[float, float, float]
    object_mass_kg: float
    object_offset_m: float  # the object's centre beyond the link tip

    def text(self) -> str:
        k = ", ".join("any" if v is None else f"{v:g}" for v in self.k)
        q = "/".join(f"{v:.0f}" for v in self.pose_deg)
        return f"K = ({k}), q = {q} deg, m_o = {self.object_mass_kg:g} kg, offset {self.object_offset_m:g} m"


@dataclass(frozen=True)
class VertexSet:
    """The coupled loop's vertex matrices (one per K corner x pose x object; duplicates dropped) and their names."""

    lam_inv: np.ndarray  # (m, 5, 5): (G_hat G^-1)^-1 = Xi^-1 K^-1, the quantity the loop is affine in
    matrices: np.ndarray  # (m, 35, 35): stability.coupled_loop_matrix_from_inverse of lam_inv
    labels: tuple[VertexLabel, ...]
    xi_block_coupling: float  # max |Xi[longitudinal rows, lateral columns]| over the grid


def box_upper_object_mass_kg(cfg: VehicleConfig, k_min: float) -> float:
    """The heaviest object the K box describes: K4 = m_UAM / m >= k_min (Eq. 19-21), m_o <= m_UAM (1/k_min - 1)."""
    return cfg.uam_mass_kg * (1.0 / k_min - 1.0)


def default_grid(cfg: VehicleConfig, k_min: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(poses_rad, object masses kg, object offsets m): every joint on {-90, 0, 90} deg plus the two Fig. 7 poses;
    0, 1, 2 kg and the box's upper mass; the object at the tip (vehicle file) and EXTRA_OBJECT_OFFSET_M beyond."""
    poses = np.vstack([k_xi.pose_grid_rad(3), k_xi.paper_poses_rad()])
    masses = np.array([0.0, 1.0, 2.0, box_upper_object_mass_kg(cfg, k_min)])
    offsets = np.array([cfg.object_offset_m, cfg.object_offset_m + EXTRA_OBJECT_OFFSET_M])
    return poses, masses, offsets


def k_corners(k_min: float, k_max: float) -> np.ndarray:
    """The 16 corners (K1, K2, K3, K4) of [k_min, k_max]^4, shape (16, 4)."""
    c = np.array([k_min, k_max], dtype=float)
    return np.stack(np.meshgrid(c, c, c, c, indexing="ij"), axis=-1).reshape(-1, 4)


def loop_parts(loop: LoopConfig, channels: Sequence[str] = sampled_loop.INDI_CHANNELS) -> sampled_loop.CoupledLoopParts:
    return sampled_loop.coupled_loop_parts(loop.wn_rad_s, loop.zeta, loop.rate_hz, loop.tl_s, channels,
                                 u0_source=loop.u0_source, u0_tau_s=loop.u0_tau_s)


def lmi_vertices(cfg: VehicleConfig, loop: LoopConfig, poses_rad: np.ndarray, object_masses_kg: np.ndarray,
                 object_offsets_m: np.ndarray) -> VertexSet:
    """Every (K corner, pose, mass, offset) vertex of the coupled loop; exact duplicates dropped (with no object Xi = I
    at every pose and offset), the first name kept."""
    corners = k_corners(loop.k_min, loop.k_max)
    kappa = 1.0 / k_xi.k_diagonals(corners[:, 0], corners[:, 1], corners[:, 2], corners[:, 3])  # (16, 5): K^-1
    poses = np.atleast_2d(np.asarray(poses_rad, dtype=float))
    masses = np.atleast_1d(np.asarray(object_masses_kg, dtype=float))
    lam_inv, labels, seen = [], [], set()
    coupling = 0.0
    for off in np.atleast_1d(np.asarray(object_offsets_m, dtype=float)):
        xi = k_xi.xi_batch(replace(cfg, object_offset_m=float(off)), poses, masses, loop.reference)
        coupling = max(coupling, k_xi.xi_block_coupling(xi))
        xi_inv = np.linalg.inv(xi)
        for i, q in enumerate(poses):
            for j, m_o in enumerate(masses):
                for c, k in zip(kappa, corners, strict=True):
                    li = xi_inv[i, j] * c[None, :]  # Xi^-1 K^-1: column scaling
                    key = np.round(li, 12).tobytes()
                    if key in seen:
                        continue
                    seen.add(key)
                    lam_inv.append(li)
                    labels.append(VertexLabel((float(k[0]), float(k[1]), float(k[2]), float(k[3])),
                                              tuple(float(math.degrees(v)) for v in q),  # type: ignore[arg-type]
                                              float(m_o), float(off)))
    li_arr = np.array(lam_inv)
    matrices = sampled_loop.coupled_loop_matrix_from_inverse(li_arr, loop_parts(loop))
    return VertexSet(li_arr, matrices, tuple(labels), coupling)


@dataclass(frozen=True)
class BlockResult:
    """The common-P question for one block family (lateral or longitudinal), deduplicated."""

    name: str
    n_vertices: int  # distinct block matrices
    lyapunov: CommonLyapunovResult
    failing: tuple[VertexLabel, ...]  # the conflict set, named (None for the K entries the block does not see)


@dataclass(frozen=True)
class VaryingKResult:
    """Is there one P for the coupled loop at every vertex? (see the module docstring)"""

    feasible: bool | None  # None: undecided (solver trouble, or blocks feasible but the assembled P not verified)
    n_vertices: int
    state_dim: int
    rate: float | None  # verified max_i ||L^T A_i L^-T||_2 of the P found: V^(1/2) shrinks by this per tick
    decay_time_s: float | None  # -tick / ln(rate): the e-folding time of V^(1/2) guaranteed under any K(t)
    max_spectral_radius: float  # max over the vertices (frozen-time; a lower bound for rate)
    max_spectral_radius_vertex: VertexLabel
    failing: tuple[VertexLabel, ...]  # infeasible: a set of vertices that share no P
    failing_block: str | None  # the block whose family has no P ("lateral", "longitudinal", "coupled")
    certificate_residual: float | None  # of the failing set's infeasibility certificate (0 = exact)
    blocks: tuple[BlockResult, ...]  # empty when the full family was solved directly
    xi_block_coupling: float
    n_sdp: int
    sdp_time_s: float  # clarabel's own time
    p: np.ndarray | None  # the common P (35 x 35, channel-major states), when feasible


def _name_block(label: VertexLabel, block: str) -> VertexLabel:
    k = label.k
    kk = (k[0], None, k[2], None) if block == "lateral" else (None, k[1], None, k[3])
    return replace(label, k=kk)


def _state_index(channels: Sequence[int]) -> np.ndarray:
    n = sampled_loop.N_LOOP_STATES
    return np.concatenate([np.arange(n * c, n * (c + 1)) for c in channels])


def _assemble(vs: VertexSet, p_lat: np.ndarray, p_long: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """P = diag(P_lat, t P_long) (in the full channel-major state) with the t that gives the smallest verified rate
    over every full vertex; None if no t in the scan verifies."""
    i_lat, i_long = _state_index(k_xi.LATERAL_IDX), _state_index(k_xi.LONGITUDINAL_IDX)
    n = vs.matrices.shape[1]
    p_lat = p_lat / np.linalg.eigvalsh(p_lat)[-1]
    p_long = p_long / np.linalg.eigvalsh(p_long)[-1]
    best: tuple[float, np.ndarray, np.ndarray] | None = None
    for t in np.geomspace(1e-3, 1e6, 37):
        p = np.zeros((n, n))
        p[np.ix_(i_lat, i_lat)] = p_lat
        p[np.ix_(i_long, i_long)] = t * p_long
        rho = contraction_factors(vs.matrices, p)
        if best is None or rho.max() < best[0]:
            best = (float(rho.max()), p, rho)
    if best is None or best[0] >= 1.0:
        return None
    return best[1], best[2]


def varying_k_lmi(cfg: VehicleConfig, loop: LoopConfig, poses_rad: np.ndarray | None = None,
                  object_masses_kg: np.ndarray | None = None, object_offsets_m: np.ndarray | None = None,
                  bisection_steps: int = 3, stop_at_infeasible_block: bool = False) -> VaryingKResult:
    """The common-Lyapunov statement for the configured loop on the (default) grid. See the module docstring.

    stop_at_infeasible_block: skip the longitudinal block once the lateral one has no common P (the answer for the
    whole family is already "no"; the longitudinal block's own rate is then not reported)."""
    d_poses, d_masses, d_offsets = default_grid(cfg, loop.k_min)
    vs = lmi_vertices(cfg, loop,
                      d_poses if poses_rad is None else poses_rad,
                      d_masses if object_masses_kg is None else object_masses_kg,
                      d_offsets if object_offsets_m is None else object_offsets_m)
    spec = np.max(np.abs(np.linalg.eigvals(vs.matrices)), axis=-1)
    i_spec = int(np.argmax(spec))
    dt = 1.0 / loop.rate_hz
    base = dict(n_vertices=len(vs.labels), state_dim=vs.matrices.shape[1], max_spectral_radius=float(spec[i_spec]),
                max_spectral_radius_vertex=vs.labels[i_spec], xi_block_coupling=vs.xi_block_coupling)

    def decay(rate: float | None) -> float | None:
        return -dt / math.log(rate) if rate is not None and 0.0 < rate < 1.0 else None

    if vs.xi_block_coupling > BLOCK_COUPLING_TOL:
        r = common_lyapunov(vs.matrices, bisection_steps=bisection_steps)
        return VaryingKResult(feasible=r.feasible, rate=r.rate, decay_time_s=decay(r.rate),
                              failing=tuple(vs.labels[i] for i in r.conflict),
                              failing_block="coupled" if r.feasible is False else None,
                              certificate_residual=r.certificate_residual, blocks=(), n_sdp=r.n_sdp,
                              sdp_time_s=r.sdp_time_s, p=r.p, **base)
    blocks: list[BlockResult] = []
    for name, idx in BLOCKS:
        parts = loop_parts(loop, tuple(sampled_loop.INDI_CHANNELS[i] for i in idx))
        sub = vs.lam_inv[:, idx][:, :, idx]  # the block-diagonal part of a block-triangular inverse
        keys = np.round(sub, 12).reshape(len(sub), -1)
        _, first = np.unique(keys, axis=0, return_index=True)
        mats = sampled_loop.coupled_loop_matrix_from_inverse(sub[first], parts)
        r = common_lyapunov(mats, bisection_steps=bisection_steps)
        failing = tuple(_name_block(vs.labels[int(first[i])], name) for i in r.conflict)
        blocks.append(BlockResult(name, len(first), r, failing))
        if stop_at_infeasible_block and r.feasible is False:
            break
    n_sdp = sum(b.lyapunov.n_sdp for b in blocks)
    t_sdp = sum(b.lyapunov.sdp_time_s for b in blocks)
    bad = next((b for b in blocks if b.lyapunov.feasible is False), None)
    if bad is not None:
        return VaryingKResult(feasible=False, rate=None, decay_time_s=None, failing=bad.failing,
                              failing_block=bad.name, certificate_residual=bad.lyapunov.certificate_residual,
                              blocks=tuple(blocks), n_sdp=n_sdp, sdp_time_s=t_sdp, p=None, **base)
    if any(b.lyapunov.feasible is None for b in blocks):
        return VaryingKResult(feasible=None, rate=None, decay_time_s=None, failing=(), failing_block=None,
                              certificate_residual=None, blocks=tuple(blocks), n_sdp=n_sdp, sdp_time_s=t_sdp,
                              p=None, **base)
    got = _assemble(vs, blocks[0].lyapunov.p, blocks[1].lyapunov.p)  # type: ignore[arg-type]
    if got is None:
        return VaryingKResult(feasible=None, rate=None, decay_time_s=None, failing=(), failing_block=None,
                              certificate_residual=None, blocks=tuple(blocks), n_sdp=n_sdp, sdp_time_s=t_sdp,
                              p=None, **base)
    p, rho = got
    rate = float(rho.max())
    return VaryingKResult(feasible=True, rate=rate, decay_time_s=decay(rate), failing=(), failing_block=None,
                          certificate_residual=None, blocks=tuple(blocks), n_sdp=n_sdp, sdp_time_s=t_sdp, p=p,
                          **base)
