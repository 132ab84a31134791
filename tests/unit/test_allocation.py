"""Prioritised WLS allocation (navig8_fc/core/allocation.py, INDI_ALLOC = 1) against independent checks:
scipy.optimize.lsq_linear as the oracle of the box-constrained weighted least squares, the exact inverse when
the demand is feasible, the actuator limits, the priority order on infeasible demands (judged on the true
nonlinear map U -> Delta Acc, not on the allocator's linearisation) and the IndiController against its
group-scaling baseline."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from navig8_fc.core import vehicle as vm
from navig8_fc.core.allocation import (
    ALLOC_WLS,
    EPS_REG,
    WLS_FAILED,
    WLS_INTERIOR,
    AllocationConfig,
    allocate_actuators,
    wls_box,
)
from navig8_fc.core.indi import ActuatorLimits, IndiConfig, IndiController, IndiInputs

CFG = vm.VehicleConfig.load()
LIM = ActuatorLimits.from_vehicle(CFG)
DT = 0.01
ALLOC = AllocationConfig(mode=ALLOC_WLS)
AL = ALLOC.vector(LIM.tilt_min_rad, LIM.tilt_max_rad, LIM.duct_speed_max, LIM.tail_speed_max)  # with the limits


def _oracle(a, d, w, eps, lo, hi):
    """The same problem as a stacked bounded linear least squares: || [W A; sqrt(eps) I] x - [W d; 0] ||^2."""
    n = a.shape[1]
    aa = np.vstack([w[:, None] * a, math.sqrt(eps) * np.eye(n)])
    bb = np.concatenate([w * d, np.zeros(n)])
    return lsq_linear(aa, bb, bounds=(lo, hi), method="bvls", tol=1e-14).x


def _cost(x, a, d, w, eps):
    return float(np.sum((w * (a @ x - d)) ** 2) + eps * x @ x)


def test_wls_box_matches_scipy_lsq_linear() -> None:
    rng = np.random.default_rng(10)
    n_constrained = 0
    worst_gap = 0.0  # how much worse than ours the oracle's cost was (it stops at its own tolerance)
    for _ in range(300):
        a = rng.normal(size=(5, 5)) * rng.uniform(0.1, 10.0, 5)  # column scales differ like tilts vs thrusts
        d = rng.normal(scale=rng.uniform(0.1, 5.0), size=5)
        w = np.array([100.0, 100.0, 0.3, 0.03, 10.0]) * rng.uniform(0.5, 2.0, 5)
        lo = -rng.uniform(0.05, 1.0, 5)
        hi = rng.uniform(0.05, 1.0, 5)
        x = np.empty(5)
        code = wls_box(a, d, w, EPS_REG, lo, hi, x)
        assert code != WLS_FAILED
        n_constrained += code != WLS_INTERIOR
        ref = _oracle(a, d, w, EPS_REG, lo, hi)
        assert np.all(x >= lo) and np.all(x <= hi)
        c, c_ref = _cost(x, a, d, w, EPS_REG), _cost(ref, a, d, w, EPS_REG)
        assert c <= c_ref * (1 + 1e-9) + 1e-12, (c, c_ref)  # never worse than the oracle
        worst_gap = max(worst_gap, (c_ref - c) / max(c, 1e-12))
        # the optimum of a strictly convex QP is unique: c(y) - c(x*) >= (y - x*)^T H (y - x*) for feasible y
        h = a.T @ np.diag(w * w) @ a + EPS_REG * np.eye(5)
        e = ref - x
        assert e @ h @ e <= max(c_ref - c, 0.0) + 1e-9 * max(c, 1e-12), (x, ref)
    assert n_constrained > 200  # most of the random problems hit the box


def test_wls_box_is_the_least_squares_solution_when_feasible() -> None:
    rng = np.random.default_rng(11)
    a = rng.normal(size=(5, 5)) + 3 * np.eye(5)
    x_true = rng.uniform(-0.5, 0.5, 5)
    d = a @ x_true
    x = np.empty(5)
    code = wls_box(a, d, np.array([100.0, 100.0, 0.3, 0.03, 10.0]), 0.0, -np.ones(5), np.ones(5), x)
    assert code == WLS_INTERIOR
    np.testing.assert_allclose(x, np.linalg.solve(a, d), rtol=1e-8, atol=1e-12)  # normal equations: cond^2


def _model(q):
    mp = vm.mass_properties(CFG, q)
    return vm.control_effectiveness_gc(CFG, mp.com_frd_m), vm.inertia_matrix_gi(mp.inertia_com, mp.mass_kg)


def _true_dacc(m, u, u0):
    return np.linalg.solve(m, u - u0)  # Delta Acc = M^-1 Delta U (Eq. 5 inverted), exact in U


def _within_limits(u, u0, step) -> None:
    a1, a3, w1, w2, w3 = vm.u_to_actuators(u)
    b1, b3, v1, _, v3 = vm.u_to_actuators(u0)
    for a, b, w, v in ((a1, b1, w1, v1), (a3, b3, w3, v3)):
        if w > 0.0:  # a duct at zero speed has no tilt in U (Sec. 3; IndiController then clips atan2's answer)
            assert LIM.tilt_min_rad - 1e-12 <= a <= LIM.tilt_max_rad + 1e-12
            if v > 0.0:
                assert abs(a - b) <= step + 1e-9
    assert 0.0 <= w1 <= LIM.duct_speed_max * (1 + 1e-12) and 0.0 <= w3 <= LIM.duct_speed_max * (1 + 1e-12)
    assert abs(w2) <= LIM.tail_speed_max * (1 + 1e-12)


def _allocate(q_deg, d):
    q = np.radians(q_deg)
    gc, gi = _model(q)
    m = np.linalg.solve(gc, gi)  # M = G_C^-1 G_I (Eq. 5)
    u0 = vm.hover_trim(CFG, q, 0.0)
    u = np.empty(5)
    pred = np.empty(5)
    assert allocate_actuators(AL, m, np.asarray(d, dtype=float), u0, u, pred) >= 0
    _within_limits(u, u0, ALLOC.tilt_step_rad)
    got = _true_dacc(m, u, u0)
    return 1.0 - np.abs(got - d) / np.maximum(np.abs(d), 1e-9)  # share of each axis met (overshoot is a miss)


POSES = [(0, 0, 0), (20, 20, 20), (-20, -20, -20)]


@pytest.mark.parametrize("q_deg", POSES)
@pytest.mark.parametrize("level", [1, 2, 3])
def test_higher_priorities_are_met_while_a_lower_one_is_infeasible(q_deg, level) -> None:
    """Priority order roll/pitch, vertical, yaw, forward ([P, Q, R, a_x, a_z] indices (0, 1), 4, 2, 3): a
    moderate demand on the axes above `level` plus an impossible one on the axis at `level`. The upper axes are
    met (true nonlinear map) to within 10 %: a weighted LS, not a strict cascade, so a far-infeasible lower axis
    pulls an upper one by about (w_low / w_high)^2 times its residual (docs/model.md, Control allocation)."""
    order = [(0, 1), (4,), (2,), (3,)]
    moderate = np.array([2.0, -6.0, 1.5, 1.0, -1.0])
    huge = np.array([0.0, 0.0, 60.0, 30.0, -40.0])  # yaw 60 rad/s^2, 3 g forward, 4 g up: none feasible
    d = np.zeros(5)
    for lv, idx in enumerate(order):
        for i in idx:
            d[i] = moderate[i] if lv < level else (huge[i] if lv == level else 0.0)
    met = _allocate(q_deg, d)
    upper = [i for lv in range(level) for i in order[lv]]
    assert np.all(met[upper] > 0.9), (level, met)
    assert np.all(met[list(order[level])] < 0.9), (level, met)  # it really was infeasible


@pytest.mark.parametrize("q_deg", POSES)
def test_roll_pitch_first_as_an_all_axes_demand_grows(q_deg) -> None:
    """Every axis at once, growing until infeasible: roll and pitch are met as well as when they are asked
    alone, whatever the other axes ask."""
    direction = np.array([20.0, -60.0, 10.0, 8.0, -8.0])  # rad/s^2 and m/s^2: pitch as in an arm reversal
    n_infeasible = 0
    for s in np.linspace(0.2, 4.0, 20):
        met = _allocate(q_deg, s * direction)
        if np.all(met > 0.999):
            continue
        n_infeasible += 1
        # the highest priority is met as well as if nothing else were asked (lexicographic order)
        alone = _allocate(q_deg, s * direction * np.array([1.0, 1.0, 0.0, 0.0, 0.0]))
        assert met[0] >= alone[0] - 0.03 and met[1] >= alone[1] - 0.03, (s, met, alone)
    assert n_infeasible >= 5


def test_random_states_stay_within_limits_and_never_nan() -> None:
    rng = np.random.default_rng(12)
    gc, gi = _model(np.zeros(3))
    m = np.linalg.solve(gc, gi)
    for _ in range(200):
        a1, a3 = rng.uniform(LIM.tilt_min_rad, LIM.tilt_max_rad, 2)
        w1, w3 = rng.uniform(0.0, LIM.duct_speed_max, 2)
        w2 = rng.uniform(-LIM.tail_speed_max, LIM.tail_speed_max)
        u0 = np.array(vm.actuators_to_u(a1, a3, w1, w2, w3))
        d = rng.normal(scale=rng.uniform(1.0, 200.0), size=5)
        u = np.empty(5)
        pred = np.empty(5)
        assert allocate_actuators(AL, m, d, u0, u, pred) >= 0
        assert np.all(np.isfinite(u))
        _within_limits(u, u0, ALLOC.tilt_step_rad)


def _indi_pair(q):
    gc, gi = _model(q)
    u0 = vm.hover_trim(CFG, q, 0.0)
    acc0 = np.linalg.solve(gi, gc @ u0)
    out = []
    for mode in (0, ALLOC_WLS):
        indi = IndiController(IndiConfig(DT, 0.0, LIM, AllocationConfig(mode=mode)))
        a1, a3, w1, w2, w3 = vm.u_to_actuators(u0)
        inp = IndiInputs(np.zeros(3), (acc0[3], 0.0, acc0[4]), (a1, a3), (w1, w2, w3), (0.0,) * 5, gc, gi)
        indi.measure(inp)
        out.append((indi, inp))
    return gc, gi, u0, acc0, out


def _step(indi, inp, acc0, v):
    o, st = indi.step(IndiInputs(DT * acc0[:3], inp.specific_force_frd_m_s2, inp.duct_tilt_rad, inp.prop_speed_rad_s,
                                 tuple(v), inp.gc, inp.gi_hat))
    return np.array(vm.actuators_to_u(o.tilt_cmd_rad[0], o.tilt_cmd_rad[1], *o.speed_cmd_rad_s)), st


def test_indi_alloc_modes_agree_when_feasible_and_wls_gives_up_forward_force_first() -> None:
    q = np.radians([20.0, 20.0, 20.0])
    gc, gi, u0, acc0, ((paper, inp0), (wls, inp1)) = _indi_pair(q)
    m = np.linalg.solve(gc, gi)
    small = acc0 + np.array([0.3, -0.5, 0.2, 0.4, -0.3])
    u_p, st_p = _step(paper, inp0, acc0, small)
    u_w, st_w = _step(wls, inp1, acc0, small)
    assert not st_p.saturated and not st_w.saturated
    np.testing.assert_array_equal(u_p, u_w)  # the exact Eq. 5 increment in both
    # A reversal-sized nose-down demand with a forward-force request: the group scaling drops the whole a_x
    # increment and keeps F_x; the WLS allocation delivers more of the pitch demand by letting F_x go.
    big = acc0 + np.array([0.0, -120.0, 0.0, 3.0, 0.0])
    u_p, st_p = _step(paper, inp0, acc0, big)
    u_w, st_w = _step(wls, inp1, acc0, big)
    assert st_p.saturated and st_w.saturated
    got_p, got_w = _true_dacc(m, u_p, u0), _true_dacc(m, u_w, u0)
    assert got_w[1] < got_p[1] - 5.0, (got_p, got_w)  # more nose-down angular acceleration (rad/s^2)
    _within_limits(u_w, u0, ALLOC.tilt_step_rad)


def test_allocation_config_refuses_bad_values() -> None:
    with pytest.raises(ValueError):
        AllocationConfig(mode=2)
    with pytest.raises(ValueError):
        AllocationConfig(mode=1, w_rp=0.0)
    with pytest.raises(ValueError):
        AllocationConfig(mode=1, tilt_step_rad=math.nan)
