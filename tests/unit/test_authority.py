"""navig8-authority (tools/authority.py, authority_static.py, authority_excursion.py): the hover moment authority
LP, the reversal bound and the bound of a flown run against closed forms and independent oracles.

The closed forms use a simplified vehicle (no dihedral, no drag torques, arm straight down, no object), where
the five wrench rows decouple: with Fx held the pitch moment comes from the tail alone, the roll moment from the
duct thrust difference, and with Fx free from the common tilt times the duct height below the CoM. The flown-run
bound reads synthetic logs built from the real log classes (navig8_tools.logdata.RunLog/Series, the interface
load_run returns), and one tiny MCAP written by the real logger for the command line.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from model_oracle import arm_kinematics

from navig8_fc.core.vehicle import VehicleConfig, actuators_to_u, control_effectiveness_gc, mass_properties
from navig8_tools import authority as au
from navig8_tools import authority_excursion as aux
from navig8_tools import authority_static as aus
from navig8_tools.logdata import RunLog, Series

V_MAX, A_MAX = 4.0, 42.0  # the plant's joint servo (params/plant.yaml)
ACT = (120.0, 1.0)  # the actuators' omega_n, zeta (params/plant.yaml)


def _simple(tail_n: float = 200.0) -> VehicleConfig:
    cfg = au.with_tail_thrust(VehicleConfig.load(), tail_n)
    return dataclasses.replace(cfg, dihedral_rad=0.0, k_torque_duct=0.0, k_torque_tail=0.0)


@pytest.mark.parametrize("tail_n", [200.0, 60.0, 20.0])
def test_pitch_authority_fx_held_closed_form(tail_n: float) -> None:
    cfg = _simple(tail_n)
    mg = cfg.uam_mass_kg * cfg.gravity_m_s2
    duct_max = 2.0 * cfg.k_thrust_duct * cfg.duct_speed_max**2  # both ducts at full speed, vertical
    arm = -cfg.tail_frd_m[0]  # the ducts sit at x = 0 = the CoM's x: only the tail's lever remains
    a = aus.hover_authority(cfg, [0.0, 0.0, 0.0], 0.0, "pitch", fx_free=False)
    # nose up: the tail pushes down, the ducts carry m g + T; nose down: the tail lifts at most m g
    assert a.max_nm == pytest.approx(arm * min(tail_n, duct_max - mg), rel=1e-6)
    assert a.min_nm == pytest.approx(-arm * min(tail_n, mg), rel=1e-6)


def test_roll_authority_closed_form() -> None:
    cfg = _simple()
    mg = cfg.uam_mass_kg * cfg.gravity_m_s2
    one_duct = cfg.k_thrust_duct * cfg.duct_speed_max**2
    y = cfg.duct_right_frd_m[1]
    a = aus.hover_authority(cfg, [0.0, 0.0, 0.0], 0.0, "roll")
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
    a = aus.hover_authority(cfg, [0.0, 0.0, 0.0], 0.0, "pitch", fx_free=True)
    assert a.max_nm == pytest.approx(best_up, rel=1e-3)
    assert a.min_nm == pytest.approx(best_dn, rel=1e-3)
    assert a.max_nm > aus.hover_authority(cfg, [0.0, 0.0, 0.0], 0.0, "pitch").max_nm  # the tilt lever helps


def test_solution_is_flyable_and_beats_random_flyable_points() -> None:
    cfg = VehicleConfig.load()
    q = [math.radians(20.0)] * 3
    a = aus.hover_authority(cfg, q, 2.0, "pitch", fx_free=True)
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

    a = aus.hover_authority(cfg, q, 2.0, "pitch", fx_free, body_pitch_rad=math.radians(pitch_deg))
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
        poly_nm = (1.0 - math.cos(math.pi / aus.POLYGON_SIDES)) * 2.0 * cfg.k_thrust_duct * cfg.duct_speed_max**2
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
        assert aux.arm_momentum_y(cfg, q[None, :], qd[None, :], mo)[0] == pytest.approx(h, rel=1e-12, abs=1e-12)


def test_min_excursion_zero_when_authority_suffices() -> None:
    t = np.linspace(0, 1, 501)
    h = 5.0 * np.sin(np.pi * t) ** 2  # peak dh/dt = 5 pi = 15.7 N m
    peak, _, _ = aux.min_pitch_excursion(t, np.full_like(t, 0.5), h, np.full_like(t, 20.0), np.full_like(t, -20.0))
    assert peak < 1e-9


def test_min_excursion_closed_form() -> None:
    """dh/dt = D on [0, T], authority U < D: counter with U while the disturbance lasts, then brake with U:
    peak = (D - U) T^2 / (2 I) + ((D - U) T / I)^2 / (2 U / I) = D (D - U) T^2 / (2 I U)."""
    inertia, d, u, big_t = 0.8, 100.0, 40.0, 0.2
    t = np.arange(0, 1.0 + 1e-12, 0.0005)
    h = d * np.minimum(t, big_t)
    peak, theta, mom = aux.min_pitch_excursion(t, np.full_like(t, inertia), h, np.full_like(t, u),
                                              np.full_like(t, -u))
    assert peak == pytest.approx(d * (d - u) * big_t**2 / (2 * inertia * u), rel=5e-3)
    assert np.max(np.abs(mom)) <= u + 1e-6


def test_reversal_bound_is_sensible() -> None:
    """The paper's reversal with 2 kg: a weaker tail cannot lower the bound; freeing Fx (the tilt lever) cannot
    raise it; the arm's peak reaction is the paper's order (Fig. 10: 125.8 N m)."""
    cfg = VehicleConfig.load()
    a = math.radians(20.0)
    held = aux.reversal_bound(cfg, a, -a, 2.0, 4.0, 42.0, fx_free=False)
    free = aux.reversal_bound(cfg, a, -a, 2.0, 4.0, 42.0, fx_free=True)
    weak = aux.reversal_bound(au.with_tail_thrust(cfg, 60.0), a, -a, 2.0, 4.0, 42.0, fx_free=False)
    assert free.min_peak_pitch_rad <= held.min_peak_pitch_rad + 1e-9 <= weak.min_peak_pitch_rad + 2e-9
    assert 100.0 < np.max(np.abs(held.disturbance_nm)) < 150.0


def _lag_matrix(dt_s: float, n: int, omega_n: float, zeta: float) -> np.ndarray:
    """Oracle: the delivered moment over step k, L @ u, for a command held over each step, from the closed-form
    second-order step response s(t) differenced at each step's middle, (k - j + 1/2) dt."""
    def step(t: np.ndarray) -> np.ndarray:
        t = np.maximum(t, 0.0)
        if abs(zeta - 1.0) < 1e-9:
            return 1.0 - np.exp(-omega_n * t) * (1.0 + omega_n * t)
        if zeta > 1.0:
            r = math.sqrt(zeta * zeta - 1.0)
            p1, p2 = omega_n * (zeta - r), omega_n * (zeta + r)
            return 1.0 - (p2 * np.exp(-p1 * t) - p1 * np.exp(-p2 * t)) / (p2 - p1)
        wd = omega_n * math.sqrt(1.0 - zeta * zeta)
        return 1.0 - np.exp(-zeta * omega_n * t) * (np.cos(wd * t) + zeta * omega_n / wd * np.sin(wd * t))

    lag = np.arange(n)[:, None] - np.arange(n)[None, :]
    g = step((lag + 0.5) * dt_s) - step((lag - 0.5) * dt_s)
    return np.where(lag >= 0, g, 0.0)


