"""navig8_fc.core.kalman: configuration, the regressor of Eq. 24, predict / correct / project / step.

Independent checks: the correct step against a textbook Kalman update and against the Joseph form, both
written here in numpy (K = P H^T (H P H^T + R)^-1); H against G_C^-1 G_hat_I Delta Acc built by
vehicle.estimated_gi; the projection against scipy's BVLS with W = P^-1; convergence on synthetic data with
known parameters.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from navig8_fc.core import vehicle as veh
from navig8_fc.core.ckf_config import CKF_PARAM_NAMES, CkfConfig, CkfMode
from navig8_fc.core.kalman import (
    ConstrainedKalmanFilter,
    inertia_ratios,
    kf_project,
    measurement_matrix,
    project_apart,
)


class Pose:
    """UAM (no object) model quantities at a fixed arm pose."""

    def __init__(self, q_deg: tuple[float, float, float] = (20.0, 20.0, 20.0)) -> None:
        self.cfg = veh.VehicleConfig.load()
        self.q = np.radians(q_deg)
        uam = veh.mass_properties(self.cfg, self.q, 0.0)
        self.j = uam.inertia_com
        self.m = uam.mass_kg
        self.gc = veh.control_effectiveness_gc(self.cfg, uam.com_frd_m)
        self.gci = np.linalg.inv(self.gc)
        self.base = np.array([self.j[0, 0], self.j[1, 1], self.j[2, 2], self.m])
        self.lower, self.upper = veh.estimate_bounds(self.j, self.m, 0.5, 1.0)
        self.box = (tuple(self.lower.tolist()), tuple(self.upper.tolist()))
        self.rho_x, self.rho_z = self.j[0, 2] / self.j[0, 0], self.j[0, 2] / self.j[2, 2]


@pytest.fixture(scope="module")
def pose() -> Pose:
    return Pose()


def _random_p(rng: np.random.Generator) -> np.ndarray:
    m = rng.normal(size=(4, 4))
    return 1e-3 * (m @ m.T + np.eye(4))


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
        "CKF_INC_N": 1, "CKF_EXC_ROT": 0.0, "CKF_EXC_LIN": 0.0, "CKF_SAT_GATE": 0, "CKF_U_SRC": 0, "CKF_ACC_REF": 0,
        "CKF_K_PIN1": 1.0, "CKF_K_PIN2": 1.0, "CKF_K_PIN3": 1.0, "CKF_K_PIN4": 1.0,
        "CKF_GRIP_RST": 0, "CKF_PRED_DJ": 0, "CKF_GC_REF": 0,
        "CKF_LMS_MU1": 0.003, "CKF_LMS_MU2": 0.05, "CKF_LMS_MU3": 0.003, "CKF_LMS_MU4": 0.001,
        "CKF_R_PITCH": 0.0, "CKF_CZ_SIG": 0.0, "CKF_LPF_SEED": 0, "CKF_IXZ_MOD": 0, "CKF_GRIP_SIG": 0.0,
        "CKF_MOM_LPF": 0, "CKF_M_SIG_OPEN": 0.0, "CKF_IXZ_SIG": 0.0, "CKF_CZ_DM": 0, "CKF_MOM_MREF": 0,
        "CKF_MOM_MOVE": 0, "CKF_PROJ_IYY": 0, "CKF_CZ_FOLLOW": 0, "CKF_M_ABS_SIG": 0.0, "CKF_GYRO": 0,
        "CKF_IYY_GRIP_W": 0.5, "CKF_SYNC": 0, "CKF_R_MOVE": 1.0,
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
    c = CkfConfig.from_params(_param_values(CKF_MODE=3, CKF_K_PIN4=0.8), dt_s=0.01)
    assert c.mode == CkfMode.PINNED and not c.adaptive and c.k_pin == (1.0, 1.0, 1.0, 0.8)
    with pytest.raises(ValueError):
        CkfConfig.from_params(_param_values(CKF_MODE=5), dt_s=0.01)
    values = _param_values()
    del values["CKF_R_U3"]
    with pytest.raises(KeyError):
        CkfConfig.from_params(values, dt_s=0.01)


def test_config_from_the_parameter_file_defaults() -> None:
    """The YAML defaults (REAL32, so float32-rounded) give the paper's R, filter constant and start delay, and the
    default estimator: 25-step windows, the command's U, Acc_m at the CoM, the saturation gate, Q = 0.1x the paper's,
    P0 = 3000 Q (docs/model.md); the paper's settings are CkfConfig() (the test above)."""
    from navig8_fc.params.registry import ParamRegistry

    reg = ParamRegistry.from_defaults(check_stability=False)
    reg.require(CKF_PARAM_NAMES)
    c = CkfConfig.from_params(reg.as_dict(), dt_s=0.01)
    ref = CkfConfig()
    np.testing.assert_allclose(c.q_diag, np.array(ref.q_diag) * 0.1, rtol=1e-6)
    np.testing.assert_allclose(c.r_diag, ref.r_diag, rtol=1e-6)
    assert c.p0_scale == 3000.0
    assert c.lpf_tau_s == pytest.approx(0.7, rel=1e-6) and c.start_delay_s == pytest.approx(0.5, rel=1e-6)
    assert c.mode == CkfMode.CONSTRAINED and c.projection_weight == "inv_p"
    assert (c.inc_window, c.u_from_command, c.acc_at_com, c.sat_gate) == (25, True, True, True)
    assert (c.exc_rot_rad_s2, c.exc_lin_m_s2) == (0.0, pytest.approx(0.2, rel=1e-6))
    assert (ref.inc_window, ref.u_from_command, ref.acc_at_com, ref.sat_gate) == (1, False, False, False)


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
# regressor (Eq. 24)
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


