"""navig8-authority (tools/authority.py): the hover moment authority LP and the reversal bound against closed forms.

The closed forms use a simplified vehicle (no dihedral, no drag torques, arm straight down, no object), where
the five wrench rows decouple: with Fx held the pitch moment comes from the tail alone, the roll moment from the
duct thrust difference, and with Fx free from the common tilt times the duct height below the CoM.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from model_oracle import arm_kinematics

from navig8_fc.core.vehicle import VehicleConfig, actuators_to_u, control_effectiveness_gc, mass_properties
from navig8_tools import authority as au


def _simple(tail_n: float = 200.0) -> VehicleConfig:
    cfg = au.with_tail_thrust(VehicleConfig.load(), tail_n)
    return dataclasses.replace(cfg, dihedral_rad=0.0, k_torque_duct=0.0, k_torque_tail=0.0)


@pytest.mark.parametrize("tail_n", [200.0, 60.0, 20.0])
def test_pitch_authority_fx_held_closed_form(tail_n: float) -> None:
    cfg = _simple(tail_n)
    mg = cfg.uam_mass_kg * cfg.gravity_m_s2
    duct_max = 2.0 * cfg.k_thrust_duct * cfg.duct_speed_max**2  # both ducts at full speed, vertical
    arm = -cfg.tail_frd_m[0]  # the ducts sit at x = 0 = the CoM's x: only the tail's lever remains
    a = au.hover_authority(cfg, [0.0, 0.0, 0.0], 0.0, "pitch", fx_free=False)
    # nose up: the tail pushes down, the ducts carry m g + T; nose down: the tail lifts at most m g
    assert a.max_nm == pytest.approx(arm * min(tail_n, duct_max - mg), rel=1e-6)
    assert a.min_nm == pytest.approx(-arm * min(tail_n, mg), rel=1e-6)


def test_roll_authority_closed_form() -> None:
    cfg = _simple()
    mg = cfg.uam_mass_kg * cfg.gravity_m_s2
    one_duct = cfg.k_thrust_duct * cfg.duct_speed_max**2
    y = cfg.duct_right_frd_m[1]
    a = au.hover_authority(cfg, [0.0, 0.0, 0.0], 0.0, "roll")
    # one duct at min(full, m g), the other the rest: L = y (T3 - T1)
    assert a.max_nm == pytest.approx(y * min(2 * one_duct - mg, mg), rel=1e-6)
    assert a.min_nm == pytest.approx(-a.max_nm, rel=1e-6)


def test_pitch_authority_fx_free_against_a_scan() -> None:
    """Fx free: both ducts tilt together (N = 0, L = 0); M = 2 K_T (z_d - c_z) U_sin - x_t K_T2 U5 with
    2 K_T U_cos + K_T2 U5 = m g and U_cos^2 + U_sin^2 <= w_max^4: a one-dimensional problem in U5, scanned."""
    cfg = _simple(60.0)
    mp = mass_properties(cfg, [0.0, 0.0, 0.0], 0.0)
    mg = mp.mass_kg * cfg.gravity_m_s2
    kt, kt2, r = cfg.k_thrust_duct, cfg.k_thrust_tail, cfg.duct_speed_max**2
    h = cfg.duct_right_frd_m[2] - mp.com_frd_m[2]
    u5 = np.linspace(-cfg.tail_speed_max**2, cfg.tail_speed_max**2, 400001)
    ucos = (mg - kt2 * u5) / (2 * kt)
    ok = (ucos >= 0) & (ucos <= r)
    usin = np.sqrt(np.clip(r * r - ucos**2, 0, None))
    m_tail = cfg.tail_frd_m[0] * kt2 * u5  # -(x_t)(F_z,t) with F_z,t = -K_T2 U5
    best_up = np.max((2 * kt * abs(h) * usin + m_tail)[ok])
    best_dn = np.min((-2 * kt * abs(h) * usin + m_tail)[ok])
    a = au.hover_authority(cfg, [0.0, 0.0, 0.0], 0.0, "pitch", fx_free=True)
    assert a.max_nm == pytest.approx(best_up, rel=1e-3)
    assert a.min_nm == pytest.approx(best_dn, rel=1e-3)
    assert a.max_nm > au.hover_authority(cfg, [0.0, 0.0, 0.0], 0.0, "pitch").max_nm  # the tilt lever helps


def test_solution_is_flyable_and_beats_random_flyable_points() -> None:
    cfg = VehicleConfig.load()
    q = [math.radians(20.0)] * 3
    a = au.hover_authority(cfg, q, 2.0, "pitch", fx_free=True)
    for u in (a.u_at_max, a.u_at_min):
        for c, s in ((u[0], u[1]), (u[2], u[3])):
            assert math.hypot(c, s) <= cfg.duct_speed_max**2 * (1 + 1e-9)
            assert abs(math.atan2(s, c)) <= cfg.tilt_max_rad + 1e-9
        assert abs(u[4]) <= cfg.tail_speed_max**2 * (1 + 1e-9)


@pytest.mark.parametrize("fx_free,pitch_deg", [(False, 0.0), (True, 0.0), (False, 45.0), (True, 45.0)])
def test_lp_matches_a_nonlinear_solver_in_actuator_space(fx_free: bool, pitch_deg: float) -> None:
    """The same problem posed in the actuators themselves (tilts, speeds, signed tail speed within their
    limits), solved by SLSQP from several starts: its best equals the LP's optimum (the LP's polygon sits at
    most 7.5e-5 inside the speed circle; SLSQP's local optima can only be lower). Pitched (the paper's 45 deg
    phase), the hover force is the weight's opposite rotated into the body by the attitude module."""
    from scipy.optimize import minimize

    from navig8_fc.core import rotation

    cfg = VehicleConfig.load()
    q = [math.radians(20.0)] * 3
    mp = mass_properties(cfg, q, 2.0)
    gc = control_effectiveness_gc(cfg, mp.com_frd_m)
    rows = [0, 2, 4] if fx_free else [0, 2, 3, 4]
    f_body = rotation.rotate_ned_to_body(rotation.euler_to_quat(0.0, math.radians(pitch_deg), 0.3),
                                         (0.0, 0.0, -mp.mass_kg * cfg.gravity_m_s2))
    assert abs(f_body[1]) < 1e-9
    target = np.array([0.0, 0.0, 0.0, f_body[0], f_body[2]])[rows]
    scale = np.array([1.0, 1.0, cfg.duct_speed_max, cfg.duct_speed_max, cfg.tail_speed_max])
    lo = [cfg.tilt_min_rad, cfg.tilt_min_rad, 0.0, 0.0, -cfg.tail_speed_max]
    hi = [cfg.tilt_max_rad, cfg.tilt_max_rad, cfg.duct_speed_max, cfg.duct_speed_max, cfg.tail_speed_max]

    def wrench(x: np.ndarray) -> np.ndarray:
        a1, a3, w1, w3, w2 = x * scale
        return gc @ actuators_to_u(a1, a3, w1, w2, w3)

    a = au.hover_authority(cfg, q, 2.0, "pitch", fx_free, body_pitch_rad=math.radians(pitch_deg))
    rng = np.random.default_rng(5)
    for sgn, lp in ((1.0, a.max_nm), (-1.0, a.min_nm)):
        found = []
        for _ in range(30):
            x0 = rng.uniform(np.array(lo) / scale, np.array(hi) / scale)
            r = minimize(lambda x, s=sgn: -s * wrench(x)[1] / 100.0, x0, method="SLSQP",
                         bounds=list(zip(np.array(lo) / scale, np.array(hi) / scale, strict=True)),
                         constraints=[{"type": "eq", "fun": lambda x: (wrench(x)[rows] - target) / 100.0}],
                         options={"maxiter": 300, "ftol": 1e-12})
            if r.success and np.max(np.abs(wrench(r.x)[rows] - target)) < 1e-6:
                found.append(wrench(r.x)[1])
        assert found
        best = max(found) if sgn > 0 else min(found)
        # nothing flyable beats the LP by more than the polygon's shortfall: at most 1 - cos(pi/n) of each duct's
        # full thrust, on a lever below 1 m (absolute: pitched, the moment is a small difference of large forces)
        poly_nm = (1.0 - math.cos(math.pi / au.POLYGON_SIDES)) * 2.0 * cfg.k_thrust_duct * cfg.duct_speed_max**2
        assert sgn * best <= sgn * lp + poly_nm + 1e-6
        assert best == pytest.approx(lp, rel=2e-3)  # and the LP's optimum is reached