def _dense_excursion(t: np.ndarray, inertia: np.ndarray, h: np.ndarray, m_max: np.ndarray, m_min: np.ndarray,
                     lag: np.ndarray | None, hold: int) -> float:
    """Oracle: the same minimax written densely (theta' = (h_0 + sum dt u - h) / I, theta by the trapezoid)."""
    from scipy.optimize import linprog

    n, dt = len(t), np.diff(t)
    c = np.zeros((n, n - 1))
    for k in range(1, n):
        c[k, :k] = dt[:k]
    if lag is not None:
        c = c @ lag
    c /= inertia[:, None]
    e = (h[0] - h) / inertia
    tr = np.zeros((n, n))
    for k in range(1, n):
        tr[k, :k] += 0.5 * dt[:k]
        tr[k, 1:k + 1] += 0.5 * dt[:k]
    a_th, b_th = tr @ c, tr @ e
    cost = np.zeros(n)
    cost[-1] = 1.0
    res = linprog(cost, A_ub=np.block([[a_th, -np.ones((n, 1))], [-a_th, -np.ones((n, 1))]]),
                  b_ub=np.concatenate([-b_th, b_th]), A_eq=np.concatenate([c[-1], [0.0]])[None, :],
                  b_eq=[-e[-1]], bounds=[(0.0, 0.0) if k < hold else (lo, hi)
                                         for k, (lo, hi) in enumerate(zip(m_min[:-1], m_max[:-1], strict=True))]
                  + [(0.0, None)], method="highs")
    assert res.status == 0
    return float(res.x[-1])


