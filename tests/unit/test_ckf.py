"""Unit tests for navig8_fc.core.ckf: the box projection, the constrained KF and the adaptive law.

Independent checks: the projection against scipy's bounded least squares (BVLS) and an explicit KKT test,
the KF update against the textbook form, H against G_C^-1 G_hat_I Delta Acc built by vehicle.estimated_gi.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from navig8_fc.core import vehicle as veh
from navig8_fc.core.ckf import (
    CKF_PARAM_NAMES,
    AdaptiveLaw,
    AdaptiveLawInputs,
    BoxProjector,
    CkfConfig,
    CkfMode,
    CkfStepInputs,
    ConstrainedKalmanFilter,
    inertia_ratios,
    inv_small,
    measurement_matrix,
    project_box_exact,
)
from navig8_fc.core.filters import LowPass1

DT = 0.01


# --------------------------------------------------------------------------------------------------
# fixtures: the real vehicle model at one pose
# --------------------------------------------------------------------------------------------------


class Pose:
    """UAM (no object) model quantities at a fixed arm pose."""

    def __init__(self, q_deg: tuple[float, float, float] = (20.0, 20.0, 20.0)) -> None:
        self.cfg = veh.VehicleConfig.load()
        self.q = np.radians(q_deg)
        uam = veh.mass_properties(self.cfg, self.q, 0.0)
        self.j = uam.inertia_com
        self.m = uam.mass_kg
        self.com = uam.com_frd_m
        self.gc = veh.control_effectiveness_gc(self.cfg, uam.com_frd_m)
        self.gci = np.linalg.inv(self.gc)
        self.base = np.array([self.j[0, 0], self.j[1, 1], self.j[2, 2], self.m])
        self.lower, self.upper = veh.estimate_bounds(self.j, self.m, 0.5, 1.0)
        self.rho_x, self.rho_z = inertia_ratios(self.j)


@pytest.fixture(scope="module")
def pose() -> Pose:
    return Pose()


def _random_spd(rng: np.random.Generator, n: int, max_log_cond: float = 4.0) -> np.ndarray:
    """Random SPD matrix with condition number 10^U(0, max_log_cond) and random orientation and scale."""
    qm, _ = np.linalg.qr(rng.normal(size=(n, n)))
    eig = 10.0 ** rng.uniform(0.0, max_log_cond, n)
    scale = 10.0 ** rng.uniform(-3.0, 3.0)
    w = scale * (qm * eig) @ qm.T
    return 0.5 * (w + w.T)


def _bvls_projection(x_hat: np.ndarray, w: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Independent reference: min ||L^T (x - x_hat)||^2 with W = L L^T, by scipy's BVLS."""
    lt = np.linalg.cholesky(w).T
    res = lsq_linear(lt, lt @ x_hat, bounds=(lo, hi), method="bvls", tol=1e-14)
    return res.x