def test_arm_momentum_against_vector_oracle() -> None:
    """h about the composite CoM, written independently: sum over all bodies of m (r - c) x (r' - c') + I theta'."""
    cfg = VehicleConfig.load()
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, qd, mo = rng.uniform(-1, 1, 3), rng.uniform(-4, 4, 3), float(rng.uniform(0, 2))
        kin = arm_kinematics(cfg, q, qd)
        bodies = [(cfg.uav_mass_kg, np.zeros(3), np.zeros(3))]
        bodies += [(cfg.link_mass_kg, kin.link_com[i], kin.link_com_vel[i]) for i in range(3)]
        bodies += [(mo, kin.object_pos, kin.object_vel)]
        m = sum(b[0] for b in bodies)
        c = sum(b[0] * b[1] for b in bodies) / m
        cd = sum(b[0] * b[2] for b in bodies) / m
        h = sum(b[0] * np.cross(b[1] - c, b[2] - cd)[1] for b in bodies)
        thd = np.cumsum(qd)
        h += cfg.link_inertia_kgm2 * thd.sum() + 0.4 * mo * cfg.object_radius_m**2 * thd[-1]
        assert au.arm_momentum_y(cfg, q[None, :], qd[None, :], mo)[0] == pytest.approx(h, rel=1e-12, abs=1e-12)


def test_min_excursion_zero_when_authority_suffices() -> None:
    t = np.linspace(0, 1, 501)
    h = 5.0 * np.sin(np.pi * t) ** 2  # peak dh/dt = 5 pi = 15.7 N m
    peak, _, _ = au.min_pitch_excursion(t, np.full_like(t, 0.5), h, np.full_like(t, 20.0), np.full_like(t, -20.0))
    assert peak < 1e-9