@pytest.mark.parametrize("zeta", [1.0, 0.7, 1.5])
def test_lag_discretisation_against_scipy(zeta: float) -> None:
    """A unit command held from step 0 is delivered as the second-order step response at each step's middle, and
    one held over a single step as the closed-form pulse response (the convolution the LP's state stands for)."""
    from scipy import signal

    wn, dt, n = 120.0, 0.002, 200
    phi, gam, cc, dd = aux.lag_discrete(dt, wn, zeta)
    z, y = np.zeros(2), []
    for _ in range(n):
        y.append(cc @ z + dd)
        z = phi @ z + gam
    t_half = np.arange(2 * n + 1) * 0.5 * dt  # scipy wants an even grid; the step middles are its odd points
    _, ref = signal.step(signal.lti([wn * wn], [1.0, 2 * zeta * wn, wn * wn]), T=t_half)
    assert np.array(y) == pytest.approx(ref[1::2], abs=1e-6)
    z, pulse = np.zeros(2), []
    for k in range(n):
        pulse.append(cc @ z + dd * (k == 0))
        z = phi @ z + gam * (k == 0)
    assert np.array(pulse) == pytest.approx(_lag_matrix(dt, n, wn, zeta)[:, 0], abs=1e-12)


@pytest.mark.parametrize("actuator,hold", [(None, 0), (ACT, 0), (ACT, 7), ((90.0, 0.7), 7)])
def test_sparse_excursion_lp_matches_the_dense_oracle(actuator: tuple[float, float] | None, hold: int) -> None:
    t = np.arange(0, 0.8 + 1e-12, 0.004)
    h = 8.0 * np.sin(np.pi * np.clip(t / 0.3, 0, 1)) ** 2 - 3.0 * np.clip((t - 0.3) / 0.1, 0, 1) * (t < 0.5)
    inertia = 0.6 + 0.2 * np.cos(t)
    hi, lo = np.full_like(t, 30.0) + 5 * t, np.full_like(t, -25.0)
    lag = None if actuator is None else _lag_matrix(0.004, len(t) - 1, *actuator)
    peak, theta, u = aux.min_pitch_excursion(t, inertia, h, hi, lo, actuator, hold)
    assert peak == pytest.approx(_dense_excursion(t, inertia, h, hi, lo, lag, hold), rel=1e-7, abs=1e-10)
    assert peak > 1e-3 and np.max(np.abs(theta)) <= peak + 1e-9 and np.all(u[:hold] == 0.0)


def test_lag_bound_limits_and_order() -> None:
    """The closed-form case above: a very fast actuator gives the lag-free peak; a causal command (held at trim
    for a while after the disturbance starts) cannot do better than one with a preview, nor than no lag."""
    inertia, d, u, big_t, dt = 0.8, 100.0, 40.0, 0.2, 0.001
    t = np.arange(0, 1.0 + 1e-12, dt)
    h = d * np.minimum(t, big_t)
    args = (t, np.full_like(t, inertia), h, np.full_like(t, u), np.full_like(t, -u))
    free, _, _ = aux.min_pitch_excursion(*args)
    fast, _, _ = aux.min_pitch_excursion(*args, actuator=(1e5, 1.0))
    slow, _, _ = aux.min_pitch_excursion(*args, actuator=ACT)
    causal, _, mom = aux.min_pitch_excursion(*args, actuator=ACT, hold_until=10)
    assert fast == pytest.approx(free, rel=2e-3)
    assert free < slow < causal
    assert np.all(mom[:10] == 0.0)
    # a delay of the command by tau = 10 ms costs at least the excursion the uncountered disturbance builds in it
    assert causal - free > 0.5 * d * (0.01**2) / inertia


