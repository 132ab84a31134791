"""Vehicle model against independent checks: discretised bodies, finite differences, closed forms."""

from __future__ import annotations

import dataclasses

import model_oracle as oracle  # noqa: E402 - tests/unit on sys.path (pytest rootdir-relative import)
import numpy as np
import pytest
import scipy.linalg

from navig8_fc.core import vehicle as vm

CFG = vm.VehicleConfig.load()
RNG = np.random.default_rng(7)


@pytest.mark.parametrize("m_obj", [0.0, 1.0, 2.0])
def test_mass_properties_match_discretised_bodies(m_obj: float) -> None:
    # Every rod as a dumbbell with its mass, centre and transverse inertia: the same bodies, exactly (1e-12).
    for _ in range(20):
        q = RNG.uniform(-1.6, 1.6, 3)
        mp = vm.mass_properties(CFG, q, m_obj)
        m, c, j, j_o = oracle.dumbbell_mass_properties(CFG, q, m_obj)
        assert mp.mass_kg == pytest.approx(m, abs=1e-12)
        np.testing.assert_allclose(mp.com_frd_m, c, atol=1e-12)
        np.testing.assert_allclose(mp.inertia_com, j, atol=1e-12)
        np.testing.assert_allclose(mp.inertia_o, j_o, atol=1e-12)


@pytest.mark.parametrize("n", [10, 100])
def test_inertia_converges_to_point_mass_rods(n: int) -> None:
    # A uniform rod (Ia = m L^2 / 12, Table 1's 0.0037 rounds 0.00375) as n point masses: each entry of the
    # inertia differs from the model by at most the discretisation error of 3 links, 3 m L^2 / (12 n^2).
    cfg = dataclasses.replace(CFG, link_inertia_kgm2=CFG.link_mass_kg * CFG.link_length_m**2 / 12.0)
    tol = 3.0 * CFG.link_mass_kg * CFG.link_length_m**2 / (12.0 * n * n)
    for _ in range(10):
        q, m_obj = RNG.uniform(-1.6, 1.6, 3), float(RNG.uniform(0.0, 2.0))
        mp = vm.mass_properties(cfg, q, m_obj)
        m, c, j, _ = oracle.rod_mass_properties(cfg, q, m_obj, n)
        assert mp.mass_kg == pytest.approx(m, abs=1e-12)
        np.testing.assert_allclose(mp.com_frd_m, c, atol=1e-12)  # symmetric rows: the centre is exact
        err = np.abs(mp.inertia_com - j).max()
        assert 0.1 * tol <= err <= tol + 1e-12  # converges as 1/n^2 (J_yy gets all 3 links), not exact by accident


def test_inertia_symmetry_and_physical_validity() -> None:
    for _ in range(50):
        q = RNG.uniform(-1.7, 1.7, 3)
        j = vm.mass_properties(CFG, q, RNG.uniform(0, 2)).inertia_com
        np.testing.assert_allclose(j, j.T, atol=1e-14)
        assert j[0, 1] == 0.0 and j[1, 2] == 0.0  # x-z plane symmetry
        p = np.linalg.eigvalsh(j)
        assert p.min() > 0
        assert p[0] + p[1] >= p[2] - 1e-12  # triangle inequality of principal moments


def test_known_values_from_notes() -> None:
    # notes 3.2: q = 0, UAM 0.517/0.599/0.202; stretched 80/10/10 with 2 kg: 0.097/1.458/1.482
    j = vm.mass_properties(CFG, np.zeros(3)).inertia_com
    np.testing.assert_allclose(np.diag(j), [0.517, 0.599, 0.202], atol=1e-3)
    j = vm.mass_properties(CFG, np.radians([80, 10, 10]), 2.0).inertia_com
    np.testing.assert_allclose(np.diag(j), [0.097, 1.458, 1.482], atol=1e-3)


