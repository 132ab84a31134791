"""Mode manager: PX4 mode encoding, pre-arm checks, takeoff -> hold, land -> disarm, scripted missions."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.flight.commands import Arm, CancelTask, Disarm, Land, ReturnToLaunch, SetMode, Takeoff
from navig8_fc.modes import (
    FlightMode,
    MavLandedState,
    MavModeFlag,
    MavState,
    MissionScript,
    ModeConfig,
    ModeInputs,
    ModeManager,
    Px4AutoSubMode,
    Px4MainMode,
    decode_px4_custom_mode,
    px4_custom_mode,
)
from navig8_fc.modes.records import Verdict

DT = 0.01
GROUND_Z = 0.0


class PointMass:
    """A vehicle that follows the setpoint at a bounded speed when engaged and rests on the ground (z >= 0)."""

    def __init__(self, pos=(0.0, 0.0, GROUND_Z), speed_m_s: float = 1.5) -> None:
        self.pos = list(pos)
        self.vel = [0.0, 0.0, 0.0]
        self.speed = speed_m_s
        self.thrust_ratio = 0.0

    def inputs(self, t: float, **kw) -> ModeInputs:
        return ModeInputs(t, tuple(self.pos), tuple(self.vel), 0.0, kw.pop("thrust_ratio", self.thrust_ratio), **kw)

    def move(self, engaged: bool, sp: Setpoint) -> None:
        if not engaged:
            self.vel = [0.0, 0.0, 0.0] if self.pos[2] >= GROUND_Z else [0.0, 0.0, 9.81 * DT + self.vel[2]]
            self.thrust_ratio = 0.0
        else:
            err = [sp.pos_ned_m[i] - self.pos[i] for i in range(3)]
            self.vel = [max(-self.speed, min(self.speed, 2.0 * e)) for e in err]
            self.thrust_ratio = 1.0
        self.pos = [self.pos[i] + self.vel[i] * DT for i in range(3)]
        if self.pos[2] >= GROUND_Z:  # the ground stops the vehicle and carries its weight
            self.pos[2] = GROUND_Z
            if self.vel[2] > 0:
                self.vel[2] = 0.0
                self.thrust_ratio = 0.1 if engaged else 0.0


def modes_command(mm: ModeManager, cmd: object) -> Verdict | None:
    """A flight command record applied to a ModeManager as FlightStack.command does (the fakes of the GCS tests);
    None for a record the mode manager does not take (arm and gripper, offboard, missions)."""
    match cmd:
        case Arm(force=force):
            return mm.arm(force)
        case Disarm(force=force):
            return mm.disarm(force)
        case Takeoff(alt_m=alt):
            return mm.takeoff(alt)
        case Land():
            return mm.land()
        case SetMode(custom_mode=custom):
            return mm.set_custom_mode(custom)
        case ReturnToLaunch():
            return mm.return_to_launch()
        case CancelTask(channel=channel):  # arm moves are not tracked by the mode manager
            return Verdict(channel == "flight" and mm.cancel_task())
    return None


def fly(mm: ModeManager, body: PointMass, t0: float, seconds: float, zs: list[float] | None = None, **kw):
    """Step the manager and the body for `seconds`; `zs` collects the body's z seen by each step."""
    outs = []
    n = int(round(seconds / DT))
    for k in range(n):
        if zs is not None:
            zs.append(body.pos[2])
        out = mm.step(body.inputs(t0 + k * DT, **kw))
        body.move(out.engaged, out.setpoint)
        outs.append(out)
    return outs, t0 + n * DT


# --- encoding -------------------------------------------------------------------------------------------
def test_px4_custom_mode_encoding() -> None:
    assert px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER) == 0x03040000  # Hold: (4 << 16) | (3 << 24)
    assert FlightMode.HOLD.custom_mode == 0x03040000
    assert FlightMode.MISSION.custom_mode == 0x04040000
    assert FlightMode.TAKEOFF.custom_mode == 0x02040000
    assert FlightMode.LAND.custom_mode == 0x06040000
    assert FlightMode.READY.custom_mode == 0x01040000
    for mode in FlightMode:
        assert decode_px4_custom_mode(mode.custom_mode) == (mode.main, mode.sub)
        assert FlightMode.from_px4(mode.main, mode.sub) is mode
    assert FlightMode.from_px4(Px4MainMode.ALTCTL, 0) is None
    with pytest.raises(ValueError):
        px4_custom_mode(256, 0)