def test_inertia_ratios() -> None:
    assert inertia_ratios(1.0, 0.0, 3.0) == (0.0, 0.0)
    assert inertia_ratios(2.0, -0.5, 4.0) == (-0.25, -0.125)


# --------------------------------------------------------------------------------------------------
# predict / correct
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


def test_correct_matches_textbook_and_joseph_form(pose: Pose) -> None:
    """correct() == the textbook update x + K (z - H x), P - K S K^T with K = P H^T S^-1, and == the Joseph
    form (I - K H) P (I - K H)^T + K R K^T, both in numpy here, over 5 consecutive updates from random P0
    (so P gets off-diagonal terms), at the real pose and with random G_C^-1 and rho: x to 1e-9, P to 1e-9
    relative; P symmetric and positive definite."""
    rng = np.random.default_rng(1)
    for trial in range(20):
        c = CkfConfig(r_diag=tuple(rng.uniform(1e4, 5e4, 5)))
        r = np.diag(c.r_diag)
        kf = ConstrainedKalmanFilter(c)
        x = pose.base * rng.uniform(0.8, 1.2, 4)
        p = _random_p(rng)
        gci = pose.gci if trial % 2 == 0 else rng.normal(size=(5, 5))  # any G_C^-1
        rho_x, rho_z = rng.uniform(-0.3, 0.3, 2)
        kf.initialise(x, p0=p)
        for _ in range(5):
            a = rng.normal(size=5)
            z = rng.normal(size=5) * 1e3
            h = measurement_matrix(gci, a, rho_x, rho_z)
            s = h @ p @ h.T + r
            k = p @ h.T @ np.linalg.inv(s)
            x_ref = x + k @ (z - h @ x)
            p_textbook = p - k @ s @ k.T
            ikh = np.eye(4) - k @ h
            p_joseph = ikh @ p @ ikh.T + k @ r @ k.T
            innov = kf.correct(z, a, gci, rho_x, rho_z)
            np.testing.assert_allclose(innov, z - h @ x, rtol=1e-12, atol=1e-12 * np.abs(z).max())
            np.testing.assert_allclose(kf.x, x_ref, rtol=1e-9)
            np.testing.assert_allclose(kf.p, p_textbook, rtol=1e-9, atol=1e-12 * np.abs(p_textbook).max())
            np.testing.assert_allclose(kf.p, p_joseph, rtol=1e-9, atol=1e-12 * np.abs(p_joseph).max())
            assert np.array_equal(kf.p, kf.p.T)
            assert np.all(np.linalg.eigvalsh(kf.p) > 0)
            x, p = kf.x, kf.p
        assert kf.n_updates == 5, trial