def test_min_excursion_closed_form() -> None:
    """dh/dt = D on [0, T], authority U < D: counter with U while the disturbance lasts, then brake with U:
    peak = (D - U) T^2 / (2 I) + ((D - U) T / I)^2 / (2 U / I) = D (D - U) T^2 / (2 I U)."""
    inertia, d, u, big_t = 0.8, 100.0, 40.0, 0.2
    t = np.arange(0, 1.0 + 1e-12, 0.0005)
    h = d * np.minimum(t, big_t)
    peak, theta, mom = au.min_pitch_excursion(t, np.full_like(t, inertia), h, np.full_like(t, u),
                                              np.full_like(t, -u))
    assert peak == pytest.approx(d * (d - u) * big_t**2 / (2 * inertia * u), rel=5e-3)
    assert np.max(np.abs(mom)) <= u + 1e-6


def test_reversal_bound_is_sensible() -> None:
    """The paper's reversal with 2 kg: a weaker tail cannot lower the bound; freeing Fx (the tilt lever) cannot
    raise it; the arm's peak reaction is the paper's order (Fig. 10: 125.8 N m)."""
    cfg = VehicleConfig.load()
    a = math.radians(20.0)
    held = au.reversal_bound(cfg, a, -a, 2.0, 4.0, 42.0, fx_free=False, grid=5)
    free = au.reversal_bound(cfg, a, -a, 2.0, 4.0, 42.0, fx_free=True, grid=5)
    weak = au.reversal_bound(au.with_tail_thrust(cfg, 60.0), a, -a, 2.0, 4.0, 42.0, fx_free=False, grid=5)
    assert free.min_peak_pitch_rad <= held.min_peak_pitch_rad + 1e-9 <= weak.min_peak_pitch_rad + 2e-9
    assert 100.0 < np.max(np.abs(held.disturbance_nm)) < 150.0


@pytest.mark.parametrize("zeta", [1.0, 0.7, 1.5])
def test_lag_matrix_step_response_against_scipy(zeta: float) -> None:
    """A unit command held from step 0 is delivered as the second-order step response at each step's middle."""
    from scipy import signal

    wn, dt, n = 120.0, 0.002, 200
    lag = au.lag_matrix(dt, n, wn, zeta)
    t_half = np.arange(2 * n + 1) * 0.5 * dt  # scipy wants an even grid; the step middles are its odd points
    _, ref = signal.step(signal.lti([wn * wn], [1.0, 2 * zeta * wn, wn * wn]), T=t_half)
    assert lag @ np.ones(n) == pytest.approx(ref[1::2], abs=1e-6)
    assert np.allclose(np.triu(lag, 1), 0.0)  # causal: nothing is delivered before it is commanded


def test_lag_bound_limits_and_order() -> None:
    """The closed-form case above: a very fast actuator gives the lag-free peak; a causal command (held at trim
    for a while after the disturbance starts) cannot do better than one with a preview, nor than no lag."""
    inertia, d, u, big_t, dt = 0.8, 100.0, 40.0, 0.2, 0.001
    t = np.arange(0, 1.0 + 1e-12, dt)
    h = d * np.minimum(t, big_t)
    args = (t, np.full_like(t, inertia), h, np.full_like(t, u), np.full_like(t, -u))
    free, _, _ = au.min_pitch_excursion(*args)
    fast, _, _ = au.min_pitch_excursion(*args, lag=au.lag_matrix(dt, len(t) - 1, 1e5, 1.0))
    slow, _, _ = au.min_pitch_excursion(*args, lag=au.lag_matrix(dt, len(t) - 1, 120.0, 1.0))
    causal, _, mom = au.min_pitch_excursion(*args, lag=au.lag_matrix(dt, len(t) - 1, 120.0, 1.0), hold_until=10)
    assert fast == pytest.approx(free, rel=2e-3)
    assert free < slow < causal
    assert np.all(mom[:10] == 0.0)
    # a delay of the command by tau = 10 ms costs at least the excursion the uncountered disturbance builds in it
    assert causal - free > 0.5 * d * (0.01**2) / inertia


def test_reversal_bound_with_lag_brackets_the_lag_free_one() -> None:
    cfg = VehicleConfig.load()
    a = math.radians(20.0)
    kw = dict(fx_free=True, grid=5, dt_s=0.004)
    free = au.reversal_bound(cfg, -a, a, 2.0, 4.0, 42.0, **kw)
    causal = au.reversal_bound(cfg, -a, a, 2.0, 4.0, 42.0, actuator=(120.0, 1.0), causal_delay_s=0.01, pre_s=0.2, **kw)
    preview = au.reversal_bound(cfg, -a, a, 2.0, 4.0, 42.0, actuator=(120.0, 1.0), pre_s=0.2, **kw)
    assert free.min_peak_pitch_rad < causal.min_peak_pitch_rad
    assert preview.min_peak_pitch_rad < causal.min_peak_pitch_rad
