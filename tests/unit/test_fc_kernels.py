"""The compiled controller kernels (navig8_fc/core/_kernels.py) against their plain-Python references."""

from __future__ import annotations

import numpy as np
import pytest

from navig8_fc.core import _kernels as k
from navig8_fc.core.indi import (
    ActuatorLimits,
    IndiConfig,
    IndiController,
    IndiControllerReference,
    IndiInputs,
)
from navig8_fc.core.outer_loop import (
    OuterLoopConfig,
    Setpoint,
    outer_loop_config_array,
    outer_loop_step,
    outer_loop_step_compiled,
)
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
            assert k.inv_gauss_jordan(a, out)
            _close(out @ a, np.eye(n), rtol=0.0, atol=1e-9)
            _close(out, np.linalg.inv(a), rtol=1e-8, atol=1e-12 * np.abs(np.linalg.inv(a)).max())
    assert not k.inv_gauss_jordan(np.zeros((3, 3)), np.empty((3, 3)))


def test_uam_model_matches_reference(cfg: VehicleConfig) -> None:
    model = UamModel(cfg)
    jb = model._jb
    geo = np.array([cfg.link_length_m, cfg.link_mass_kg, cfg.link_inertia_kgm2, cfg.mount_frd_m[0],
                    cfg.mount_frd_m[2], cfg.uam_mass_kg, jb[0], jb[1], jb[2], jb[3]])
    rng = np.random.default_rng(7)
    for _ in range(100):
        q, qd, qdd = rng.uniform(-2, 2, 3), rng.uniform(-3, 3, 3), rng.uniform(-10, 10, 3)
        mo = float(rng.uniform(-0.5, 2.0))
        ref = model.evaluate(q, qd, qdd, mo)
        inertia, rate, gc, gc_inv, uo = (np.empty((3, 3)), np.empty((3, 3)), np.empty((5, 5)), np.empty((5, 5)),
                                         np.empty(k.N_UO))
        k.uam_model(q, qd, qdd, mo, geo, model._f, model._m0, inertia, rate, gc, gc_inv, uo)
        _close(inertia, ref.inertia_com)
        _close(rate, ref.inertia_rate)
        _close(gc, ref.gc)
        _close(gc_inv, np.linalg.inv(ref.gc), rtol=1e-9, atol=1e-12 * np.abs(gc_inv).max())
        assert uo[k.UO_MASS] == ref.mass_kg and uo[k.UO_SINGULAR] == 0.0
        _close(uo[[k.UO_CX, k.UO_CZ]], ref.com_frd_m[[0, 2]])
        _close(uo[[k.UO_ARM_AX, k.UO_ARM_AZ]], ref.arm_accel_xz)