def test_reversal_bound_with_lag_brackets_the_lag_free_one() -> None:
    cfg = VehicleConfig.load()
    a = math.radians(20.0)
    kw = dict(fx_free=True, dt_s=0.004)
    free = aux.reversal_bound(cfg, -a, a, 2.0, V_MAX, A_MAX, **kw)
    causal = aux.reversal_bound(cfg, -a, a, 2.0, V_MAX, A_MAX, actuator=ACT, causal_delay_s=0.01, pre_s=0.2, **kw)
    preview = aux.reversal_bound(cfg, -a, a, 2.0, V_MAX, A_MAX, actuator=ACT, pre_s=0.2, **kw)
    assert free.min_peak_pitch_rad < causal.min_peak_pitch_rad
    assert preview.min_peak_pitch_rad < causal.min_peak_pitch_rad


# --------------------------------------------------------------------------------------
# The static authority along the CoM's path
# --------------------------------------------------------------------------------------


def test_batched_authority_equals_one_at_a_time_and_infeasible_is_none() -> None:
    """authority_at_coms solves all CoM points and tilt pieces as one block-diagonal LP: the same optima as one
    point at a time (hover_authority); a vehicle too heavy to lift gives None (and hover_authority raises)."""
    cfg = VehicleConfig.load()
    poses = [[0.0] * 3, [math.radians(20.0)] * 3, [math.radians(v) for v in (80.0, 10.0, 10.0)]]
    mps = [mass_properties(cfg, q, 2.0) for q in poses]
    coms = np.array([[mp.com_frd_m[0], mp.com_frd_m[2]] for mp in mps])
    batch = aus.authority_at_coms(cfg, coms, mps[0].mass_kg, "pitch", True, body_pitch_rad=0.3)
    for q, b in zip(poses, batch, strict=True):
        one = aus.hover_authority(cfg, q, 2.0, "pitch", True, body_pitch_rad=0.3)
        assert b is not None
        assert (b.min_nm, b.max_nm) == pytest.approx((one.min_nm, one.max_nm), abs=1e-6)
    assert aus.authority_at_coms(cfg, coms[:1], 40.0) == [None]
    with pytest.raises(ValueError, match="infeasible"):
        aus.hover_authority(cfg, poses[0], 40.0)


@pytest.mark.parametrize("fx_free,pitch_deg,tail_n", [(False, 0.0, 200.0), (True, 0.0, 200.0), (True, 45.0, 60.0),
                                                      (False, 45.0, 60.0)])
def test_authority_map_is_never_narrower_than_the_lp(fx_free: bool, pitch_deg: float, tail_n: float) -> None:
    """The lattice's bilinear interpolant against the LP at random CoM points of the reachable box (the real
    vehicle, dihedral included): its range contains the LP's (the convexity argument of AuthorityMap; the
    dihedral's coupling breaks it by at most ~2e-4 N m), contains the flyable (inscribed-polygon) range, and is
    tight where the authority is affine (Fx held)."""
    cfg = au.with_tail_thrust(VehicleConfig.load(), tail_n)
    th = math.radians(pitch_deg)
    amap = aus.AuthorityMap(cfg, 8.0, th, fx_free)
    rng = np.random.default_rng(7)
    cx, cz = rng.uniform(-0.32, 0.32, 25), rng.uniform(-0.06, 0.37, 25)
    lo, hi = amap.bounds(cx, cz)
    pts = np.column_stack([cx, cz])
    outer = aus.authority_at_coms(cfg, pts, 8.0, "pitch", fx_free, aus.MAP_SIDES, th, outer=True)
    inner = aus.authority_at_coms(cfg, pts, 8.0, "pitch", fx_free, aus.POLYGON_SIDES, th)
    for i, (o, n) in enumerate(zip(outer, inner, strict=True)):
        assert o is not None and n is not None
        assert hi[i] >= o.max_nm - 1e-3 and lo[i] <= o.min_nm + 1e-3
        assert o.max_nm >= n.max_nm - 1e-6 and o.min_nm <= n.min_nm + 1e-6
        assert hi[i] - o.max_nm < 2.0 and o.min_nm - lo[i] < 2.0  # the kinks of the Fx-free LP cost < 2 N m
        if not fx_free:
            assert (hi[i], lo[i]) == pytest.approx((o.max_nm, o.min_nm), abs=1e-3)