def test_mavlink_enum_values_match_pymavlink() -> None:
    assert MavModeFlag.CUSTOM_MODE_ENABLED == mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert MavModeFlag.SAFETY_ARMED == mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    for s in MavState:
        assert s == getattr(mavlink2, f"MAV_STATE_{s.name}")
    for s in MavLandedState:
        assert s == getattr(mavlink2, f"MAV_LANDED_STATE_{s.name}")


# --- arming -----------------------------------------------------------------------------------------------
def test_arm_denied_without_data_and_on_failed_prearm_checks() -> None:
    mm = ModeManager()
    ok, reason = mm.arm()
    assert not ok and "no sensor data" in reason
    body = PointMass()
    mm.step(body.inputs(0.0, sensors_ok=False))
    ok, reason = mm.arm()
    assert not ok and reason.startswith("Arming denied") and "sensors" in reason
    assert not mm.armed
    mm.step(body.inputs(0.01, estimator_ready=False))
    ok, reason = mm.arm()
    assert not ok and "estimator" in reason
    assert mm.prearm_check().ok is False


def test_shell_faults_fail_prearm_and_make_an_armed_vehicle_critical_between_steps() -> None:
    """A fault the shell finds on the wall clock (no bundles: no steps) acts at once, without a step."""
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    assert mm.prearm_check().ok and mm.system_status == MavState.STANDBY
    mm.set_fault("sensors", "no sensor data from navig8-bridge for 0.5 s")
    check = mm.prearm_check()
    assert not check.ok and "navig8-bridge" in check.reason
    ok, reason = mm.arm()
    assert not ok and reason == "Arming denied: no sensor data from navig8-bridge for 0.5 s" and not mm.armed
    assert mm.system_status == MavState.STANDBY  # disarmed: standby, but not armable
    assert mm.clear_fault("sensors") and not mm.clear_fault("sensors")
    assert mm.arm().ok and mm.system_status == MavState.ACTIVE
    mm.set_fault("rate", "control rate mismatch")
    assert mm.system_status == MavState.CRITICAL  # armed with a fault, before any further step
    assert mm.step(body.inputs(0.01)).system_status == MavState.CRITICAL
    ok, reason = mm.takeoff(2.0)
    assert not ok and "control rate mismatch" in reason
    assert mm.faults == {"rate": "control rate mismatch"}
    mm.clear_fault("rate")
    assert mm.system_status == MavState.ACTIVE and mm.step(body.inputs(0.02)).system_status == MavState.ACTIVE


def test_arm_denied_when_not_on_ground_unless_forced() -> None:
    mm = ModeManager()
    body = PointMass(pos=(0.0, 0.0, -3.0))
    body.vel = [0.0, 0.0, 1.0]
    mm.step(body.inputs(0.0, thrust_ratio=1.0))
    ok, reason = mm.arm()
    assert not ok and "ground" in reason
    ok, _ = mm.arm(force=True)
    assert ok and mm.armed
    out = mm.step(body.inputs(0.01, thrust_ratio=1.0))
    assert out.flight_mode is FlightMode.HOLD and out.engaged  # a forced arm in the air holds position


def test_arm_sets_home_and_base_mode() -> None:
    mm = ModeManager()
    body = PointMass(pos=(1.0, 2.0, 0.0))
    out = mm.step(body.inputs(0.0))
    assert out.landed and out.landed_state == MavLandedState.ON_GROUND
    assert out.system_status == MavState.STANDBY
    assert out.base_mode == MavModeFlag.CUSTOM_MODE_ENABLED and not out.armed
    assert out.home_ned_m == (1.0, 2.0, 0.0)  # a home before arming, so GCSs can show one
    assert mm.prearm_check().ok
    assert mm.arm() == (True, "")
    out = mm.step(body.inputs(0.01))
    assert out.armed and out.base_mode == MavModeFlag.CUSTOM_MODE_ENABLED | MavModeFlag.SAFETY_ARMED
    assert out.system_status == MavState.ACTIVE
    assert out.flight_mode is FlightMode.READY and not out.engaged
    assert "Armed" in out.events
    assert mm.arm().ok  # idempotent


