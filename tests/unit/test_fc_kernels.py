"""The compiled controller kernels (navig8_fc/core: linalg.py, g_c.py, front_end.py, indi.py) against independent
checks: numpy's inverse and solve, the textbook filters of core/filters.py, the vector-form model oracle and finite
differences."""

from __future__ import annotations

import math

import model_oracle as oracle
import numpy as np
import pytest

from navig8_fc.core import front_end, g_c, linalg
from navig8_fc.core.filters import BackwardDifference, LowPass1
from navig8_fc.core.indi import ActuatorLimits, IndiConfig, IndiController, IndiInputs
from navig8_fc.core.vehicle import UamModel, VehicleConfig, estimated_gi

RTOL = 1e-12


def _close(a, b, rtol: float = RTOL, atol: float = 1e-12) -> None:
    np.testing.assert_allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), rtol=rtol, atol=atol)


def test_inverse_matches_numpy() -> None:
    rng = np.random.default_rng(3)
    for n in (2, 4, 5):
        for _ in range(50):
            a = rng.normal(size=(n, n)) * rng.uniform(0.1, 1e4)
            out = np.empty((n, n))
            assert linalg.inv_gauss_jordan(a, out)
            _close(out @ a, np.eye(n), rtol=0.0, atol=1e-9)
            _close(out, np.linalg.inv(a), rtol=1e-8, atol=1e-12 * np.abs(np.linalg.inv(a)).max())
    assert not linalg.inv_gauss_jordan(np.zeros((3, 3)), np.empty((3, 3)))


def test_uam_model_inverse_and_slots(cfg: VehicleConfig) -> None:
    """uam_model's G_C^-1 is numpy's inverse of its G_C; its UO slots are the model's mass, CoM and arm term."""
    model = UamModel(cfg)
    rng = np.random.default_rng(7)
    for _ in range(100):
        q, qd, qdd = rng.uniform(-2, 2, 3), rng.uniform(-3, 3, 3), rng.uniform(-10, 10, 3)
        mo = float(rng.uniform(-0.5, 2.0))
        inertia, rate, gc, gc_inv, uo = (np.empty((3, 3)), np.empty((3, 3)), np.empty((5, 5)), np.empty((5, 5)),
                                         g_c.UO.zeros())
        g_c.uam_model(q, qd, qdd, mo, model.geometry, model.force_per_input, model.moment_o_per_input, inertia, rate,
                    gc, gc_inv, uo)
        _close(gc_inv, np.linalg.inv(gc), rtol=1e-9, atol=1e-12 * np.abs(gc_inv).max())
        m, c, j, _ = oracle.dumbbell_mass_properties(cfg, q)
        assert uo[g_c.UO.SINGULAR] == 0.0
        _close(uo[[g_c.UO.MASS, g_c.UO.CX, g_c.UO.CZ]], [m, c[0], c[2]])
        _close(inertia, j)
        kin = oracle.arm_kinematics(cfg, q, qd, qdd)
        mo = max(mo, 0.0)  # a negative estimate counts as no object
        want = (cfg.link_mass_kg * kin.link_com_acc.sum(axis=0) + mo * kin.tip_acc) / (cfg.uam_mass_kg + mo)
        _close(uo[[g_c.UO.ARM_AX, g_c.UO.ARM_AZ]], want[[0, 2]], atol=1e-9)


@pytest.mark.parametrize("scale", [0.05, 1.0])
def test_indi_filters_and_increment(cfg: VehicleConfig, scale: float) -> None:
    """IndiController (indi_step) against textbook parts: LowPass1 on gyro, specific force x/z and U0 (Sec. 3's U
    from the measured actuators), BackwardDifference of the filtered gyro, and, while unsaturated,
    Delta U = G_C^-1 G_hat_I Delta Acc (Eq. 5) by numpy's solve, U = U0 + Delta U (Eq. 6)."""
    icfg = IndiConfig(0.01, 0.05, ActuatorLimits.from_vehicle(cfg))
    indi = IndiController(icfg)
    gyro_lpf, diff = LowPass1(icfg.lpf_tau_s, icfg.dt_s, 3), BackwardDifference(icfg.dt_s, 3)
    acc_lpf, u0_lpf = LowPass1(icfg.lpf_tau_s, icfg.dt_s, 2), LowPass1(icfg.lpf_tau_s, icfg.dt_s, 5)
    model = UamModel(cfg)
    rng = np.random.default_rng(13)
    n_free = 0
    for i in range(200):
        st = model.evaluate(rng.uniform(-0.5, 0.5, 3), (0.0, 0.0, 0.0))
        gi = estimated_gi(st.inertia_com, np.array([st.inertia_com[0, 0], st.inertia_com[1, 1],
                                                     st.inertia_com[2, 2], st.mass_kg]) * rng.uniform(1, 2))
        a1, a3 = rng.uniform(0.2, 1.2, 2)
        w1, w2, w3 = 800.0 + 50 * rng.normal(), 200 * rng.normal(), 800.0
        inp = IndiInputs(tuple(rng.normal(size=3)), (float(rng.normal()), 0.0, -9.8 + float(rng.normal())),
                         (a1, a3), (w1, w2, w3), tuple(scale * rng.normal(size=5)), st.gc, gi)
        u_meas = [math.cos(a1) * w1**2, math.sin(a1) * w1**2, math.cos(a3) * w3**2, math.sin(a3) * w3**2,
                  math.copysign(w2**2, w2)]
        acc_f = [*diff.step(gyro_lpf.step(inp.gyro_frd_rad_s)),
                 *acc_lpf.step((inp.specific_force_frd_m_s2[0], inp.specific_force_frd_m_s2[2]))]
        u0 = u0_lpf.step(u_meas)
        if i % 50 == 7:
            got_acc, got_u0 = indi.measure(inp)
            _close(got_acc, acc_f)
            _close(got_u0, u0)
            continue
        out, status = indi.step(inp)
        _close(status.acc_filtered, acc_f)
        _close(status.u0_filtered, u0)
        d_acc = np.array(inp.accel_cmd) - acc_f
        _close(status.delta_acc, d_acc)
        if not status.saturated:
            n_free += 1
            du = np.linalg.solve(st.gc, gi @ d_acc)
            _close(status.delta_u, du, rtol=1e-9, atol=1e-6)
            _close(out.u_cmd, np.array(u0) + du, rtol=1e-9, atol=1e-6)
    assert n_free > 50