def test_motion_terms_through_a_grasp() -> None:
    """Where the object changes between two samples, the step's end values are taken with the step's starting
    object (the plant keeps the body rates through a grasp, so the momentum about the CoM jumps, theta' does not)."""
    cfg = VehicleConfig.load()
    q = np.array([[0.1, 0.2, 0.3], [0.12, 0.21, 0.3], [0.14, 0.22, 0.3]])
    qd = np.array([[2.0, 1.0, 0.0]] * 3)
    motion = aux.ArmMotion(np.array([0.0, 0.01, 0.02]), q, qd, np.array([0.0, 1.5, 1.5]), np.zeros(3))
    terms = aux.motion_terms(cfg, motion)
    assert terms["iyy"][1] == pytest.approx(mass_properties(cfg, q[1], 1.5).inertia_com[1, 1], rel=1e-12)
    assert terms["iyy_end"][0] == pytest.approx(mass_properties(cfg, q[1], 0.0).inertia_com[1, 1], rel=1e-12)
    assert terms["h_end"][0] == pytest.approx(aux.arm_momentum_y(cfg, q[1:2], qd[1:2], 0.0)[0], rel=1e-12)
    assert terms["h_end"][1] == terms["h"][2] and terms["iyy_end"][1] == terms["iyy"][2]
    assert terms["h"][1] != pytest.approx(terms["h_end"][0])


# --------------------------------------------------------------------------------------
# The bound of a flown run
# --------------------------------------------------------------------------------------


def _log(motion: aux.ArmMotion, setpoint: bool = True) -> RunLog:
    """A run log as load_run returns it, with the /truth fields bound_from_log reads (and /fc/setpoint)."""
    truth = [{"joint_pos_rad": list(q), "joint_rate_rad_s": list(qd), "object_mass_kg": float(m),
              "euler_rad": [0.0, float(p), 0.0]}
             for q, qd, m, p in zip(motion.q_rad, motion.qd_rad_s, motion.object_mass_kg, motion.body_pitch_rad,
                                    strict=True)]
    topics = {"/truth": Series(np.asarray(motion.t_s), truth)}
    if setpoint:
        topics["/fc/setpoint"] = Series(np.asarray(motion.t_s), [{"pitch_rad": float(p)}
                                                                 for p in motion.body_pitch_rad])
    return RunLog(Path("synthetic.mcap"), topics, {})


def _reversal_log(mass_kg: float, q_from_deg: float = -20.0, q_to_deg: float = 20.0, pitch_deg: float = 0.0,
                  rest_s: float = 0.5) -> RunLog:
    """The paper's reversal as the plant's servo flies it (1 ms steps), logged at 100 Hz like the runners."""
    return _log(aux.reversal_motion(math.radians(q_from_deg), math.radians(q_to_deg), mass_kg, V_MAX, A_MAX,
                                   dt_s=0.01, settle_s=1.0, pre_s=rest_s, body_pitch_rad=math.radians(pitch_deg)))


def _rest_log(q_deg: tuple[float, float, float], mass_kg: float, duration_s: float = 2.0) -> RunLog:
    n = int(round(duration_s / 0.01)) + 1
    q = np.tile(np.radians(q_deg), (n, 1))
    return _log(aux.ArmMotion(np.arange(n) * 0.01, q, np.zeros_like(q), np.full(n, mass_kg), np.zeros(n)))