def _kkt_residual(x: np.ndarray, x_hat: np.ndarray, w: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Largest violation of the box-QP optimality conditions, relative to |W (x - x_hat)| scale."""
    g = w @ (x - x_hat)
    scale = float(np.abs(w).max() * max(np.abs(x - x_hat).max(), 1e-300))
    width = hi - lo
    at_lo = x <= lo + 1e-12 * (1.0 + width)
    at_hi = x >= hi - 1e-12 * (1.0 + width)
    viol = np.where(at_lo & ~at_hi, np.maximum(-g, 0.0), np.where(at_hi & ~at_lo, np.maximum(g, 0.0), np.abs(g)))
    viol = np.where(at_lo & at_hi, 0.0, viol)
    return float(viol.max()) / scale if scale > 0 else 0.0


# --------------------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------------------


def test_config_defaults_are_the_paper_settings() -> None:
    c = CkfConfig()
    assert c.q_diag == (1e-4, 5e-5, 1e-4, 5e-4)
    assert c.r_diag == (1500.0**2, 2000.0**2, 1500.0**2, 2000.0**2, 10000.0**2)
    assert c.lpf_tau_s == 0.7 and c.start_delay_s == 0.5 and c.dt_s == 0.01
    assert c.projection_weight == "inv_p" and c.mode == CkfMode.CONSTRAINED and c.constrained and c.adaptive


def _param_values(**overrides: float) -> dict[str, float]:
    v: dict[str, float] = {
        "CKF_MODE": 2, "CKF_LPF_TAU": 0.7, "CKF_START_DLY": 0.5,
        "CKF_Q_IXX": 1e-4, "CKF_Q_IYY": 5e-5, "CKF_Q_IZZ": 1e-4, "CKF_Q_M": 5e-4,
        "CKF_R_U1": 2.25e6, "CKF_R_U2": 4e6, "CKF_R_U3": 2.25e6, "CKF_R_U4": 4e6, "CKF_R_U5": 1e8,
        "CKF_P0_SCALE": 100.0, "CKF_PROJ_W": 0,
    }
    v.update(overrides)
    return v


def test_config_from_params() -> None:
    c = CkfConfig.from_params(_param_values(), dt_s=0.01)
    assert c == CkfConfig()
    c = CkfConfig.from_params(_param_values(CKF_MODE=1, CKF_PROJ_W=1, CKF_LPF_TAU=0.3), dt_s=0.005)
    assert c.mode == CkfMode.UNCONSTRAINED and not c.constrained and c.adaptive
    assert c.projection_weight == "identity" and c.lpf_tau_s == 0.3 and c.dt_s == 0.005
    c = CkfConfig.from_params(_param_values(CKF_MODE=0), dt_s=0.01)
    assert c.mode == CkfMode.FIXED and not c.adaptive
    with pytest.raises(ValueError):
        CkfConfig.from_params(_param_values(CKF_PROJ_W=2), dt_s=0.01)
    with pytest.raises(ValueError):
        CkfConfig.from_params(_param_values(CKF_MODE=3), dt_s=0.01)
    values = _param_values()
    del values["CKF_R_U3"]
    with pytest.raises(KeyError):
        CkfConfig.from_params(values, dt_s=0.01)


def test_config_from_the_parameter_file_defaults() -> None:
    """The YAML defaults (REAL32, so float32-rounded) give the paper configuration."""
    from navig8_fc.params.registry import ParamRegistry

    reg = ParamRegistry.from_defaults(check_stability=False)
    reg.require(CKF_PARAM_NAMES)
    c = CkfConfig.from_params(reg.as_dict(), dt_s=0.01)
    ref = CkfConfig()
    np.testing.assert_allclose(c.q_diag, ref.q_diag, rtol=1e-6)
    np.testing.assert_allclose(c.r_diag, ref.r_diag, rtol=1e-6)
    assert c.lpf_tau_s == pytest.approx(0.7, rel=1e-6) and c.start_delay_s == pytest.approx(0.5, rel=1e-6)
    assert c.mode == CkfMode.CONSTRAINED and c.projection_weight == "inv_p"


def test_config_validation() -> None:
    with pytest.raises(ValueError):
        CkfConfig(q_diag=(1.0, 1.0, 1.0))
    with pytest.raises(ValueError):
        CkfConfig(r_diag=(1.0, 1.0, 0.0, 1.0, 1.0))
    with pytest.raises(ValueError):
        CkfConfig(q_diag=(1.0, -1.0, 1.0, 1.0))
    with pytest.raises(ValueError):
        CkfConfig(dt_s=0.0)
    with pytest.raises(ValueError):
        CkfConfig(projection_weight="diag")  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------------
# measurement model (Eq. 24)
# --------------------------------------------------------------------------------------------------


def test_measurement_matrix_equals_gc_inv_times_estimated_gi(pose: Pose) -> None:
    """H(a) x == G_C,UAM^-1 G_hat_I(x) a for any x, a (Eq. 23 = Eq. 24), to 1e-12 relative."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        a = rng.normal(size=5)
        x = pose.base * rng.uniform(0.5, 3.0, 4)
        h = measurement_matrix(pose.gci, a, pose.rho_x, pose.rho_z)
        ref = pose.gci @ veh.estimated_gi(pose.j, x) @ a
        np.testing.assert_allclose(h @ x, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


def test_rho_is_zero_without_product_of_inertia() -> None:
    assert inertia_ratios(np.diag([1.0, 2.0, 3.0])) == (0.0, 0.0)


# --------------------------------------------------------------------------------------------------
# box projection
# --------------------------------------------------------------------------------------------------


def _random_problem(rng: np.random.Generator, n: int = 4) -> tuple[np.ndarray, ...]:
    w = _random_spd(rng, n)
    centre = rng.uniform(-5.0, 5.0, n)
    half = 10.0 ** rng.uniform(-2.0, 1.0, n)
    lo, hi = centre - half, centre + half
    # Points inside, just outside and far outside, per component.
    spread = rng.choice([0.5, 1.5, 5.0], size=n)
    x_hat = centre + half * spread * rng.uniform(-1.0, 1.0, n)
    return x_hat, w, lo, hi


def test_exact_projection_matches_bvls_and_kkt() -> None:
    """project_box_exact vs scipy BVLS on random SPD W (cond <= 1e4): 1e-6 relative; KKT holds to 1e-8."""
    rng = np.random.default_rng(11)
    for _ in range(300):
        x_hat, w, lo, hi = _random_problem(rng)
        x = project_box_exact(x_hat, w, lo, hi)
        assert np.all(x >= lo) and np.all(x <= hi)
        ref = _bvls_projection(x_hat, w, lo, hi)
        scale = max(1.0, float(np.abs(ref).max()))
        assert np.max(np.abs(x - ref)) <= 1e-6 * scale
        assert _kkt_residual(x, x_hat, w, lo, hi) < 1e-8


def test_clarabel_projection_matches_exact() -> None:
    """The persistent clarabel projector equals project_box_exact to 1e-6 relative, never leaves the box,
    and needs no fallback on these problems (points inside and outside; also with skip_inside=False so
    clarabel solves the inside points too)."""
    rng = np.random.default_rng(5)
    proj = BoxProjector(4)
    n_outside = 0
    for k in range(400):
        x_hat, w, lo, hi = _random_problem(rng)
        res = proj.project(x_hat, w, lo, hi, skip_inside=(k % 2 == 0))
        ref = project_box_exact(x_hat, w, lo, hi)
        assert np.all(res.x >= lo) and np.all(res.x <= hi), "projection left the box"
        scale = max(1.0, float(np.abs(ref).max()))
        assert np.max(np.abs(res.x - ref)) <= 1e-6 * scale
        n_outside += int(res.projected)
    assert n_outside > 100  # the test really exercised the QP
    assert proj.n_fallbacks == 0
    assert proj.n_calls >= n_outside


def test_clarabel_projection_with_w_inv_polish() -> None:
    """Passing W^-1 (the KF's P) only changes how the solution is polished, not the result."""
    rng = np.random.default_rng(8)
    proj = BoxProjector(4)
    for _ in range(200):
        x_hat, w, lo, hi = _random_problem(rng)
        a = proj.project(x_hat, w, lo, hi, w_inv=np.linalg.inv(w)).x
        b = project_box_exact(x_hat, w, lo, hi)
        assert np.max(np.abs(a - b)) <= 1e-6 * max(1.0, float(np.abs(b).max()))


def test_identity_weight_is_clipping() -> None:
    rng = np.random.default_rng(2)
    proj = BoxProjector(4)
    eye = np.eye(4)
    for _ in range(200):
        x_hat, _, lo, hi = _random_problem(rng)
        clipped = np.clip(x_hat, lo, hi)
        np.testing.assert_allclose(proj.project(x_hat, eye, lo, hi).x, clipped, rtol=0, atol=1e-12)
        np.testing.assert_allclose(project_box_exact(x_hat, eye, lo, hi), clipped, rtol=0, atol=1e-12)


def test_minimum_variance_projection_is_not_clipping() -> None:
    """With correlated W = P^-1, holding one bound shifts the other components by P_ji/P_ii (notes 5)."""
    p = np.array([[1.0, 0.5], [0.5, 1.0]])
    w = np.linalg.inv(p)
    x = project_box_exact([2.0, 0.0], w, [-10.0, -10.0], [1.0, 10.0])
    np.testing.assert_allclose(x, [1.0, -0.5], rtol=0, atol=1e-12)
    proj = BoxProjector(2)
    np.testing.assert_allclose(proj.project(np.array([2.0, 0.0]), w, [-10.0, -10.0], [1.0, 10.0]).x,
                               [1.0, -0.5], rtol=0, atol=1e-9)


def test_projection_of_inside_point_is_identity_and_empty_box_raises() -> None:
    x = np.array([1.0, 2.0, 3.0, 4.0])
    lo, hi = x - 1.0, x + 1.0
    w = np.eye(4)
    assert np.array_equal(project_box_exact(x, w, lo, hi), x)
    res = BoxProjector(4).project(x, w, lo, hi)
    assert not res.projected and np.array_equal(res.x, x)
    with pytest.raises(ValueError):
        project_box_exact(x, w, hi, lo)
    with pytest.raises(ValueError):
        BoxProjector(4).project(x, w, hi, lo)


def test_degenerate_box_lower_equals_upper() -> None:
    rng = np.random.default_rng(4)
    proj = BoxProjector(4)
    w = _random_spd(rng, 4)
    lo = np.array([1.0, 2.0, 3.0, 4.0])
    hi = lo.copy()
    hi[2] += 1.0
    x_hat = np.array([0.0, 5.0, 10.0, 4.0])
    ref = project_box_exact(x_hat, w, lo, hi)
    assert ref[0] == 1.0 and ref[1] == 2.0 and ref[3] == 4.0 and lo[2] <= ref[2] <= hi[2]
    res = proj.project(x_hat, w, lo, hi)
    np.testing.assert_allclose(res.x, ref, rtol=0, atol=1e-6)


def test_fallback_when_clarabel_does_not_solve() -> None:
    """max_iter = 1 makes clarabel stop early: the exact solver answers and the fallback is counted."""
    rng = np.random.default_rng(9)
    proj = BoxProjector(4, max_iter=1)
    x_hat, w, lo, hi = _random_problem(rng)
    x_hat = hi + 1.0  # surely outside
    res = proj.project(x_hat, w, lo, hi)
    assert res.used_fallback and proj.n_fallbacks == 1
    assert "Solved" != proj.last_status
    np.testing.assert_array_equal(res.x, project_box_exact(x_hat, w, lo, hi))


# --------------------------------------------------------------------------------------------------
# Kalman filter
# --------------------------------------------------------------------------------------------------


def test_predict_adds_dt_times_inertia_rate_exactly(pose: Pose) -> None:
    c = CkfConfig(dt_s=0.01)
    kf = ConstrainedKalmanFilter(c)
    kf.initialise(pose.base)
    p0 = kf.p
    np.testing.assert_array_equal(p0, np.diag(100.0 * np.array(c.q_diag)))
    idot = np.array([0.3, -1.7, 2.6])
    kf.predict(idot)
    expected = pose.base + 0.01 * np.array([idot[0], idot[1], idot[2], 0.0])
    np.testing.assert_array_equal(kf.x, expected)  # Eq. 22, bit-exact
    np.testing.assert_array_equal(kf.p, p0 + np.diag(c.q_diag))


def test_correct_matches_textbook_update(pose: Pose) -> None:
    """Joseph-form update == x + K (z - H x), P - K S K^T with K = P H^T S^-1 (1e-9 relative)."""
    rng = np.random.default_rng(1)
    c = CkfConfig(r_diag=(1e4, 2e4, 1e4, 2e4, 5e4))
    kf = ConstrainedKalmanFilter(c)
    m = rng.normal(size=(4, 4))
    p0 = 1e-3 * (m @ m.T + np.eye(4))
    kf.initialise(pose.base, p0=p0)
    a = rng.normal(size=5)
    z = rng.normal(size=5) * 1e3
    h = measurement_matrix(pose.gci, a, pose.rho_x, pose.rho_z)
    s = h @ p0 @ h.T + np.diag(c.r_diag)
    k = p0 @ h.T @ np.linalg.inv(s)
    x_ref = pose.base + k @ (z - h @ pose.base)
    p_ref = p0 - k @ s @ k.T
    innov = kf.correct(z, a, pose.gci, pose.rho_x, pose.rho_z)
    np.testing.assert_allclose(innov, z - h @ pose.base, rtol=1e-12)
    np.testing.assert_allclose(kf.x, x_ref, rtol=1e-9)
    np.testing.assert_allclose(kf.p, p_ref, rtol=1e-9, atol=1e-12 * np.abs(p_ref).max())
    assert np.array_equal(kf.p, kf.p.T)
    assert np.all(np.linalg.eigvalsh(kf.p) > 0)


def _synthetic_run(
    pose: Pose, x_true: np.ndarray, mode: CkfMode, weight: str = "inv_p", n_steps: int = 2000, seed: int = 0
) -> tuple[ConstrainedKalmanFilter, list[np.ndarray]]:
    """Delta Acc ~ N(0, 1) per component, Delta U = H(Delta Acc) x_true + N(0, 100^2), constant pose."""
    rng = np.random.default_rng(seed)
    sigma_u = 100.0
    c = CkfConfig(q_diag=(1e-8,) * 4, r_diag=(sigma_u**2,) * 5, mode=mode, projection_weight=weight)  # type: ignore[arg-type]
    kf = ConstrainedKalmanFilter(c)
    kf.initialise(pose.base)
    xs = []
    for k in range(n_steps):
        a = rng.normal(0.0, 1.0, 5)
        du = measurement_matrix(pose.gci, a, pose.rho_x, pose.rho_z) @ x_true + rng.normal(0.0, sigma_u, 5)
        res = kf.step(
            CkfStepInputs(du, a, pose.gci, pose.rho_x, pose.rho_z, np.zeros(3), pose.lower, pose.upper),
            predict=k > 0,
        )
        xs.append(res.x_hat)
    return kf, xs


@pytest.mark.parametrize("weight", ["inv_p", "identity"])
def test_kf_converges_inside_bounds_and_never_leaves_them(pose: Pose, weight: str) -> None:
    """Known constant parameters inside the box: within 2 % after 2000 steps; the box always holds."""
    x_true = pose.base * np.array([1.5, 1.3, 1.7, 1.25])
    kf, xs = _synthetic_run(pose, x_true, CkfMode.CONSTRAINED, weight)
    np.testing.assert_allclose(kf.x, x_true, rtol=0.02)
    for x in xs:
        assert np.all(x >= pose.lower) and np.all(x <= pose.upper)
    assert kf.n_projection_fallbacks == 0


def test_kf_unconstrained_converges(pose: Pose) -> None:
    x_true = pose.base * np.array([1.5, 1.3, 1.7, 1.25])
    kf, _ = _synthetic_run(pose, x_true, CkfMode.UNCONSTRAINED)
    np.testing.assert_allclose(kf.x, x_true, rtol=0.02)


def test_true_parameter_outside_bounds(pose: Pose) -> None:
    """I_yy true = 2.6 I_UAM,yy > the 2 I_UAM,yy bound (notes 6.1 item 6): constrained sits on the bound,
    unconstrained goes outside (to the truth, 2 %)."""
    x_true = pose.base * np.array([1.5, 2.6, 1.2, 1.3])
    kf_c, xs_c = _synthetic_run(pose, x_true, CkfMode.CONSTRAINED)
    kf_u, _ = _synthetic_run(pose, x_true, CkfMode.UNCONSTRAINED)
    assert kf_c.x[1] == pose.upper[1]
    for x in xs_c:
        assert np.all(x >= pose.lower) and np.all(x <= pose.upper)
    np.testing.assert_allclose(kf_c.x[[0, 2, 3]], x_true[[0, 2, 3]], rtol=0.02)
    assert kf_u.x[1] > pose.upper[1] * 1.2
    np.testing.assert_allclose(kf_u.x, x_true, rtol=0.02)


def test_projection_keeps_p_unreduced(pose: Pose) -> None:
    """Estimate projection moves the mean only (module docstring, notes 5)."""
    kf = ConstrainedKalmanFilter(CkfConfig())
    kf.initialise(pose.base * 2.5)  # outside the box
    p_before = kf.p
    res = kf.project(pose.lower, pose.upper)
    assert res.projected
    np.testing.assert_array_equal(kf.p, p_before)
    assert np.all(kf.x <= pose.upper) and np.all(kf.x >= pose.lower)


def test_kf_counts_projection_fallbacks(pose: Pose) -> None:
    kf = ConstrainedKalmanFilter(CkfConfig())
    kf._projector = BoxProjector(4, max_iter=1)  # force clarabel to stop early
    kf.initialise(pose.base * 2.5)
    res = kf.step(CkfStepInputs(np.zeros(5), np.zeros(5), pose.gci, pose.rho_x, pose.rho_z, np.zeros(3),
                                pose.lower, pose.upper))
    assert res.used_fallback and kf.n_projection_fallbacks == 1
    assert np.all(res.x_hat <= pose.upper) and np.all(res.x_hat >= pose.lower)


def test_step_requires_initialise(pose: Pose) -> None:
    kf = ConstrainedKalmanFilter(CkfConfig())
    with pytest.raises(RuntimeError):
        kf.step(CkfStepInputs(np.zeros(5), np.zeros(5), pose.gci, 0.0, 0.0, np.zeros(3), pose.lower, pose.upper))


# --------------------------------------------------------------------------------------------------
# adaptive law
# --------------------------------------------------------------------------------------------------


def _law_inputs(pose: Pose, t: float, u: np.ndarray, acc: np.ndarray) -> AdaptiveLawInputs:
    return AdaptiveLawInputs(
        t_s=t, u_meas=u, acc_m=acc, gc_uam_inv=pose.gci, inertia_uam=pose.j, mass_uam_kg=pose.m,
        inertia_rate_uam=np.zeros((3, 3)), k_min=0.5, k_max=1.0,
    )


def _excitation(pose: Pose, x_true: np.ndarray, n: int, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """u around hover with a random walk; acc = G_true u + b with G_true^-1 = G_C^-1 G_hat_I(x_true), b const."""
    rng = np.random.default_rng(seed)
    g_true_inv = pose.gci @ veh.estimated_gi(pose.j, x_true)
    g_true = np.linalg.inv(g_true_inv)
    u_trim = veh.hover_trim(pose.cfg, pose.q, 0.0)
    bias = np.array([0.1, -0.2, 0.05, 0.3, -9.80665])
    out = []
    walk = np.zeros(5)
    for _ in range(n):
        walk += rng.normal(0.0, 3e3, 5)
        walk *= 0.98
        u = u_trim + walk
        out.append((u, g_true @ u + bias))
    return out


def test_adaptive_law_before_start_and_start(pose: Pose) -> None:
    law = AdaptiveLaw(CkfConfig())
    x_true = pose.base * 1.4
    data = _excitation(pose, x_true, 80)
    gi_uam = veh.inertia_matrix_gi(pose.j, pose.m)
    for k, (u, acc) in enumerate(data):
        t = 10.0 + k * DT  # the delay counts from the first sample, not from t = 0
        g, st = law.step(_law_inputs(pose, t, u, acc))
        if t - 10.0 < 0.5 - 1e-9:
            assert not st.running
            np.testing.assert_allclose(g, gi_uam, rtol=1e-14, atol=1e-15)
            assert st.k == (1.0, 1.0, 1.0, 1.0) and st.n_updates == 0
        else:
            assert st.running
            if k == 50:  # first running tick: x0 = [J11, J22, J33, m] (K = 1), one correction
                assert st.n_updates == 1
        np.testing.assert_allclose(st.lower, pose.lower)
        np.testing.assert_allclose(st.upper, pose.upper)
        assert len(st.x_hat) == 4 and len(st.innovation) == 5 and len(st.active_lower) == 4
    assert st.n_updates == 30


def test_adaptive_law_increments_are_one_step_differences_of_filtered_signals(pose: Pose) -> None:
    law = AdaptiveLaw(CkfConfig(start_delay_s=0.0))
    ref_u, ref_a = LowPass1(0.7, DT, 5), LowPass1(0.7, DT, 5)
    prev_u = prev_a = None
    for k, (u, acc) in enumerate(_excitation(pose, pose.base * 1.2, 20)):
        _, st = law.step(_law_inputs(pose, k * DT, u, acc))
        fu, fa = np.array(ref_u.step(u.tolist())), np.array(ref_a.step(acc.tolist()))
        if prev_u is None:
            assert st.delta_u == (0.0,) * 5
        else:
            np.testing.assert_allclose(st.delta_u, fu - prev_u, rtol=1e-12, atol=1e-9)
            np.testing.assert_allclose(st.delta_acc, fa - prev_a, rtol=1e-12, atol=1e-15)
        prev_u, prev_a = fu, fa


def test_adaptive_law_reset_restarts_delay_and_filter(pose: Pose) -> None:
    law = AdaptiveLaw(CkfConfig(start_delay_s=0.1))
    data = _excitation(pose, pose.base * 1.3, 40)
    for k, (u, acc) in enumerate(data[:20]):
        _, st = law.step(_law_inputs(pose, k * DT, u, acc))
    assert st.running and law.kf.initialised and st.n_updates == 10
    law.reset()
    assert not law.kf.initialised
    for k, (u, acc) in enumerate(data[20:], start=20):
        _, st = law.step(_law_inputs(pose, k * DT, u, acc))
        if k == 20:
            assert st.delta_u == (0.0,) * 5  # filters re-initialise on the first sample after reset
        if k < 30:
            assert not st.running  # the delay counts again from t = 0.2 s
    assert st.running and st.n_updates == 10


def test_adaptive_law_fixed_mode_never_runs(pose: Pose) -> None:
    law = AdaptiveLaw(CkfConfig(mode=CkfMode.FIXED))
    gi_uam = veh.inertia_matrix_gi(pose.j, pose.m)
    for k, (u, acc) in enumerate(_excitation(pose, pose.base * 1.5, 100)):
        g, st = law.step(_law_inputs(pose, k * DT, u, acc))
        assert not st.running
        np.testing.assert_allclose(g, gi_uam, rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("mode", [CkfMode.CONSTRAINED, CkfMode.UNCONSTRAINED])
def test_adaptive_law_converges_on_consistent_data(pose: Pose, mode: CkfMode) -> None:
    """Noise-free u/acc consistent with G_true (plus a constant acceleration bias, which the increments
    remove): x_hat -> x_true within 2 % in 20 s. x_true inside the box for constrained, and the
    unconstrained filter is given a component outside it (I_zz = 2.4 I_UAM,zz) to show it leaves the box."""
    factors = np.array([1.6, 1.3, 1.8, 1.2]) if mode == CkfMode.CONSTRAINED else np.array([1.6, 1.3, 2.4, 1.2])
    x_true = pose.base * factors
    law = AdaptiveLaw(CkfConfig(mode=mode, r_diag=(1.0,) * 5, q_diag=(1e-10,) * 4, p0_scale=1e8))
    for k, (u, acc) in enumerate(_excitation(pose, x_true, 2000, seed=1)):
        g, st = law.step(_law_inputs(pose, k * DT, u, acc))
        if mode == CkfMode.CONSTRAINED and st.running:
            assert all(lo <= x <= hi for lo, x, hi in zip(st.lower, st.x_hat, st.upper, strict=True))
    np.testing.assert_allclose(st.x_hat, x_true, rtol=0.02)
    np.testing.assert_allclose(st.k, pose.base / np.array(st.x_hat), rtol=1e-12)
    np.testing.assert_allclose(g, veh.estimated_gi(pose.j, np.array(st.x_hat)), rtol=1e-14)
    if mode == CkfMode.UNCONSTRAINED:
        assert st.active_upper[2] and st.x_hat[2] > st.upper[2]
    assert st.n_projection_fallbacks == 0
    assert math.isfinite(sum(st.p_diag))


def test_adaptive_law_fast_path_equals_public_pieces_bit_for_bit(pose: Pose) -> None:
    """AdaptiveLaw.step (plain-float bookkeeping, KF._step_lists) gives exactly what the public pieces give:
    LowPass1 increments, ConstrainedKalmanFilter.step(CkfStepInputs) and vehicle.estimate_bounds /
    estimated_gi / k_from_estimate. Projections are active on most ticks (x_true outside the box)."""
    cfg = CkfConfig(start_delay_s=0.05)
    law, kf = AdaptiveLaw(cfg), ConstrainedKalmanFilter(cfg)
    ref_u, ref_a = LowPass1(cfg.lpf_tau_s, DT, 5), LowPass1(cfg.lpf_tau_s, DT, 5)
    idot = np.array([[0.02, 0.0, -0.01], [0.0, 0.03, 0.0], [-0.01, 0.0, 0.01]])
    prev = None
    n_projected = 0
    for k, (u, acc) in enumerate(_excitation(pose, pose.base * np.array([2.5, 1.3, 0.8, 1.2]), 300)):
        inp = AdaptiveLawInputs(
            t_s=k * DT, u_meas=u, acc_m=acc, gc_uam_inv=pose.gci, inertia_uam=pose.j, mass_uam_kg=pose.m,
            inertia_rate_uam=idot, k_min=0.5, k_max=1.0,
        )
        g, st = law.step(inp)
        fu, fa = np.array(ref_u.step(u)), np.array(ref_a.step(acc))
        du, da = (np.zeros(5), np.zeros(5)) if prev is None else (fu - prev[0], fa - prev[1])
        prev = (fu, fa)
        lower, upper = veh.estimate_bounds(pose.j, pose.m, 0.5, 1.0)
        assert st.lower == tuple(lower.tolist()) and st.upper == tuple(upper.tolist())
        assert st.delta_u == tuple(du.tolist()) and st.delta_acc == tuple(da.tolist())
        if not st.running:
            assert np.array_equal(g, veh.estimated_gi(pose.j, pose.base))
            continue
        first = not kf.initialised
        if first:
            kf.initialise(pose.base)
        res = kf.step(
            CkfStepInputs(du, da, pose.gci, pose.rho_x, pose.rho_z, np.diag(idot).copy(), lower, upper),
            predict=not first,
        )
        n_projected += res.projected
        assert st.x_hat == tuple(res.x_hat.tolist())
        assert st.x_unconstrained == tuple(res.x_unconstrained.tolist())
        assert st.innovation == tuple(res.innovation.tolist())
        assert st.p_diag == tuple(res.p_diag.tolist())
        assert st.k == tuple(veh.k_from_estimate(pose.j, pose.m, res.x_hat).tolist())
        assert st.active_lower == tuple((res.x_hat <= lower).tolist())
        assert st.active_upper == tuple((res.x_hat >= upper).tolist())
        assert np.array_equal(g, veh.estimated_gi(pose.j, res.x_hat))
        assert law.mass_estimate_kg == res.x_hat[3]
    assert n_projected > 100


def test_inv_small_is_numpy_inv_bit_for_bit(pose: Pose) -> None:
    rng = np.random.default_rng(3)
    mats = [pose.gc, veh.control_effectiveness_gc(pose.cfg, np.array([0.02, 0.0, 0.07]))]
    for _ in range(200):
        a = rng.normal(size=(4, 4))
        mats += [a @ a.T + 1e-3 * np.eye(4), rng.normal(size=(5, 5))]
    for a in mats:
        x = inv_small(a)
        assert np.array_equal(x, np.linalg.inv(a)) and x.flags.c_contiguous
    with pytest.raises(np.linalg.LinAlgError):
        inv_small(np.zeros((4, 4)))