def test_the_regressor_makes_the_measurement_consistent(pose: Pose) -> None:
    """A noise-free measurement of x itself (z = H x) leaves x unchanged (zero innovation)."""
    kf = ConstrainedKalmanFilter(CkfConfig())
    kf.initialise(pose.base)
    a = np.array([0.3, -0.2, 0.5, 0.1, -0.4])
    z = pose.gci @ veh.estimated_gi(pose.j, pose.base) @ a
    innov = kf.correct(z, a, pose.gci, pose.rho_x, pose.rho_z)
    np.testing.assert_allclose(innov, 0.0, atol=1e-9 * np.abs(z).max())
    np.testing.assert_allclose(kf.x, pose.base, rtol=1e-12)


def test_non_finite_measurement_poisons_the_estimate(pose: Pose) -> None:
    """A NaN Delta Acc makes S non-finite: x and P become NaN (as the LAPACK update did), and stay so."""
    kf = ConstrainedKalmanFilter(CkfConfig(mode=CkfMode.UNCONSTRAINED))
    kf.initialise(pose.base)
    kf.correct(np.zeros(5), np.array([np.nan, 0.0, 0.0, 0.0, 0.0]), pose.gci, pose.rho_x, pose.rho_z)
    assert np.isnan(kf.x).all() and np.isnan(kf.p).all()


# --------------------------------------------------------------------------------------------------
# projection and step
# --------------------------------------------------------------------------------------------------


