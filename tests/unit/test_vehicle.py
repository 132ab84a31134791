"""Vehicle model against independent checks: discretised bodies, finite differences, closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core import vehicle as vm

CFG = vm.VehicleConfig.load()
RNG = np.random.default_rng(7)


def _dumbbell_inertia(q: np.ndarray, m_obj: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Independent composite inertia: every link as two point masses that have the rod's mass,
    CoM and transverse inertia; the object as a point plus its sphere inertia. Returns m, c, J_c."""
    pts: list[tuple[float, np.ndarray]] = []
    theta = 0.0
    joint = np.array(CFG.mount_frd_m, dtype=float)
    d = math.sqrt(CFG.link_inertia_kgm2 / CFG.link_mass_kg)  # 2*(m/2)*d^2 = Ia
    for qi in q:
        theta += qi
        e = np.array([math.sin(theta), 0.0, math.cos(theta)])
        mid = joint + 0.5 * CFG.link_length_m * e
        pts += [(CFG.link_mass_kg / 2, mid + d * e), (CFG.link_mass_kg / 2, mid - d * e)]
        joint = joint + CFG.link_length_m * e
    if m_obj > 0:
        pts.append((m_obj, joint + CFG.object_offset_m * e))
    m = CFG.uav_mass_kg + sum(w for w, _ in pts)
    c = sum((w * r for w, r in pts), np.zeros(3)) / m
    j = CFG.uav_inertia_array + CFG.uav_mass_kg * (c @ c * np.eye(3) - np.outer(c, c))
    for w, r in pts:
        rr = r - c
        j = j + w * (rr @ rr * np.eye(3) - np.outer(rr, rr))
    if m_obj > 0:
        j = j + 0.4 * m_obj * CFG.object_radius_m**2 * np.eye(3)
    return m, c, j


@pytest.mark.parametrize("m_obj", [0.0, 1.0, 2.0])
def test_mass_properties_match_discretised_bodies(m_obj: float) -> None:
    for _ in range(20):
        q = RNG.uniform(-1.6, 1.6, 3)
        mp = vm.mass_properties(CFG, q, m_obj)
        m, c, j = _dumbbell_inertia(q, m_obj)
        assert mp.mass_kg == pytest.approx(m, abs=1e-12)
        np.testing.assert_allclose(mp.com_frd_m, c, atol=1e-12)
        np.testing.assert_allclose(mp.inertia_com, j, atol=1e-12)


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
    h = 1e-6
    for _ in range(20):
        q = RNG.uniform(-1.5, 1.5, 3)
        qd = RNG.uniform(-4, 4, 3)
        jd = vm.inertia_rate(CFG, q, qd, m_obj)
        fd = (vm.mass_properties(CFG, q + h * qd, m_obj).inertia_com
              - vm.mass_properties(CFG, q - h * qd, m_obj).inertia_com) / (2 * h)
        np.testing.assert_allclose(jd, fd, atol=1e-7, rtol=1e-6)