def test_outer_loop_matches_reference() -> None:
    cfg = OuterLoopConfig(1.0, 2.0, 2.0, 5.0, 6.0, 10.0, 3.0, 9.81)
    arr = outer_loop_config_array(cfg)
    rng = np.random.default_rng(5)
    for _ in range(200):
        sp = Setpoint(tuple(rng.uniform(-5, 5, 3)), float(rng.uniform(-1, 1)), float(rng.uniform(-3, 3)))
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        args = (tuple(rng.uniform(-5, 5, 3)), tuple(rng.uniform(-3, 3, 3)), tuple(quat), tuple(rng.normal(size=3)))
        ref = outer_loop_step(cfg, sp, *args)
        got = outer_loop_step_compiled(arr, sp, *args)
        for name in ref.__dataclass_fields__:
            a, b = getattr(got, name), getattr(ref, name)
            assert isinstance(a, type(b))
            _close(a, b, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("scale", [1.0, 40.0])  # 40: large commands drive the saturation handling
def test_indi_matches_reference(cfg: VehicleConfig, scale: float) -> None:
    icfg = IndiConfig(0.01, 0.05, ActuatorLimits.from_vehicle(cfg))
    fast, ref = IndiController(icfg), IndiControllerReference(icfg)
    model = UamModel(cfg)
    rng = np.random.default_rng(13)
    saturated = 0
    for i in range(300):
        st = model.evaluate(rng.uniform(-0.5, 0.5, 3), (0.0, 0.0, 0.0))
        gi = estimated_gi(st.inertia_com, np.array([st.inertia_com[0, 0], st.inertia_com[1, 1],
                                                     st.inertia_com[2, 2], st.mass_kg]) * rng.uniform(1, 2))
        inp = IndiInputs(tuple(rng.normal(size=3)), (float(rng.normal()), 0.0, -9.8 + float(rng.normal())),
                         tuple(rng.uniform(0.2, 1.2, 2)), (800.0 + 50 * rng.normal(), 200 * rng.normal(), 800.0),
                         tuple(scale * rng.normal(size=5)), st.gc, gi, np.linalg.inv(st.gc))
        if i % 50 == 7:
            _close(fast.measure(inp), ref.measure(inp))
            continue
        (o1, s1), (o2, s2) = fast.step(inp), ref.step(inp)
        _close(o1.u_cmd, o2.u_cmd, rtol=1e-9, atol=1e-6)
        _close(o1.tilt_cmd_rad + o1.speed_cmd_rad_s, o2.tilt_cmd_rad + o2.speed_cmd_rad_s, rtol=1e-9, atol=1e-9)
        for name in ("acc_filtered", "u0_filtered", "delta_acc", "delta_u", "saturation_scale"):
            _close(getattr(s1, name), getattr(s2, name), rtol=1e-9, atol=1e-6)
        assert (s1.saturated, s1.fallback_to_u0) == (s2.saturated, s2.fallback_to_u0)
        saturated += s1.saturated
    if scale > 1.0:
        assert saturated > 10
    fast.reset()
    ref.reset()
    inp = IndiInputs((0.1, 0.2, 0.3), (0.0, 0.0, -9.8), (0.5, 0.5), (700.0, 10.0, 700.0), (0.0,) * 5,
                     st.gc, gi, np.linalg.inv(st.gc))
    _close(fast.step(inp)[1].acc_filtered, ref.step(inp)[1].acc_filtered)


def test_front_end_matches_reference(cfg: VehicleConfig) -> None:
    """fc_front against the Python front end it replaced: complementary joint observer, BackwardDifference
    on q-dot and the gyro, UamModel.evaluate, Acc_m (Eq. 23) and actuators_to_u_list; also after a reset."""
    from navig8_fc.core.controller import JOINT_OBS_TAU_S
    from navig8_fc.core.filters import BackwardDifference
    from navig8_fc.core.indi import actuators_to_u_list

    dt = 0.01
    g = dt / (JOINT_OBS_TAU_S + dt)
    model = UamModel(cfg)
    jb = model._jb
    geo = np.array([cfg.link_length_m, cfg.link_mass_kg, cfg.link_inertia_kgm2, cfg.mount_frd_m[0],
                    cfg.mount_frd_m[2], cfg.uam_mass_kg, jb[0], jb[1], jb[2], jb[3]])
    rng = np.random.default_rng(23)
    fst, fo, uo = np.zeros(k.N_FST), np.zeros(k.N_FO), np.zeros(k.N_UO)
    for run in range(2):
        fst[:] = 0.0
        q_est = None
        gyro_diff, qd_diff = BackwardDifference(dt, 3), BackwardDifference(dt, 3)
        for _ in range(50):
            sens = np.concatenate([rng.normal(size=3), rng.normal(size=3) + [0, 0, -9.8], rng.uniform(0, 1.5, 2),
                                   rng.uniform(0, 900, 3) * [1, rng.choice([-1, 1]), 1], rng.uniform(-1, 1, 3),
                                   rng.normal(size=3)])
            mo = float(rng.uniform(0, 1)) * run
            inertia, rate, gc, gc_inv = np.empty((3, 3)), np.empty((3, 3)), np.empty((5, 5)), np.empty((5, 5))
            k.fc_front(fst, dt, g, 1.0 / dt, sens, mo, geo, model._f, model._m0, inertia, rate, gc, gc_inv, uo, fo)
            s = sens.tolist()
            q_meas, qd = s[11:14], s[14:17]
            if q_est is None:
                q_est = q_meas
            else:
                pred = [q_est[i] + dt * qd[i] for i in range(3)]
                q_est = [pred[i] + g * (q_meas[i] - pred[i]) for i in range(3)]
            qdd = qd_diff.step(qd)
            ref = model.evaluate(q_est, qd, qdd, mo)
            wdot = gyro_diff.step(s[0:3])
            acc_m = [*wdot, s[3] + ref.arm_accel_xz[0], s[5] + ref.arm_accel_xz[1]]
            _close(fo[k.FO_QEST:k.FO_QEST + 3], q_est)
            _close(fo[k.FO_QDD:k.FO_QDD + 3], qdd)
            _close(fo[k.FO_ACC_M:k.FO_ACC_M + 5], acc_m)
            _close(fo[k.FO_U_MEAS:k.FO_U_MEAS + 5], actuators_to_u_list(*s[6:11]))
            _close(inertia, ref.inertia_com)
            _close(rate, ref.inertia_rate)
            _close(gc, ref.gc)
            _close(gc_inv @ gc, np.eye(5), rtol=0.0, atol=1e-9)