def test_projection_is_the_bvls_optimum_with_w_inv_p_and_keeps_p(pose: Pose) -> None:
    """project() with W = P^-1 equals scipy's BVLS on the Cholesky-transformed problem (1e-9 relative) and
    moves the mean only (module docstring, notes 5); with W = I it is clipping, exactly."""
    rng = np.random.default_rng(6)
    n_projected = 0
    for _ in range(100):
        p = _random_p(rng)
        x0 = pose.base * rng.uniform(0.3, 3.0, 4)
        kf = ConstrainedKalmanFilter(CkfConfig())
        kf.initialise(x0, p0=p)
        res = kf.project(pose.lower, pose.upper)
        lt = np.linalg.cholesky(np.linalg.inv(p)).T
        ref = lsq_linear(lt, lt @ x0, bounds=(pose.lower, pose.upper), method="bvls", tol=1e-14).x
        np.testing.assert_allclose(kf.x, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
        assert np.all(kf.x >= pose.lower) and np.all(kf.x <= pose.upper)
        np.testing.assert_array_equal(kf.p, p)
        assert res.projected == bool(np.any((x0 < pose.lower) | (x0 > pose.upper)))
        n_projected += res.projected
        clip = ConstrainedKalmanFilter(CkfConfig(projection_weight="identity"))
        clip.initialise(x0, p0=p)
        clip.project(pose.lower, pose.upper)
        np.testing.assert_array_equal(clip.x, np.clip(x0, pose.lower, pose.upper))
    assert n_projected > 50


def test_kf_counts_projection_fallbacks(pose: Pose) -> None:
    """A projection the active-set iteration cannot certify (found by search over random P and x) is
    answered by the enumeration and counted; the answer is the BVLS optimum."""
    from navig8_fc.core import box_qp

    rng = np.random.default_rng(0)
    lo, hi = np.zeros(4), np.ones(4)
    x = np.empty(4)
    for _ in range(20000):
        qm, _ = np.linalg.qr(rng.normal(size=(4, 4)))
        p = (qm * 10.0 ** rng.uniform(0.0, 4.0, 4)) @ qm.T
        p = 0.5 * (p + p.T)
        w = np.linalg.inv(p)
        x0 = rng.uniform(-5.0, 6.0, 4)
        if np.all((x0 >= lo) & (x0 <= hi)):
            continue
        if box_qp.active_set_solve(x0, w, p, True, lo, hi, x, box_qp.MAX_ITER) == 0:
            break
    else:
        pytest.fail("no problem without an active-set certificate found")
    kf = ConstrainedKalmanFilter(CkfConfig())
    kf.initialise(x0, p0=p)
    res = kf.project(lo, hi)
    assert res.used_fallback and kf.n_projection_fallbacks == 1
    lt = np.linalg.cholesky(w).T
    ref = lsq_linear(lt, lt @ x0, bounds=(lo, hi), method="bvls", tol=1e-14).x
    np.testing.assert_allclose(kf.x, ref, rtol=0, atol=1e-7)


def test_step_equals_predict_correct_project_bit_for_bit(pose: Pose) -> None:
    """step() (one compiled call) == predict(), correct(), project() called one by one, for every mode and
    weight, with projections active (x_true outside the box)."""
    rng = np.random.default_rng(4)
    x_true = pose.base * np.array([2.5, 1.3, 0.8, 1.2])
    for mode in (CkfMode.CONSTRAINED, CkfMode.UNCONSTRAINED):
        for weight in ("inv_p", "identity"):
            c = CkfConfig(mode=mode, projection_weight=weight)  # type: ignore[arg-type]
            a, b = ConstrainedKalmanFilter(c), ConstrainedKalmanFilter(c)
            a.initialise(pose.base)
            b.initialise(pose.base)
            n_projected = 0
            for k in range(200):
                da = rng.normal(size=5)
                du = measurement_matrix(pose.gci, da, pose.rho_x, pose.rho_z) @ x_true + rng.normal(0.0, 100.0, 5)
                idot = None if k == 0 else tuple(rng.normal(0.0, 0.01, 3).tolist())
                r = a.step(du, da, pose.gci, pose.rho_x, pose.rho_z, idot, *pose.box)
                if idot is not None:
                    b.predict(idot)
                innov = b.correct(du, da, pose.gci, pose.rho_x, pose.rho_z)
                x_unc = b.x
                proj = b.project(pose.lower, pose.upper) if c.constrained else None
                assert r.innovation == tuple(innov.tolist())
                assert r.x_unconstrained == tuple(x_unc.tolist())
                assert r.x_hat == tuple(b.x.tolist()) and np.array_equal(a.x, b.x)
                assert r.p_diag == tuple(np.diag(b.p).tolist()) and np.array_equal(a.p, b.p)
                assert r.projected == (proj is not None and proj.projected)
                n_projected += r.projected
            assert (n_projected > 50) == c.constrained
            assert a.n_updates == b.n_updates == 200


def _synthetic_run(
    pose: Pose, x_true: np.ndarray, mode: CkfMode, weight: str = "inv_p", n_steps: int = 2000, seed: int = 0
) -> tuple[ConstrainedKalmanFilter, list[tuple[float, ...]]]:
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
        res = kf.step(du, a, pose.gci, pose.rho_x, pose.rho_z, None if k == 0 else (0.0, 0.0, 0.0), *pose.box)
        xs.append(res.x_hat)
    return kf, xs


@pytest.mark.parametrize("weight", ["inv_p", "identity"])
def test_kf_converges_inside_bounds_and_never_leaves_them(pose: Pose, weight: str) -> None:
    """Known constant parameters inside the box: within 2 % after 2000 steps; the box always holds."""
    x_true = pose.base * np.array([1.5, 1.3, 1.7, 1.25])
    kf, xs = _synthetic_run(pose, x_true, CkfMode.CONSTRAINED, weight)
    np.testing.assert_allclose(kf.x, x_true, rtol=0.02)
    for x in xs:
        assert np.all(np.array(x) >= pose.lower) and np.all(np.array(x) <= pose.upper)
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
        assert np.all(np.array(x) >= pose.lower) and np.all(np.array(x) <= pose.upper)
    np.testing.assert_allclose(kf_c.x[[0, 2, 3]], x_true[[0, 2, 3]], rtol=0.02)
    assert kf_u.x[1] > pose.upper[1] * 1.2
    np.testing.assert_allclose(kf_u.x, x_true, rtol=0.02)


def test_use_before_initialise_raises_and_empty_box_raises(pose: Pose) -> None:
    kf = ConstrainedKalmanFilter(CkfConfig())
    with pytest.raises(RuntimeError):
        kf.step(np.zeros(5), np.zeros(5), pose.gci, 0.0, 0.0, None, *pose.box)
    with pytest.raises(RuntimeError):
        kf.correct(np.zeros(5), np.zeros(5), pose.gci, 0.0, 0.0)
    kf.initialise(pose.base * 3.0)
    with pytest.raises(ValueError):
        kf.project(pose.upper, pose.lower)
    with pytest.raises(ValueError):
        kf.step(np.zeros(5), np.zeros(5), pose.gci, 0.0, 0.0, None, pose.box[1], pose.box[0])


def _pitch_row_data(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[np.ndarray, ...]]]:
    """Windows of Eq. 24 from a known truth x_true with an equation error in the force row a_x that follows the pitch
    excitation (what the force rows carry and the model lacks while the mass converges, docs/model.md "Estimator"):
    G_C Delta U = G_I(x_true) Delta Acc + e, e[3] = 2 Delta Q-dot, plus white noise on every row."""
    rng = np.random.default_rng(seed)
    gc = np.eye(5) + 0.3 * rng.standard_normal((5, 5))
    gc_inv = np.linalg.inv(gc)
    j = np.diag([0.5, 0.6, 0.9])
    x_true = np.array([0.7, 0.9, 1.1, 8.0])
    rho_x, rho_z = 0.0, 0.0
    data = []
    for _ in range(n):
        da = rng.standard_normal(5) * np.array([0.3, 0.3, 0.3, 0.5, 0.5])
        gi_da = np.array([x_true[0], x_true[1], x_true[2], x_true[3], x_true[3]]) * da  # rho = 0: G_I diagonal
        e = 0.01 * rng.standard_normal(5)
        e[3] += 2.0 * da[1]
        du = gc_inv @ (gi_da + e)
        data.append((du, da, gc_inv, rho_x, rho_z))
    return j, x_true, np.diag(j), data