def test_disarm_in_air_denied_unless_forced() -> None:
    mm, body, t = armed_on_ground()
    assert mm.takeoff(2.0).ok
    _, t = fly(mm, body, t, 4.0)
    ok, reason = mm.disarm()
    assert not ok and "not landed" in reason
    assert mm.disarm(force=True).ok and not mm.armed


def armed_on_ground():
    """A manager armed on the ground with its point mass and time (test_command_shaping.py uses it too)."""
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    assert mm.arm().ok
    mm.step(body.inputs(DT))
    return mm, body, 2 * DT


# --- takeoff / hold / land ---------------------------------------------------------------------------
def test_takeoff_requires_armed_and_valid_altitude() -> None:
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    ok, reason = mm.takeoff(2.0)
    assert not ok and "not armed" in reason
    mm.arm()
    assert not mm.takeoff(-1.0).ok
    assert not mm.takeoff(1000.0).ok


def test_takeoff_climbs_then_holds() -> None:
    mm, body, t = armed_on_ground()
    assert mm.takeoff(2.0).ok
    body_z: list[float] = []
    outs, t = fly(mm, body, t, 6.0, body_z)
    modes = [o.flight_mode for o in outs]
    assert modes[0] is FlightMode.TAKEOFF and modes[-1] is FlightMode.HOLD
    assert outs[0].landed_state == MavLandedState.TAKEOFF
    # The setpoint ramps (no 2 m step) at the configured climb rate.
    zs = [o.setpoint.pos_ned_m[2] for o in outs if o.flight_mode is FlightMode.TAKEOFF]
    assert max(abs(b - a) for a, b in zip(zs, zs[1:], strict=False)) <= ModeConfig().takeoff_climb_rate_m_s * DT + 1e-12
    i_hold = modes.index(FlightMode.HOLD)
    assert abs(body_z[i_hold] - (-2.0)) < 0.2  # within tolerance when the switch happened
    assert abs(body_z[i_hold - 1] - (-2.0)) >= 0.2 or zs[-1] != -2.0  # and not before
    assert outs[-1].setpoint.pos_ned_m[2] == pytest.approx(-2.0)
    assert outs[-1].landed_state == MavLandedState.IN_AIR
    assert outs[-1].custom_mode == 0x03040000
    assert any("Takeoff complete" in e for o in outs for e in o.events)
    assert abs(body.pos[2] + 2.0) < 0.05


def test_land_descends_then_disarms_after_touchdown_plus_delay() -> None:
    mm, body, t = armed_on_ground()
    mm.takeoff(2.0)
    _, t = fly(mm, body, t, 6.0)
    assert mm.land().ok
    outs, t = fly(mm, body, t, 10.0)
    assert outs[0].flight_mode is FlightMode.LAND and outs[0].landed_state == MavLandedState.LANDING
    i_landed = next(i for i, o in enumerate(outs) if "Landed" in o.events)
    i_disarm = next(i for i, o in enumerate(outs) if not o.armed)
    dt_disarm = outs[i_disarm].t_s - outs[i_landed].t_s
    assert 1.0 - 1e-9 <= dt_disarm <= 1.0 + 2 * DT
    assert not outs[i_landed].engaged  # motors idle at touchdown
    assert "Disarmed after landing" in outs[i_disarm].events
    assert outs[-1].flight_mode is FlightMode.READY and outs[-1].landed_state == MavLandedState.ON_GROUND
    descent = [o.setpoint.pos_ned_m[2] for o in outs[:i_landed] if o.engaged]
    assert all(b - a <= ModeConfig().land_descent_rate_m_s * DT + 1e-12 for a, b in zip(descent, descent[1:],
                                                                                         strict=False))


