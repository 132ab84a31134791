"""navig8_fc.core.lms: the LMS baseline (CKF_MODE 4), its configuration and parameters.

Independent checks: one step against the gradient of the weighted squared equation error taken by central
differences in numpy (not the kernel's formula); the measurements built from G_C^-1 G_hat_I(x_true) Delta Acc with
vehicle.estimated_gi (Eq. 4), not from the regressor the estimator uses; convergence to known parameters on
synthetic, persistently exciting data; the box from vehicle.estimate_bounds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_kalman import Pose  # the model quantities at a fixed arm pose

from navig8_fc.core import vehicle as veh
from navig8_fc.core.adaptive_law import AdaptiveLaw, AdaptiveLawConfig, AdaptiveLawInputs
from navig8_fc.core.ckf_config import CKF_PARAM_NAMES, CkfConfig, CkfMode
from navig8_fc.core.lms import LmsEstimator
from navig8_fc.params.registry import ParamRegistry

SIGMA_U = 100.0  # noise on Delta U of the synthetic data, (rad/s)^2
R_WEIGHT = 1.0e4**2  # the error weighting r_j of the tests: makes the normalised regressor O(1) for Delta Acc ~ N(0, 1)


@pytest.fixture(scope="module")
def pose() -> Pose:
    return Pose()


def _measure(pose: Pose, x_true: np.ndarray, da: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Delta U = G_C^-1 G_hat_I(x_true) Delta Acc + noise (Eq. 23 with Eq. 4's G_hat_I)."""
    return pose.gci @ veh.estimated_gi(pose.j, x_true) @ da + rng.normal(0.0, SIGMA_U, 5)


def _rates(pose: Pose, gain: float = 0.1) -> tuple[float, ...]:
    """Per-state rates mu_i = gain / E[|H~_i|^2] for Delta Acc ~ N(0, 1): the normalised regressor's column norms
    differ by ~100 here (the mass column is the largest), and one rate per state (Paparazzi's per-axis mu) is what
    equalises them. E[|H~_i|^2] is measured on the noise-free model (column i of G_C^-1 G_hat_I(e_i x0_i) da)."""
    rng = np.random.default_rng(99)
    acc = np.zeros(4)
    for _ in range(500):
        da = rng.normal(size=5)
        for i in range(4):
            xi = np.zeros(4)
            xi[i] = pose.base[i]
            col = pose.gci @ veh.estimated_gi(pose.j, xi) @ da  # H[:, i] x0_i, with every other state zero
            acc[i] += float(col @ col) / R_WEIGHT / 500
    return tuple(gain / a for a in acc)


def _run(pose: Pose, x_true: np.ndarray, mu: tuple[float, ...], n_steps: int = 3000,
         seed: int = 0) -> tuple[LmsEstimator, list[tuple[float, ...]]]:
    rng = np.random.default_rng(seed)
    est = LmsEstimator(CkfConfig(mode=CkfMode.LMS, r_diag=(R_WEIGHT,) * 5, lms_mu=mu))
    est.initialise(pose.base)
    xs = []
    for k in range(n_steps):
        da = rng.normal(0.0, 1.0, 5)  # persistently exciting: i.i.d. in every component
        r = est.step(_measure(pose, x_true, da, rng), da, pose.gci, pose.rho_x, pose.rho_z,
                     None if k == 0 else (0.0, 0.0, 0.0), *pose.box)
        xs.append(r.x_hat)
    return est, xs


def test_one_step_is_the_scaled_gradient_step(pose: Pose) -> None:
    """x+ = x - mu_i x0_i^2 dJ/dx_i with J(x) = sum_j (Delta U_j - (G_C^-1 G_hat_I(x) Delta Acc)_j)^2 / (2 r_j),
    the gradient by central differences of J written here; the innovation is Delta U - that prediction at x-."""
    rng = np.random.default_rng(3)
    r_diag = (1500.0**2, 2000.0**2, 1500.0**2, 2000.0**2, 10000.0**2)
    mu = (2e-5, 3e-5, 5e-5, 7e-6)  # small: the step stays far inside the box (no clipping in this check)
    est = LmsEstimator(CkfConfig(mode=CkfMode.LMS, r_diag=r_diag, lms_mu=mu))
    x0 = pose.base.copy()
    est.initialise(x0)
    da = rng.normal(0.0, 2.0, 5)
    du = _measure(pose, x0 * np.array([1.4, 1.2, 1.6, 1.3]), da, rng)

    def cost(x: np.ndarray) -> float:
        e = du - pose.gci @ veh.estimated_gi(pose.j, x) @ da
        return float(np.sum(e * e / np.array(r_diag)) / 2.0)

    grad = np.empty(4)
    for i in range(4):
        h = 1e-6 * x0[i]
        xp, xm = x0.copy(), x0.copy()
        xp[i] += h
        xm[i] -= h
        grad[i] = (cost(xp) - cost(xm)) / (2.0 * h)
    wide = (tuple((0.1 * x0).tolist()), tuple((10.0 * x0).tolist()))
    r = est.step(du, da, pose.gci, pose.rho_x, pose.rho_z, None, *wide)
    expected = x0 - np.array(mu) * x0**2 * grad
    assert np.all(np.abs(expected - x0) > 1e-4 * x0) and np.all(np.abs(expected - x0) < 0.5 * x0)  # moved, unclipped
    np.testing.assert_allclose(r.x_hat, expected, rtol=1e-7)
    np.testing.assert_allclose(r.innovation, du - pose.gci @ veh.estimated_gi(pose.j, x0) @ da, rtol=1e-10)
    assert r.p_diag == (0.0,) * 4 and r.corrected and not r.projected and est.n_updates == 1