@pytest.mark.parametrize("pitch_r", [0.0, 1e-3])
def test_the_pitch_row_in_moment_space_is_not_biased_by_the_force_rows(pitch_r: float) -> None:
    """With the pitch row corrected in Delta U space the force row's error leaks into I_yy (the pitch column spreads
    over all five rows); in moment space (CKF_R_PITCH > 0) I_yy converges to the truth. No projection: no bound."""
    _, x_true, jd, data = _pitch_row_data(400)
    cfg = CkfConfig(mode=CkfMode.UNCONSTRAINED, q_diag=(0.0, 0.0, 0.0, 0.0), r_diag=(1e-2,) * 5, p0_scale=0.0,
                    pitch_r_nm2=pitch_r)
    kf = ConstrainedKalmanFilter(cfg)
    kf.initialise([jd[0], jd[1], jd[2], 6.0], p0=np.diag([1.0, 1.0, 1.0, 10.0]))
    for du, da, gc_inv, rho_x, rho_z in data:
        kf.correct(du, da, gc_inv, rho_x, rho_z)
    x = kf.x
    rel_err = abs(x[1] - x_true[1]) / x_true[1]
    if pitch_r > 0.0:
        assert rel_err < 0.02, x
    else:  # the Delta U update, the same data: biased (the failure the moment-space row removes)
        assert rel_err > 0.1, x
    assert abs(x[0] - x_true[0]) / x_true[0] < 0.2 and abs(x[2] - x_true[2]) / x_true[2] < 0.2, x