class ThrustingAtContact(PointMass):
    """A vehicle whose controller keeps its thrust up when the ground stops it (an INDI answering the impact)."""

    def move(self, engaged: bool, sp: Setpoint) -> None:
        super().move(engaged, sp)
        if engaged:
            self.thrust_ratio = 1.0


def test_land_touches_down_at_ground_contact_without_waiting_for_the_thrust_cue() -> None:
    # The thrust cue never comes here (thrust/weight stays 1 on the ground), and the detector's hold would come
    # too late for a real INDI anyway: at home height and no longer descending, LAND idles within one step.
    mm, body, t = armed_on_ground()
    body.__class__ = ThrustingAtContact
    mm.takeoff(2.0)
    _, t = fly(mm, body, t, 6.0)
    assert mm.land().ok
    zs: list[float] = []
    outs, t = fly(mm, body, t, 8.0, zs)
    i_contact = next(i for i, z in enumerate(zs) if z >= GROUND_Z)
    i_landed = next(i for i, o in enumerate(outs) if "Landed" in o.events)
    assert i_landed - i_contact <= 1 and not outs[i_landed].engaged
    assert not outs[-1].armed and outs[-1].flight_mode is FlightMode.READY


@pytest.mark.parametrize(("z", "ticks"), [
    (1.0, 300),  # home on a roof: 1 m below home height, no ground holds it up while the setpoint is followed
    (0.05, 5),  # near home height, but the setpoint has not got ahead of the vehicle yet: nothing holds it up
])
def test_land_below_home_height_does_not_cut_the_motors_in_the_air(z: float, ticks: int) -> None:
    # The vehicle hovers still at z (NED, home at 0) with its thrust carrying its weight while LAND descends.
    mm, body, t = armed_on_ground()
    mm.takeoff(2.0)
    _, t = fly(mm, body, t, 6.0)
    assert mm.land().ok
    for k in range(ticks):
        out = mm.step(ModeInputs(t + k * DT, (0.0, 0.0, z), (0.0, 0.0, 0.0), 0.0, 1.0))
        assert out.engaged and "Landed" not in out.events, k


def test_land_denied_when_disarmed_and_idempotent() -> None:
    mm = ModeManager()
    mm.step(PointMass().inputs(0.0))
    assert not mm.land().ok
    mm, body, t = armed_on_ground()
    mm.takeoff(2.0)
    _, t = fly(mm, body, t, 6.0)
    assert mm.land().ok and mm.land().ok
    outs, _ = fly(mm, body, t, 0.5)
    assert [e for o in outs for e in o.events].count("Landing") == 1


def test_set_mode_hold_and_denials() -> None:
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    # Hold can be selected while disarmed (PX4): the controller stays idle, the mode is reported.
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER).ok
    out = mm.step(body.inputs(0.005))
    assert out.flight_mode is FlightMode.HOLD and not out.engaged and not out.armed
    ok, reason = mm.set_mode(Px4MainMode.ALTCTL, 0)
    assert not ok and "ALTCTL" in reason
    ok, reason = mm.set_mode(Px4MainMode.POSCTL, 0)
    assert not ok and "not flying" in reason
    mm.arm()
    ok, reason = mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.MISSION)
    assert not ok and "no mission" in reason
    # Hold on the ground stays idle (PX4 does not take off in Hold).
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER).ok
    out = mm.step(body.inputs(0.01))
    assert out.flight_mode is FlightMode.HOLD and not out.engaged and out.landed_state == MavLandedState.ON_GROUND
    # Takeoff and Land through set_mode.
    assert mm.set_custom_mode(FlightMode.TAKEOFF.custom_mode).ok
    outs, t = fly(mm, body, 0.02, 6.0)
    assert outs[-1].flight_mode is FlightMode.HOLD and abs(body.pos[2] + ModeConfig().takeoff_default_alt_m) < 0.05
    ok, reason = mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.READY)
    assert not ok and "ground" in reason
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND).ok
    outs, _ = fly(mm, body, t, 12.0)
    assert not outs[-1].armed


