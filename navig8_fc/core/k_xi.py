"""The bounds on K (paper Sec. 3.2, Eq. 14-20, Fig. 7): eigenvalues of G_hat G^-1 = K Xi over arm poses, object
masses and K in [k_min, k_max]^4. Xi comes from navig8_fc.core.vehicle (Eq. 14). The worst case over the
workspace (min_eigenvalue_over_workspace) is the stability floor the parameter registry checks against
lambda_crit of H_i(s) (stability.py).

Pure math (numpy only): no I/O, no clocks, no prints.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from navig8_fc.core.vehicle import VehicleConfig

# Paper Fig. 7 poses (deg): arm stretched forward and curled, both holding a 2 kg object.
POSE_STRETCHED_DEG: tuple[float, float, float] = (80.0, 10.0, 10.0)
POSE_CURLED_DEG: tuple[float, float, float] = (60.0, 60.0, 60.0)
FIG7_OBJECT_MASS_KG = 2.0

# Index sets of the 5 rows/columns [L, M, N, Fx, Fz] (= [P_dot, Q_dot, R_dot, a_x, a_z]).
LATERAL_IDX = (0, 2)  # roll and yaw: K1, K3 act here (lam_4, lam_5 of Eq. 18)
LONGITUDINAL_IDX = (1, 3, 4)  # pitch, Fx, Fz: K2, K4, K4 (lam_1..lam_3 of Eq. 17)

_IMAG_TOL = 1e-9  # |Im| below this counts as a real eigenvalue (round-off of the 5x5 eig)

REFERENCES = ("com", "o")


def xi_batch(cfg: VehicleConfig, poses_rad: np.ndarray, object_masses_kg: np.ndarray,
             reference: str = "com") -> np.ndarray:
    """Xi (Eq. 14) for every (pose, mass): array (n_poses, n_masses, 5, 5) (vehicle.effectiveness_pair).

    reference: the point whose acceleration the INDI force rows feed back. "com" (the true composite CoM):
    Eq. 14 as printed. "o" (the paper's specific force at O, INDI_ACC_REF = 0): the loop flies T(O - c) G, so
    G_hat G_flown^-1 = K Xi T^-1 (vehicle.reference_transform; T^-1 = 2 I - T)."""
    # here, not at the top: vehicle loads numba and the model's kernels (~0.3 s of CPU), which the stability floor's
    # eigenvalues over a Xi already computed (min_eigenvalue_of_xi, the FC's floor worker) do not need
    from navig8_fc.core.vehicle import effectiveness_pair, mass_properties, reference_transform

    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    poses = np.atleast_2d(np.asarray(poses_rad, dtype=float))
    masses = np.atleast_1d(np.asarray(object_masses_kg, dtype=float))
    out = np.empty((poses.shape[0], masses.size, 5, 5))
    for i, q in enumerate(poses):
        for j, m_o in enumerate(masses):
            out[i, j] = effectiveness_pair(cfg, q, float(m_o)).xi
            if reference == "o":
                c = mass_properties(cfg, q, float(m_o)).com_frd_m
                out[i, j] = out[i, j] @ (2.0 * np.eye(5) - reference_transform(-c))
    return out


def k_diagonals(k1: np.ndarray, k2: np.ndarray, k3: np.ndarray, k4: np.ndarray) -> np.ndarray:
    """Rows diag(K) = [K1, K2, K3, K4, K4] (Eq. 3) for broadcastable K arrays: shape (..., 5)."""
    k1, k2, k3, k4 = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (k1, k2, k3, k4)))
    return np.stack([k1, k2, k3, k4, k4], axis=-1)


def k_xi_eigenvalues(xi: np.ndarray, k_diag: np.ndarray) -> np.ndarray:
    """All 5 eigenvalues of K Xi (Eq. 14), batched: xi (..., 5, 5) and k_diag (..., 5) broadcast together.

    K Xi = diag(k) Xi scales the rows of Xi. Returned sorted by ascending real part along the last axis.
    """
    kxi = np.asarray(k_diag)[..., :, None] * np.asarray(xi)
    lam = np.linalg.eigvals(kxi)
    order = np.argsort(lam.real, axis=-1, kind="stable")
    return np.take_along_axis(lam, order, axis=-1)


def xi_block_coupling(xi: np.ndarray) -> float:
    """max |Xi[longitudinal rows, lateral columns]|.

    Zero means Xi (and K Xi, since K is diagonal) is block triangular in the order (lateral, longitudinal),
    so the eigenvalues split into the lateral pair (K1, K3: lam_4, lam_5, Eq. 18) and the longitudinal
    block (K2, K4: lam_1..lam_3, Eq. 17, upper triangular in our model).
    """
    x = np.asarray(xi)
    return float(np.max(np.abs(x[..., LONGITUDINAL_IDX, :][..., :, LATERAL_IDX])))


def pose_grid_rad(n_per_joint: int, q_max_rad: float = math.pi / 2) -> np.ndarray:
    """Full factorial grid of the 3 joint angles over [-q_max, q_max]: shape (n^3, 3)."""
    g = np.linspace(-q_max_rad, q_max_rad, n_per_joint)
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)


def paper_poses_rad() -> np.ndarray:
    """The two poses of Fig. 7 (stretched 80/10/10 deg, curled 60/60/60 deg): shape (2, 3)."""
    return np.radians(np.array([POSE_STRETCHED_DEG, POSE_CURLED_DEG]))


@dataclass(frozen=True)
class KBoundsResult:
    """Worst case of the eigenvalues of K Xi (Sec. 3.2, Fig. 7) over the evaluated (pose, mass, K) set."""

    k_min: float
    k_max: float
    min_eigenvalue: float  # min over everything of Re(eig(K Xi))
    pose_rad: tuple[float, float, float]  # where the minimum occurs
    object_mass_kg: float
    k: tuple[float, float, float, float]  # (K1, K2, K3, K4)
    eigenvalues_at_min: tuple[complex, ...]  # all 5 eigenvalues at the minimum, ascending real part
    max_eigenvalue: float  # max of Re(eig(K Xi)): the slow side (Sec. 3.2, Eq. 19-20 upper bound on K)
    max_abs_imag: float  # largest |Im| of any eigenvalue (0 if K Xi always has real eigenvalues)
    max_imag_pose_rad: tuple[float, float, float]
    max_imag_object_mass_kg: float
    max_imag_k: tuple[float, float, float, float]
    max_imag_eigenvalue: complex  # the eigenvalue with the largest |Im| (upper half plane)
    complex_fraction: float  # share of evaluated (pose, mass, K) cases with a complex pair
    max_xi_block_coupling: float  # xi_block_coupling over all (pose, mass); ~0 => lateral/longitudinal split
    n_poses: int
    n_masses: int
    n_k: int  # K matrices evaluated per (pose, mass)
    n_cases: int  # total 5x5 eigenproblems


def _k_set(k_min: float, k_max: float, n_k: int) -> np.ndarray:
    """diag(K) rows: an n_k x n_k (K1, K3) grid at K2 = K4 = k_min, plus the 16 corners of [k_min, k_max]^4.

    K2 and K4 only enter the longitudinal eigenvalues, which are K2 Xi_11 and K4 Xi_33 = K4 Xi_44 (Eq. 17),
    so their minimum over the box is at K2 = K4 = k_min; the corners confirm that with full 5x5 eigenvalues
    instead of assuming the block structure.
    """
    g = np.linspace(k_min, k_max, n_k)
    k1, k3 = np.meshgrid(g, g, indexing="ij")
    grid = k_diagonals(k1.ravel(), k_min, k3.ravel(), k_min)
    c = np.array([k_min, k_max])
    corners = np.stack(np.meshgrid(c, c, c, c, indexing="ij"), axis=-1).reshape(-1, 4)
    # Corners with K2 = K4 = k_min are already on the grid.
    corners = corners[(corners[:, 1] != k_min) | (corners[:, 3] != k_min)]
    corner_rows = k_diagonals(corners[:, 0], corners[:, 1], corners[:, 2], corners[:, 3])
    return np.vstack([grid, corner_rows])


def _check_k_range(k_min: float, k_max: float) -> None:
    if not (0.0 < k_min <= k_max and math.isfinite(k_max)):
        raise ValueError(f"need 0 < k_min <= k_max, got k_min={k_min}, k_max={k_max}")


def _worst_case(
    xi: np.ndarray, k_rows: np.ndarray, poses: np.ndarray, masses: np.ndarray, k_min: float, k_max: float
) -> KBoundsResult:
    n_p, n_m = xi.shape[:2]
    # (n_p, n_m, n_k, 5): full 5x5 eigenvalues for every combination.
    lam = k_xi_eigenvalues(xi[:, :, None, :, :], k_rows[None, None, :, :])
    re = lam.real
    i_min = np.unravel_index(int(np.argmin(re[..., 0])), re.shape[:3])
    im = np.abs(lam.imag)
    i_im = np.unravel_index(int(np.argmax(im.max(axis=-1))), im.shape[:3])
    lam_im = lam[i_im]
    e_im = complex(lam_im[int(np.argmax(np.abs(lam_im.imag)))])
    e_im = complex(e_im.real, abs(e_im.imag))
    k_of = lambda row: (float(row[0]), float(row[1]), float(row[2]), float(row[3]))
    pose_of = lambda p: (float(p[0]), float(p[1]), float(p[2]))
    return KBoundsResult(
        k_min=float(k_min),
        k_max=float(k_max),
        min_eigenvalue=float(re[i_min][0]),
        pose_rad=pose_of(poses[i_min[0]]),
        object_mass_kg=float(masses[i_min[1]]),
        k=k_of(k_rows[i_min[2]]),
        eigenvalues_at_min=tuple(complex(v) for v in lam[i_min]),
        max_eigenvalue=float(re.max()),
        max_abs_imag=float(im[i_im].max()),
        max_imag_pose_rad=pose_of(poses[i_im[0]]),
        max_imag_object_mass_kg=float(masses[i_im[1]]),
        max_imag_k=k_of(k_rows[i_im[2]]),
        max_imag_eigenvalue=e_im,
        complex_fraction=float(np.mean(im.max(axis=-1) > _IMAG_TOL)),
        max_xi_block_coupling=xi_block_coupling(xi),
        n_poses=int(n_p),
        n_masses=int(n_m),
        n_k=int(k_rows.shape[0]),
        n_cases=int(re.shape[0] * re.shape[1] * re.shape[2]),
    )


def k_bounds_analysis(
    cfg: VehicleConfig,
    k_min: float,
    k_max: float,
    poses_rad: np.ndarray | None = None,
    object_masses_kg: Sequence[float] | np.ndarray | None = None,
    n_k: int = 9,
    reference: str = "com",
) -> KBoundsResult:
    """Fig. 7 / Sec. 3.2 worst case: min Re(eig(K Xi)) over poses, object masses and K in [k_min, k_max]^4.

    Defaults: every joint on a 7-point grid over +-90 deg (30 deg steps, 343 poses) plus the two Fig. 7
    poses; object masses 0, 0.5, 1, 1.5, 2 kg; (K1, K3) on an n_k x n_k grid at K2 = K4 = k_min plus the 16
    corners of the 4-D box. Every case is a full 5x5 eigenproblem (batched numpy.linalg.eigvals).
    reference "o": the matrix the paper's loop flies (xi_batch).
    """
    _check_k_range(k_min, k_max)
    if n_k < 2:
        raise ValueError(f"n_k must be >= 2 (the grid includes both ends), got {n_k}")
    poses = (
        np.vstack([pose_grid_rad(7), paper_poses_rad()])
        if poses_rad is None
        else np.atleast_2d(np.asarray(poses_rad, dtype=float))
    )
    if object_masses_kg is None:
        masses = np.linspace(0.0, 2.0, 5)
    else:
        masses = np.atleast_1d(np.asarray(object_masses_kg, dtype=float))
    xi = xi_batch(cfg, poses, masses, reference)
    return _worst_case(xi, _k_set(k_min, k_max, n_k), poses, masses, k_min, k_max)


def workspace_xi(cfg: VehicleConfig) -> np.ndarray:
    """Xi (Eq. 14) over the stability floor's coarse workspace: joints on {-90, -45, 0, 45, 90} deg (125 poses) plus
    the Fig. 7 poses, object masses {0, 1, 2} kg; array (127, 3, 5, 5). It does not depend on K, so a caller that
    checks many K boxes (the parameter registry's floor) computes it once (~0.1 s) and passes it to
    min_eigenvalue_of_xi (~15 ms a box)."""
    poses = np.vstack([pose_grid_rad(5), paper_poses_rad()])
    return xi_batch(cfg, poses, np.array([0.0, 1.0, 2.0]))


def min_eigenvalue_of_xi(xi: np.ndarray, k_min: float, k_max: float) -> float:
    """Worst case of Re(eig(K Xi)) over the Xi batch `xi` (..., 5, 5) and K on the box's 3 x 3 (K1, K3) grid plus
    its corners (_k_set)."""
    _check_k_range(k_min, k_max)
    lam = k_xi_eigenvalues(xi[..., None, :, :], _k_set(k_min, k_max, 3)[(None,) * (xi.ndim - 2)])
    return float(lam.real.min())


def min_eigenvalue_over_workspace(cfg: VehicleConfig, k_min: float, k_max: float) -> float:
    """Cheap worst case of Re(eig(K Xi)) for the parameter registry's stability floor (well under 1 s).

    Coarse version of k_bounds_analysis: Xi over workspace_xi's poses and masses, (K1, K3) on a 3 x 3 grid plus the
    K corners. At object mass 0, Xi = I and the result is exactly k_min, so the answer is never above k_min.
    """
    _check_k_range(k_min, k_max)
    return min_eigenvalue_of_xi(workspace_xi(cfg), k_min, k_max)


@dataclass(frozen=True)
class LateralSurfaces:
    """lam_4 and lam_5 of G_hat G^-1 over the (K1, K3) plane at one pose and object mass (Fig. 7)."""

    k1: np.ndarray  # (n3, n1) meshgrid, K1 varies along axis 1
    k3: np.ndarray  # (n3, n1)
    lam4: np.ndarray  # (n3, n1) complex: the lateral eigenvalue with the smaller real part
    lam5: np.ndarray  # (n3, n1) complex: the other one (conjugate of lam4 when the pair is complex)
    xi_block_coupling: float  # ~0 justifies reading the pair off the lateral 2x2 block


def lateral_eigenvalue_surfaces(
    cfg: VehicleConfig,
    q_rad: np.ndarray,
    object_mass_kg: float,
    k1: np.ndarray,
    k3: np.ndarray,
) -> LateralSurfaces:
    """lam_4, lam_5 (Eq. 18) over the (K1, K3) grid for Fig. 7.

    Xi is block triangular (xi_block_coupling ~ 0, checked by the caller or the tests), so the two
    eigenvalues that depend on K1 and K3 are exactly the eigenvalues of the lateral 2x2 block
    diag(K1, K3) Xi[(0, 2), (0, 2)]; they do not depend on K2 or K4.
    """
    xi = xi_batch(cfg, np.asarray(q_rad, dtype=float)[None, :], np.array([object_mass_kg]))[0, 0]
    k1g, k3g = np.meshgrid(np.asarray(k1, dtype=float), np.asarray(k3, dtype=float))
    lat = xi[np.ix_(LATERAL_IDX, LATERAL_IDX)]
    kdiag = np.stack([k1g, k3g], axis=-1)
    lam = np.linalg.eigvals(kdiag[..., :, None] * lat)
    order = np.argsort(lam.real, axis=-1, kind="stable")
    lam = np.take_along_axis(lam, order, axis=-1)
    return LateralSurfaces(k1g, k3g, lam[..., 0], lam[..., 1], xi_block_coupling(xi))


def flown_k(k_hat: Sequence[float], lam_ref: float, k_flown_min: float) -> tuple[float, float, float, float]:
    """The K the INDI flies (INDI_LAM_REF, INDI_KFL_MIN): K_flown,i = max(lam_ref K_hat,i, k_flown_min) on the
    rotational axes i = 1..3, K4 (the mass axis) = K_hat,4 untouched. The eigenvalue of G_hat G^-1 on an axis is
    K / K_true (Eq. 14-17 with Xi = I), so lam_ref is the flown loop gain's target once K_hat converges to the truth;
    the estimate K_hat itself (its box, Eq. 20-21, and its update, Eq. 22-24) is not changed."""
    k1, k2, k3, k4 = (float(v) for v in k_hat)
    return (max(lam_ref * k1, k_flown_min), max(lam_ref * k2, k_flown_min), max(lam_ref * k3, k_flown_min), k4)


def flown_k_box(k_min: float, k_max: float, lam_ref: float, k_flown_min: float) -> tuple[float, float]:
    """A box [lo, hi] that holds every flown K (flown_k) for K_hat in the Eq. 20 box [k_min, k_max]^4: the rotational
    axes span [max(lam_ref k_min, k_flown_min), max(lam_ref k_max, k_flown_min)], the mass axis [k_min, k_max]; the
    union is returned (one box for all four axes, as the floor's sweep and the LMI's corners take it: a superset,
    so the guarantee computed on it holds for the K flown). lam_ref = 1 and k_flown_min <= k_min give the Eq. 20 box
    itself."""
    lo_rot = max(lam_ref * k_min, k_flown_min)
    hi_rot = max(lam_ref * k_max, k_flown_min)
    return (min(lo_rot, k_min), max(hi_rot, k_max))


def flown_gi_hat(gi_flat: Sequence[float], k_hat: Sequence[float], lam_ref: float,
                 k_flown_min: float) -> tuple[np.ndarray, tuple[float, ...]]:
    """G_hat_I (Eq. 4) rebuilt for the flown K (flown_k: K_flown,i = max(lam_ref K_hat,i, k_flown_min), i = 1..3):
    column i of G_hat_I holds only x_i = J_ii / K_i (the roll/yaw cross terms of rows 0 and 2 scale with their
    column's x, vehicle.estimated_gi), so x_i,flown = x_i K_hat,i / K_flown,i is a scaling of the three rotational
    columns; the mass columns are untouched. gi_flat: G_hat_I row-major. Returns the new 5x5 array and its row-major
    tuple. Plain floats: 15 products cost less than numpy's per-call overhead on a 5x5."""
    k1, k2, k3 = float(k_hat[0]), float(k_hat[1]), float(k_hat[2])
    a, b, c = lam_ref * k1, lam_ref * k2, lam_ref * k3
    s1 = k1 / (a if a > k_flown_min else k_flown_min)
    s2 = k2 / (b if b > k_flown_min else k_flown_min)
    s3 = k3 / (c if c > k_flown_min else k_flown_min)
    f = list(gi_flat)
    for r in (0, 5, 10, 15, 20):
        f[r] *= s1
        f[r + 1] *= s2
        f[r + 2] *= s3
    return np.array(f).reshape(5, 5), tuple(f)


def eig_margin_lower_bound(
    vehicle: VehicleConfig,
    q_rad: Sequence[float],
    k_min: float,
    k_max: float,
    lambda_crit: float,
    object_masses_kg: Sequence[float] = (0.0, 1.0, 2.0),
) -> float:
    """min Re eig(K Xi(q, m)) over K in [k_min, k_max]^4 and the object masses, minus lambda_crit.

    K is sampled at the 16 corners of the box plus a
    3 x 3 (K1, K3) grid at K2 = K4 = k_min (where core.stability shows the longitudinal minimum lies).
    Cost: ~1.4 ms per call, so the shell computes it at the telemetry rate, not every control step.
    """
    xi = xi_batch(vehicle, np.asarray([q_rad], dtype=float), np.asarray(object_masses_kg, dtype=float))
    c = np.array([k_min, k_max])
    corners = np.stack(np.meshgrid(c, c, c, c, indexing="ij"), axis=-1).reshape(-1, 4)
    g = np.linspace(k_min, k_max, 3)
    k1, k3 = np.meshgrid(g, g, indexing="ij")
    grid = np.column_stack([k1.ravel(), np.full(9, k_min), k3.ravel(), np.full(9, k_min)])
    ks = np.vstack([corners, grid])
    k_diag = k_diagonals(ks[:, 0], ks[:, 1], ks[:, 2], ks[:, 3])
    lam = k_xi_eigenvalues(xi[:, :, None, :, :], k_diag[None, None, :, :])
    return float(lam.real.min()) - float(lambda_crit)