def test_converges_to_the_truth_inside_the_box(pose: Pose) -> None:
    """Known constant parameters inside the box, i.i.d. Delta Acc ~ N(0, 1), Delta U noise 100 (rad/s)^2: within
    2 % after 3000 steps; the box holds on every step."""
    x_true = pose.base * np.array([1.5, 1.3, 1.7, 1.25])
    est, xs = _run(pose, x_true, _rates(pose))
    np.testing.assert_allclose(est.x, x_true, rtol=0.02)
    assert np.max(np.abs(np.array(xs[:50]) - x_true) / x_true) > 0.1  # it did not start there
    for x in xs:
        assert np.all(np.array(x) >= pose.lower) and np.all(np.array(x) <= pose.upper)


def test_truth_outside_the_box_sits_on_the_bound(pose: Pose) -> None:
    """I_yy true = 2.6 I_UAM,yy > the 2 I_UAM,yy bound: the estimate ends on the upper bound exactly (the clip),
    the other states at the truth (2 %)."""
    x_true = pose.base * np.array([1.5, 2.6, 1.2, 1.3])
    est, xs = _run(pose, x_true, _rates(pose))
    assert est.x[1] == pose.upper[1]
    np.testing.assert_allclose(est.x[[0, 2, 3]], x_true[[0, 2, 3]], rtol=0.02)
    for x in xs:
        assert np.all(np.array(x) >= pose.lower) and np.all(np.array(x) <= pose.upper)


def test_zero_rate_never_moves(pose: Pose) -> None:
    """mu = 0 holds every state at x0 exactly; a zero rate on one state holds that state while the others converge
    (the held state's truth is its x0 here, so holding it biases nothing)."""
    x_true = pose.base * np.array([1.5, 1.3, 1.7, 1.25])
    est, xs = _run(pose, x_true, (0.0,) * 4, n_steps=300)
    assert all(x == tuple(pose.base.tolist()) for x in xs) and est.n_updates == 300
    rates = list(_rates(pose))
    rates[2] = 0.0
    x_true = pose.base * np.array([1.5, 1.3, 1.0, 1.25])
    est, _ = _run(pose, x_true, tuple(rates))
    assert est.x[2] == pose.base[2]
    np.testing.assert_allclose(est.x[[0, 1, 3]], x_true[[0, 1, 3]], rtol=0.02)


def test_drift_gates_and_errors(pose: Pose) -> None:
    """The Eq. 22 drift is applied without a correction; correct=False and the excitation gate hold the states;
    a non-finite measurement is not learned from; an empty box and use before initialise raise."""
    est = LmsEstimator(CkfConfig(mode=CkfMode.LMS, exc_rot_rad_s2=0.5, exc_lin_m_s2=0.5))
    with pytest.raises(RuntimeError):
        est.step(np.zeros(5), np.zeros(5), pose.gci, 0.0, 0.0, None, *pose.box)
    x0 = pose.base * 1.2
    est.initialise(x0)
    r = est.step(np.full(5, 1e4), np.ones(5), pose.gci, pose.rho_x, pose.rho_z, (0.1, 0.2, 0.3), *pose.box,
                 correct=False)
    np.testing.assert_allclose(r.x_hat, x0 + 0.01 * np.array([0.1, 0.2, 0.3, 0.0]), rtol=1e-12)
    assert not r.corrected and r.innovation == (0.0,) * 5
    da = np.array([1.0, 0.1, 0.1, 0.1, 0.1])  # only the roll increment passes the gate
    r2 = est.step(np.full(5, 1e4), da, pose.gci, pose.rho_x, pose.rho_z, None, *pose.box)
    assert r2.corrected and r2.excited == (True, False, False, False)
    assert r2.x_hat[1:] == r.x_hat[1:] and r2.x_hat[0] != r.x_hat[0]
    r3 = est.step(np.full(5, np.nan), np.ones(5), pose.gci, pose.rho_x, pose.rho_z, None, *pose.box)
    assert not r3.corrected and r3.x_hat == r2.x_hat
    with pytest.raises(ValueError, match="empty box"):
        est.step(np.zeros(5), np.zeros(5), pose.gci, 0.0, 0.0, None, pose.box[1], pose.box[0])
    with pytest.raises(ValueError):
        est.initialise(np.array([0.1, 0.0, 0.1, 1.0]))  # a zero state cannot scale the step


