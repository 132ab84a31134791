"""navig8_fc.core.adaptive_law: the law of Fig. 3 at its public boundary.

Independent checks: the increments against filters.LowPass1 (a separate implementation of the same
low-pass), the box and G_hat_I against vehicle.estimate_bounds / estimated_gi / k_from_estimate, the KF part
against ConstrainedKalmanFilter.step fed with those increments, and convergence to known parameters on
data generated from a known G.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_kalman import Pose  # the model quantities at a fixed arm pose (one helper for both filter tests)

from navig8_fc.core import vehicle as veh
from navig8_fc.core.adaptive_law import (
    AdaptiveLaw,
    AdaptiveLawConfig,
    AdaptiveLawInputs,
    AdaptiveLawStatus,
)
from navig8_fc.core.ckf_config import CkfConfig, CkfMode
from navig8_fc.core.filters import LowPass1
from navig8_fc.core.kalman import ConstrainedKalmanFilter
from navig8_fc.core.law_filters import LAW_OUT, LAW_STATE, lpf_increments

DT = 0.01


@pytest.fixture(scope="module")
def pose() -> Pose:
    return Pose()


def _law(k_min: float = 0.5, k_max: float = 1.0, **ckf: object) -> AdaptiveLaw:
    return AdaptiveLaw(AdaptiveLawConfig(CkfConfig(**ckf), k_min, k_max))  # type: ignore[arg-type]


def _law_inputs(pose: Pose, t: float, u: np.ndarray, acc: np.ndarray,
                idot: np.ndarray | None = None) -> AdaptiveLawInputs:
    return AdaptiveLawInputs(
        t_s=t, u_meas=u, acc_m=acc, gc_uam_inv=pose.gci, inertia_uam=pose.j, mass_uam_kg=pose.m,
        inertia_rate_uam=np.zeros((3, 3)) if idot is None else idot,
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


def test_config_holds_the_k_bounds() -> None:
    c = AdaptiveLawConfig()
    assert (c.k_min, c.k_max) == (0.5, 1.0) and c.ckf == CkfConfig()  # Eq. 20, Sec. 4
    for k_min, k_max in ((0.0, 1.0), (1.2, 1.0), (0.5, math.inf), (math.nan, 1.0)):
        with pytest.raises(ValueError):
            AdaptiveLawConfig(CkfConfig(), k_min, k_max)


def test_before_start_and_start(pose: Pose) -> None:
    law = _law()
    data = _excitation(pose, pose.base * 1.4, 80)
    gi_uam = veh.inertia_matrix_gi(pose.j, pose.m)
    for k, (u, acc) in enumerate(data):
        t = 10.0 + k * DT  # the delay counts from the first sample, not from t = 0
        g, st = law.step(_law_inputs(pose, t, u, acc))
        if t - 10.0 < 0.5 - 1e-9:
            assert not st.running and law.mass_estimate_kg is None
            np.testing.assert_allclose(g, gi_uam, rtol=1e-14, atol=1e-15)
            assert st.k == (1.0, 1.0, 1.0, 1.0) and st.n_updates == 0
        else:
            assert st.running and law.mass_estimate_kg == st.x_hat[3]
            if k == 50:  # first running tick: x0 = [J11, J22, J33, m] (K = 1), one correction
                assert st.n_updates == 1
        np.testing.assert_allclose(st.lower, pose.lower)
        np.testing.assert_allclose(st.upper, pose.upper)
        assert len(st.x_hat) == 4 and len(st.innovation) == 5 and len(st.active_lower) == 4
    assert st.n_updates == 30


def test_increments_are_one_step_differences_of_filtered_signals(pose: Pose) -> None:
    law = _law(start_delay_s=0.0)
    ref_u, ref_a = LowPass1(0.7, DT, 5), LowPass1(0.7, DT, 5)
    prev_u = prev_a = None
    for k, (u, acc) in enumerate(_excitation(pose, pose.base * 1.2, 20)):
        _, st = law.step(_law_inputs(pose, k * DT, u, acc))
        fu, fa = np.array(ref_u.step(u.tolist())), np.array(ref_a.step(acc.tolist()))
        if prev_u is None:
            assert st.delta_u == (0.0,) * 5
        else:
            assert st.delta_u == tuple((fu - prev_u).tolist())  # same IEEE operations as LowPass1
            assert st.delta_acc == tuple((fa - prev_a).tolist())
        prev_u, prev_a = fu, fa


def test_increments_kernel_python_path(pose: Pose) -> None:
    """lpf_increments' plain-Python path (its py_func) equals the compiled kernel bit for bit (windows of 1 and 3,
    a saturation flag on some steps)."""
    for n_window in (1.0, 3.0):
        st_c, st_p = LAW_STATE.zeros(), LAW_STATE.zeros()
        out_c, out_p = LAW_OUT.zeros(), LAW_OUT.zeros()
        for k, (u, acc) in enumerate(_excitation(pose, pose.base, 10)):
            sat = 1.0 if k == 4 else 0.0
            gyro = acc[:3] * 0.5
            lpf_increments(st_c, 0.0142, n_window, u, acc, 0.1 * k, gyro, sat, 2.0, out_c)
            lpf_increments.py_func(st_p, 0.0142, n_window, u, acc, 0.1 * k, gyro, sat, 2.0, out_p)
            assert np.array_equal(st_c, st_p) and np.array_equal(out_c, out_p)
    views = LAW_OUT.views(out_c)
    assert views.delta_u.shape == (5,) and views.delta_acc.shape == (5,)


def test_window_increments_and_corrections_every_n_steps(pose: Pose) -> None:
    """CKF_INC_N = 5: every 5th step the increments are the LowPass1 outputs' difference over the 5 steps (zeros in
    between), and only those steps correct (n_updates); the estimate moves only on them (predict has I-dot = 0)."""
    n = 5
    law = _law(start_delay_s=0.0, inc_window=n)
    ref_u, ref_a = LowPass1(0.7, DT, 5), LowPass1(0.7, DT, 5)
    hist_u, hist_a = [], []
    x_prev = None
    for k, (u, acc) in enumerate(_excitation(pose, pose.base * 1.3, 41)):
        _, st = law.step(_law_inputs(pose, k * DT, u, acc))
        hist_u.append(np.array(ref_u.step(u.tolist())))
        hist_a.append(np.array(ref_a.step(acc.tolist())))
        if k > 0 and k % n == 0:
            assert st.delta_u == tuple((hist_u[k] - hist_u[k - n]).tolist())
            assert st.delta_acc == tuple((hist_a[k] - hist_a[k - n]).tolist())
            assert st.corrected and st.n_updates == k // n and st.x_hat != x_prev
        else:
            assert st.delta_u == (0.0,) * 5 and st.delta_acc == (0.0,) * 5 and not st.corrected
            assert st.n_updates == k // n
            if x_prev is not None:
                assert st.x_hat == x_prev
        x_prev = st.x_hat


def test_excitation_gate_holds_unexcited_states(pose: Pose) -> None:
    """CKF_EXC_*: only the states whose regressor increment reaches the threshold are corrected. Data excite pitch
    (|Delta Q-dot| large) and nothing else: I_yy moves, I_xx, I_zz and m stay exactly at x0; with no threshold all
    four move. Without any excited state there is no correction at all."""
    rng = np.random.default_rng(3)
    g_true_inv = pose.gci @ veh.estimated_gi(pose.j, pose.base * np.array([1.5, 1.5, 1.5, 1.2]))
    u_trim = veh.hover_trim(pose.cfg, pose.q, 0.0)

    def run(exc_rot: float, exc_lin: float, q_amp: float) -> tuple[tuple[float, ...], int]:
        law = _law(start_delay_s=0.0, inc_window=10, exc_rot_rad_s2=exc_rot, exc_lin_m_s2=exc_lin,
                   q_diag=(1e-12,) * 4, p0_scale=1e9)
        for k in range(400):
            acc = np.array([1e-3 * rng.normal(), q_amp * math.sin(k * 0.05), 1e-3 * rng.normal(),
                            1e-3 * rng.normal(), -9.80665 + 1e-3 * rng.normal()])
            _, st = law.step(_law_inputs(pose, k * DT, u_trim + g_true_inv @ acc, acc))
        return st.x_hat, st.n_updates

    x_gated, n_gated = run(0.05, 0.05, 3.0)
    assert x_gated[0] == pose.base[0] and x_gated[2] == pose.base[2] and x_gated[3] == pose.base[3]
    assert x_gated[1] > pose.base[1] * 1.05 and n_gated > 0
    x_free, _ = run(0.0, 0.0, 3.0)
    assert all(a != b for a, b in zip(x_free, pose.base, strict=True))
    x_quiet, n_quiet = run(0.05, 0.05, 0.0)
    assert n_quiet == 0 and x_quiet == tuple(pose.base.tolist())


def test_saturation_gate_skips_saturated_windows(pose: Pose) -> None:
    """CKF_SAT_GATE: a window during which the INDI reported saturation (indi_saturated on any of its steps), or
    that lies within one filter time constant after such a step (the low-passed signals still carry it), is not
    learned from; the same data without the flag, or with the gate off, are."""
    data = _excitation(pose, pose.base * 1.4, 60)
    tau = 0.04  # the hold: ceil(tau / dt) = 4 steps

    def run(gate: bool, flag_steps: set[int]) -> tuple[AdaptiveLawStatus, list[int]]:
        law = _law(start_delay_s=0.0, inc_window=10, sat_gate=gate, lpf_tau_s=tau)
        flagged_windows = []
        for k, (u, acc) in enumerate(data):
            _, _, st = law.step_arrays(k * DT, u, acc, pose.gci, pose.j, pose.m, np.zeros((3, 3)), 0.0,
                                       k in flag_steps)
            if st.saturated:
                flagged_windows.append(k)
        return st, flagged_windows

    flagged = {13, 14, 35}  # inside the windows closing at 20 and 40, their holds too
    st, windows = run(True, flagged)
    assert windows == [20, 40] and st.n_saturation_skips == 2 and st.n_updates == 5 - 2
    st, windows = run(False, flagged)  # gate off: flagged as they are (no hold), all learned from
    assert windows == [20, 40] and st.n_saturation_skips == 0 and st.n_updates == 5
    st, windows = run(True, set())
    assert windows == [] and st.n_updates == 5
    st, windows = run(True, {18})  # the hold (18 + 4 steps) reaches into the window closing at 30
    assert windows == [20, 30] and st.n_saturation_skips == 2


def test_u_from_command(pose: Pose) -> None:
    """CKF_U_SRC = 1: the law's U is the command U passed in (u_meas ignored); without a command (None) u_meas."""
    data = _excitation(pose, pose.base * 1.2, 12)
    by_cmd, by_meas = _law(start_delay_s=0.0, u_from_command=True), _law(start_delay_s=0.0)
    for k, (u, acc) in enumerate(data):
        noise = np.full(5, 500.0 * (-1) ** k) if k > 0 else np.zeros(5)  # the first sample: no command yet
        _, _, st_c = by_cmd.step_arrays(k * DT, u + noise, acc, pose.gci, pose.j, pose.m, np.zeros((3, 3)), 0.0,
                                        False, u if k > 0 else None)
        _, _, st_m = by_meas.step_arrays(k * DT, u, acc, pose.gci, pose.j, pose.m, np.zeros((3, 3)))
        if k > 0:
            assert st_c.delta_u == st_m.delta_u
    assert st_c.x_hat == st_m.x_hat