@pytest.mark.parametrize("m_obj", [0.0, 2.0])
def test_inertia_rate_matches_finite_differences(m_obj: float) -> None:
    # Along a joint trajectory q(t) = q0 + qd t + qdd t^2 / 2: I-dot(t) against the central difference of the
    # inertia (vehicle.inertia_rate and UamModel.evaluate's, the controller's view without object).
    h = 1e-6
    um = vm.UamModel(CFG)
    for _ in range(20):
        q0, qd0, qdd = RNG.uniform(-1.5, 1.5, 3), RNG.uniform(-4, 4, 3), RNG.uniform(-40, 40, 3)
        t = float(RNG.uniform(0.0, 0.1))

        def q_at(tt: float, q0=q0, qd0=qd0, qdd=qdd) -> np.ndarray:
            return q0 + qd0 * tt + 0.5 * qdd * tt * tt

        qd = qd0 + qdd * t
        fd = (vm.mass_properties(CFG, q_at(t + h), m_obj).inertia_com
              - vm.mass_properties(CFG, q_at(t - h), m_obj).inertia_com) / (2 * h)
        np.testing.assert_allclose(vm.inertia_rate(CFG, q_at(t), qd, m_obj), fd, atol=1e-7, rtol=1e-6)
        if m_obj == 0.0:
            np.testing.assert_allclose(um.evaluate(q_at(t), qd, qdd).inertia_rate, fd, atol=1e-7, rtol=1e-6)