@pytest.mark.parametrize("q_from_deg,pitch_deg", [(20.0, 0.0), (-20.0, 0.0), (-20.0, 45.0)])
def test_bound_from_log_of_the_paper_reversal_equals_reversal_bound(q_from_deg: float, pitch_deg: float) -> None:
    """A 100 Hz log of the paper's reversal (2 kg, +-60 N tail) read back by bound_from_log (one window; the LP on a
    2 ms grid, q resampled by cubic Hermite) gives reversal_bound's four numbers (the servo integrated at 1 ms,
    sampled at 2 ms) within 0.01 deg; on the campaign's default 5 ms grid within 0.05 deg (its grid starts 0.2 s
    before the onset, not on the reversal's own samples)."""
    cfg = au.with_tail_thrust(VehicleConfig.load(), 60.0)
    a0, a1, th = math.radians(q_from_deg), math.radians(-q_from_deg), math.radians(pitch_deg)
    log = _reversal_log(2.0, q_from_deg, -q_from_deg, pitch_deg)
    for dt, tol in ((0.002, 0.01), (0.005, 0.05)):
        rep = au.bound_from_log(log, cfg, actuator=ACT, dt_s=dt)
        assert len(rep["windows"]) == 1 and rep["windows"][0]["t_onset_s"] == pytest.approx(0.5)
        assert rep["trim_feasible"] and rep["worst_t_s"] == pytest.approx(0.5)
        for fx_free in (False, True):
            fx = "free" if fx_free else "held"
            ref = aux.reversal_bound(cfg, a0, a1, 2.0, V_MAX, A_MAX, fx_free, dt_s=dt, body_pitch_rad=th)
            assert rep[f"lag_free_fx_{fx}_deg"] == pytest.approx(math.degrees(ref.min_peak_pitch_rad), abs=tol)
            ref = aux.reversal_bound(cfg, a0, a1, 2.0, V_MAX, A_MAX, fx_free, dt_s=dt, actuator=ACT,
                                    causal_delay_s=au.CAUSAL_DELAY_S, pre_s=au.LAG_PRE_S, body_pitch_rad=th)
            assert rep[f"causal_fx_{fx}_deg"] == pytest.approx(math.degrees(ref.min_peak_pitch_rad), abs=tol)
        assert rep["bound_deg"] == rep["causal_fx_free_deg"]
    # the order of the variants: lag costs, F_x free helps
    assert rep["lag_free_fx_free_deg"] < rep["causal_fx_free_deg"] < rep["causal_fx_held_deg"]
    assert rep["lag_free_fx_free_deg"] < rep["lag_free_fx_held_deg"] < rep["causal_fx_held_deg"]


def test_bound_from_log_arm_at_rest_is_zero() -> None:
    rep = au.bound_from_log(_rest_log((20.0, 20.0, 20.0), 2.0), VehicleConfig.load(), actuator=ACT)
    assert rep["windows"] == [] and rep["trim_feasible"] and rep["untrimmable_t_s"] is None
    assert rep["bound_deg"] == 0.0 and rep["lag_free_fx_held_deg"] == 0.0 and rep["worst_t_s"] == 0.0
    # a move so small and slow that the authority absorbs it: ~0 too
    n = 301
    t = np.arange(n) * 0.01
    q = np.column_stack([0.01 * np.sin(np.pi * t / 3.0) ** 2] * 3)
    qd = np.column_stack([0.01 * np.pi / 3.0 * np.sin(2 * np.pi * t / 3.0)] * 3)
    rep = au.bound_from_log(_log(aux.ArmMotion(t, q, qd, np.full(n, 1.0), np.zeros(n))), VehicleConfig.load(),
                            actuator=ACT)
    assert len(rep["windows"]) == 1 and rep["lag_free_fx_held_deg"] < 1e-6 and rep["bound_deg"] < 0.01


def test_bound_from_log_is_monotonic_in_the_object_and_the_tail() -> None:
    """A heavier object gives a larger bound (every variant); a weaker tail never a smaller one, and a larger one
    with F_x held (with F_x free the ducts' tilt lever, not the tail, limits the reversal: docs/model.md)."""
    strong, weak = au.with_tail_thrust(VehicleConfig.load(), 200.0), au.with_tail_thrust(VehicleConfig.load(), 60.0)
    keys = ("lag_free_fx_held_deg", "lag_free_fx_free_deg", "causal_fx_held_deg", "causal_fx_free_deg")
    by_mass = [au.bound_from_log(_reversal_log(m), weak, actuator=ACT) for m in (0.5, 1.0, 2.0)]
    for k in keys:
        assert by_mass[0][k] < by_mass[1][k] < by_mass[2][k]
    log = _reversal_log(2.0, 20.0, -20.0)
    s, w = au.bound_from_log(log, strong, actuator=ACT), au.bound_from_log(log, weak, actuator=ACT)
    for k in keys:
        assert w[k] >= s[k] - 1e-6
    assert w["causal_fx_held_deg"] > s["causal_fx_held_deg"] + 1.0
    # and a slower actuator costs more in the causal variants, nothing lag-free
    slow = au.bound_from_log(log, weak, actuator=(0.6 * ACT[0], ACT[1]))
    assert slow["causal_fx_free_deg"] > w["causal_fx_free_deg"] + 0.5
    assert slow["lag_free_fx_free_deg"] == pytest.approx(w["lag_free_fx_free_deg"], abs=1e-9)


