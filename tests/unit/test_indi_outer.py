"""INDI inner loop and outer loops against independent references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navig8_fc.core import rotation as rot
from navig8_fc.core import vehicle as vm
from navig8_fc.core.indi import ActuatorLimits, IndiConfig, IndiController, IndiInputs
from navig8_fc.core.outer_loop import OuterLoopConfig, Setpoint, outer_loop_step

CFG = vm.VehicleConfig.load()
DT = 0.01


def _plant_accel(u: np.ndarray, gc: np.ndarray, gi: np.ndarray) -> np.ndarray:
    """Linear plant: [Pdot, Qdot, Rdot, a_x, a_z] = G_I^-1 G_C U (Eq. 1-2), gravity-free specific force."""
    return np.linalg.solve(gi, gc @ u)


def _model(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """G_C and G_I of the UAM without object at pose q (Eq. 1-2)."""
    mp = vm.mass_properties(CFG, q)
    return vm.control_effectiveness_gc(CFG, mp.com_frd_m), vm.inertia_matrix_gi(mp.inertia_com, mp.mass_kg)


def _inputs(gyro, f_xz, u0, v, gc, gi_hat):
    a1, a3, w1, w2, w3 = vm.u_to_actuators(u0)
    return IndiInputs(
        gyro_frd_rad_s=gyro, specific_force_frd_m_s2=(f_xz[0], 0.0, f_xz[1]), duct_tilt_rad=(a1, a3),
        prop_speed_rad_s=(w1, w2, w3),
        accel_cmd=tuple(v), gc=gc, gi_hat=gi_hat,
    )


@pytest.mark.parametrize("q_deg", [(0, 0, 0), (20, 20, 20), (80, 10, 10)])
def test_indi_recovers_commanded_acceleration_in_one_step(q_deg) -> None:
    q = np.radians(q_deg)
    gc, gi = _model(q)
    indi = IndiController(IndiConfig(DT, 0.0, ActuatorLimits.from_vehicle(CFG)))  # tau 0: filters pass through
    u0 = vm.hover_trim(CFG, q, 0.0)
    acc0 = _plant_accel(u0, gc, gi)  # current accelerations produced by U0
    rng = np.random.default_rng(3)
    w0 = rng.normal(0, 0.1, 3)
    wdot0 = acc0[:3]
    indi.measure(_inputs(w0, acc0[3:], u0, np.zeros(5), gc, gi))  # prime the differentiator
    v = acc0 + np.array([0.5, -0.8, 0.3, 0.7, -0.4])
    out, st = indi.step(_inputs(w0 + DT * wdot0, acc0[3:], u0, v, gc, gi))
    u_new = vm.actuators_to_u(out.tilt_cmd_rad[0], out.tilt_cmd_rad[1], *out.speed_cmd_rad_s)
    np.testing.assert_allclose(_plant_accel(u_new, gc, gi), v, rtol=1e-9, atol=1e-9)
    assert not st.saturated


def test_indi_with_scaled_effectiveness_moves_by_lambda() -> None:
    # With G_hat = K G (K diag), one step moves each axis by Delta Acc / K (Eq. 14 with Xi = I).
    q = np.zeros(3)
    gc, gi = _model(q)
    k = np.array([0.5, 0.8, 0.6, 0.7, 0.7])
    gi_hat = gi @ np.diag(1.0 / k)
    indi = IndiController(IndiConfig(DT, 0.0, ActuatorLimits.from_vehicle(CFG)))
    u0 = vm.hover_trim(CFG, q, 0.0)
    acc0 = _plant_accel(u0, gc, gi)
    indi.measure(_inputs(np.zeros(3), acc0[3:], u0, np.zeros(5), gc, gi_hat))
    dv = np.array([0.2, 0.3, -0.1, 0.4, 0.5])
    out, _ = indi.step(_inputs(DT * acc0[:3], acc0[3:], u0, acc0 + dv, gc, gi_hat))
    u_new = vm.actuators_to_u(out.tilt_cmd_rad[0], out.tilt_cmd_rad[1], *out.speed_cmd_rad_s)
    got = _plant_accel(u_new, gc, gi) - acc0
    # G_hat^-1 = G_C^-1 G_I K^-1, so Delta acc = G G_hat^-1 dv = G_I^-1 G_I K^-1 dv... but the columns:
    # G_I K^-1 scales column j of G_I by 1/K_j; G_I^-1 G_I K^-1 = K^-1 exactly.
    np.testing.assert_allclose(got, dv / k, rtol=1e-9, atol=1e-9)


def test_saturation_keeps_limits_and_priorities_and_never_nan() -> None:
    q = np.zeros(3)
    gc, gi = _model(q)
    indi = IndiController(IndiConfig(DT, 0.0, ActuatorLimits.from_vehicle(CFG)))
    u0 = vm.hover_trim(CFG, q, 0.0)
    acc0 = _plant_accel(u0, gc, gi)
    indi.measure(_inputs(np.zeros(3), acc0[3:], u0, np.zeros(5), gc, gi))
    # Huge forward-force and yaw demand plus a modest pitch demand: forward force gives way first.
    v = acc0 + np.array([0.0, 2.0, 400.0, 500.0, 0.0])
    out, st = indi.step(_inputs(DT * acc0[:3], acc0[3:], u0, v, gc, gi))
    assert st.saturated and st.saturation_scale[0] < 1.0
    lim = ActuatorLimits.from_vehicle(CFG)
    assert all(lim.tilt_min_rad <= a <= lim.tilt_max_rad for a in out.tilt_cmd_rad)
    assert 0 <= out.speed_cmd_rad_s[0] <= lim.duct_speed_max and abs(out.speed_cmd_rad_s[1]) <= lim.tail_speed_max
    u_new = vm.actuators_to_u(out.tilt_cmd_rad[0], out.tilt_cmd_rad[1], *out.speed_cmd_rad_s)
    got = _plant_accel(u_new, gc, gi)
    assert got[1] - acc0[1] == pytest.approx(2.0, rel=1e-6)  # pitch kept exactly
    # NaN command: falls back to U0, finite outputs.
    out, st = indi.step(_inputs(DT * acc0[:3], acc0[3:], u0, [math.nan] * 5, gc, gi))
    assert st.fallback_to_u0 and all(math.isfinite(x) for x in out.speed_cmd_rad_s + out.tilt_cmd_rad)


def test_rotation_helpers_against_numpy() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        r, p, y = rng.uniform(-1.2, 1.2, 3)
        q = rot.euler_to_quat(r, p, y)
        np.testing.assert_allclose(rot.quat_to_euler(q), (r, p, y), atol=1e-12)
        # R = Rz(y) Ry(p) Rx(r)
        cz, sz, cy, sy, cx, sx = math.cos(y), math.sin(y), math.cos(p), math.sin(p), math.cos(r), math.sin(r)
        rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
        ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        np.testing.assert_allclose(np.array(rot.quat_to_dcm(q)), rz @ ry @ rx, atol=1e-12)
        v = rng.normal(size=3)
        np.testing.assert_allclose(rot.rotate_ned_to_body(q, rot.rotate_body_to_ned(q, v)), v, atol=1e-12)
    # shortest rotation: 350 deg of yaw command from 0 is -10 deg
    e = rot.attitude_error_rotvec(rot.euler_to_quat(0, 0, 0), rot.euler_to_quat(0, 0, math.radians(350)))
    np.testing.assert_allclose(e, [0, 0, math.radians(-10)], atol=1e-12)
    assert rot.enu_to_ned((1.0, 2.0, 3.0)) == (2.0, 1.0, -3.0)


OL = OuterLoopConfig(1.0, 3.0, 2.0, 4.0, 4.0, 8.0, 2.0, 9.80665)


def test_outer_loop_hover_and_roll_nulls_lateral_force() -> None:
    level = rot.euler_to_quat(0, 0, 0)
    st = outer_loop_step(OL, Setpoint((0, 0, -2)), (0, 0, -2), (0, 0, 0), level, (0, 0, 0))
    np.testing.assert_allclose(st.accel_cmd, [0, 0, 0, 0, -9.80665], atol=1e-12)
    # Lateral error at 45 deg pitch and 30 deg yaw: the commanded attitude makes body-y force zero.
    sp = Setpoint((1.0, 2.0, -2.0), math.radians(45), math.radians(30))
    st = outer_loop_step(OL, sp, (0, 0, -2), (0, 0, 0), level, (0, 0, 0))
    f_body_at_cmd = rot.rotate_ned_to_body(st.att_cmd_quat, st.specific_force_cmd_ned_m_s2)
    assert abs(f_body_at_cmd[1]) < 1e-9
    assert f_body_at_cmd[2] < 0  # thrust up
    r, p, y = rot.quat_to_euler(st.att_cmd_quat)
    assert p == pytest.approx(math.radians(45)) and y == pytest.approx(math.radians(30))
    assert math.sqrt(sum(a * a for a in st.accel_cmd_ned_m_s2)) <= OL.acc_max_m_s2 + 1e-12


def _clip(v: np.ndarray, limit: float) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v * (limit / n) if n > limit > 0.0 else v


def test_outer_loop_against_scipy_rotations() -> None:
    # The cascade of the module docstring, computed here with scipy's Rotation (ZYX Euler, rotation vectors):
    # a_cmd, f_cmd = a_cmd - g, the roll that nulls body-y force at the commanded pitch and yaw, body x/z force
    # with the measured attitude, omega_cmd = K_att rotvec(q^-1 q_cmd) limited, Pdot.. = K_rate (omega_cmd - omega).
    rng = np.random.default_rng(5)
    g = np.array([0.0, 0.0, OL.gravity_m_s2])
    for _ in range(200):
        sp = Setpoint(tuple(rng.uniform(-5, 5, 3)), float(rng.uniform(-1, 1)), float(rng.uniform(-3, 3)))
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        pos, vel, gyro = rng.uniform(-5, 5, 3), rng.uniform(-3, 3, 3), rng.normal(size=3)
        st = outer_loop_step(OL, sp, pos, vel, quat, gyro)
        a_cmd = _clip(OL.vel_k * (_clip(OL.pos_k * (np.array(sp.pos_ned_m) - pos), OL.vel_max_m_s) - vel),
                      OL.acc_max_m_s2)
        f_cmd = a_cmd - g
        np.testing.assert_allclose(st.accel_cmd_ned_m_s2, a_cmd, atol=1e-12)
        np.testing.assert_allclose(st.specific_force_cmd_ned_m_s2, f_cmd, atol=1e-12)
        cmd = Rotation.from_quat(np.roll(st.att_cmd_quat, -1))  # scipy: [x, y, z, w]
        np.testing.assert_allclose(cmd.as_euler("ZYX")[[1, 0]], [sp.pitch_rad, sp.yaw_rad], atol=1e-9)
        assert cmd.as_euler("ZYX")[2] == pytest.approx(st.roll_cmd_rad, abs=1e-9)
        f_at_cmd = cmd.inv().apply(f_cmd)
        assert abs(f_at_cmd[1]) < 1e-9 * max(1.0, np.linalg.norm(f_cmd)) and f_at_cmd[2] <= 0.0
        meas = Rotation.from_quat(np.roll(quat, -1))
        f_body = meas.inv().apply(f_cmd)
        w_cmd = _clip(OL.att_k * (meas.inv() * cmd).as_rotvec(), OL.rate_max_rad_s)
        np.testing.assert_allclose(st.rate_cmd_frd_rad_s, w_cmd, atol=1e-9)
        np.testing.assert_allclose(st.accel_cmd, [*(OL.rate_k * (w_cmd - gyro)), f_body[0], f_body[2]], atol=1e-9)