def test_hold_in_air_keeps_position_where_entered() -> None:
    mm, body, t = armed_on_ground()
    mm.takeoff(3.0)
    outs, t = fly(mm, body, t, 1.5)  # still climbing
    assert outs[-1].flight_mode is FlightMode.TAKEOFF
    z_now = body.pos[2]
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER).ok
    out = mm.step(body.inputs(t))
    assert out.flight_mode is FlightMode.HOLD and out.engaged
    assert out.setpoint.pos_ned_m[2] == pytest.approx(z_now)


# --- scripted missions -------------------------------------------------------------------------------------
def _paper_like_script(duration: float = 3.0) -> MissionScript:
    def sp(t: float) -> Setpoint:
        return Setpoint((0.0, 2.0 if t >= 1.0 else 0.0, -2.0), 0.0, math.pi / 2)

    return MissionScript("paper", sp, starts_armed_in_air=True, duration_s=duration)


def test_air_start_script_follows_setpoints_on_sim_time() -> None:
    script = _paper_like_script()
    mm = ModeManager(script=script)
    assert mm.armed and mm.flight_mode is FlightMode.MISSION
    body = PointMass(pos=(0.0, 0.0, -2.0))
    body.thrust_ratio = 1.0
    outs, _ = fly(mm, body, 0.0, 2.5)
    assert all(o.armed and o.engaged and o.flight_mode is FlightMode.MISSION for o in outs)
    for o in outs:
        assert o.setpoint == script.setpoint_at(o.t_s)  # mission clock == sim time: same as the in-process run
        assert o.mission_time_s == o.t_s
    assert outs[0].custom_mode == 0x04040000
    assert outs[0].home_ned_m == (0.0, 0.0, 0.0)  # start position projected to the ground
    assert outs[0].landed_state == MavLandedState.IN_AIR


def test_script_completion_holds_at_final_setpoint() -> None:
    script = _paper_like_script(duration=1.5)
    mm = ModeManager(script=script)
    body = PointMass(pos=(0.0, 0.0, -2.0))
    outs, _ = fly(mm, body, 0.0, 2.0)
    assert outs[-1].flight_mode is FlightMode.HOLD and outs[-1].engaged
    assert outs[-1].setpoint == script.setpoint_at(1.5)
    assert any("complete" in e for o in outs for e in o.events)


def test_mission_pause_and_resume() -> None:
    script = _paper_like_script(duration=10.0)
    mm = ModeManager(script=script)
    body = PointMass(pos=(0.0, 0.0, -2.0))
    _, t = fly(mm, body, 0.0, 0.5)
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER).ok
    outs, t = fly(mm, body, t, 1.0)
    assert all(o.flight_mode is FlightMode.HOLD for o in outs)
    assert all(o.setpoint.pos_ned_m[1] == 0.0 for o in outs)  # the t >= 1 s step did not happen in Hold
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.MISSION).ok
    out = mm.step(body.inputs(t))
    assert out.flight_mode is FlightMode.MISSION
    assert out.mission_time_s == pytest.approx(0.5, abs=2 * DT)  # resumed where it paused


# --- land detector and robustness --------------------------------------------------------------------------
def test_land_detector_uses_height_when_thrust_unknown() -> None:
    mm = ModeManager()
    mm.step(ModeInputs(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0))
    assert mm.landed
    mm.step(ModeInputs(0.01, (0.0, 0.0, -2.0), (0.0, 0.0, 0.0), 0.0))
    assert not mm.landed
    # Needs landed_hold_s of quiet samples after the first one.
    t = 0.02
    while t < 0.02 + ModeConfig().landed_hold_s - 1e-9:
        mm.step(ModeInputs(t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0))
        assert not mm.landed
        t += DT
    mm.step(ModeInputs(t + DT, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0))
    assert mm.landed


def test_nan_state_never_becomes_a_setpoint() -> None:
    mm, body, t = armed_on_ground()
    mm.takeoff(2.0)
    _, t = fly(mm, body, t, 6.0)
    out = mm.step(ModeInputs(t, (math.nan, 0.0, -2.0), (0.0, 0.0, 0.0), math.nan, 1.0))
    assert all(math.isfinite(v) for v in (*out.setpoint.pos_ned_m, out.setpoint.yaw_rad))
    assert out.system_status == MavState.CRITICAL