def test_arm_kinematics_derivatives_by_finite_differences() -> None:
    h = 1e-5
    q, qd, qdd = RNG.uniform(-1, 1, 3), RNG.uniform(-4, 4, 3), RNG.uniform(-40, 40, 3)
    k0 = vm.arm_kinematics(CFG, q, qd, qdd)

    def at(t):
        return vm.arm_kinematics(CFG, q + qd * t + 0.5 * qdd * t * t, qd + qdd * t, qdd)

    kp, km = at(h), at(-h)
    np.testing.assert_allclose(k0.link_com_vel, (kp.link_com - km.link_com) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(k0.object_acc, (kp.object_vel - km.object_vel) / (2 * h), atol=1e-5)
    # q = 0 points down, q > 0 swings forward.
    tip = vm.arm_kinematics(CFG, np.zeros(3)).joints[-1]
    np.testing.assert_allclose(tip, np.array(CFG.mount_frd_m) + [0, 0, 0.9], atol=1e-12)
    assert vm.arm_kinematics(CFG, np.radians([30, 0, 0])).joints[-1][0] > 0


def _wrench_from_actuators(a1, a3, w1, w2, w3, ref):
    """Independent propulsion model straight from the duct geometry (notes 2.1)."""
    g = CFG.dihedral_rad
    r1 = np.array(CFG.duct_right_frd_m)
    r3 = r1 * [1, -1, 1]
    r2 = np.array(CFG.tail_frd_m)
    d1 = np.array([math.sin(a1), -math.sin(g) * math.cos(a1), -math.cos(g) * math.cos(a1)])
    d3 = np.array([math.sin(a3), math.sin(g) * math.cos(a3), -math.cos(g) * math.cos(a3)])
    f1 = CFG.k_thrust_duct * w1 * w1 * d1
    f3 = CFG.k_thrust_duct * w3 * w3 * d3
    f2 = -CFG.k_thrust_tail * math.copysign(w2 * w2, w2) * np.array([0, 0, 1.0])
    t1 = -CFG.spin_duct1 * CFG.k_torque_duct * w1 * w1 * d1
    t3 = CFG.spin_duct1 * CFG.k_torque_duct * w3 * w3 * d3
    t2 = CFG.spin_tail * CFG.k_torque_tail * math.copysign(w2 * w2, w2) * np.array([0, 0, 1.0])
    f = f1 + f2 + f3
    m = np.cross(r1 - ref, f1) + np.cross(r3 - ref, f3) + np.cross(r2 - ref, f2) + t1 + t2 + t3
    return f, m


def test_gc_reproduces_the_actuator_wrench() -> None:
    for _ in range(30):
        a1, a3 = RNG.uniform(-1.7, 1.7, 2)
        w1, w3 = RNG.uniform(0, 950, 2)
        w2 = RNG.uniform(-1000, 1000)
        c = vm.mass_properties(CFG, RNG.uniform(-1.5, 1.5, 3), RNG.uniform(0, 2)).com_frd_m
        u = vm.actuators_to_u(a1, a3, w1, w2, w3)
        f, m = _wrench_from_actuators(a1, a3, w1, w2, w3, c)
        want = np.array([m[0], m[1], m[2], f[0], f[2]])
        np.testing.assert_allclose(vm.control_effectiveness_gc(CFG, c) @ u, want, rtol=1e-10, atol=1e-9)
        f2, m2 = vm.propulsion_wrench(CFG, u, c)
        np.testing.assert_allclose(f2, f, atol=1e-9)
        np.testing.assert_allclose(m2, m, atol=1e-9)


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
    f, m_o = _wrench_from_actuators(*a, np.zeros(3))
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


def test_eigenvalues_from_k_and_from_estimate_agree() -> None:
    q = np.radians([60, -60, 60])
    pair = vm.effectiveness_pair(CFG, q, 2.0)
    j = vm.mass_properties(CFG, q).inertia_com
    k = np.array([0.55, 0.8, 0.95, 0.6])
    x = np.array([j[0, 0], j[1, 1], j[2, 2], CFG.uam_mass_kg]) / k
    lam_k = vm.ghat_ginv_eigenvalues(pair, k)
    lam_x = vm.ghat_ginv_eigenvalues_from_estimate(pair, vm.estimated_gi(j, x))
    np.testing.assert_allclose(np.sort_complex(lam_k), np.sort_complex(lam_x), atol=1e-9)


def test_fast_uam_model_matches_reference_functions() -> None:
    um = vm.UamModel(CFG)
    for _ in range(20):
        q, qd, qdd = RNG.uniform(-1.6, 1.6, 3), RNG.uniform(-4, 4, 3), RNG.uniform(-40, 40, 3)
        st = um.evaluate(q, qd, qdd)
        mp = vm.mass_properties(CFG, q)
        np.testing.assert_allclose(st.inertia_com, mp.inertia_com, atol=1e-12)
        np.testing.assert_allclose(st.com_frd_m, mp.com_frd_m, atol=1e-12)
        np.testing.assert_allclose(st.inertia_rate, vm.inertia_rate(CFG, q, qd), atol=1e-12)
        np.testing.assert_allclose(st.gc, vm.control_effectiveness_gc(CFG, mp.com_frd_m), atol=1e-12)
        kin = vm.arm_kinematics(CFG, q, qd, qdd)
        mo = RNG.uniform(0, 2)
        want = (CFG.link_mass_kg * kin.link_com_acc.sum(axis=0) + mo * kin.object_acc) / (CFG.uam_mass_kg + mo)
        np.testing.assert_allclose(um.evaluate(q, qd, qdd, mo).arm_accel_xz, want[[0, 2]], atol=1e-12)


def test_fast_gc_about_is_row_arithmetic_of_the_reference_wrench() -> None:
    """UamModel.gc_about (plain floats) equals the numpy row form M_c = M_O - c x F bit for bit."""
    um = vm.UamModel(CFG)
    f, m0 = vm._force_moment_per_input(CFG, np.zeros(3))
    for _ in range(20):
        cx, cz = RNG.uniform(-0.1, 0.1, 2)
        want = np.vstack([m0[0] + cz * f[1], m0[1] - (cz * f[0] - cx * f[2]), m0[2] - cx * f[1], f[0], f[2]])
        assert np.array_equal(um.gc_about(cx, cz), want)


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


def test_eig_record_kernel_matches_numpy_reference_incl_complex_pairs() -> None:
    # The compiled record (numba, complex LAPACK) against the numpy reference, over random poses, objects,
    # estimates and G_C given or evaluated; random estimates far from the truth give complex pairs too.
    rng = np.random.default_rng(11)
    um = vm.UamModel(CFG)
    n_complex = 0
    for _ in range(60):
        q = rng.uniform(-1.2, 1.2, 3)
        mo = float(rng.uniform(0.0, 2.0))
        true = vm.mass_properties(CFG, q, mo)
        gi_hat = rng.uniform(0.05, 3.0, (5, 5)) * 0.2 + np.diag(rng.uniform(0.2, 10.0, 5))
        gc = um.evaluate(q, (0.0, 0.0, 0.0)).gc.ravel() if rng.random() < 0.5 else None
        args = (um, q, gi_hat.ravel(), true.com_frd_m, true.inertia_com, true.mass_kg, 0.5, 0.1, gc)
        got, want = vm.ghat_ginv_eig_record(*args), vm.ghat_ginv_eig_record(*args, compiled=False)
        lg = np.array(got["eig_real"]) + 1j * np.array(got["eig_imag"])
        lw = np.array(want["eig_real"]) + 1j * np.array(want["eig_imag"])
        n_complex += int(np.any(np.abs(lw.imag) > 1e-9))
        # Same multiset of eigenvalues (order-free: the characteristic polynomials agree), same sort by real part.
        np.testing.assert_allclose(np.poly(lg), np.poly(lw), rtol=1e-8, atol=1e-8)
        np.testing.assert_allclose(np.sort(lg.real), np.sort(lw.real), rtol=1e-9, atol=1e-9)
        assert list(lg.real) == sorted(lg.real)
        assert got["true_inertia_mass"] == want["true_inertia_mass"]
    assert n_complex >= 2, "the check never met a complex pair"