def test_oracle_arm_kinematics_derivatives_by_finite_differences() -> None:
    # The oracle's own check: its velocities and accelerations are the derivatives of its positions.
    h = 1e-5
    q, qd, qdd = RNG.uniform(-1, 1, 3), RNG.uniform(-4, 4, 3), RNG.uniform(-40, 40, 3)
    k0 = oracle.arm_kinematics(CFG, q, qd, qdd)

    def at(t):
        return oracle.arm_kinematics(CFG, q + qd * t + 0.5 * qdd * t * t, qd + qdd * t, qdd)

    kp, km = at(h), at(-h)
    np.testing.assert_allclose(k0.link_com_vel, (kp.link_com - km.link_com) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(k0.object_acc, (kp.object_vel - km.object_vel) / (2 * h), atol=1e-5)
    # q = 0 points down, q > 0 swings forward.
    np.testing.assert_allclose(k0.tip_acc, (kp.joints[-1] - 2 * k0.joints[-1] + km.joints[-1]) / h**2, atol=1e-3)
    tip = oracle.arm_kinematics(CFG, np.zeros(3)).joints[-1]
    np.testing.assert_allclose(tip, np.array(CFG.mount_frd_m) + [0, 0, 0.9], atol=1e-12)
    assert oracle.arm_kinematics(CFG, np.radians([30, 0, 0])).joints[-1][0] > 0


def test_gc_reproduces_the_actuator_wrench() -> None:
    um = vm.UamModel(CFG)
    for _ in range(30):
        a1, a3 = RNG.uniform(-1.7, 1.7, 2)
        w1, w3 = RNG.uniform(0, 950, 2)
        w2 = RNG.uniform(-1000, 1000)
        c = vm.mass_properties(CFG, RNG.uniform(-1.5, 1.5, 3), RNG.uniform(0, 2)).com_frd_m
        u = vm.actuators_to_u(a1, a3, w1, w2, w3)
        f, m = oracle.wrench_from_actuators(CFG, a1, a3, w1, w2, w3, c)
        want = np.array([m[0], m[1], m[2], f[0], f[2]])
        np.testing.assert_allclose(vm.control_effectiveness_gc(CFG, c) @ u, want, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(um.gc_about(c[0], c[2]) @ u, want, rtol=1e-10, atol=1e-9)
        f2, m2 = vm.propulsion_wrench(CFG, u, c)
        np.testing.assert_allclose(f2, f, atol=1e-9)
        np.testing.assert_allclose(m2, m, atol=1e-9)


def test_gc_is_the_derivative_of_the_wrench_in_u() -> None:
    # G_C's column k = d[M_c, F_x, F_z]/dU_k: central differences of the geometric wrench (U -> actuators ->
    # duct forces), at random U and CoM. The wrench is linear in U, so the difference is exact up to rounding.
    h = 50.0  # rad^2/s^2, against |U| ~ 1e5
    for _ in range(10):
        c = vm.mass_properties(CFG, RNG.uniform(-1.5, 1.5, 3), RNG.uniform(0, 2)).com_frd_m
        u = vm.actuators_to_u(*RNG.uniform(-1.0, 1.0, 2), *RNG.uniform(300, 900, 1), RNG.uniform(-500, 500),
                              *RNG.uniform(300, 900, 1))

        def wrench(uu: np.ndarray, c=c) -> np.ndarray:
            f, m = oracle.wrench_from_actuators(CFG, *vm.u_to_actuators(uu), c)
            return np.array([m[0], m[1], m[2], f[0], f[2]])

        fd = np.column_stack([(wrench(u + h * e) - wrench(u - h * e)) / (2 * h) for e in np.eye(5)])
        gc = vm.control_effectiveness_gc(CFG, c)
        np.testing.assert_allclose(gc, fd, rtol=1e-7, atol=1e-9 * np.abs(gc).max())


def test_gc_longitudinal_determinant_is_independent_of_com() -> None:
    # notes 2.3: det of the [M, Fx, Fz] x [Us, Ws, U5] block does not depend on the CoM, and G_C is
    # invertible over the whole workspace.
    conds = []
    for q1 in np.radians(np.arange(-90, 91, 15)):
        for q2 in np.radians([-90, -45, 0, 45, 90]):
            for q3 in np.radians([-90, 0, 90]):
                for m_obj in (0.0, 2.0):
                    gc = vm.control_effectiveness_gc(CFG, vm.mass_properties(CFG, [q1, q2, q3], m_obj).com_frd_m)
                    conds.append(np.linalg.cond(gc))
    assert max(conds) < 1e3, max(conds)


def test_u_actuator_round_trip() -> None:
    for _ in range(50):
        a = (RNG.uniform(-3, 3), RNG.uniform(-3, 3), RNG.uniform(1, 950), RNG.uniform(-1000, 1000),
             RNG.uniform(1, 950))
        back = vm.u_to_actuators(vm.actuators_to_u(*a))
        np.testing.assert_allclose(back, a, rtol=1e-9)


@pytest.mark.parametrize("q_deg, m_obj", [((0, 0, 0), 1.0), ((20, 20, 20), 2.0), ((-20, -20, -20), 2.0)])
def test_hover_trim_balances_gravity_about_the_true_com(q_deg, m_obj) -> None:
    q = np.radians(q_deg)
    mp = vm.mass_properties(CFG, q, m_obj)
    a = vm.u_to_actuators(vm.hover_trim(CFG, q, m_obj))
    f, m_o = oracle.wrench_from_actuators(CFG, *a, np.zeros(3))
    m_c = m_o - np.cross(mp.com_frd_m, f)
    np.testing.assert_allclose(m_c, 0, atol=1e-9)
    np.testing.assert_allclose(f[[0, 2]], [0, -mp.mass_kg * CFG.gravity_m_s2], atol=1e-9)
    # Fy is not in G_C: the dihedral side forces cancel up to the small differential thrust that
    # balances the tail's drag torque (< 0.1 % of the weight; the outer loop's roll absorbs it).
    assert abs(f[1]) < 1e-3 * mp.mass_kg * CFG.gravity_m_s2
    assert CFG.duct_speed_min <= a[2] <= CFG.duct_speed_max and CFG.tail_speed_min <= a[3] <= CFG.tail_speed_max


def test_estimated_gi_structure() -> None:
    j = vm.mass_properties(CFG, np.radians([20, -10, 30])).inertia_com
    m = CFG.uam_mass_kg
    k = np.array([0.6, 0.7, 0.8, 0.9])
    x = np.array([j[0, 0], j[1, 1], j[2, 2], m]) / k
    gi_hat = vm.estimated_gi(j, x)
    # Eq. 4: G_hat_I = G_I,UAM K^-1 (columns scaled), so G_hat_I K = G_I,UAM.
    np.testing.assert_allclose(gi_hat @ vm.k_matrix(k), vm.inertia_matrix_gi(j, m), atol=1e-12)
    np.testing.assert_allclose(vm.k_from_estimate(j, m, x), k)
    lo, hi = vm.estimate_bounds(j, m, 0.5, 1.0)
    np.testing.assert_allclose(lo, [j[0, 0], j[1, 1], j[2, 2], m])
    np.testing.assert_allclose(hi, 2 * lo)


def test_uam_model_against_the_oracle() -> None:
    # UamModel.evaluate (the controller's kernel): mass properties of the UAM without object (dumbbell oracle),
    # G_C about its CoM (geometric wrench) and the arm's CoM acceleration with a point object of the estimated
    # mass at the tip: sum_k m_k r''_k / m over the links plus the object (vector-form kinematics).
    um = vm.UamModel(CFG)
    for _ in range(20):
        q, qd, qdd = RNG.uniform(-1.6, 1.6, 3), RNG.uniform(-4, 4, 3), RNG.uniform(-40, 40, 3)
        mo = float(RNG.uniform(0, 2))
        st = um.evaluate(q, qd, qdd, mo)
        m, c, j, _ = oracle.dumbbell_mass_properties(CFG, q)
        assert st.mass_kg == pytest.approx(m, abs=1e-12)
        np.testing.assert_allclose(st.com_frd_m, c, atol=1e-12)
        np.testing.assert_allclose(st.inertia_com, j, atol=1e-12)
        u = RNG.uniform(-1e5, 1e5, 5)
        f, mom = oracle.wrench_from_actuators(CFG, *vm.u_to_actuators(u), c)
        np.testing.assert_allclose(st.gc @ u, [mom[0], mom[1], mom[2], f[0], f[2]], rtol=1e-9, atol=1e-6)
        kin = oracle.arm_kinematics(CFG, q, qd, qdd)
        want = (CFG.link_mass_kg * kin.link_com_acc.sum(axis=0) + mo * kin.tip_acc) / (CFG.uam_mass_kg + mo)
        np.testing.assert_allclose(st.arm_accel_xz, want[[0, 2]], atol=1e-12)


def test_eig_record_matches_k_xi_eigenvalues() -> None:
    # With G_hat_I = G_I,UAM K^-1 the record's eigenvalues are those of K Xi (Eq. 14).
    q = np.radians([20, -30, 40])
    k = np.array([0.6, 0.9, 0.7, 0.8])
    um = vm.UamModel(CFG)
    j = vm.mass_properties(CFG, q).inertia_com
    x = np.array([j[0, 0], j[1, 1], j[2, 2], CFG.uam_mass_kg]) / k
    true = vm.mass_properties(CFG, q, 1.5)
    rec = vm.ghat_ginv_eig_record(um, q, vm.estimated_gi(j, x).ravel(), true.com_frd_m, true.inertia_com,
                                  true.mass_kg, 0.5, 0.1)
    want = vm.ghat_ginv_eigenvalues(vm.effectiveness_pair(CFG, q, 1.5), k)
    np.testing.assert_allclose(np.sort(rec["eig_real"]), np.sort(want.real), atol=1e-9)
    assert rec["true_inertia_mass"][3] == pytest.approx(true.mass_kg)


def test_eig_record_matches_scipy_eig_incl_complex_pairs() -> None:
    # The record's eigenvalues (numba kernel, real LAPACK path and complex fallback) against scipy.linalg.eigvals of
    # (G_hat_I^-1 G_C,UAM)(G_C,true^-1 G_I,true) formed here with numpy, over random poses, objects, estimates and
    # G_C given or evaluated; random estimates far from the truth give complex pairs too.
    rng = np.random.default_rng(11)
    um = vm.UamModel(CFG)
    n_complex = 0
    for _ in range(60):
        q = rng.uniform(-1.2, 1.2, 3)
        mo = float(rng.uniform(0.0, 2.0))
        true = vm.mass_properties(CFG, q, mo)
        gi_hat = rng.uniform(0.05, 3.0, (5, 5)) * 0.2 + np.diag(rng.uniform(0.2, 10.0, 5))
        gc_uam = vm.control_effectiveness_gc(CFG, vm.mass_properties(CFG, q).com_frd_m)
        given = gc_uam.ravel() if rng.random() < 0.5 else None
        got = vm.ghat_ginv_eig_record(um, q, gi_hat.ravel(), true.com_frd_m, true.inertia_com, true.mass_kg, 0.5,
                                      0.1, given)
        gi_true = vm.inertia_matrix_gi(true.inertia_com, true.mass_kg)
        gc_true = vm.control_effectiveness_gc(CFG, true.com_frd_m)
        lw = scipy.linalg.eigvals(np.linalg.solve(gi_hat, gc_uam) @ np.linalg.solve(gc_true, gi_true))
        lg = np.array(got["eig_real"]) + 1j * np.array(got["eig_imag"])
        n_complex += int(np.any(np.abs(lw.imag) > 1e-9))
        # Same multiset of eigenvalues (order-free: the characteristic polynomials agree), sorted by real part.
        np.testing.assert_allclose(np.poly(lg), np.poly(lw), rtol=1e-8, atol=1e-8)
        np.testing.assert_allclose(np.sort(lg.real), np.sort(lw.real), rtol=1e-9, atol=1e-9)
        assert list(lg.real) == sorted(lg.real)
        assert got["true_inertia_mass"] == [gi_true[0, 0], gi_true[1, 1], gi_true[2, 2], true.mass_kg]
    assert n_complex >= 2, "the check never met a complex pair"
