"""The coupled sampled loop, the common-Lyapunov SDP and the statement for the loop flown while K varies.

Independent routes used here:
- the coupled loop against sampled_loop_matrix (a separate implementation: a tick closure, one mode) for diagonal
  Lambda, against the union of the per-eigenvalue spectra for Lambda = T diag(lam) T^-1, and the direction of the
  coupling against the FC's increment u = U0 + G_hat^-1 (v - Acc_f) element by element;
- one vertex: feasible iff the spectral radius is below 1, with scipy's discrete Lyapunov solver as the witness;
- a pair of nilpotent matrices whose product has spectral radius a^2: switching diverges for a > 1 (so no common P
  can exist) and P = diag(1, 1/a) style scalings give the exact best common rate a for a < 1;
- convexity: a P found for the vertices also contracts random convex combinations and interior K.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import linalg

from navig8_fc.core import k_xi, sampled_loop
from navig8_fc.core import lyapunov as ly
from navig8_fc.core import varying_k as vk
from navig8_fc.core.vehicle import VehicleConfig

LOOP = (120.0, 1.0, 100.0, 0.02)  # wn rad/s, zeta, rate Hz, tau_L s: the defaults
DEFAULT_LOOP = vk.LoopConfig(120.0, 1.0, 100.0, 0.02, 0.5, 1.0, "model", 0.2, "com")


@pytest.fixture(scope="module")
def cfg() -> VehicleConfig:
    return VehicleConfig.load()


def _spectrum_close(a: np.ndarray, b: np.ndarray, tol: float) -> bool:
    """Same multiset of eigenvalues: greedy nearest matching."""
    left = list(np.asarray(b))
    for z in np.asarray(a):
        j = int(np.argmin([abs(z - w) for w in left]))
        if abs(z - left[j]) > tol:
            return False
        left.pop(j)
    return not left


# --- the coupled loop ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("u0", [("model", 0.2), ("measured", math.inf), ("model", math.inf)])
@pytest.mark.parametrize("plant_wn", [None, 80.0])
def test_coupled_loop_with_diagonal_lambda_is_the_block_diagonal_of_the_decoupled_modes(u0, plant_wn) -> None:
    lams = (0.3, 0.7, 1.0, 1.6, 2.5)
    parts = sampled_loop.coupled_loop_parts(*LOOP, sampled_loop.INDI_CHANNELS, plant_wn, None, *u0)
    a = sampled_loop.coupled_loop_matrix(np.diag(lams), parts)
    for i, (lam, ch) in enumerate(zip(lams, sampled_loop.INDI_CHANNELS, strict=True)):
        ref = sampled_loop.sampled_loop_matrix(lam, *LOOP, ch, plant_wn, None, *u0)
        blk = slice(7 * i, 7 * i + 7)
        np.testing.assert_allclose(a[blk, blk], ref, atol=1e-12)
        off = np.delete(a[blk], np.arange(7 * i, 7 * i + 7), axis=1)
        assert np.all(off == 0.0)


@pytest.mark.parametrize("channels", [("rotational",) * 5, ("force",) * 5, sampled_loop.INDI_CHANNELS])
def test_coupled_loop_spectrum_is_the_union_of_the_modes(channels) -> None:
    """Lambda = T diag(lam) T^-1, T neither orthogonal nor triangular (Lambda not normal); complex lam included.
    With mixed channels T may only mix rows with the same feedback (rotational rows 0-2, force rows 3-4)."""
    rng = np.random.default_rng(3)
    t = np.eye(5) + 0.6 * rng.normal(size=(5, 5))
    if len(set(channels)) > 1:
        t[np.ix_((0, 1, 2), (3, 4))] = 0.0
        t[np.ix_((3, 4), (0, 1, 2))] = 0.0
    # A real Lambda with a complex pair: T times a real block form (the pair on rows 1, 2, both rotational).
    a, w = 1.1, 0.25
    form = np.diag([0.45, a, a, 0.8, 2.2])
    form[1, 2], form[2, 1] = w, -w
    lams = np.array([0.45, a + 1j * w, a - 1j * w, 0.8, 2.2])
    lam_matrix = t @ form @ np.linalg.inv(t)
    assert np.abs(lam_matrix @ lam_matrix.T - lam_matrix.T @ lam_matrix).max() > 0.1  # not normal
    parts = sampled_loop.coupled_loop_parts(*LOOP, channels, None, None, "model", 0.2)
    coupled = np.linalg.eigvals(sampled_loop.coupled_loop_matrix(lam_matrix, parts))
    union = np.concatenate([np.linalg.eigvals(_mode_matrix(lam, ch)) for lam, ch in zip(lams, channels, strict=True)])
    assert _spectrum_close(coupled, union, 1e-6)


def _mode_matrix(lam: complex, channel: str) -> np.ndarray:
    """sampled_loop_matrix at a complex lam: it is affine in 1/lam (the increment), so extend it from two real ones."""
    a1 = sampled_loop.sampled_loop_matrix(1.0, *LOOP, channel, None, None, "model", 0.2)
    a2 = sampled_loop.sampled_loop_matrix(0.5, *LOOP, channel, None, None, "model", 0.2)
    return a1 + (1.0 / lam - 1.0) * (a2 - a1)  # 1/0.5 - 1/1 = 1


def test_coupling_enters_as_the_inverse_of_ghat_ginv_row_by_row() -> None:
    """u_i = U0_i - sum_j (Lambda^-1)_ij Acc_f,j (Eq. 5-6 in acceleration units): the u row of channel i reads
    channel j's acceleration with weight -(Lambda^-1)_ij, not (Lambda^-1)_ji or Lambda_ij."""
    lam = np.array([[1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0],
                    [0.0, 0.7, 0.0, 1.5, 0.0], [0.0, -0.4, 0.0, 0.3, 2.0]])
    parts = sampled_loop.coupled_loop_parts(*LOOP)
    a = sampled_loop.coupled_loop_matrix(lam, parts)
    inv = np.linalg.inv(lam)
    for i in range(5):
        for j in range(5):
            if i == j:
                continue
            ch = sampled_loop.INDI_CHANNELS[j]
            # c_j: how channel j's filtered acceleration depends on its states (decoupled loop, affine in 1/lam)
            c_j = (sampled_loop.sampled_loop_matrix(0.5, *LOOP, ch)[4]
                   - sampled_loop.sampled_loop_matrix(1.0, *LOOP, ch)[4]) * -1.0
            np.testing.assert_allclose(a[7 * i + 4, 7 * j : 7 * j + 7], -inv[i, j] * c_j, atol=1e-12)