def test_the_law_flies_the_lms_in_mode_4(pose: Pose) -> None:
    """AdaptiveLaw with CKF_MODE 4 holds an LmsEstimator, reports no covariance, keeps the box and converges to the
    truth (2 %) on noise-free data generated from a known G (plus a constant acceleration bias the increments remove),
    with the default 25-step increment windows."""
    x_true = pose.base * np.array([1.6, 1.3, 1.8, 1.2])
    g_true = np.linalg.inv(pose.gci @ veh.estimated_gi(pose.j, x_true))
    law = AdaptiveLaw(AdaptiveLawConfig(CkfConfig(mode=CkfMode.LMS, lms_mu=(0.05,) * 4, inc_window=25)))
    assert isinstance(law.kf, LmsEstimator)
    rng = np.random.default_rng(1)
    u_trim = veh.hover_trim(pose.cfg, pose.q, 0.0)
    bias = np.array([0.1, -0.2, 0.05, 0.3, -9.80665])
    walk = np.zeros(5)
    for k in range(3000):
        walk = 0.98 * (walk + rng.normal(0.0, 3e3, 5))
        u = u_trim + walk
        _, st = law.step(AdaptiveLawInputs(t_s=k * 0.01, u_meas=u, acc_m=g_true @ u + bias, gc_uam_inv=pose.gci,
                                           inertia_uam=pose.j, mass_uam_kg=pose.m, inertia_rate_uam=np.zeros((3, 3))))
        if st.running:
            assert st.p_diag == (0.0,) * 4
            assert all(lo <= x <= hi for lo, x, hi in zip(st.lower, st.x_hat, st.upper, strict=True))
    assert np.all(np.abs(pose.base - x_true) / x_true > 0.15)  # it starts at K = 1, far from the truth
    np.testing.assert_allclose(st.x_hat, x_true, rtol=0.02)
    assert st.n_updates > 100 and st.n_projection_fallbacks == 0


# --------------------------------------------------------------------------------------------------
# configuration and parameters
# --------------------------------------------------------------------------------------------------


def test_config_mode_4_and_rates() -> None:
    reg = ParamRegistry.from_defaults(check_stability=False)
    values = reg.as_dict()
    c = CkfConfig.from_params({**values, "CKF_MODE": 4, "CKF_LMS_MU3": 0.25}, 0.01)
    assert c.mode == CkfMode.LMS and c.adaptive and not c.constrained
    assert c.lms_mu[2] == 0.25 and len(c.lms_mu) == 4
    with pytest.raises(ValueError, match="CKF_MODE"):
        CkfConfig.from_params({**values, "CKF_MODE": 5}, 0.01)
    with pytest.raises(ValueError):
        CkfConfig(lms_mu=(0.1, -0.1, 0.1, 0.1))
    with pytest.raises(ValueError):
        CkfConfig(lms_mu=(0.1, math.nan, 0.1, 0.1))
    missing = {k: v for k, v in values.items() if k != "CKF_LMS_MU2"}
    with pytest.raises(KeyError):
        CkfConfig.from_params(missing, 0.01)


def test_registry_accepts_mode_4_refuses_5_and_the_rates_have_ranges() -> None:
    reg = ParamRegistry.from_defaults()
    assert reg.set("CKF_MODE", 4).accepted and reg["CKF_MODE"] == 4
    res = reg.set("CKF_MODE", 5)
    assert not res.accepted and reg["CKF_MODE"] == 4
    names = [f"CKF_LMS_MU{i}" for i in range(1, 5)]
    assert set(names) <= set(CKF_PARAM_NAMES)
    # appended: the parameters before them keep their MAVLink index
    idx = [reg.index_of(n) for n in names]
    assert idx == list(range(idx[0], idx[0] + 4))
    assert all(reg.index_of(n) > idx[-1] for n in ("CKF_R_PITCH", "CKF_CZ_SIG"))  # appended after them
    assert reg.index_of("CKF_K_PIN4") < reg.index_of("CKF_LMS_MU1")
    for n in names:
        d = reg.definition(n)
        assert d.type == "REAL32" and d.min == 0.0 and math.isfinite(d.max) and d.min <= d.default <= d.max
        assert d.not_armed and d.description
        assert not reg.set(n, -0.1).accepted and not reg.set(n, d.max * 2.0).accepted
    assert CkfConfig.from_params(reg.as_dict(), 0.01).lms_mu == pytest.approx(
        tuple(float(reg[n]) for n in names))