def test_bound_from_log_untrimmable_pose() -> None:
    """2.5 kg at the stretched arm 80/10/10 with a +-40 N tail: the hover needs a nose-up moment the tail cannot
    give with F_x held (the LP's range lies below 0), so no controller holds it: trim_feasible False, bound inf,
    worst_t_s the first time there. +-200 N holds it."""
    cfg40 = au.with_tail_thrust(VehicleConfig.load(), 40.0)
    assert aus.hover_authority(cfg40, np.radians([80.0, 10.0, 10.0]), 2.5).max_nm < 0.0
    rep = au.bound_from_log(_rest_log((80.0, 10.0, 10.0), 2.5), cfg40, actuator=ACT)
    assert not rep["trim_feasible"] and rep["bound_deg"] == math.inf and rep["worst_t_s"] == 0.0
    assert au.bound_from_log(_rest_log((80.0, 10.0, 10.0), 2.5), VehicleConfig.load(), actuator=ACT)["trim_feasible"]
    # grasped at 1.0 s, at rest at that pose: untrimmable from then on
    n = 201
    q = np.tile(np.radians([80.0, 10.0, 10.0]), (n, 1))
    mo = np.where(np.arange(n) >= 100, 2.5, 0.0)
    rep = au.bound_from_log(_log(aux.ArmMotion(np.arange(n) * 0.01, q, np.zeros_like(q), mo, np.zeros(n))), cfg40,
                            actuator=ACT)
    assert not rep["trim_feasible"] and rep["untrimmable_t_s"] == pytest.approx(1.0)


def test_bound_from_log_reads_the_commanded_pitch() -> None:
    """The static authority is taken at /fc/setpoint's pitch (45 deg: a different bound from level); without a
    setpoint topic, at the flown pitch of /truth (here the same)."""
    cfg = au.with_tail_thrust(VehicleConfig.load(), 60.0)
    pitched, level = _reversal_log(2.0, pitch_deg=45.0), _reversal_log(2.0)
    a = au.bound_from_log(pitched, cfg, actuator=ACT)
    assert a["pitch_source"] == "/fc/setpoint" and a["windows"][0]["pitch_cmd_deg"] == pytest.approx([45.0, 45.0])
    assert a["causal_fx_held_deg"] > au.bound_from_log(level, cfg, actuator=ACT)["causal_fx_held_deg"] + 5.0
    no_sp = RunLog(pitched.path, {"/truth": pitched.topics["/truth"]}, {})
    b = au.bound_from_log(no_sp, cfg, actuator=ACT)
    assert b["pitch_source"].startswith("/truth") and b["bound_deg"] == pytest.approx(a["bound_deg"], abs=1e-9)


def test_arm_windows_split_and_merge() -> None:
    """Moves resting at least pre_s + min_settle_s apart get their own windows (cut at the next one's start); closer
    ones share a window that keeps the first onset."""
    t = np.arange(0, 6.0 + 1e-9, 0.01)
    qd = np.zeros((len(t), 3))
    for a, b in ((1.0, 1.3), (2.0, 2.3), (2.5, 2.8)):
        qd[(t > a + 1e-9) & (t < b - 1e-9), 0] = 1.0
    w = au.arm_windows(t, qd, pre_s=0.2, settle_s=0.5, min_settle_s=0.2)
    assert len(w) == 2
    assert (w[0]["t_onset_s"], w[0]["t_stop_s"], w[0]["moves"]) == pytest.approx((1.0, 1.3, 1))
    assert (w[0]["t_start_s"], w[0]["t_end_s"]) == pytest.approx((0.8, 1.8))  # cut at the next start
    assert (w[1]["t_onset_s"], w[1]["t_stop_s"], w[1]["moves"]) == pytest.approx((2.0, 2.8, 2))
    assert w[1]["t_end_s"] == pytest.approx(3.3)
    assert au.arm_windows(t, np.zeros((len(t), 3))) == []


