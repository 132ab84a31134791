"""INDI_ACC_REF: the acceleration of the estimated composite CoM as the INDI/Acc_m reference point, and
the eigenvalue monitor's matrix against the loop actually flown.

- fc_front's correction a_c - (f_O + c-ddot_rel) = omega-dot x c + omega x (omega x c), against numpy's cross
  products with c from the point-mass oracle (UAM + a point object of the estimated mass).
- The flown effectiveness T(p - c) G_I^-1 G_C against a central finite difference of the plant's own dynamics
  (sim_bridge kernels: another implementation of the rigid body) in the actuator positions, for p = O (the
  paper's loop) and p = the true CoM; and the monitor's eigenvalues against those of G_hat G_fd^-1.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from model_oracle import dumbbell_mass_properties

from navig8_fc.core import front_end, g_c
from navig8_fc.core.vehicle import (
    UamModel,
    VehicleConfig,
    actuators_to_u,
    control_effectiveness_gc,
    flown_effectiveness,
    ghat_ginv_eig_record,
    inertia_matrix_gi,
    u_to_actuators,
)
from sim_bridge.params import PlantParams
from sim_bridge.plant import Plant
from sim_bridge.plant_layout import X
from sim_bridge.scenario import load_scenario


@pytest.fixture(scope="module")
def cfg() -> VehicleConfig:
    return VehicleConfig.load()


def _front(model: UamModel, acc_ref: float, gyros, accel, tilt, speed, jpos, mo: float, dt: float):
    """fc_front over the gyro samples (joints still); returns Acc_m and uo after the last."""
    fst, fo, uo = front_end.FST.zeros(), front_end.FO.zeros(), g_c.UO.zeros()
    sens = front_end.TIN.zeros()
    t = front_end.TIN.views(sens)
    t.accel[:], t.tilt[:], t.speed[:], t.jpos[:], t.jrate[:] = accel, tilt, speed, jpos, 0.0
    for gyro in gyros:
        t.gyro[:] = gyro
        bufs = np.empty((3, 3)), np.empty((3, 3)), np.empty((5, 5)), np.empty((5, 5))
        front_end.fc_front(fst, dt, 0.0, 1.0 / dt, sens, mo, model.geometry, model.force_per_input,
                   model.moment_o_per_input, *bufs, uo, fo, acc_ref, 0.0)
    return fo[front_end.FO.ACC_M.sl].copy(), uo.copy()


def test_front_end_reference_point_correction(cfg: VehicleConfig) -> None:
    model = UamModel(cfg)
    rng = np.random.default_rng(4)
    dt = 0.01
    for _ in range(10):
        w0, w1 = rng.normal(size=3), rng.normal(size=3)
        inputs = ((w0, w1), rng.normal(size=3) + [0, 0, -9.8], rng.uniform(0, 1.5, 2), rng.uniform(0, 900, 3),
                  rng.uniform(-1, 1, 3), float(rng.uniform(0, 2)), dt)
        a0, _ = _front(model, 0.0, *inputs)
        a1, uo1 = _front(model, 1.0, *inputs)
        _, c, _, _ = dumbbell_mass_properties(cfg, inputs[4], inputs[5])  # UAM + the point object (estimated mass)
        assert [uo1[g_c.UO.CEX], uo1[g_c.UO.CEZ]] == pytest.approx([c[0], c[2]], abs=1e-12)
        wdot = (w1 - w0) / dt  # the front end's backward difference of the gyro
        corr = np.cross(wdot, c) + np.cross(w1, np.cross(w1, c))
        np.testing.assert_array_equal(a1[:3], a0[:3])
        np.testing.assert_allclose(a1[3:] - a0[3:], corr[[0, 2]], rtol=1e-12, atol=1e-12)


def _plant_at(cfg: VehicleConfig, q_rad, object_kg: float) -> tuple[Plant, np.ndarray]:
    """A noise-free hover plant and its state at rest with the arm at q_rad holding object_kg."""
    plant = Plant(cfg, PlantParams.load().without_noise(), load_scenario("hover"), np.random.default_rng(0))
    x = plant.state_vector.copy()
    x[X.Q.sl] = q_rad
    x[X.QTGT.sl] = q_rad
    x[X.QD.sl] = 0.0
    x[X.MOBJ] = object_kg
    return plant, x


def _acc_at(plant: Plant, x: np.ndarray, u: np.ndarray, p: np.ndarray) -> np.ndarray:
    """[omega-dot, (f_O + omega-dot x p)_x, _z] of the plant at state x with its actuators at U (body at rest, arm
    still)."""
    x = x.copy()
    x[X.ACT.sl] = u_to_actuators(u)
    x[X.ACTD.sl] = 0.0
    tr = plant.truth_at(x)
    a = tr.specific_force_frd_m_s2 + np.cross(tr.ang_accel_frd_rad_s2, p)
    return np.array([*tr.ang_accel_frd_rad_s2, a[0], a[2]])


@pytest.mark.parametrize("pose_deg,object_kg", [((20, 20, 20), 2.0), ((-20, -20, -20), 1.0), ((80, 10, 10), 2.0)])
def test_flown_effectiveness_matches_plant_finite_difference(cfg: VehicleConfig, pose_deg, object_kg) -> None:
    q = np.radians(pose_deg)
    plant, x = _plant_at(cfg, q, object_kg)
    tr = plant.truth_at(x)
    c = np.asarray(tr.com_frd_m)
    gc_true = control_effectiveness_gc(cfg, c)
    gi_true = inertia_matrix_gi(np.asarray(tr.inertia_com_kgm2), tr.mass_kg)
    u0 = actuators_to_u(0.2, -0.1, 650.0, 300.0, 640.0)
    model = UamModel(cfg)
    uam = model.evaluate(q, (0.0, 0.0, 0.0))
    gi_hat = inertia_matrix_gi(uam.inertia_com, uam.mass_kg)  # K = 1
    for p in (np.zeros(3), c, np.array([0.05, 0.0, 0.12])):
        g_fd = np.empty((5, 5))
        for j in range(5):
            h = 1e-3 * max(abs(u0[j]), 1e4)
            e = np.zeros(5)
            e[j] = h
            g_fd[:, j] = (_acc_at(plant, x, u0 + e, p) - _acc_at(plant, x, u0 - e, p)) / (2 * h)
        g_model = flown_effectiveness(gc_true, gi_true, p - c)
        # rounding of the central difference only: the maps are linear in U at rest
        np.testing.assert_allclose(g_model, g_fd, rtol=1e-6, atol=1e-9 * np.abs(g_fd).max())
        # the monitor's eigenvalues are those of G_hat G_fd^-1 (the loop flown with reference point p)
        rec = ghat_ginv_eig_record(model, q, gi_hat.ravel(), c, np.asarray(tr.inertia_com_kgm2), tr.mass_kg,
                                   0.5, 0.1, uam.gc.ravel(), p)
        lam = np.linalg.eigvals(np.linalg.solve(gi_hat, uam.gc) @ np.linalg.inv(g_fd))
        lam = lam[np.lexsort((lam.imag, lam.real))]
        got = np.array(rec["eig_real"]) + 1j * np.array(rec["eig_imag"])
        got = got[np.lexsort((got.imag, got.real))]
        np.testing.assert_allclose(got, lam, rtol=1e-5, atol=1e-6)


def test_reference_point_changes_the_flown_eigenvalues(cfg: VehicleConfig) -> None:
    """The paper's loop (p = O) flies T(-c) G, not G: at +20 deg x 3 with 2 kg its smallest eigenvalue (K = 1)
    differs from the Eq. 14 matrix's; with p = the true CoM the two agree (T = I)."""
    q = [math.radians(20.0)] * 3
    plant, x = _plant_at(cfg, q, 2.0)
    tr = plant.truth_at(x)
    c = np.asarray(tr.com_frd_m)
    model = UamModel(cfg)
    uam = model.evaluate(q, (0.0, 0.0, 0.0))
    gi_hat = inertia_matrix_gi(uam.inertia_com, uam.mass_kg).ravel()
    args = (model, q, gi_hat, c, np.asarray(tr.inertia_com_kgm2), tr.mass_kg, 0.5, 0.1, uam.gc.ravel())
    eq14 = ghat_ginv_eig_record(*args)["eig_real"]
    at_c = ghat_ginv_eig_record(*args, c)["eig_real"]
    at_o = ghat_ginv_eig_record(*args, np.zeros(3))
    np.testing.assert_allclose(at_c, eq14, rtol=1e-9)
    assert np.max(np.abs(np.array(at_o["eig_real"]) - eq14)) > 1e-3 or np.max(np.abs(at_o["eig_imag"])) > 1e-3


