"""Command shaping (outer_loop.shape_reference, OL_JERK_MAX / OL_ATT_ACC_REF) against independent checks: finite
differences of its own outputs, the ZYX Euler kinematics (scipy), the limits it promises, and the controller's
commanded attitude with and without it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_modes import armed_on_ground, fly

from navig8_fc.core import outer_loop
from navig8_fc.core.controller import ControllerConfig, FcSensors, FlightControllerCore
from navig8_fc.core.outer_loop import (
    JERK_K_PER_VEL_K,
    SH,
    OuterLoopConfig,
    Setpoint,
    shape_reference,
    shaper_config_array,
)
from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.modes import FlightMode, ModeInputs, Px4AutoSubMode, Px4MainMode
from navig8_fc.modes.braking import braking_distance_m
from navig8_fc.params.registry import ParamRegistry

DT = 0.01
G = 9.80665
J_MAX, A_REF, V_MAX = 5.0, 2.0, 2.0
OL = OuterLoopConfig(1.0, 3.0, V_MAX, 4.0, 4.0, 8.0, 2.0, G, jerk_max_m_s3=J_MAX, ref_acc_max_m_s2=A_REF,
                     att_rate_ref_rad_s=0.6, att_acc_ref_rad_s2=1.0, ff_level=2)


def _fly(cfg: OuterLoopConfig, sp: np.ndarray, n: int, start_yaw: float = 0.0, pos=None) -> dict[str, np.ndarray]:
    """The reference alone over n ticks; the vehicle is taken to sit on it (no time stretch) unless pos is given."""
    shc = shaper_config_array(cfg, DT)
    st = SH.zeros()
    quat = np.array(Rotation.from_euler("ZYX", [start_yaw, 0.0, 0.0]).as_quat(scalar_first=True))
    p = np.zeros(3) if pos is None else np.asarray(pos, dtype=float)
    out = {k: [] for k in ("pos", "vel", "acc", "pitch", "yaw", "rate", "ang_acc")}
    sp_out, ff = outer_loop.OSP.zeros(), outer_loop.OFF.zeros()
    for _ in range(n):
        shape_reference(shc, st, sp, p if pos is not None else st[SH.POS:SH.POS + 3].copy(), np.zeros(3), quat,
                        sp_out, ff)
        out["pos"].append(sp_out[0:3].copy())
        out["pitch"].append(sp_out[3])
        out["yaw"].append(sp_out[4])
        for k in ("vel", "acc", "rate", "ang_acc"):
            out[k].append(ff[getattr(outer_loop.OFF, k.upper()).sl].copy())
    return {k: np.array(v) for k, v in out.items()}


def _osp(pos, pitch=0.0, yaw=0.0) -> np.ndarray:
    return outer_loop.OSP.pack(pos=pos, pitch=pitch, yaw=yaw)


def test_position_step_respects_the_limits_and_arrives() -> None:
    r = _fly(OL, _osp((2.0, 0.0, 0.0)), 800)
    p, v, a = r["pos"][:, 0], r["vel"][:, 0], r["acc"][:, 0]
    jerk = np.diff(a) / DT
    assert np.max(np.abs(jerk)) <= J_MAX * (1 + 1e-9)
    assert np.max(np.abs(a)) <= A_REF * (1 + 1e-9)
    assert np.max(np.abs(v)) <= V_MAX
    # the feed-forwards are the reference's own derivatives (central differences, exact integration over a tick)
    np.testing.assert_allclose((p[2:] - p[:-2]) / (2 * DT), v[1:-1], atol=2e-3)
    np.testing.assert_allclose((v[2:] - v[:-2]) / (2 * DT), a[1:-1], atol=3e-2)
    assert abs(p[-1] - 2.0) < 1e-3 and abs(v[-1]) < 1e-3
    assert np.max(p) < 2.0 + 0.05  # well damped: no more than 5 cm past the target
    assert np.all(r["pos"][:, 1:] == 0.0)


def test_attitude_feedforward_matches_the_euler_kinematics() -> None:
    """A combined roll (from a sideways step), pitch and yaw motion: the body-rate feed-forward equals the ZYX
    kinematics p = phi' - psi' sin(theta), q = theta' cos(phi) + psi' sin(phi) cos(theta), r = -theta' sin(phi) +
    psi' cos(phi) cos(theta) of the reference's Euler angles (scipy), whose rates are central differences."""
    r = _fly(OL, _osp((0.0, 2.0, 0.0), pitch=0.6, yaw=1.2), 300)
    # the reference attitude from its own definition: roll such that the body has no y specific force
    acc = r["acc"]
    eul = []
    for a, th, ps in zip(acc, r["pitch"], r["yaw"], strict=True):
        f = np.array([a[0], a[1], a[2] - G])
        rz = Rotation.from_euler("ZYX", [ps, th, 0.0])
        fl = rz.inv().apply(f)  # in the yawed-and-pitched frame
        eul.append((math.atan2(fl[1], -fl[2]), th, ps))
        body_f = Rotation.from_euler("ZYX", [ps, th, eul[-1][0]]).inv().apply(f)
        assert abs(body_f[1]) < 1e-9
    eul = np.unwrap(np.array(eul), axis=0)
    d = (eul[2:] - eul[:-2]) / (2 * DT)
    phi, th = eul[1:-1, 0], eul[1:-1, 1]
    pqr = np.column_stack([d[:, 0] - d[:, 2] * np.sin(th),
                           d[:, 1] * np.cos(phi) + d[:, 2] * np.sin(phi) * np.cos(th),
                           -d[:, 1] * np.sin(phi) + d[:, 2] * np.cos(phi) * np.cos(th)])
    # the feed-forward is the backward difference over the tick: compare at the midpoint
    ff_mid = 0.5 * (r["rate"][1:-1] + r["rate"][2:])
    assert np.max(np.abs(pqr)) > 0.3  # it does move
    np.testing.assert_allclose(ff_mid[1:], pqr[1:], atol=0.02)
    # angular acceleration: the rate's change per tick, bounded (the jerk is rate-limited: no impulses)
    np.testing.assert_allclose(r["ang_acc"][2:], np.diff(r["rate"], axis=0)[1:] / DT, atol=1e-9)
    assert np.max(np.abs(r["ang_acc"])) < 10.0


def test_pitch_yaw_reference_limits_and_short_way() -> None:
    r = _fly(OL, _osp((0.0, 0.0, 0.0), pitch=math.radians(45), yaw=math.radians(-170)), 600,
             start_yaw=math.radians(170))
    yaw = np.unwrap(r["yaw"])
    assert yaw[-1] == pytest.approx(math.radians(190), abs=1e-6)  # 170 -> 190 (= -170) deg: +20 across +-180, not -340
    for x in (np.asarray(r["pitch"]), yaw):
        w = np.diff(x) / DT
        assert np.max(np.abs(w)) <= 0.6 + 1e-9
        assert np.max(np.abs(np.diff(w) / DT)) <= 1.0 + 1e-6
    assert r["pitch"][-1] == pytest.approx(math.radians(45), abs=1e-9)
    assert np.max(r["pitch"]) <= math.radians(45) + 1e-5  # no overshoot (but the dead-beat arrival's rounding)


def test_reference_waits_for_a_vehicle_left_behind() -> None:
    cfg = OuterLoopConfig(**{**OL.__dict__, "err_max_m": 0.5})
    r = _fly(cfg, _osp((5.0, 0.0, 0.0)), 600, pos=(0.0, 0.0, 0.0))  # the vehicle never moves
    assert np.max(r["pos"][:, 0]) <= 0.5
    r = _fly(OL, _osp((5.0, 0.0, 0.0)), 600, pos=(0.0, 0.0, 0.0))  # without the stretch it runs away
    assert r["pos"][-1, 0] > 4.0


def _core(**shaping: float) -> tuple[FlightControllerCore, VehicleConfig]:
    vehicle = VehicleConfig.load()
    values = ParamRegistry.from_defaults().as_dict()
    values.update(shaping)
    return FlightControllerCore(vehicle, ControllerConfig.from_params(values, vehicle)), vehicle


def _hover_sensors(vehicle: VehicleConfig, t: float, pos=(0.0, 0.0, -2.0)) -> FcSensors:
    w = 620.0
    return FcSensors(t_s=t, gyro_frd_rad_s=(0.0, 0.0, 0.0), accel_frd_m_s2=(0.0, 0.0, -vehicle.gravity_m_s2),
                     pos_ned_m=pos,
                     vel_ned_m_s=(0.0, 0.0, 0.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0), duct_tilt_rad=(0.0, 0.0),
                     prop_speed_rad_s=(w, 0.0, w), joint_pos_rad=(0.0, 0.0, 0.0), joint_rate_rad_s=(0.0, 0.0, 0.0))


def _roll_cmds(core: FlightControllerCore, vehicle: VehicleConfig, n: int) -> np.ndarray:
    """Commanded roll (deg) over n ticks of a sideways 2 m step from a steady hover (the vehicle held still)."""
    rolls = []
    for i in range(n):
        sp = Setpoint((0.0, 0.0, -2.0) if i < 10 else (0.0, 2.0, -2.0))
        _, st = core.step(_hover_sensors(vehicle, i * DT), sp)
        rolls.append(math.degrees(st.outer.roll_cmd_rad))
    return np.array(rolls)


def test_controller_position_step_no_longer_steps_the_attitude_command() -> None:
    paper, vehicle = _core(OL_JERK_MAX=0.0, OL_ATT_ACC_REF=0.0)  # the paper's stateless loop
    roll = _roll_cmds(paper, vehicle, 60)
    assert np.max(np.abs(np.diff(roll))) > 20.0  # the paper's loop: atan(OL_ACC_MAX / g) in one tick
    shaped, _ = _core(OL_JERK_MAX=J_MAX, OL_ACC_REF=A_REF)
    roll = _roll_cmds(shaped, vehicle, 60)
    # tilt rate about j_max / g = 0.5 rad/s, plus the feedback on the (held) vehicle's growing lag
    assert np.max(np.abs(np.diff(roll))) < 1.0
    assert np.max(np.abs(roll)) > 5.0  # and it does tilt toward the step


def test_controller_seeds_the_reference_from_the_vehicle() -> None:
    """Engaging (or arming) far from the setpoint: the first tick's reference is where the vehicle is, so the
    commanded attitude starts level. A mode change (resync) in the middle of a move, with the vehicle on its
    reference, keeps the reference's acceleration, so the commanded attitude does not step either."""
    core, vehicle = _core(OL_JERK_MAX=J_MAX, OL_ACC_REF=A_REF)
    core.step(_hover_sensors(vehicle, 0.0), Setpoint((0.0, 0.0, -2.0)), engaged=False)
    _, st = core.step(_hover_sensors(vehicle, DT, pos=(0.0, -3.0, -2.0)), Setpoint((0.0, 0.0, -2.0)))
    assert abs(math.degrees(st.outer.roll_cmd_rad)) < 0.5
    rolls = []
    for i in range(2, 80):
        if i == 40:
            core.resync_reference()
        # the vehicle flies its reference exactly (the shaped setpoint and velocity of the last tick)
        s = replace(_hover_sensors(vehicle, i * DT), pos_ned_m=tuple(core._shape_sp[0:3]),
                    vel_ned_m_s=tuple(core._shape_ff[0:3]))
        _, st = core.step(s, Setpoint((0.0, 0.0, -2.0)))
        rolls.append(math.degrees(st.outer.roll_cmd_rad))
    assert np.max(np.abs(rolls)) > 3.0
    assert np.max(np.abs(np.diff(rolls))) < 0.5


