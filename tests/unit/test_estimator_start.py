"""The identification preset's pieces of the adaptive law (docs/model.md, "Estimator" items 8-9): the running-mean
start of the law's low-passes (CKF_LPF_SEED), the delivered U (CKF_U_SRC 2, actuator_model.DeliveredU) and the
modelled product of inertia (CKF_IXZ_MOD)."""

from __future__ import annotations

import math

import numpy as np

from navig8_fc.core.actuator_model import DeliveredU
from navig8_fc.core.adaptive_law import LAW_OUT, LAW_STATE, LS_AF, LS_UF, known_ixz, lpf_increments
from navig8_fc.core.kalman import measurement_matrix
from navig8_fc.core.vehicle import actuators_to_u


def test_the_running_mean_start_is_the_mean_then_the_low_pass() -> None:
    rng = np.random.default_rng(3)
    alpha = 0.0142
    st, st0, out = LAW_STATE.zeros(), LAW_STATE.zeros(), LAW_OUT.zeros()
    xs = rng.normal(size=(200, 5))
    for k, x in enumerate(xs):
        lpf_increments(st, alpha, 25.0, x, -x, 0.0, 0.0, 0.0, out, 1.0)
        lpf_increments(st0, alpha, 25.0, x, -x, 0.0, 0.0, 0.0, out, 0.0)
        if k + 1 <= 1.0 / alpha:  # the mean of the samples so far
            np.testing.assert_allclose(st[LS_UF:LS_UF + 5], xs[:k + 1].mean(axis=0), atol=1e-12)
            np.testing.assert_allclose(st[LS_AF:LS_AF + 5], -xs[:k + 1].mean(axis=0), atol=1e-12)
    # then the plain low-pass: from the same state both give the same next value
    st0[:] = st
    x = rng.normal(size=5)
    lpf_increments(st, alpha, 25.0, x, x, 0.0, 0.0, 0.0, out, 1.0)
    lpf_increments(st0, alpha, 25.0, x, x, 0.0, 0.0, 0.0, out, 0.0)
    np.testing.assert_array_equal(st, st0)


def test_the_delivered_u_lags_the_command_in_actuator_space() -> None:
    d = DeliveredU(120.0, 1.0, 0.01)
    u = np.zeros(5)
    tilt, speed = (0.1, -0.05), (600.0, 200.0, 610.0)
    d.step(tilt, speed, u, True)
    np.testing.assert_allclose(u, actuators_to_u(*tilt, *speed), rtol=1e-12)  # seeded at rest on the command
    speed2 = (700.0, 200.0, 610.0)
    d.step(tilt, speed2, u, False)
    w1 = math.sqrt(u[0] ** 2 + u[1] ** 2)
    assert 600.0 ** 2 < w1 < 700.0 ** 2  # one period into the step: on its way
    for _ in range(100):
        d.step(tilt, speed2, u, False)
    np.testing.assert_allclose(u, actuators_to_u(*tilt, *speed2), rtol=1e-9)
    d.step(tilt, speed, u, True)  # seeded again
    np.testing.assert_allclose(u, actuators_to_u(*tilt, *speed), rtol=1e-12)


def test_the_modelled_ixz_leaves_i_xx_and_i_zz_alone_in_their_rows() -> None:
    rng = np.random.default_rng(5)
    gc_inv = rng.normal(size=(5, 5)) + 3.0 * np.eye(5)
    ixx, iyy, izz, ixz, m = 0.32, 0.87, 0.67, -0.357, 7.0
    gi = np.array([[ixx, 0, ixz, 0, 0], [0, iyy, 0, 0, 0], [ixz, 0, izz, 0, 0], [0, 0, 0, m, 0], [0, 0, 0, 0, m]])
    da = rng.normal(size=5)
    du = gc_inv @ gi @ da  # Eq. 23 with the true I_xz
    z = known_ixz(du, gc_inv, tuple(da), ixz)
    h = measurement_matrix(gc_inv, da, 0.0, 0.0)  # rho_x = rho_z = 0: I_xx, I_zz on their own axes
    np.testing.assert_allclose(h @ np.array([ixx, iyy, izz, m]), z, atol=1e-12)
