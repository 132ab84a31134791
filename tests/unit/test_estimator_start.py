"""The identification preset's pieces of the adaptive law (docs/model.md, "Estimator" items 8-9): the running-mean
start of the law's low-passes (CKF_LPF_SEED), the delivered U (CKF_U_SRC 2, actuator_model.DeliveredU) and the
modelled product of inertia (CKF_IXZ_MOD)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core.actuator_model import DeliveredU
from navig8_fc.core.adaptive_law import ixz_mass_column, known_ixz
from navig8_fc.core.ckf_config import CkfConfig, CkfMode
from navig8_fc.core.kalman import ConstrainedKalmanFilter, measurement_matrix
from navig8_fc.core.law_filters import LAW_OUT, LAW_STATE, LS_AF, LS_UF, lpf_increments
from navig8_fc.core.vehicle import actuators_to_u

Z3 = np.zeros(3)  # no gyroscopic moment (CKF_GYRO off)


def test_the_running_mean_start_is_the_mean_then_the_low_pass() -> None:
    rng = np.random.default_rng(3)
    alpha = 0.0142
    st, st0, out = LAW_STATE.zeros(), LAW_STATE.zeros(), LAW_OUT.zeros()
    xs = rng.normal(size=(200, 5))
    for k, x in enumerate(xs):
        lpf_increments(st, alpha, 25.0, x, -x, 0.0, Z3, 0.0, 0.0, out, 1.0)
        lpf_increments(st0, alpha, 25.0, x, -x, 0.0, Z3, 0.0, 0.0, out, 0.0)
        if k + 1 <= 1.0 / alpha:  # the mean of the samples so far
            np.testing.assert_allclose(st[LS_UF:LS_UF + 5], xs[:k + 1].mean(axis=0), atol=1e-12)
            np.testing.assert_allclose(st[LS_AF:LS_AF + 5], -xs[:k + 1].mean(axis=0), atol=1e-12)
    # then the plain low-pass: from the same state both give the same next value
    st0[:] = st
    x = rng.normal(size=5)
    lpf_increments(st, alpha, 25.0, x, x, 0.0, Z3, 0.0, 0.0, out, 1.0)
    lpf_increments(st0, alpha, 25.0, x, x, 0.0, Z3, 0.0, 0.0, out, 0.0)
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


def _object_ixz(q1_deg: float, mo: float) -> tuple[float, float]:
    """(the modelled object's I_xz, its slope in the object's mass) of the FC's model at q1 (g_c.uam_model)."""
    from navig8_fc.core import g_c
    from navig8_fc.core.vehicle import UamModel, VehicleConfig, arm_state
    mdl = UamModel(VehicleConfig.load())
    inertia, rate = np.empty((3, 3)), np.empty((3, 3))
    gc, gci, uo = np.empty((5, 5)), np.empty((5, 5)), g_c.UO.zeros()
    g_c.uam_model(*arm_state([math.radians(q1_deg), 0.0, 0.0], [0.0] * 3, [0.0] * 3), mo, mdl.geometry,
                  mdl.force_per_input, mdl.moment_o_per_input, inertia, rate, gc, gci, uo)
    return float(uo[g_c.UO.OBJ_IXZ]), float(uo[g_c.UO.OBJ_IXZ_DM])


@pytest.mark.parametrize("mo", [0.0, 0.5, 1.0])
def test_the_object_ixz_slope_is_its_derivative_in_the_mass(mo: float) -> None:
    eps = 1e-5
    _, slope = _object_ixz(60.0, mo)
    lo = max(mo - eps, 0.0)
    numeric = (_object_ixz(60.0, mo + eps)[0] - _object_ixz(60.0, lo)[0]) / (mo + eps - lo)
    assert slope == pytest.approx(numeric, rel=1e-5)
    assert slope < -0.2  # at q1 60 deg a 1 kg object moves I_xz by about -0.28 kg m^2: no zero slope passes


def _held_fit(with_mass_column: bool) -> tuple[float, float]:
    """A KF told the object's I_xz at its own mass estimate (CKF_IXZ_MOD 1 / 2): roll and yaw windows first, read while
    m_hat is still the UAM's, then mass windows. Noise-free; returns the relative errors of I_zz and m."""
    rng = np.random.default_rng(8)
    gc_inv = rng.normal(size=(5, 5)) + 3.0 * np.eye(5)
    m_uam, mo, dxdz, j13 = 6.5, 1.0, 0.3, -0.2

    def ixz_obj(m: float) -> tuple[float, float]:  # a point object: -mu dx dz and its slope
        o = max(m - m_uam, 0.0)
        return -dxdz * m_uam * o / (m_uam + o), -dxdz * (m_uam / (m_uam + o)) ** 2

    ixx, iyy, izz, m = 0.42, 0.9, 0.87, m_uam + mo
    gi = np.array([[ixx, 0, j13 + ixz_obj(m)[0], 0, 0], [0, iyy, 0, 0, 0], [j13 + ixz_obj(m)[0], 0, izz, 0, 0],
                   [0, 0, 0, m, 0], [0, 0, 0, 0, m]])
    kf = ConstrainedKalmanFilter(CkfConfig(mode=CkfMode.UNCONSTRAINED, q_diag=(1e-12,) * 4, r_diag=(1e-6,) * 5,
                                           p0_scale=1e10))
    kf.initialise([0.22, 0.45, 0.45, m_uam])
    box = ((0.0,) * 4, (10.0,) * 4)
    for k in range(40):
        da = rng.normal(size=5)
        da[2] = 0.8 * da[0] + 0.3 * da[2]  # roll and yaw accelerations correlated, as at q1 60 deg (J13 ~ J11)
        da[3:] = 0.0 if k < 20 else da[3:]  # the mass excitation comes later, as after a grasp
        da[:3] = da[:3] if k < 20 else 0.0
        oi, slope = ixz_obj(float(kf.x[3]))
        z = known_ixz(gc_inv @ gi @ da, gc_inv, tuple(da), j13 + oi)
        hm = None
        if with_mass_column:
            z, hm = ixz_mass_column(z, gc_inv, tuple(da), slope, float(kf.x[3]))
        kf.step(z, da, gc_inv, 0.0, 0.0, None, *box, h_mass=hm)
    return abs(kf.x[2] / izz - 1.0), abs(kf.x[3] / m - 1.0)


def test_the_mass_column_carries_the_windows_read_at_the_wrong_mass() -> None:
    """CKF_IXZ_MOD 2 (adaptive_law.ixz_mass_column): the roll and yaw windows read while m_hat was the UAM's carry an
    I_xz 0.26 kg m^2 off; the mass column keeps their I_zz correlated with m in P, so the later mass windows correct
    it. Without it (CKF_IXZ_MOD 1) I_zz stays off however well the mass is found."""
    err_izz, err_m = _held_fit(True)
    assert err_m < 1e-3 and err_izz < 0.03, (err_izz, err_m)
    err_izz1, err_m1 = _held_fit(False)
    assert err_m1 < 1e-3 and err_izz1 > 0.1, (err_izz1, err_m1)