def _reference_from(v0_m_s: float, a0_m_s2: float, target_y_m: float, n: int = 800) -> np.ndarray:
    """The shaped reference's east position, started at the origin moving east at v0 and accelerating at a0 (the
    state a mode change resyncs it to), flying to a setpoint target_y east."""
    shc = shaper_config_array(OL, DT)
    st = SH.zeros()
    st[SH.INIT], st[SH.VEL + 1], st[SH.ACC + 1] = 1.0, v0_m_s, a0_m_s2
    quat = np.array([1.0, 0.0, 0.0, 0.0])
    sp, sp_out, ff = _osp((0.0, target_y_m, 0.0)), outer_loop.OSP.zeros(), outer_loop.OFF.zeros()
    ys = []
    for _ in range(n):
        shape_reference(shc, st, sp, st[SH.POS:SH.POS + 3].copy(), st[SH.VEL:SH.VEL + 3].copy(), quat, sp_out, ff)
        ys.append(sp_out[1])
    return np.array(ys)


@pytest.mark.parametrize("v0", [0.25, 1.0, 2.0])
@pytest.mark.parametrize("a0", [-2.0, 0.0, 2.0])
def test_hold_entered_at_speed_stops_ahead_without_turning_back(v0: float, a0: float) -> None:
    """Hold entered while the reference flies east at v0, accelerating at a0, holds at the stopping point of the
    reference's braking limits: the shaped reference brakes to it and stays (backs up by at most 5 cm, against
    12-30 cm for the time-optimal distance without the jerk stage's lag); holding the entry point itself would fly
    past it and back by most of the braking distance."""
    mm, body, t = armed_on_ground()
    mm.set_braking(A_REF, J_MAX, 1.0 / (JERK_K_PER_VEL_K * OL.vel_k))
    mm.takeoff(3.0)
    _outs, t = fly(mm, body, t, 1.5)  # still climbing: Hold is a mode change
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER).ok
    here = tuple(body.pos)
    out = mm.step(ModeInputs(t, here, (0.0, v0, 0.0), 0.0, 1.0, accel_ned_m_s2=(0.0, a0, 0.0)))
    assert out.flight_mode is FlightMode.HOLD
    ahead_m = out.setpoint.pos_ned_m[1] - here[1]
    assert out.setpoint.pos_ned_m[0] == pytest.approx(here[0]) and out.setpoint.pos_ned_m[2] == pytest.approx(here[2])
    ys = _reference_from(v0, a0, ahead_m)
    assert ys.max() - ys[-1] < 0.05 and abs(ys[-1] - ahead_m) < 0.02, (ys.max(), ys[-1], ahead_m)
    entry = _reference_from(v0, a0, 0.0)  # the entry point as the hold target
    assert entry.max() - entry[-1] > 0.5 * ahead_m  # it turns back


