"""The pitch row's mass column (CKF_CZ_DM; docs/model.md, "Estimator" item 16): the law's moments are taken about the
estimated CoM, the UAM's with a point object of the estimated mass at the gripper, so the pitch row's CoM error has a
part in the mass error, c = c_z' (m - m_hat) + nuisance, and the row y = G_C[M, :] Delta U = I_yy Delta Q-dot
+ c_z Delta F_x - c_x Delta F_z carries the mass column c_z' Delta F_x - c_x' Delta F_z (kf_nuisance.kf_correct_pitch).

Independent checks: the update against a textbook Kalman update with Schmidt-held I_xx, I_zz, written here in numpy;
the model's slope against the numerical derivative of its own reference point in the object's mass (g_c.uam_model);
a synthetic truth whose reference point follows the mass estimate.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core import g_c
from navig8_fc.core.ckf_config import CkfConfig, CkfMode
from navig8_fc.core.kalman import ConstrainedKalmanFilter
from navig8_fc.core.kf_nuisance import NZ_COV, NZ_SIZE, NZ_VAR, NZ_X, kf_correct_pitch


def _textbook(x, p, nz, gc_inv, du, dq, r, com_dm):
    """The scalar update of [x (4), c] with h = [0, dq, 0, c_z' F_x - c_x' F_z, F_x] and I_xx, I_zz held (their gain
    rows zero; Joseph form, exact for the masked gain), m held too when the slope is zero; the extended KF's measurement
    y + h_m m_hat (the reference point is at m_hat, so the row predicts no mass term there). Returns (x, P, nz)."""
    gc = np.linalg.inv(gc_inv)
    y, fx, fz = gc[1] @ du, gc[3] @ du, gc[4] @ du
    h = np.array([0.0, dq, 0.0, com_dm[1] * fx - com_dm[0] * fz, fx])
    xa = np.append(x, nz[NZ_X])
    pa = np.zeros((5, 5))
    pa[:4, :4] = p
    pa[:4, 4] = pa[4, :4] = nz[NZ_COV:NZ_COV + 4]
    pa[4, 4] = nz[NZ_VAR]
    s = h @ pa @ h + r
    k = pa @ h / s
    k[[0, 2]] = 0.0
    if com_dm == (0.0, 0.0):
        k[3] = 0.0
    xa = xa + k * (y + h[3] * x[3] - h @ xa)  # linearised at m_hat = x[3]: y + h_m m_hat = h xa + noise
    a = np.eye(5) - np.outer(k, h)
    pa = a @ pa @ a.T + r * np.outer(k, k)
    nz_out = np.zeros(NZ_SIZE)
    nz_out[NZ_X], nz_out[NZ_VAR], nz_out[NZ_COV:NZ_COV + 4] = xa[4], pa[4, 4], pa[:4, 4]
    return xa[:4], pa[:4, :4], nz_out


@pytest.mark.parametrize("com_dm", [(0.0, 0.0), (0.03, 0.11), (-0.05, 0.02)])
def test_the_pitch_row_with_its_mass_column_is_the_textbook_update(com_dm: tuple[float, float]) -> None:
    """x, P and the CoM nuisance after the kernel's update equal the textbook's (1e-9 relative), 10 random cases each;
    with a zero slope the mass is not moved by the row (the update before CKF_CZ_DM)."""
    rng = np.random.default_rng(21)
    for _ in range(10):
        m = rng.normal(size=(5, 5))
        pa = 1e-3 * (m @ m.T + np.eye(5))
        x = np.array([0.7, 0.9, 1.1, 7.0]) * rng.uniform(0.8, 1.2, 4)
        p = pa[:4, :4].copy()
        nz = np.zeros(NZ_SIZE)
        nz[NZ_X], nz[NZ_VAR], nz[NZ_COV:NZ_COV + 4] = 0.01, pa[4, 4], pa[:4, 4]
        gc_inv = np.linalg.inv(np.eye(5) + 0.3 * rng.normal(size=(5, 5)))
        du, dq, r = rng.normal(size=5), float(rng.normal()), 1e-2
        xt, pt, nzt = _textbook(x, p, nz, gc_inv, du, dq, r, com_dm)
        x0 = x.copy()
        # nx, the I_xz nuisance, an array as the filter passes it (only written here: not measured by this row);
        # None would compile the kernel again for that type
        assert kf_correct_pitch(x, p, r, gc_inv, du, dq, nz, math.nan, np.zeros(NZ_SIZE), com_dm[0], com_dm[1])
        np.testing.assert_allclose(x, xt, rtol=1e-9)
        np.testing.assert_allclose(p, pt, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(nz, nzt, rtol=1e-9, atol=1e-15)
        if com_dm == (0.0, 0.0):
            assert x[3] == x0[3]


def _reference_point(q1_deg: float, mo: float) -> tuple[float, float, float, float]:
    """(c_x, c_z) of the FC's reference point with a point object of mo at the gripper and its slope in mo
    (g_c.uam_model's CEX, CEZ and CE_DM)."""
    from navig8_fc.core.vehicle import UamModel, VehicleConfig, arm_state
    mdl = UamModel(VehicleConfig.load())
    inertia, rate = np.empty((3, 3)), np.empty((3, 3))
    gc, gci, uo = np.empty((5, 5)), np.empty((5, 5)), g_c.UO.zeros()
    g_c.uam_model(*arm_state([math.radians(q1_deg), 0.0, 0.0], [0.0] * 3, [0.0] * 3), mo, mdl.geometry,
                  mdl.force_per_input, mdl.moment_o_per_input, inertia, rate, gc, gci, uo)
    return float(uo[g_c.UO.CEX]), float(uo[g_c.UO.CEZ]), float(uo[g_c.UO.CE_DM]), float(uo[g_c.UO.CE_DM + 1])


@pytest.mark.parametrize(("q1_deg", "mo"), [(0.0, 0.0), (0.0, 1.0), (60.0, 0.5)])
def test_the_reference_points_slope_is_its_derivative_in_the_mass(q1_deg: float, mo: float) -> None:
    eps = 1e-5
    *_, sx, sz = _reference_point(q1_deg, mo)
    lo = max(mo - eps, 0.0)
    hi_x, hi_z, _, _ = _reference_point(q1_deg, mo + eps)
    lo_x, lo_z, _, _ = _reference_point(q1_deg, lo)
    assert sx == pytest.approx((hi_x - lo_x) / (mo + eps - lo), rel=1e-5, abs=1e-9)
    assert sz == pytest.approx((hi_z - lo_z) / (mo + eps - lo), rel=1e-5)
    assert sz > 0.05  # the gripper hangs about 1 m below O at q1 0 deg: 0.1 m of CoM per kg, no zero slope passes


def _held_pitch_fit(com_mass_slope: bool) -> tuple[float, float]:
    """Pitch windows only (the force rows' R huge: they carry no mass information here), with the law's reference point
    at the mass estimate: the truth's CoM error is c_z' (m_true - m_hat) for the window's m_hat, Delta F_x follows the
    pitch excitation (correlation 0.8). Returns the relative errors of I_yy and m."""
    rng = np.random.default_rng(4)
    x_true = np.array([0.7, 0.9, 1.1, 7.5])
    slope_m_per_kg = 0.1
    cfg = CkfConfig(mode=CkfMode.UNCONSTRAINED, q_diag=(0.0,) * 4, r_diag=(1e-2, 1e-2, 1e-2, 1e8, 1e8),
                    p0_scale=0.0, pitch_r_nm2=1e-4, com_sigma_m=0.02)
    kf = ConstrainedKalmanFilter(cfg)
    kf.initialise([0.7, 0.6, 1.1, 6.5], p0=np.diag([1e-4, 0.1, 1e-4, 1.0]))
    kf.object_held(True, 0.02, 0.1)
    eye, box = np.eye(5), ((0.0,) * 4, (1e3,) * 4)
    for _ in range(300):
        da = rng.standard_normal(5) * 0.3
        fx = x_true[3] * (0.8 * da[1] + 0.6 * 0.3 * rng.standard_normal())
        c_err = slope_m_per_kg * (x_true[3] - kf.x[3])
        du = np.array([x_true[0] * da[0], x_true[1] * da[1] + c_err * fx, x_true[2] * da[2], fx, 0.0])
        du[:3] += 1e-3 * rng.standard_normal(3)
        kf.step(du, da, eye, 0.0, 0.0, None, *box, com_dm=(0.0, slope_m_per_kg if com_mass_slope else 0.0))
    return abs(kf.x[1] - x_true[1]) / x_true[1], abs(kf.x[3] - x_true[3]) / x_true[3]


def test_with_the_mass_column_the_pitch_row_identifies_the_mass_and_i_yy() -> None:
    iyy_err, m_err = _held_pitch_fit(True)
    assert iyy_err < 0.01 and m_err < 0.01, (iyy_err, m_err)


def test_without_the_mass_column_the_mass_stays_where_it_started() -> None:
    iyy_err, m_err = _held_pitch_fit(False)
    assert m_err > 0.1, (iyy_err, m_err)  # 6.5 against 7.5 kg: the row never moves it


def test_the_mass_column_waits_for_the_arm_at_rest() -> None:
    """AdaptiveLaw passes the reference point's slope to the pitch row only after the arm's |I_yy-dot| has stayed below
    ARM_REST_IYY_DOT for PITCH_EVENT_HOLD_TAU filter constants and a window (from the estimator's first tick too): a
    moved arm leaves the trim's move in the low-passed command, which the mass column would read as mass."""
    from navig8_fc.core.adaptive_law import ARM_REST_IYY_DOT, PITCH_EVENT_HOLD_TAU, AdaptiveLaw, AdaptiveLawConfig
    ckf = CkfConfig(pitch_r_nm2=0.01, com_mass_slope=True, inc_window=25, lpf_tau_s=0.7, dt_s=0.01)
    law = AdaptiveLaw(AdaptiveLawConfig(ckf))
    wait_s = PITCH_EVENT_HOLD_TAU * 0.7 + 0.25
    slope = (0.02, 0.1)
    still, moving = np.zeros((3, 3)), np.zeros((3, 3))
    moving[1, 1] = 1.5 * ARM_REST_IYY_DOT
    assert law.pitch_mass_slope(1.0, still, slope) == (0.0, 0.0)  # the first tick: the rest counts from here
    assert law.pitch_mass_slope(1.0 + wait_s - 0.01, still, slope) == (0.0, 0.0)
    assert law.pitch_mass_slope(1.0 + wait_s + 1e-9, still, slope) == slope
    assert law.pitch_mass_slope(5.0, moving, slope) == (0.0, 0.0)
    assert law.pitch_mass_slope(5.0 + wait_s - 0.01, still, slope) == (0.0, 0.0)
    assert law.pitch_mass_slope(5.0 + wait_s + 1e-9, still, slope) == slope
    off = AdaptiveLaw(AdaptiveLawConfig(CkfConfig(pitch_r_nm2=0.01)))
    assert off.pitch_mass_slope(100.0, still, slope) == (0.0, 0.0)  # CKF_CZ_DM 0: never