# --- the SDP -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("radius", [0.5, 0.95, 0.999, 1.001, 1.05])
def test_one_vertex_is_feasible_iff_its_spectral_radius_is_below_one(radius: float) -> None:
    rng = np.random.default_rng(7)
    a = rng.normal(size=(4, 4)) + np.diag([0.0, 0.0, 3.0, 0.0])  # non-normal
    a *= radius / np.max(np.abs(np.linalg.eigvals(a)))
    r = ly.common_lyapunov(a[None], bisection_steps=4)
    if radius < 1.0:
        p_lyap = linalg.solve_discrete_lyapunov(a.T, np.eye(4))  # A^T P A - P = -I
        assert np.linalg.eigvalsh(p_lyap)[0] > 0.0
        assert r.feasible is True and r.max_spectral_radius <= r.rate < 1.0
        # the Lyapunov solution's own contraction factor is achievable, so the bisection does at least as well
        assert r.rate <= float(ly.contraction_factors(a[None], p_lyap)[0]) + 1e-6
    else:
        p_lyap = linalg.solve_discrete_lyapunov(a.T, np.eye(4))
        assert np.linalg.eigvalsh(0.5 * (p_lyap + p_lyap.T))[0] < 0.0  # no positive definite solution
        assert r.feasible is False and r.unstable_vertices == (0,)
        # the SDP itself (not only the spectral pre-check) finds no P
        ops = [ly.congruence_operator(a, *ly._svec_maps(4))]
        assert ly._solve_sdp(ops, 1.0, True, 4).feasible is False


@pytest.mark.parametrize("a", [0.5, 0.9, 1.2, 2.0])
def test_two_individually_stable_matrices_without_a_common_p(a: float) -> None:
    """A1 = [[0, a], [0, 0]], A2 = A1^T: both nilpotent (spectral radius 0), A1 A2 = diag(a^2, 0). For a > 1 the
    switching A1 A2 A1 A2 ... grows like a^(2k), so no common P can exist; for a < 1, P = I contracts by a, and
    a is the best common rate: with P = diag(p1, p2), A1^T P A1 <= r^2 P and A2^T P A2 <= r^2 P need a^4 <= r^4."""
    a1 = np.array([[0.0, a], [0.0, 0.0]])
    mats = np.stack([a1, a1.T])
    r = ly.common_lyapunov(mats, bisection_steps=12)
    assert r.max_spectral_radius == 0.0
    if a < 1.0:
        assert r.feasible is True and r.rate == pytest.approx(a, abs=2e-3)
        assert np.all(ly.contraction_factors(mats, r.p) <= r.rate + 1e-12)
    else:
        assert r.feasible is False and set(r.conflict) == {0, 1}
        assert r.certificate_residual is not None and r.certificate_residual < 1e-6


def test_a_common_p_also_contracts_the_convex_hull() -> None:
    rng = np.random.default_rng(11)
    base = np.diag([0.9, 0.5, -0.3])
    mats = np.stack([base + 0.15 * rng.normal(size=(3, 3)) for _ in range(6)])
    r = ly.common_lyapunov(mats, bisection_steps=4)
    assert r.feasible is True
    w = rng.dirichlet(np.ones(6), size=200)
    hull = np.einsum("km,mij->kij", w, mats)
    assert np.max(ly.contraction_factors(hull, r.p)) <= r.rate + 1e-12