def test_stability_analysis_of_the_flown_matrix(cfg: VehicleConfig) -> None:
    """k_bounds_analysis(reference="o") analyses K Xi T^-1, i.e. G_hat (T(O - c) G)^-1 built from the
    finite-difference-checked flown_effectiveness; reference="com" is Eq. 14."""
    from navig8_fc.core import k_xi
    from navig8_fc.core.vehicle import effectiveness_pair, k_matrix, mass_properties

    q = np.radians([[20.0, 20.0, 20.0]])
    k = np.array([0.5, 1.0, 0.5, 1.0])
    r_o = k_xi.k_bounds_analysis(cfg, 0.5, 1.0, poses_rad=q, object_masses_kg=[2.0], n_k=2, reference="o")
    r_c = k_xi.k_bounds_analysis(cfg, 0.5, 1.0, poses_rad=q, object_masses_kg=[2.0], n_k=2, reference="com")
    pair = effectiveness_pair(cfg, q[0], 2.0)
    c = mass_properties(cfg, q[0], 2.0).com_frd_m
    g_hat_inv = np.linalg.solve(k_matrix(k) @ np.linalg.inv(pair.gi_uam) @ pair.gc_uam, np.eye(5))  # (K G_I^-1 G_C)^-1
    g_flown = flown_effectiveness(pair.gc_true, pair.gi_true, -c)
    lam = np.sort(np.linalg.eigvals(np.linalg.inv(g_hat_inv) @ np.linalg.inv(g_flown)).real)
    xi_o = k_xi.xi_batch(cfg, q, np.array([2.0]), "o")[0, 0]
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(k_matrix(k) @ xi_o).real), lam, rtol=1e-9)
    assert r_o.min_eigenvalue != pytest.approx(r_c.min_eigenvalue, abs=1e-3)
    with pytest.raises(ValueError):
        k_xi.xi_batch(cfg, q, np.array([2.0]), "x")