@pytest.mark.parametrize("com_sigma_m", [0.0, 0.05])
def test_the_pitch_rows_com_nuisance_removes_the_bias_of_a_wrong_reference_point(com_sigma_m: float) -> None:
    """The law's moments about a point 3 cm off the true CoM: the pitch row is I_yy Delta Q-dot + c Delta F_x with
    Delta F_x following the pitch excitation (correlation 0.8, as the ducts' tilt follows the doublets). Without the
    nuisance state I_yy absorbs c Delta F_x; with it (object_held, prior sigma 5 cm) I_yy and c converge to the truth.
    G_C = I, so Delta U is the moment/force increment itself. No projection: no bound."""
    rng = np.random.default_rng(11)
    x_true = np.array([0.7, 0.9, 1.1, 8.0])
    c_true_m = 0.03
    cfg = CkfConfig(mode=CkfMode.UNCONSTRAINED, q_diag=(0.0,) * 4, r_diag=(1e-2,) * 5, p0_scale=0.0,
                    pitch_r_nm2=1e-3, com_sigma_m=com_sigma_m)
    kf = ConstrainedKalmanFilter(cfg)
    kf.initialise([0.5, 0.6, 0.9, 8.0], p0=np.diag([1.0, 0.01, 1.0, 1.0]))
    if com_sigma_m > 0.0:
        kf.object_held(True, com_sigma_m, 1.0)
    eye = np.eye(5)
    for _ in range(400):
        da = rng.standard_normal(5) * 0.3
        da[3] = 0.8 * da[1] + 0.6 * 0.3 * rng.standard_normal()  # a_x follows Q-dot
        du = np.array([x_true[0] * da[0], x_true[1] * da[1] + c_true_m * x_true[3] * da[3], x_true[2] * da[2],
                       x_true[3] * da[3], x_true[3] * da[4]]) + 0.01 * rng.standard_normal(5)
        kf.correct(du, da, eye, 0.0, 0.0)
    rel_err = abs(kf.x[1] - x_true[1]) / x_true[1]
    if com_sigma_m > 0.0:
        assert rel_err < 0.02 and abs(kf.pitch_com_offset_m - c_true_m) < 0.005, (kf.x, kf.pitch_com_offset_m)
    else:
        assert rel_err > 0.1, kf.x
    kf.object_held(False, com_sigma_m, 1.0)  # a release: no object, no nuisance
    assert kf.pitch_com_offset_m == 0.0


def test_lower_variance_caps_the_diagonal_and_keeps_the_correlations() -> None:
    """lower_variance (CKF_M_SIG_OPEN): P <- D P D, D = diag(min(1, sqrt(var_max / P_ii))): the capped variances are
    var_max, the others and every correlation unchanged, P symmetric positive definite."""
    rng = np.random.default_rng(3)
    kf = ConstrainedKalmanFilter(CkfConfig())
    p = _random_p(rng)
    kf.initialise(np.ones(4), p)
    cap = 0.25 * p[3, 3]
    kf.lower_variance((0.0, 0.0, 10.0 * p[2, 2], cap))
    q = kf.p
    np.testing.assert_allclose(np.diag(q), [p[0, 0], p[1, 1], p[2, 2], cap], rtol=1e-12)
    corr = lambda m: m / np.sqrt(np.outer(np.diag(m), np.diag(m)))  # noqa: E731
    np.testing.assert_allclose(corr(q), corr(p), rtol=1e-12)
    assert np.array_equal(q, q.T) and np.all(np.linalg.eigvalsh(q) > 0.0)


