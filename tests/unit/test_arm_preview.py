"""INDI_ARM_FF = 2: the arm preview, checked against independent references.

- The FC's servo model against the closed-form time-optimal trapezoid (accelerate at a_max to v_max, coast,
  brake at a_max) and against the plant's servo (`sim_bridge.joint_servo.servo_accel`, written separately).
- The preview's ḣ at t + lead against ḣ (`g_c.mass_props`, itself checked against tools/authority_excursion's
  h in test_arm_wrench.py) at the state the plant's servo reaches at t + lead.
- The scenario's arm plan as the FC parses it against the bridge's own target lookup (`Scenario.arm_targets`).
- The controller: with INDI_ARM_FF = 2 and an arm step coming within the lead time the pitch command leans against
  the reaction before the arm moves; without a plan INDI_ARM_FF = 2 flies exactly as INDI_ARM_FF = 1.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core import g_c
from navig8_fc.core.arm_preview import (
    arm_preview_step,
    hold_plan,
    plan_rows,
    plan_target,
    servo_model_run,
)
from navig8_fc.core.controller import ControllerConfig, FcSensors, FlightControllerCore
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.core.vehicle import VehicleConfig, model_geometry
from navig8_fc.flight.script import load_flight_script
from navig8_fc.params.registry import ParamRegistry
from sim_bridge.joint_servo import servo_accel
from sim_bridge.scenario import load_scenario

A_MAX, V_MAX, H = 42.0, 4.0, 1e-3


def _trapezoid(d: float, t: float) -> tuple[float, float, float]:
    """Closed-form time-optimal rest-to-rest move over distance d > 0: (q, q', q'') at t (q'' of the phase)."""
    t_acc = V_MAX / A_MAX
    d_acc = 0.5 * A_MAX * t_acc**2
    if 2 * d_acc > d:  # triangular
        t_acc = math.sqrt(d / A_MAX)
        t_coast = 0.0
    else:
        t_coast = (d - 2 * d_acc) / V_MAX
    v_pk = A_MAX * t_acc
    if t < t_acc:
        return 0.5 * A_MAX * t * t, A_MAX * t, A_MAX
    q1 = 0.5 * A_MAX * t_acc**2
    if t < t_acc + t_coast:
        return q1 + v_pk * (t - t_acc), v_pk, 0.0
    q2 = q1 + v_pk * t_coast
    tb = t - t_acc - t_coast
    if tb < t_acc:
        return q2 + v_pk * tb - 0.5 * A_MAX * tb * tb, v_pk - A_MAX * tb, -A_MAX
    return d, 0.0, 0.0


def _plant_servo(q0: np.ndarray, qd0: np.ndarray, plan: np.ndarray, t0: float, n: int) -> np.ndarray:
    """The plant's servo law (sim_bridge) run n periods: [q, q', q'' of the next period]."""
    q, v = q0.astype(float).copy(), qd0.astype(float).copy()
    for i in range(n + 1):
        a = np.array([servo_accel(plan_target(plan, t0 + i * H, j) - q[j], v[j], H, A_MAX, V_MAX) for j in range(3)])
        if i < n:
            q, v = q + v * H + 0.5 * a * H * H, v + a * H
    return np.concatenate([q, v, a])


@pytest.mark.parametrize("d", [0.698, 0.1, -0.5])
def test_servo_model_matches_the_closed_form_trapezoid(d: float) -> None:
    plan = hold_plan((d, 0.0, 0.0))
    state = np.zeros(9)
    t = 0.0
    for _ in range(400):
        q_ref, v_ref, _ = _trapezoid(abs(d), t)
        assert abs(state[0]) == pytest.approx(q_ref, abs=0.2 * V_MAX * H + 1e-3)
        assert abs(state[3]) == pytest.approx(v_ref, abs=A_MAX * H * 1.01 + 1e-9)
        servo_model_run(plan, t, 1, H, A_MAX, V_MAX, state)
        t += H
    assert state[0] == pytest.approx(d, abs=1e-9) and state[3] == pytest.approx(0.0, abs=1e-9)


def test_servo_model_follows_the_plant_servo_on_the_paper_square_wave() -> None:
    plan = plan_rows(((0.0, 2.0, (0.0,) * 3, (0.35,) * 3), (2.5, 2.5, (0.35,) * 3, (-0.35,) * 3),
                      (5.0, 5.0, (-0.35,) * 3, (0.35,) * 3)))
    state = np.zeros(9)
    ref = np.zeros(9)
    n = 6000
    worst_q = 0.0
    for i in range(n):
        servo_model_run(plan, i * H, 1, H, A_MAX, V_MAX, state)
        ref = _plant_servo(ref[:3], ref[3:6], plan, i * H, 1)
        worst_q = max(worst_q, float(np.max(np.abs(state[:3] - ref[:3]))))
    assert worst_q < 2e-3  # rad: the two laws differ only in the last period of each arrival


def test_preview_predicts_the_reaction_the_plant_servo_produces(cfg: VehicleConfig) -> None:
    geo = model_geometry(cfg)
    q_rest = np.full(3, 0.35)
    plan = plan_rows(((0.0, 0.0, tuple(q_rest), tuple(q_rest)), (2.5, 2.5, tuple(q_rest), (-0.35,) * 3)))
    mo = 1.5
    for t_s, lead in ((2.47, 0.05), (2.45, 0.06), (2.55, 0.03), (2.6, 0.08)):
        # the joints at t_s as the plant's servo has them, and what they do at t_s + lead
        now = _plant_servo(q_rest, np.zeros(3), plan, 0.0, round(t_s / H))
        fut = _plant_servo(now[:3], now[3:6], plan, t_s, round(lead / H))
        mp = g_c.MP.zeros()
        g_c.mass_props(fut[:3], fut[3:6], fut[6:], mo, geo, np.empty((3, 3)), np.empty((3, 3)), mp)
        ref = np.zeros(10)
        ref[:6], ref[9] = now[:6], 1.0
        # ref is advanced one control tick (dt) before predicting: start it dt earlier on the plant's trajectory
        dt = 0.01
        before = _plant_servo(q_rest, np.zeros(3), plan, 0.0, round((t_s - dt) / H))
        ref[:6] = before[:6]
        got = arm_preview_step(plan, t_s, dt, lead, now[:3], now[3:6], H, A_MAX, V_MAX, mo, geo, ref, np.zeros(9))
        assert got == pytest.approx(float(mp[g_c.MP.HDC]), rel=0.02, abs=0.5)
    # before the step nothing happens yet within a short lead; a lead that reaches past the step sees the reaction
    ref = np.zeros(10)
    quiet = arm_preview_step(plan, 2.40, 0.01, 0.05, q_rest, np.zeros(3), H, A_MAX, V_MAX, mo, geo, ref, np.zeros(9))
    ref = np.zeros(10)
    ahead = arm_preview_step(plan, 2.47, 0.01, 0.05, q_rest, np.zeros(3), H, A_MAX, V_MAX, mo, geo, ref, np.zeros(9))
    assert abs(quiet) < 1e-9 and abs(ahead) > 10.0


def test_preview_starts_a_noisy_joint_at_rest_on_its_target(cfg: VehicleConfig) -> None:
    """A joint estimate 0.01 rad off its target at rest is not read as a move (the noise would give ±a_max)."""
    geo = model_geometry(cfg)
    plan = hold_plan((0.35, 0.35, 0.35))
    ref = np.zeros(10)
    got = arm_preview_step(plan, 1.0, 0.01, 0.05, np.array([0.36, 0.34, 0.355]), np.array([0.01, -0.01, 0.0]), H,
                           A_MAX, V_MAX, 1.0, geo, ref, np.zeros(9))
    assert got == pytest.approx(0.0, abs=1e-9)


def test_fc_arm_plan_equals_the_bridge_targets() -> None:
    script = load_flight_script("paper")
    plan = plan_rows(tuple((g.t0_s, g.t1_s, g.q_start_rad, g.q_end_rad) for g in script.arm_plan))
    scen = load_scenario("paper")
    for t in np.random.default_rng(3).uniform(-0.5, 31.0, 300):
        want = scen.arm_targets(float(t))
        assert [plan_target(plan, float(t), j) for j in range(3)] == pytest.approx(list(want), abs=1e-12)


def test_plan_rows_refuses_bad_segments() -> None:
    with pytest.raises(ValueError):
        plan_rows(())
    with pytest.raises(ValueError):
        plan_rows(((1.0, 0.5, (0.0,) * 3, (0.1,) * 3),))
    with pytest.raises(ValueError):
        plan_rows(((0.0, 0.0, (math.nan,) * 3, (0.1,) * 3),))


@pytest.fixture(scope="module")
def cfg() -> VehicleConfig:
    return VehicleConfig.load()


def _core(cfg: VehicleConfig, arm_ff: int) -> FlightControllerCore:
    values = ParamRegistry.from_defaults().as_dict()
    values.update(INDI_ARM_FF=arm_ff, INDI_ARM_LEAD=0.05, CKF_START_DLY=100.0)
    return FlightControllerCore(cfg, ControllerConfig.from_params(values, cfg))


def _plant_joints(plan: np.ndarray, n_ticks: int, amax: float = A_MAX, vmax: float = V_MAX,
                  stall: tuple[int, float] | None = None) -> list[np.ndarray]:
    """The joints (q, q') at each 0.01 s tick as the plant's servo law (sim_bridge, written separately) moves them
    along plan with the given limits; stall = (joint, t_s): that joint stops dead from t_s on."""
    q = np.array([plan_target(plan, 0.0, j) for j in range(3)])
    v = np.zeros(3)
    out = []
    for i in range(n_ticks):
        out.append(np.concatenate([q, v]))
        for sub in range(10):
            t = i * 0.01 + sub * H
            a = np.array([servo_accel(plan_target(plan, t, j) - q[j], v[j], H, amax, vmax) for j in range(3)])
            if stall is not None and t >= stall[1]:
                a[stall[0]], v[stall[0]] = 0.0, 0.0
            q, v = q + v * H + 0.5 * a * H * H, v + a * H
    return out


def _fly(core: FlightControllerCore, cfg: VehicleConfig, n: int, joints: list[np.ndarray] | None = None
         ) -> tuple[list[float], list]:
    """n hover ticks, the arm at rest on q = 0.35 rad or measured as `joints`; the INDI's pitch command (Q-dot)
    and the feed-forward status each tick."""
    w = 610.0
    out, ff = [], []
    for i in range(n):
        qj = joints[i] if joints is not None else np.array([0.35] * 3 + [0.0] * 3)
        s = FcSensors(t_s=i * 0.01, gyro_frd_rad_s=(0.0, 0.0, 0.0), accel_frd_m_s2=(0.0, 0.0, -cfg.gravity_m_s2),
                      pos_ned_m=(0.0, 0.0, -2.0), vel_ned_m_s=(0.0, 0.0, 0.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0),
                      duct_tilt_rad=(0.0, 0.0), prop_speed_rad_s=(w, 50.0, w), joint_pos_rad=tuple(qj[:3].tolist()),
                      joint_rate_rad_s=tuple(qj[3:].tolist()))
        _, st = core.step(s, Setpoint((0.0, 0.0, -2.0), 0.0, 0.0), engaged=True)
        assert st.indi is not None
        out.append(float(st.indi.delta_acc[1]))
        ff.append(st.ff)
    return out, ff


# A first move (0.35 -> 0 at 0.1 s) that earns the preview its trust, then the reversal 0 -> -0.35 at 1.0 s.
_EARN_PLAN = plan_rows(((0.0, 0.0, (0.35,) * 3, (0.35,) * 3), (0.1, 0.1, (0.35,) * 3, (0.0,) * 3),
                        (1.0, 1.0, (0.0,) * 3, (-0.35,) * 3)))


def test_controller_leans_against_a_coming_reversal(cfg: VehicleConfig) -> None:
    ff1, _ = _fly(_core(cfg, 1), cfg, 40)
    ff2_no_plan, _ = _fly(_core(cfg, 2), cfg, 40)
    assert ff2_no_plan == ff1  # no plan: the measured reaction, as INDI_ARM_FF = 1
    joints = _plant_joints(_EARN_PLAN, 110)
    ff1, _ = _fly(_core(cfg, 1), cfg, 110, joints)
    core = _core(cfg, 2)
    core.set_arm_plan(_EARN_PLAN)
    ff2, st = _fly(core, cfg, 110, joints)
    # the first move earned full trust; at rest before 1.0 s - lead both fly the same; from 0.96 s on the command
    # carries the arm's coming reaction while the joints are still measured at rest (the plan alone moves it)
    assert st[90].arm_trust == 1.0 and st[90].arm_drops == 0
    assert ff2[60:94] == pytest.approx(ff1[60:94], abs=1e-6)
    assert max(abs(a - b) for a, b in zip(ff2[96:100], ff1[96:100], strict=True)) > 5.0


def test_preview_untrusted_until_a_move_agrees(cfg: VehicleConfig) -> None:
    """Trust is earned by arm motion that agrees with the model: a reversal coming before any move is flown on the
    measured reaction (INDI_ARM_FF = 1) exactly."""
    ff1, _ = _fly(_core(cfg, 1), cfg, 40)
    core = _core(cfg, 2)
    core.set_arm_plan(plan_rows(((0.0, 0.0, (0.35,) * 3, (0.35,) * 3), (0.30, 0.30, (0.35,) * 3, (-0.35,) * 3))))
    ff2, st = _fly(core, cfg, 30)
    assert ff2 == pytest.approx(ff1[:30], abs=1e-9) and st[-1].arm_trust == 0.0


@pytest.mark.parametrize("scale", [0.2, 2.0])
def test_a_servo_off_its_model_loses_trust_and_is_identified(cfg: VehicleConfig, scale: float) -> None:
    """A servo 5x slower or 2x faster than the data sheet (ARM_SERVO_*): the first move disagrees within two ticks
    of its start and trust is withdrawn; the limits are identified from that move (within 10 %), so the second
    move agrees with the model and earns trust back."""
    amax, vmax = A_MAX * scale, V_MAX * scale
    # 1.4 rad moves: long enough to reach the rate limit at either speed
    plan = plan_rows(((0.0, 0.0, (0.0,) * 3, (0.0,) * 3), (0.1, 0.1, (0.0,) * 3, (1.4,) * 3),
                      (2.0, 2.0, (1.4,) * 3, (0.0,) * 3)))
    n = 350
    joints = _plant_joints(plan, n, amax, vmax)
    core = _core(cfg, 2)
    core.set_arm_plan(plan)
    _, st = _fly(core, cfg, n, joints)
    first_bad = next(i for i, s in enumerate(st) if s.arm_drops > 0 or s.arm_err_rad_s > 0.3 + 0.15 * vmax)
    assert 10 <= first_bad <= 13  # the move starts at 0.10 s
    assert all(s.arm_trust == 0.0 for s in st[first_bad:150])
    assert st[199].arm_v_hat_rad_s == pytest.approx(vmax, rel=0.1)
    assert st[199].arm_a_hat_rad_s2 == pytest.approx(amax, rel=0.1)
    assert st[199].arm_idents >= 1
    drops = st[199].arm_drops
    assert st[-1].arm_drops == drops and st[-1].arm_trust == 1.0  # the second move agreed and earned trust


def test_a_new_flight_earns_trust_again_and_keeps_the_identified_servo(cfg: VehicleConfig) -> None:
    """reset() (arming) withdraws the trust the last flight earned; the servo limits it identified stay."""
    plan = plan_rows(((0.0, 0.0, (0.0,) * 3, (0.0,) * 3), (0.1, 0.1, (0.0,) * 3, (1.4,) * 3),
                      (2.0, 2.0, (1.4,) * 3, (0.0,) * 3)))
    n = 350
    joints = _plant_joints(plan, n, A_MAX * 2.0, V_MAX * 2.0)
    core = _core(cfg, 2)
    core.set_arm_plan(plan)
    _, st = _fly(core, cfg, n, joints)
    assert st[-1].arm_trust == 1.0
    core.reset()
    _, st2 = _fly(core, cfg, 2, joints[-2:])
    assert st2[-1].arm_trust == 0.0
    assert st2[-1].arm_v_hat_rad_s == pytest.approx(st[-1].arm_v_hat_rad_s)


def test_a_stalled_joint_withdraws_the_preview(cfg: VehicleConfig) -> None:
    plan = plan_rows(((0.0, 0.0, (0.0,) * 3, (0.0,) * 3), (0.1, 0.1, (0.0,) * 3, (0.7,) * 3),
                      (1.0, 1.0, (0.7,) * 3, (-0.7,) * 3)))
    joints = _plant_joints(plan, 150, stall=(1, 1.05))
    core = _core(cfg, 2)
    core.set_arm_plan(plan)
    _, st = _fly(core, cfg, 150, joints)
    assert st[95].arm_trust == 1.0  # the first move earned it
    assert st[108].arm_trust == 0.0 and st[-1].arm_trust == 0.0