def test_reset_restarts_delay_and_filter(pose: Pose) -> None:
    law = _law(start_delay_s=0.1)
    data = _excitation(pose, pose.base * 1.3, 40)
    for k, (u, acc) in enumerate(data[:20]):
        _, st = law.step(_law_inputs(pose, k * DT, u, acc))
    assert st.running and law.kf.initialised and st.n_updates == 10
    law.reset()
    assert not law.kf.initialised and law.mass_estimate_kg is None
    for k, (u, acc) in enumerate(data[20:], start=20):
        _, st = law.step(_law_inputs(pose, k * DT, u, acc))
        if k == 20:
            assert st.delta_u == (0.0,) * 5  # filters re-initialise on the first sample after reset
        if k < 30:
            assert not st.running  # the delay counts again from t = 0.2 s
    assert st.running and st.n_updates == 10


def test_fixed_mode_never_runs(pose: Pose) -> None:
    law = _law(mode=CkfMode.FIXED)
    gi_uam = veh.inertia_matrix_gi(pose.j, pose.m)
    for k, (u, acc) in enumerate(_excitation(pose, pose.base * 1.5, 100)):
        g, st = law.step(_law_inputs(pose, k * DT, u, acc))
        assert not st.running
        np.testing.assert_allclose(g, gi_uam, rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize(("k_pin", "k_flown"), [((0.6, 0.7, 0.8, 0.9), (0.6, 0.7, 0.8, 0.9)),
                                               ((0.3, 1.0, 1.4, 0.5), (0.5, 1.0, 1.0, 0.5))])  # clipped to the box
def test_pinned_mode_flies_eq4_with_the_constant_k(pose: Pose, k_pin: tuple, k_flown: tuple) -> None:
    # Eq. 3-4 with K constant: G_hat_I = G_I,UAM K^-1, built here from the matrices (not the law's column scaling);
    # the KF never runs, whatever the data, and the mass estimate is the constant model's m_UAM / K4.
    law = _law(mode=CkfMode.PINNED, k_pin=k_pin)
    expected = veh.inertia_matrix_gi(pose.j, pose.m) @ np.linalg.inv(veh.k_matrix(np.array(k_flown)))
    for k, (u, acc) in enumerate(_excitation(pose, pose.base * 1.5, 100)):
        g, st = law.step(_law_inputs(pose, k * DT, u, acc))
        assert not st.running and st.n_updates == 0
        np.testing.assert_allclose(st.k, k_flown, rtol=1e-12)
        np.testing.assert_allclose(g, expected, rtol=1e-12, atol=1e-15)
    assert law.mass_estimate_kg == pytest.approx(pose.m / k_flown[3], rel=1e-12)


def test_pinned_k_must_be_positive() -> None:
    with pytest.raises(ValueError, match="k_pin"):
        CkfConfig(mode=CkfMode.PINNED, k_pin=(1.0, 0.0, 1.0, 1.0))
    from navig8_fc.params.registry import ParamRegistry

    values = ParamRegistry.from_defaults().as_dict()
    assert CkfConfig.from_params({**values, "CKF_MODE": 3, "CKF_K_PIN2": 0.7}, DT).k_pin == (1.0, 0.7, 1.0, 1.0)
    with pytest.raises(ValueError, match="CKF_MODE"):
        CkfConfig.from_params({**values, "CKF_MODE": 5}, DT)


@pytest.mark.parametrize("mode", [CkfMode.CONSTRAINED, CkfMode.UNCONSTRAINED])
def test_converges_on_consistent_data(pose: Pose, mode: CkfMode) -> None:
    """Noise-free u/acc consistent with G_true (plus a constant acceleration bias, which the increments
    remove): x_hat -> x_true within 2 % in 20 s. x_true inside the box for constrained, and the
    unconstrained filter is given a component outside it (I_zz = 2.4 I_UAM,zz) to show it leaves the box."""
    factors = np.array([1.6, 1.3, 1.8, 1.2]) if mode == CkfMode.CONSTRAINED else np.array([1.6, 1.3, 2.4, 1.2])
    x_true = pose.base * factors
    law = _law(mode=mode, r_diag=(1.0,) * 5, q_diag=(1e-10,) * 4, p0_scale=1e8)
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


def test_law_equals_its_public_pieces_bit_for_bit(pose: Pose) -> None:
    """AdaptiveLaw.step gives exactly what the public pieces give: LowPass1 increments,
    ConstrainedKalmanFilter.step and vehicle.estimate_bounds / estimated_gi / k_from_estimate.
    Projections are active on most ticks (x_true outside the box)."""
    cfg = CkfConfig(start_delay_s=0.05)
    law, kf = AdaptiveLaw(AdaptiveLawConfig(cfg)), ConstrainedKalmanFilter(cfg)
    ref_u, ref_a = LowPass1(cfg.lpf_tau_s, DT, 5), LowPass1(cfg.lpf_tau_s, DT, 5)
    idot = np.array([[0.02, 0.0, -0.01], [0.0, 0.03, 0.0], [-0.01, 0.0, 0.01]])
    prev = None
    n_projected = 0
    for k, (u, acc) in enumerate(_excitation(pose, pose.base * np.array([2.5, 1.3, 0.8, 1.2]), 300)):
        g, st = law.step(_law_inputs(pose, k * DT, u, acc, idot))
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
        res = kf.step(du, da, pose.gci, pose.rho_x, pose.rho_z, None if first else tuple(np.diag(idot).tolist()),
                      tuple(lower.tolist()), tuple(upper.tolist()))
        n_projected += res.projected
        x_hat = np.array(res.x_hat)
        assert st.x_hat == res.x_hat and st.x_unconstrained == res.x_unconstrained
        assert st.innovation == res.innovation and st.p_diag == res.p_diag
        assert st.k == tuple(veh.k_from_estimate(pose.j, pose.m, x_hat).tolist())
        assert st.active_lower == tuple((x_hat <= lower).tolist())
        assert st.active_upper == tuple((x_hat >= upper).tolist())
        assert np.array_equal(g, veh.estimated_gi(pose.j, x_hat))
        assert law.mass_estimate_kg == res.x_hat[3]
    assert n_projected > 100


def test_set_k_bounds_moves_the_box_and_keeps_the_state(pose: Pose) -> None:
    """New K bounds act from the next step on (Eq. 21 box = I_UAM / K, the estimate kept inside it); the
    estimator is not restarted (its update count continues), and the estimate departs from the old law's."""
    data = _excitation(pose, pose.base * np.array([2.5, 1.3, 0.8, 1.2]), 200)
    changed, fresh = _law(start_delay_s=0.05), _law(start_delay_s=0.05)
    for k, (u, acc) in enumerate(data[:100]):
        changed.step(_law_inputs(pose, k * DT, u, acc))
        fresh.step(_law_inputs(pose, k * DT, u, acc))
    changed.set_k_bounds(0.6, 0.9)
    assert (changed.config.k_min, changed.config.k_max) == (0.6, 0.9)
    with pytest.raises(ValueError):
        changed.set_k_bounds(0.9, 0.6)
    lower, upper = veh.estimate_bounds(pose.j, pose.m, 0.6, 0.9)
    for k, (u, acc) in enumerate(data[100:], start=100):
        _, st = changed.step(_law_inputs(pose, k * DT, u, acc))
        _, st_old = fresh.step(_law_inputs(pose, k * DT, u, acc))
        assert st.lower == tuple(lower.tolist()) and st.upper == tuple(upper.tolist())
        assert all(lo <= x <= hi for lo, x, hi in zip(st.lower, st.x_hat, st.upper, strict=True))
        assert st.n_updates == st_old.n_updates  # not restarted
    assert st.x_hat != st_old.x_hat


def test_gripper_events_forget_the_object(pose: Pose) -> None:
    """CKF_GRIP_RST: a grasp resets P to P0 (the covariance had shrunk), a release puts the estimate back to the one
    before the grasp and resets P; no correction within the low-pass's time constant after either. Noise-free data
    consistent with a heavier vehicle (x_true) throughout, so the estimate has moved and P shrunk before the grasp."""
    x_true = pose.base * np.array([1.6, 1.3, 1.8, 1.2])
    cfg = dict(r_diag=(1.0,) * 5, q_diag=(1e-10,) * 4, p0_scale=1e8, grip_reset=True)
    law = _law(**cfg)
    data = _excitation(pose, x_true, 3000, seed=3)
    p0_trace = 4 * 1e8 * 1e-10
    st = None
    for k, (u, acc) in enumerate(data[:300]):  # 3 s with the gripper open
        _, st = law.step(AdaptiveLawInputs(
            t_s=k * DT, u_meas=u, acc_m=acc, gc_uam_inv=pose.gci, inertia_uam=pose.j, mass_uam_kg=pose.m,
            inertia_rate_uam=np.zeros((3, 3)), gripper_closed=False))
    before = np.array(st.x_hat)
    shrunk = sum(st.p_diag)
    assert shrunk < 0.5 * p0_trace  # learning has shrunk P
    k0 = 300
    for k, (u, acc) in enumerate(data[300:2000], start=k0):
        _, st = law.step(AdaptiveLawInputs(
            t_s=k * DT, u_meas=u, acc_m=acc, gc_uam_inv=pose.gci, inertia_uam=pose.j, mass_uam_kg=pose.m,
            inertia_rate_uam=np.zeros((3, 3)), gripper_closed=True))
        if k == k0:  # the grasp: P back to P0 (plus this tick's Q), the estimate kept, no correction yet
            assert sum(st.p_diag) == pytest.approx(p0_trace, rel=1e-6) and not st.corrected
            np.testing.assert_allclose(st.x_hat, before, rtol=1e-12)
            assert st.n_forgets == 1
    held = np.array(st.x_hat)
    np.testing.assert_allclose(held, x_true, rtol=0.05)  # the object's data identified
    _, st = law.step(AdaptiveLawInputs(
        t_s=2000 * DT, u_meas=data[2000][0], acc_m=data[2000][1], gc_uam_inv=pose.gci, inertia_uam=pose.j,
        mass_uam_kg=pose.m, inertia_rate_uam=np.zeros((3, 3)), gripper_closed=False))
    np.testing.assert_allclose(st.x_hat, before, rtol=1e-9)  # the release: back where it was before the grasp
    assert sum(st.p_diag) == pytest.approx(p0_trace, rel=1e-6) and st.n_forgets == 2 and not st.corrected


def test_without_grip_reset_gripper_events_change_nothing(pose: Pose) -> None:
    data = _excitation(pose, pose.base * 1.3, 400, seed=4)
    runs = []
    for grip in (False, True):
        law = _law(r_diag=(1.0,) * 5, q_diag=(1e-10,) * 4, p0_scale=1e8)
        for k, (u, acc) in enumerate(data):
            _, st = law.step(AdaptiveLawInputs(
                t_s=k * DT, u_meas=u, acc_m=acc, gc_uam_inv=pose.gci, inertia_uam=pose.j, mass_uam_kg=pose.m,
                inertia_rate_uam=np.zeros((3, 3)), gripper_closed=grip and k > 200))
        runs.append(st.x_hat)
    assert runs[0] == runs[1]


def test_grip_sigma_widens_the_prior_of_i_xx_i_zz_and_m_at_a_grasp(pose: Pose) -> None:
    """CKF_GRIP_SIG: at a grasp the variances of I_xx and I_zz are at least (w x their box's width)^2 (the object may
    put them anywhere in the box, the estimate restarts at its edge); I_yy and m keep P0. P0 here is small, so the
    raise is what sets them."""
    w = 0.8
    law = _law(r_diag=(1.0,) * 5, q_diag=(1e-10,) * 4, p0_scale=10.0, grip_reset=True, grip_sigma_w=w)
    data = _excitation(pose, pose.base, 200, seed=6)
    st = None
    for k, (u, acc) in enumerate(data):
        _, st = law.step(AdaptiveLawInputs(
            t_s=k * DT, u_meas=u, acc_m=acc, gc_uam_inv=pose.gci, inertia_uam=pose.j, mass_uam_kg=pose.m,
            inertia_rate_uam=np.zeros((3, 3)), gripper_closed=k >= 100))
        if k == 100:
            break
    assert st is not None and st.n_forgets == 1
    width = np.array(st.upper) - np.array(st.lower)
    np.testing.assert_allclose([st.p_diag[i] for i in (0, 2)], [(w * width[i]) ** 2 for i in (0, 2)], rtol=1e-6)
    np.testing.assert_allclose([st.p_diag[i] for i in (1, 3)], 10.0 * 1e-10 + 1e-10, rtol=1e-6)


def test_mass_sigma_open_narrows_the_mass_prior_with_no_object_held(pose: Pose) -> None:
    """CKF_M_SIG_OPEN: at the start with the gripper reporting open, and after a release, the mass's variance is at
    most sigma^2 (the UAM's mass, which the model knows); at the start with an object held, or with the gripper's state
    unknown, and at a grasp it is P0's. The inertias keep P0."""
    sig, p0 = 0.2, 1e9 * 1e-10  # P0's sigma 0.32 kg
    data = _excitation(pose, pose.base, 300, seed=7)

    def p_diag_at(closed: list[bool | None], k_stop: int) -> tuple[float, ...]:
        law = _law(r_diag=(1.0,) * 5, q_diag=(1e-10,) * 4, p0_scale=1e9, inc_window=40, grip_reset=True,
                   mass_sigma_open_kg=sig)
        st = None
        for k, (u, acc) in enumerate(data[:k_stop + 1]):
            _, st = law.step(AdaptiveLawInputs(
                t_s=k * DT, u_meas=u, acc_m=acc, gc_uam_inv=pose.gci, inertia_uam=pose.j, mass_uam_kg=pose.m,
                inertia_rate_uam=np.zeros((3, 3)), gripper_closed=closed[k]))
        assert st is not None and st.running and not st.corrected
        return st.p_diag

    start = int(0.5 / DT)  # CKF_START_DLY: the KF starts here (no window closes on this tick, nor on the events')
    opened: list[bool | None] = [False] * 300
    assert p_diag_at(opened, start) == pytest.approx((p0, p0, p0, sig ** 2), rel=1e-6)
    for closed in ([True] * 300, [None] * 300):
        assert p_diag_at(closed, start) == pytest.approx((p0,) * 4, rel=1e-6)
    grasp_release: list[bool | None] = [start + 10 <= k < start + 100 for k in range(300)]
    assert p_diag_at(grasp_release, start + 10)[3] == pytest.approx(p0, rel=1e-6)  # a grasp: P0
    assert p_diag_at(grasp_release, start + 100)[3] == pytest.approx(sig ** 2, rel=1e-6)  # a release: sigma^2


def test_the_low_passed_moment_equals_the_moment_of_the_low_passed_u_at_a_fixed_pose(pose: Pose) -> None:
    """CKF_MOM_LPF: with G_C constant (a fixed arm pose, no h') the low-passed moment's increment is
    G_C[M, :] Delta U_f, so the pitch row reads what it reads without the option (to rounding); the option differs
    only where G_C moves."""
    x_true = pose.base * np.array([1.6, 1.3, 1.8, 1.2])
    ests = []
    for mom in (False, True):
        law = _law(r_diag=(1.0,) * 5, q_diag=(1e-10,) * 4, p0_scale=1e8, pitch_r_nm2=0.01, inc_window=25,
                   lpf_mean_start=True, moment_lpf=mom)
        for k, (u, acc) in enumerate(_excitation(pose, x_true, 1500, seed=2)):
            _, st = law.step(_law_inputs(pose, k * DT, u, acc))
        ests.append(np.array(st.x_hat))
    np.testing.assert_allclose(ests[1], ests[0], rtol=1e-6)