def test_outputs_carry_plain_ints_in_every_mode() -> None:
    mm, body, t = armed_on_ground()
    mm.takeoff(2.0)
    outs, t = fly(mm, body, t, 6.0)
    mm.land()
    more, _ = fly(mm, body, t, 10.0)
    seen = set()
    for o in outs + more:
        seen.add(o.flight_mode)
        assert o.custom_mode == px4_custom_mode(o.flight_mode.main, o.flight_mode.sub)
        for v in (o.custom_mode, o.base_mode, o.landed_state, o.system_status):
            assert type(v) is int
        assert o.base_mode == (MavModeFlag.CUSTOM_MODE_ENABLED | (MavModeFlag.SAFETY_ARMED if o.armed else 0))
        assert type(o.events) is tuple
    assert seen == {FlightMode.TAKEOFF, FlightMode.HOLD, FlightMode.LAND, FlightMode.READY}
    assert [e for o in outs + more for e in o.events].count("Landed") == 1  # events are reported once


def test_mission_resting_on_the_ground_reports_on_ground() -> None:
    mm = ModeManager(script=_paper_like_script(duration=10.0))
    out = mm.step(ModeInputs(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.1))
    assert out.flight_mode is FlightMode.MISSION and out.landed
    assert out.landed_state == MavLandedState.ON_GROUND and out.system_status == MavState.ACTIVE
    assert out.events == ("Mission paper started (armed in the air)",)
    out = mm.step(ModeInputs(0.01, (0.0, 0.0, -1.0), (0.0, 0.0, -1.0), 0.0, 1.0))
    assert out.landed_state == MavLandedState.IN_AIR and out.events == () and out.mission_time_s == 0.01


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("where", range(8))
def test_every_non_finite_state_value_is_caught(where: int, bad: float) -> None:
    mm, body, t = armed_on_ground()
    mm.takeoff(2.0)
    _, t = fly(mm, body, t, 6.0)
    good = mm.step(body.inputs(t))
    values = [*body.pos, *body.vel, 0.0, t + DT]
    values[where] = bad
    out = mm.step(ModeInputs(values[7], tuple(values[0:3]), tuple(values[3:6]), values[6], 1.0))
    assert out.system_status == MavState.CRITICAL
    assert all(math.isfinite(v) for v in (*out.setpoint.pos_ned_m, out.setpoint.yaw_rad, out.t_s))
    assert out.t_s == (good.t_s if where == 7 else t + DT)  # a bad time reuses the last good one


def test_huge_finite_state_is_not_mistaken_for_a_bad_sample() -> None:
    # The terms' sum overflows to Inf, yet every value is finite: the sample is used as it is.
    mm = ModeManager()
    out = mm.step(ModeInputs(0.0, (1e308, 1e308, 0.0), (1e308, 0.0, 0.0), 0.0, 0.0))
    assert out.system_status == MavState.STANDBY and out.setpoint.pos_ned_m == (1e308, 1e308, 0.0)
    mm.arm(force=True)
    out = mm.step(ModeInputs(0.01, (1e308, 1e308, 0.0), (1e308, 0.0, 0.0), 0.0, 0.0))
    assert out.system_status == MavState.ACTIVE


def test_time_going_back_does_not_move_a_ramp() -> None:
    mm, body, t = armed_on_ground()
    mm.takeoff(2.0)
    outs, t = fly(mm, body, t, 0.5)
    z = outs[-1].setpoint.pos_ned_m[2]
    out = mm.step(body.inputs(t - 0.2))  # dt < 0 counts as 0
    assert out.flight_mode is FlightMode.TAKEOFF and out.setpoint.pos_ned_m[2] == z
    out = mm.step(body.inputs(t - 0.2 + DT))
    assert out.setpoint.pos_ned_m[2] == pytest.approx(z - ModeConfig().takeoff_climb_rate_m_s * DT)