def test_cli_log_prints_the_bound_of_a_tiny_mcap(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """navig8-authority --log on an MCAP written by the real logger (truth records with the fields the bound reads,
    the run metadata naming scenario and world as navig8-sim records them)."""
    from navig8_fc.shell.mcap_log import McapLogger

    motion = aux.reversal_motion(math.radians(-20.0), math.radians(20.0), 2.0, V_MAX, A_MAX, dt_s=0.01, settle_s=0.6,
                                pre_s=0.3)
    path = tmp_path / "rev.mcap"
    world = {"vehicle.propulsion.k_thrust_tail": 6e-05, "vehicle.propulsion.k_torque_tail": 1.2e-06}
    with McapLogger(path) as lg:
        lg.metadata("run", {"scenario": "paper", "controller": "proposed", "seed": 1, "world": world})
        for t, q, qd in zip(motion.t_s, motion.q_rad, motion.qd_rad_s, strict=True):
            t_ns = int(round(t * 1e9))
            lg.log("/truth", t_ns, {"joint_pos_rad": list(q), "joint_rate_rad_s": list(qd), "object_mass_kg": 2.0,
                                    "euler_rad": [0.0, 0.0, 0.0]})
            lg.log("/fc/setpoint", t_ns, {"pos_ned_m": [0.0, 0.0, -2.0], "pitch_rad": 0.0, "yaw_rad": 0.0})
    assert au.main(["--log", str(path), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    ref = au.bound_from_log(_log(motion), au.with_tail_thrust(VehicleConfig.load(), 60.0), actuator=ACT)
    assert rep["tail_max_thrust_n"] == pytest.approx(60.0) and rep["world"] == world
    assert rep["bound_deg"] == pytest.approx(ref["bound_deg"], abs=1e-9) and rep["trim_feasible"]
    assert au.main(["--log", str(path), "--world", "vehicle.propulsion.k_thrust_tail=2e-4"]) == 0
    out = capsys.readouterr().out
    assert "tail +-200 N" in out and "bound (causal with the actuators' lag, F_x free)" in out


def test_a_long_window_in_pieces_is_a_relaxation_of_the_whole() -> None:
    """Two reversals 0.3 s apart share a window longer than one piece (CHUNK_S): it is bounded on the log's 10 ms
    grid in overlapping pieces, the first from rest, the later ones with their state free, so each piece's number,
    and their max, is at most the whole window's LP (a relaxation), and not far below it here."""
    cfg = au.with_tail_thrust(VehicleConfig.load(), 60.0)
    a = math.radians(20.0)
    one = aux.reversal_motion(-a, a, 2.0, V_MAX, A_MAX, dt_s=0.01, settle_s=0.3, pre_s=0.5)
    two = aux.reversal_motion(a, -a, 2.0, V_MAX, A_MAX, dt_s=0.01, settle_s=1.0, pre_s=0.0)
    cat = [np.concatenate([x, y[1:]]) for x, y in ((one.q_rad, two.q_rad), (one.qd_rad_s, two.qd_rad_s))]
    n = len(cat[0])
    motion = aux.ArmMotion(np.arange(n) * 0.01, cat[0], cat[1], np.full(n, 2.0), np.zeros(n))
    rep = au.bound_from_log(_log(motion), cfg, actuator=ACT)
    (w,) = rep["windows"]
    assert w["moves"] == 2 and w["pieces"] > 1 and w["dt_s"] == au.LONG_DT_S
    k0 = int(round(w["t_start_s"] / 0.01))
    whole = aux.ArmMotion(motion.t_s[k0:], motion.q_rad[k0:], motion.qd_rad_s[k0:], motion.object_mass_kg[k0:],
                         motion.body_pitch_rad[k0:])
    onset = int(round((w["t_onset_s"] - w["t_start_s"]) / 0.01))
    for fx_free in (False, True):
        fx = "free" if fx_free else "held"
        ref = aux.window_bound(cfg, whole, fx_free, ACT, onset + 1)
        got = rep[f"causal_fx_{fx}_deg"]
        assert got <= math.degrees(ref.min_peak_pitch_rad) + 1e-6
        assert got > 0.8 * math.degrees(ref.min_peak_pitch_rad)