def test_the_ixz_nuisance_is_a_fifth_state_of_the_update(pose: Pose) -> None:
    """While held (ixz_held, CKF_IXZ_SIG) the update is the textbook KF on [x, d], d the I_xz error with H's fifth
    column G_C^-1 [Delta R-dot, 0, Delta P-dot, 0, 0], over 5 consecutive updates (x, P and d to 1e-9 relative); with
    the prior's sigma 0, or after a release, it is the 4-state update bit for bit."""
    rng = np.random.default_rng(3)
    sigma = 0.02
    for trial in range(10):
        c = CkfConfig(r_diag=tuple(rng.uniform(1e4, 5e4, 5)))
        r = np.diag(c.r_diag)
        gci = pose.gci if trial % 2 == 0 else rng.normal(size=(5, 5))
        x0 = pose.base * rng.uniform(0.8, 1.2, 4)
        p0 = _random_p(rng)
        kf, plain = ConstrainedKalmanFilter(c), ConstrainedKalmanFilter(c)
        kf.initialise(x0, p0=p0)
        plain.initialise(x0, p0=p0)
        kf.ixz_held(True, sigma)
        xa = np.append(x0, 0.0)
        pa = np.zeros((5, 5))
        pa[:4, :4] = p0
        pa[4, 4] = sigma**2
        for _ in range(5):
            a = rng.normal(size=5)
            z = rng.normal(size=5) * 1e3
            h = np.column_stack([measurement_matrix(gci, a, 0.0, 0.0), gci[:, 0] * a[2] + gci[:, 2] * a[0]])
            s = h @ pa @ h.T + r
            k = pa @ h.T @ np.linalg.inv(s)
            xa = xa + k @ (z - h @ xa)
            pa = pa - k @ s @ k.T
            kf.correct(z, a, gci, 0.0, 0.0)
            np.testing.assert_allclose(kf.x, xa[:4], rtol=1e-9)
            np.testing.assert_allclose(kf.ixz_offset_kgm2, xa[4], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(kf.p, pa[:4, :4], rtol=1e-9, atol=1e-12 * np.abs(pa).max())
        kf.ixz_held(False, sigma)  # a release: no object, no nuisance; from here the 4-state update bit for bit
        assert kf.ixz_offset_kgm2 == 0.0
        plain.initialise(kf.x, p0=kf.p)
        for _ in range(3):
            a, z = rng.normal(size=5), rng.normal(size=5) * 1e3
            kf.correct(z, a, gci, 0.0, 0.0)
            plain.correct(z, a, gci, 0.0, 0.0)
            assert np.array_equal(kf.x, plain.x) and np.array_equal(kf.p, plain.p)


@pytest.mark.parametrize("ixz_sigma", [0.0, 0.05])
def test_the_ixz_nuisance_removes_the_bias_of_a_wrong_product_of_inertia(ixz_sigma: float) -> None:
    """The roll and yaw rows with the modelled I_xz 0.03 kg m^2 off (the object's at a wrong mass estimate) and the
    yaw excitation following the roll's (correlation 0.8, as the doublets couple them): without the nuisance I_zz
    absorbs d Delta P-dot; with it (ixz_held, prior sigma 0.05 kg m^2) I_zz and d converge to the truth. G_C = I."""
    rng = np.random.default_rng(5)
    x_true = np.array([0.7, 0.9, 1.1, 8.0])
    d_true = 0.03
    cfg = CkfConfig(mode=CkfMode.UNCONSTRAINED, q_diag=(0.0,) * 4, r_diag=(1e-4,) * 5, p0_scale=0.0,
                    ixz_sigma_kgm2=ixz_sigma)
    kf = ConstrainedKalmanFilter(cfg)
    kf.initialise([0.5, 0.6, 0.9, 8.0], p0=np.diag([1.0, 1.0, 1.0, 1.0]))
    kf.ixz_held(True, ixz_sigma)
    eye = np.eye(5)
    for _ in range(400):
        da = rng.standard_normal(5) * 0.3
        da[2] = 0.8 * da[0] + 0.6 * 0.3 * rng.standard_normal()  # R-dot follows P-dot
        du = np.array([x_true[0] * da[0] + d_true * da[2], x_true[1] * da[1], x_true[2] * da[2] + d_true * da[0],
                       x_true[3] * da[3], x_true[3] * da[4]]) + 0.01 * rng.standard_normal(5)
        kf.correct(du, da, eye, 0.0, 0.0)
    rel_err = abs(kf.x[2] - x_true[2]) / x_true[2]
    if ixz_sigma > 0.0:
        assert rel_err < 0.01 and abs(kf.ixz_offset_kgm2 - d_true) < 0.005, (kf.x, kf.ixz_offset_kgm2)
    else:
        assert rel_err > 0.02 and kf.ixz_offset_kgm2 == 0.0, kf.x


def test_iyy_projected_apart_is_not_moved_by_the_mass_leaving_its_box() -> None:
    """CKF_PROJ_IYY (kalman.project_apart): with I_yy correlated with the mass, W = P^-1 moves I_yy when the mass is
    returned to its box (the conditional shift P_ym / P_mm of the violation); projected apart it stays, and the mass
    goes to its bound either way."""
    p = np.diag([0.01, 0.06, 0.04, 0.04])
    p[1, 3] = p[3, 1] = 0.3 * np.sqrt(0.06 * 0.04)
    # arrays, as ConstrainedKalmanFilter passes them (tuples would compile the projection's kernels again, ~20 s)
    lo, hi = np.array([0.3, 0.5, 0.3, 6.5]), np.array([0.8, 1.2, 0.6, 13.0])
    x_joint, x_apart = np.array([0.4, 0.6, 0.35, 5.8]), np.array([0.4, 0.6, 0.35, 5.8])
    kf_project(x_joint, p, False, lo, hi)
    project_apart(x_apart, p, False, lo, hi, 1)
    assert x_joint[3] == pytest.approx(6.5) and x_apart[3] == pytest.approx(6.5)
    assert x_joint[1] == pytest.approx(0.6 + p[1, 3] / p[3, 3] * 0.7)  # 0.6 + 0.86 x 0.7
    assert x_apart[1] == 0.6
    x_out = np.array([0.4, 1.5, 0.35, 7.0])  # I_yy itself outside: clipped to its own bound, the mass untouched
    project_apart(x_out, p, False, lo, hi, 1)
    assert x_out[1] == pytest.approx(1.2) and x_out[3] == 7.0


def test_the_pitch_nuisance_follows_the_reference_point_only_while_held() -> None:
    """CKF_CZ_FOLLOW (ConstrainedKalmanFilter.move_pitch_reference): the nuisance is the true CoM's height less the
    reference point's, so a point moved down by dz moves it by -dz; with no object held it stays zero."""
    kf = ConstrainedKalmanFilter(CkfConfig(pitch_r_nm2=0.01, com_sigma_m=0.03))
    kf.initialise((0.38, 0.57, 0.30, 6.5))
    kf.move_pitch_reference(0.01)
    assert kf.pitch_com_offset_m == 0.0
    kf.object_held(True, 0.03, 0.0)
    p_before = kf.p
    kf.move_pitch_reference(0.01)
    assert kf.pitch_com_offset_m == pytest.approx(-0.01)
    np.testing.assert_array_equal(kf.p, p_before)


def test_while_the_arm_moves_the_update_is_the_textbook_one_with_r_scaled(pose: Pose) -> None:
    """CKF_R_MOVE: step(arm_moving=True) is the textbook update x + K (z - H x), K = P H^T (H P H^T + s R)^-1, with
    the noise variances s times R (numpy here, to 1e-9); arm_moving=False the same with R; and a filter configured
    with s R and s times the pitch row's variance, at rest, steps bit for bit as the scaled one while moving."""
    rng = np.random.default_rng(7)
    scale = 8.0
    for trial in range(10):
        r_diag = tuple(rng.uniform(1e4, 5e4, 5))
        base = dict(r_diag=r_diag, mode=CkfMode.UNCONSTRAINED)
        x0 = pose.base * rng.uniform(0.8, 1.2, 4)
        p0 = _random_p(rng)
        a = rng.normal(size=5)
        z = rng.normal(size=5) * 1e3
        h = measurement_matrix(pose.gci, a, pose.rho_x, pose.rho_z)
        for moving, s in ((True, scale), (False, 1.0)):
            kf = ConstrainedKalmanFilter(CkfConfig(**base, r_move_scale=scale))
            kf.initialise(x0, p0=p0)
            kf.step(z, a, pose.gci, pose.rho_x, pose.rho_z, None, pose.base * 0.5, pose.base * 2.0, arm_moving=moving)
            k = p0 @ h.T @ np.linalg.inv(h @ p0 @ h.T + s * np.diag(r_diag))
            np.testing.assert_allclose(kf.x, x0 + k @ (z - h @ x0), rtol=1e-9)
        # the pitch row in moment space too: the scaled filter moving == a filter configured with the scaled variances
        pitch = dict(mode=CkfMode.CONSTRAINED, pitch_r_nm2=0.01, com_sigma_m=0.0)
        moving = ConstrainedKalmanFilter(CkfConfig(r_diag=r_diag, r_move_scale=scale, **pitch))
        scaled = ConstrainedKalmanFilter(CkfConfig(r_diag=tuple(scale * v for v in r_diag),
                                                   **{**pitch, "pitch_r_nm2": 0.01 * scale}))
        for kf, mv in ((moving, True), (scaled, False)):
            kf.initialise(x0, p0=p0)
            kf.step(z, a, pose.gci, pose.rho_x, pose.rho_z, None, pose.base * 0.5, pose.base * 2.0, arm_moving=mv)
        assert np.array_equal(moving.x, scaled.x) and np.array_equal(moving.p, scaled.p), trial
    with pytest.raises(ValueError):
        CkfConfig(r_move_scale=0.5)