def _random_spd(rng: np.random.Generator, n: int) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    return (q * 10.0 ** rng.uniform(-2.0, 2.0, n)) @ q.T


def test_front_end_against_textbook_parts(cfg: VehicleConfig) -> None:
    """fc_front against independent parts: the complementary joint observer written here, BackwardDifference on
    q-dot and the gyro, the dumbbell oracle's inertia at q_est, the central difference of the oracle's inertia
    along q-dot for I-dot, Acc_m (Eq. 23) with the oracle's arm term and Sec. 3's U; also after a reset."""
    from navig8_fc.core.controller import JOINT_OBS_TAU_S

    dt = 0.01
    g = dt / (JOINT_OBS_TAU_S + dt)
    model = UamModel(cfg)
    rng = np.random.default_rng(23)
    fst, fo, uo = front_end.FST.zeros(), front_end.FO.zeros(), g_c.UO.zeros()
    for run in range(2):
        fst[:] = 0.0
        q_est = None
        gyro_diff, qd_diff = BackwardDifference(dt, 3), BackwardDifference(dt, 3)
        for _ in range(50):
            sens = front_end.TIN.zeros()
            t = front_end.TIN.views(sens)
            t.gyro[:], t.accel[:] = rng.normal(size=3), rng.normal(size=3) + [0, 0, -9.8]
            t.tilt[:], t.speed[:] = rng.uniform(0, 1.5, 2), rng.uniform(0, 900, 3) * [1, rng.choice([-1, 1]), 1]
            t.jpos[:], t.jrate[:] = rng.uniform(-1, 1, 3), rng.normal(size=3)
            mo = float(rng.uniform(0, 1)) * run
            inertia, rate, gc, gc_inv = np.empty((3, 3)), np.empty((3, 3)), np.empty((5, 5)), np.empty((5, 5))
            front_end.fc_front(fst, dt, g, 1.0 / dt, sens, mo, model.geometry, model.force_per_input,
                       model.moment_o_per_input, inertia, rate, gc, gc_inv, uo, fo, 0.0, 0.0)
            q_meas, qd = t.jpos.tolist(), t.jrate.tolist()
            if q_est is None:
                q_est = q_meas
            else:
                pred = [q_est[i] + dt * qd[i] for i in range(3)]
                q_est = [pred[i] + g * (q_meas[i] - pred[i]) for i in range(3)]
            qdd = qd_diff.step(qd)
            kin = oracle.arm_kinematics(cfg, q_est, qd, qdd)
            arm = (cfg.link_mass_kg * kin.link_com_acc.sum(axis=0) + mo * kin.tip_acc) / (cfg.uam_mass_kg + mo)
            acc_m = [*gyro_diff.step(t.gyro), t.accel[0] + arm[0], t.accel[2] + arm[2]]
            (a1, a3), (w1, w2, w3) = t.tilt.tolist(), t.speed.tolist()
            u = [math.cos(a1) * w1**2, math.sin(a1) * w1**2, math.cos(a3) * w3**2, math.sin(a3) * w3**2,
                 math.copysign(w2**2, w2)]
            f = front_end.FO.views(fo)
            _close(f.qest, q_est)
            _close(f.qdd, qdd)
            _close(f.acc_m, acc_m, atol=1e-9)
            _close(f.u_meas, u)
            _close(inertia, oracle.dumbbell_mass_properties(cfg, q_est)[2])
            h = 1e-6
            fd = (oracle.dumbbell_mass_properties(cfg, np.add(q_est, h * np.array(qd)))[2]
                  - oracle.dumbbell_mass_properties(cfg, np.subtract(q_est, h * np.array(qd)))[2]) / (2 * h)
            _close(rate, fd, rtol=1e-6, atol=1e-7)
            _close(gc_inv @ gc, np.eye(5), rtol=0.0, atol=1e-9)