def _time_optimal_brake_m(v0: float, a0: float, acc_max: float, jerk_max: float, dt: float = 1e-5) -> float:
    """The braking distance by integration: the acceleration heads for -acc_max at jerk_max until the ramp back to
    zero would take exactly the speed left (v <= a^2 / (2 j)), then ramps back."""
    s, v, a = 0.0, v0, a0
    while v > 0.0:
        ramp_out = a < 0.0 and v <= a * a / (2.0 * jerk_max)
        jerk = jerk_max if ramp_out else (-jerk_max if a > -acc_max else 0.0)
        a_next = a + jerk * dt if not ramp_out else min(a + jerk * dt, 0.0)
        if not ramp_out and jerk < 0.0:
            a_next = max(a_next, -acc_max)
        s += v * dt + 0.5 * a * dt * dt
        v += 0.5 * (a + a_next) * dt
        a = a_next
        if ramp_out and a == 0.0:
            break
    return s


@pytest.mark.parametrize(("v0", "a0"), [(0.1, 0.0), (2.0, 0.0), (0.5, 2.0), (2.0, 1.0), (1.0, -1.0), (3.0, -0.5)])
def test_braking_distance_matches_an_integrated_time_optimal_brake(v0: float, a0: float) -> None:
    """braking_distance_m's closed form (trapezoid or triangle of acceleration) against a fine Euler integration of
    the same bang-bang jerk law, and with no jerk limit v^2 / (2 A); the reaction lag adds the distance flown
    while it lasts."""
    a_max, j_max = 2.0, 5.0
    assert braking_distance_m(v0, a0, a_max, j_max) == pytest.approx(_time_optimal_brake_m(v0, a0, a_max, j_max),
                                                                      abs=2e-3)
    assert braking_distance_m(v0, a0, a_max, math.inf) == pytest.approx(v0 * v0 / (2 * a_max))
    lag = 0.1
    v_lag = v0 + a0 * lag
    assert braking_distance_m(v0, a0, a_max, j_max, lag) == pytest.approx(
        v0 * lag + 0.5 * a0 * lag * lag + _time_optimal_brake_m(v_lag, a0, a_max, j_max), abs=2e-3)