def test_svec_is_clarabels_triangle() -> None:
    m = np.arange(9.0).reshape(3, 3)
    m = m + m.T
    v = ly.svec(m)
    s2 = math.sqrt(2.0)
    np.testing.assert_allclose(v, [m[0, 0], s2 * m[0, 1], m[1, 1], s2 * m[0, 2], s2 * m[1, 2], m[2, 2]])
    np.testing.assert_allclose(ly.smat(v, 3), m)
    assert float(v @ v) == pytest.approx(float(np.sum(m * m)))


# --- the statement for the flown loop ------------------------------------------------------------------------------
def test_vertices_are_lifted_in_k_inverse_and_interior_k_is_inside(cfg) -> None:
    """The loop is affine in K^-1 (u = U0 - Xi^-1 K^-1 Acc_f), so a K inside the box gives a matrix that is a convex
    combination of the corner matrices at the same pose and object: checked through the P of the corners (the
    lateral block, rows P_dot and R_dot, K1 and K3, to keep the SDP small)."""
    poses = k_xi.paper_poses_rad()[:1]
    xi = k_xi.xi_batch(cfg, poses, np.array([2.0]))[0, 0]
    lat = np.ix_(k_xi.LATERAL_IDX, k_xi.LATERAL_IDX)
    parts = vk.loop_parts(DEFAULT_LOOP, ("rotational", "rotational"))
    corners = np.array([[k1, k3] for k1 in (0.5, 1.0) for k3 in (0.5, 1.0)])
    mats = sampled_loop.coupled_loop_matrix(corners[:, :, None] * xi[lat][None], parts)
    r = ly.common_lyapunov(mats, bisection_steps=2)
    assert r.feasible is True
    ks = np.random.default_rng(5).uniform(0.5, 1.0, size=(256, 2))
    inner = sampled_loop.coupled_loop_matrix(ks[:, :, None] * xi[lat][None], parts)
    assert np.max(ly.contraction_factors(inner, r.p)) <= r.rate + 1e-9
    # the lateral block of the full vertex set is the same family (Xi is block triangular)
    vs = vk.lmi_vertices(cfg, DEFAULT_LOOP, poses, np.array([2.0]), np.array([0.0]))
    assert vs.matrices.shape == (16, 35, 35) and vs.xi_block_coupling < 1e-12


def test_small_grid_feasible_and_verified_on_the_full_coupled_matrices(cfg) -> None:
    """Light objects at the tip: the lateral and longitudinal families have a common P each, and the assembled
    35-state P contracts every full vertex (the check is plain linear algebra on the coupled matrices)."""
    poses = k_xi.paper_poses_rad()
    r = vk.varying_k_lmi(cfg, DEFAULT_LOOP, poses, np.array([0.0, 1.0]), np.array([0.0]), bisection_steps=2)
    assert r.feasible is True and r.xi_block_coupling < 1e-12
    vs = vk.lmi_vertices(cfg, DEFAULT_LOOP, poses, np.array([0.0, 1.0]), np.array([0.0]))
    rho = ly.contraction_factors(vs.matrices, r.p)
    assert r.max_spectral_radius <= r.rate < 1.0 and np.max(rho) == pytest.approx(r.rate, rel=1e-12)
    assert r.decay_time_s == pytest.approx(-0.01 / math.log(r.rate))


def test_default_configuration_has_no_common_p_on_the_grid(cfg) -> None:
    """The defaults (0.02 s filter, model-based U0, feedback at the estimated CoM) on the default grid.

    Frozen-time, every vertex is stable (spectral radius < 1: the paper's argument passes). The lateral family has no
    common P: two vertices with the (K1, K3) corners swapped, (1, 0.5) and (0.5, 1), at two different poses with the
    box's heaviest object (6.5 kg, held 0.1 m beyond the tip). At either pose alone the four (K1, K3) corners do share
    a P, so it is the switching between poses together with K that no quadratic function covers. The longitudinal
    block is not needed for the answer (stop_at_infeasible_block)."""
    r = vk.varying_k_lmi(cfg, DEFAULT_LOOP, stop_at_infeasible_block=True)
    assert r.max_spectral_radius < 1.0
    assert r.feasible is False and r.failing_block == "lateral" and len(r.failing) == 2
    assert r.certificate_residual is not None and r.certificate_residual < 1e-6
    heavy = vk.box_upper_object_mass_kg(cfg, 0.5)
    assert heavy == pytest.approx(6.5)
    assert {v.object_mass_kg for v in r.failing} == {heavy}
    assert {(v.k[0], v.k[2]) for v in r.failing} == {(1.0, 0.5), (0.5, 1.0)}
    assert len({v.pose_deg for v in r.failing}) == 2
    for v in r.failing:  # one pose alone: the K corners share a P
        alone = vk.varying_k_lmi(cfg, DEFAULT_LOOP, np.radians([v.pose_deg]), np.array([heavy]),
                                 np.array([v.object_offset_m]), bisection_steps=0, stop_at_infeasible_block=True)
        assert alone.blocks[0].lyapunov.feasible is True
