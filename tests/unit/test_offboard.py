"""Offboard targets per type_mask: the decoder (navig8_fc.gcs.offboard, PX4's reading of the ignore bits), the mode
manager flying them on a point-mass vehicle whose velocity is K_p (setpoint - position) (the outer loop's velocity
command with a perfect inner loop), and the GcsService path from the MAVLink messages to the FlightStack."""

from __future__ import annotations

import math

import pytest
from test_gcs_service import API, GCS, Rig
from test_mission_executor import flying
from test_modes import DT, PointMass, fly

from navig8_fc.gcs import offboard as ob
from navig8_fc.modes import FlightMode, ModeManager, OffboardTarget
from navig8_fc.modes.offboard import attitude_acceleration
from navig8_fc.modes.px4 import Px4MainMode

NAN = math.nan
KP_BODY = 2.0  # PointMass: velocity = 2 (setpoint - position), bounded at 1.5 m/s
_POS, _VEL, _YAWS = ob.PT_X | ob.PT_Y | ob.PT_Z, ob.PT_VX | ob.PT_VY | ob.PT_VZ, ob.PT_YAW | ob.PT_YAW_RATE
ALL_BUT = {"pos": _VEL | ob.PT_ACCEL | _YAWS, "vel": _POS | ob.PT_ACCEL | _YAWS,
           "posvel": ob.PT_ACCEL | _YAWS}  # type_mask flying only these (yaw and yaw rate ignored too)


def _quat(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """ZYX Euler -> quaternion, by composing the three elementary rotations (q_z q_y q_x) with the Hamilton product."""
    def mul(a, b):
        aw, ax, ay, az = a
        bw, bx, by, bz = b
        return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)
    qz = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    qy = (math.cos(pitch / 2), 0.0, math.sin(pitch / 2), 0.0)
    qx = (math.cos(roll / 2), math.sin(roll / 2), 0.0, 0.0)
    return mul(mul(qz, qy), qx)


# --- decoding ----------------------------------------------------------------------------------------
def _pt(mask: int, frame: int = ob.MAV_FRAME_LOCAL_NED, yaw_now: float = 0.0) -> ob.Decoded:
    return ob.position_target("SPT", mask, frame, (1.0, 2.0, -3.0), (0.1, 0.2, 0.3), (0.0, 0.0, 0.5), 0.7, 0.4,
                              yaw_now)


def test_type_mask_bits_select_position_velocity_yaw_and_yaw_rate() -> None:
    d = _pt(ALL_BUT["pos"] & ~ob.PT_YAW)  # position + yaw
    assert d.target.pos_ned_m == (1.0, 2.0, -3.0) and all(map(math.isnan, d.target.vel_ned_m_s))
    assert d.target.yaw_rad == 0.7 and math.isnan(d.target.yaw_rate_rad_s) and not d.ignored
    d = _pt(ALL_BUT["vel"] & ~ob.PT_YAW_RATE)  # velocity + yaw rate (MAVSDK set_velocity_ned with a yaw rate)
    assert all(map(math.isnan, d.target.pos_ned_m)) and d.target.vel_ned_m_s == (0.1, 0.2, 0.3)
    assert math.isnan(d.target.yaw_rad) and d.target.yaw_rate_rad_s == 0.4
    d = _pt(ALL_BUT["posvel"] | ob.PT_Y | ob.PT_VY)  # per axis: y has neither
    assert d.target.pos_ned_m[0] == 1.0 and math.isnan(d.target.pos_ned_m[1]) and math.isnan(d.target.vel_ned_m_s[1])


def test_acceleration_is_flown_alone_named_beside_pos_vel_and_force_and_empty_targets_are_refused() -> None:
    d = _pt(ALL_BUT["pos"] & ~ob.PT_AZ)  # beside a position on its axis: a feed-forward the setpoint cannot carry
    assert d.target is not None and "acceleration ignored" in d.ignored
    assert all(map(math.isnan, d.target.acc_ned_m_s2))
    assert "force" in _pt(ALL_BUT["pos"] & ~ob.PT_AZ | ob.PT_FORCE_SET).refusal
    assert "invalid" in _pt(_POS | _VEL | ob.PT_ACCEL | _YAWS).refusal
    alone = ob.position_target("SPT", _POS | _VEL | _YAWS, 1, (0, 0, 0), (0, 0, 0), (0.5, -0.2, 0.1), 0, 0, 0)
    assert alone.target is not None and not alone.ignored and alone.target.acc_ned_m_s2 == (0.5, -0.2, 0.1)
    body = ob.position_target("SPT", _POS | _VEL | _YAWS, ob.MAV_FRAME_BODY_NED, (0, 0, 0), (0, 0, 0), (1.0, 0, 0),
                              0, 0, math.pi / 2)  # forward while facing east
    assert body.target.acc_ned_m_s2 == pytest.approx((0.0, 1.0, 0.0), abs=1e-12)
    bad = ob.position_target("SPT", ALL_BUT["vel"], 1, (0, 0, 0), (math.inf, 0, 0), (0, 0, 0), 0, 0, 0)
    assert bad.target is None and "finite" in bad.refusal


def test_body_ned_velocity_is_rotated_by_the_heading_and_position_ignored() -> None:
    d = _pt(ALL_BUT["posvel"], ob.MAV_FRAME_BODY_NED, yaw_now=math.pi / 2)  # facing east: forward = east
    assert all(map(math.isnan, d.target.pos_ned_m))
    assert d.target.vel_ned_m_s == pytest.approx((-0.2, 0.1, 0.3))  # 0.1 forward -> east, 0.2 right -> south


def test_attitude_target_is_read_as_px4_reads_it_for_a_multicopter() -> None:
    """The quaternion is the attitude; thrust the collective along body -z (PX4's fill_thrust for MAV_TYPE_TRICOPTER:
    thrust_body = (0, 0, -thrust)); THRUST_BODY_SET takes thrust_body as given; thrust ignored: none."""
    q = _quat(math.radians(-20), math.radians(45), math.radians(30))
    d = ob.attitude_target(ob.AT_RATES, q, 0.7, (0, 0, 0))
    t = d.target
    assert (t.roll_rad, t.pitch_rad, t.yaw_rad) == pytest.approx(tuple(map(math.radians, (-20, 45, 30))))
    assert t.thrust_body == (0.0, 0.0, -0.7) and all(map(math.isnan, t.pos_ned_m)) and not d.ignored
    d = ob.attitude_target(ob.AT_RATES | ob.AT_THRUST_BODY_SET, q, 0.0, (0, 0, 0), (-0.3, 0.0, -0.3))
    assert d.target.thrust_body == (-0.3, 0.0, -0.3)
    assert "no thrust_body" in ob.attitude_target(ob.AT_RATES | ob.AT_THRUST_BODY_SET, q, 0.5, (0, 0, 0)).refusal
    assert "body-rate" in ob.attitude_target(ob.AT_ATTITUDE | ob.AT_THRUST, q, 0.5, (0, 0.1, 0)).refusal
    assert "body rates ignored" in ob.attitude_target(0, q, 0.5, (0, 0.1, 0)).ignored
    assert "pitch 70 deg beyond" in ob.attitude_target(ob.AT_RATES, _quat(0, math.radians(70), 0), 0.5,
                                                       (0, 0, 0)).refusal
    assert "roll -65 deg beyond" in ob.attitude_target(ob.AT_RATES, _quat(math.radians(-65), 0, 0), 0.5,
                                                       (0, 0, 0)).refusal
    assert "thrust" in ob.attitude_target(ob.AT_RATES, q, 1.5, (0, 0, 0)).refusal
    assert "unit" in ob.attitude_target(ob.AT_RATES, (0.5, 0, 0, 0), 0.5, (0, 0, 0)).refusal
    d = ob.attitude_target(ob.AT_RATES | ob.AT_THRUST, q, NAN, (0, 0, 0))  # thrust ignored: altitude held
    assert all(map(math.isnan, d.target.thrust_body))


G = 9.80665


def _att(roll_deg: float, pitch_deg: float, yaw_deg: float, thrust: float | tuple = NAN) -> OffboardTarget:
    body = thrust if isinstance(thrust, tuple) else (0.0, 0.0, -thrust)
    return OffboardTarget(yaw_rad=math.radians(yaw_deg), pitch_rad=math.radians(pitch_deg),
                          roll_rad=math.radians(roll_deg), thrust_body=body)


def test_attitude_and_thrust_give_a_multicopters_acceleration() -> None:
    """Closed forms with hover thrust h = 0.5: a = g R(q) (0, 0, -t) / h + (0, 0, g) NED."""
    h = 0.5

    def acc(tgt: OffboardTarget) -> tuple[float, float, float]:
        return attitude_acceleration(tgt, h, G)

    assert acc(_att(0, 0, 40, 0.5)) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)  # level at hover: holds
    assert acc(_att(0, 0, 0, 0.7)) == pytest.approx((0.0, 0.0, -0.4 * G))  # 0.7: climbs at 0.4 g
    assert acc(_att(0, 0, 0, 0.0)) == pytest.approx((0.0, 0.0, G))  # idle: falls
    phi = math.radians(30)  # the example's roll at 0.6: sideways 1.2 g sin 30, up 1.2 g cos 30 - g
    assert acc(_att(30, 0, 0, 0.6)) == pytest.approx((0.0, 1.2 * G * math.sin(phi), G - 1.2 * G * math.cos(phi)))
    assert acc(_att(30, 0, 90, 0.6))[:2] == pytest.approx((-1.2 * G * math.sin(phi), 0.0), abs=1e-9)  # east: right
    th = math.radians(-20)  # nose down: forward
    assert acc(_att(0, -20, 0, 0.5)) == pytest.approx((-G * math.sin(th), 0.0, G - G * math.cos(th)))
    no_thrust = acc(_att(10, -20, 0))  # level flight at that tilt: g tan along it, the altitude held
    d = (math.cos(math.radians(10)) * math.sin(math.radians(20)), math.sin(math.radians(10)))
    cz = math.cos(math.radians(10)) * math.cos(math.radians(20))
    assert no_thrust[:2] == pytest.approx((G * d[0] / cz, G * d[1] / cz)) and math.isnan(no_thrust[2])
    # THRUST_BODY_SET: pitched 45 deg with the thrust vector turned back to vertical, the paper's pitch hover
    s45 = math.sin(math.radians(45))
    assert acc(_att(0, 45, 0, (h * s45, 0.0, -h * s45))) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    assert all(map(math.isnan, acc(OffboardTarget(pitch_rad=0.3))))  # no attitude: nothing


# --- flying them -------------------------------------------------------------------------------------------
def _offboard(target: OffboardTarget):
    mm, body, t = flying()
    mm.set_position_gain(KP_BODY)
    mm.offboard_setpoint(target)
    assert mm.set_mode(Px4MainMode.OFFBOARD, 0).ok
    return mm, body, t


def test_velocity_target_is_tracked_with_the_feed_forward_and_without_lag() -> None:
    v = (0.4, -0.3, 0.0)
    mm, body, t = _offboard(OffboardTarget(vel_ned_m_s=v))
    start = list(body.pos)
    outs, t = fly(mm, body, t, 3.0)
    assert body.vel == pytest.approx(list(v), abs=1e-3)
    # Closed form: the vehicle is where v * 3 s takes it (no steady lag v / K_p = 0.25 m behind the reference).
    assert body.pos == pytest.approx([start[i] + v[i] * 3.0 for i in range(3)], abs=0.02)
    assert outs[-1].flight_mode is FlightMode.OFFBOARD


def test_velocity_reference_cannot_wind_up_while_the_vehicle_is_held_back() -> None:
    mm, body, t = _offboard(OffboardTarget(vel_ned_m_s=(1.0, 0.0, 0.0)))
    lead = mm.config.manual_lead_m
    for k in range(300):  # the vehicle is stuck (e.g. a wall): 3 s of 1 m/s demand
        out = mm.step(body.inputs(t + k * 0.01))
    assert out.setpoint.pos_ned_m[0] - body.pos[0] <= lead + 1.0 / KP_BODY + 1e-9


def test_position_with_velocity_feed_forward_and_yaw_rate() -> None:
    mm, body, t = _offboard(OffboardTarget(yaw_rate_rad_s=0.5, vel_ned_m_s=(0.0, 0.0, 0.0)))
    yaw0 = mm.last_output.setpoint.yaw_rad if mm.last_output else 0.0
    outs, t = fly(mm, body, t, 1.0)
    assert outs[-1].setpoint.yaw_rad == pytest.approx(yaw0 + 0.5, abs=0.02)
    # A moving position stream with its velocity: the vehicle is on the stream, not v / K_p behind it.
    v = 0.5
    for k in range(200):
        tk = t + k * 0.01
        x = 0.5 * (k * 0.01)
        mm.offboard_setpoint(OffboardTarget((x, 0.0, -1.5), (v, 0.0, 0.0), yaw_rad=0.0))
        out = mm.step(body.inputs(tk))
        body.move(out.engaged, out.setpoint)
    assert body.pos[0] == pytest.approx(0.5 * 1.99, abs=0.03) and out.setpoint.yaw_rad == 0.0


def test_attitude_target_climbs_rolls_sideways_and_holds_pitch_and_yaw() -> None:
    """The example's sequence on the point mass: 0.7 climbs, a roll of 30 deg at the thrust that holds the altitude
    (h / cos 30) moves it to the right and the setpoint keeps the commanded pitch and yaw; the acceleration is
    limited to the reference's (2 m/s^2), the velocity to OL_VEL_MAX."""
    mm, body, t = _offboard(_att(0, 0, 0, 0.7))
    z0 = body.pos[2]
    outs, t = fly(mm, body, t, 2.0)
    assert body.pos[2] < z0 - 1.0 and body.vel[2] < -0.9  # climbing
    mm.offboard_setpoint(_att(30, 0, 0, 0.5 / math.cos(math.radians(30))))
    y0 = body.pos[1]
    outs, t = fly(mm, body, t, 2.0)
    assert body.pos[1] > y0 + 1.0 and body.vel[1] > 0.9  # to the right (east at yaw 0)
    mm.offboard_setpoint(_att(0, 20, 90, 0.5 / math.cos(math.radians(20))))  # nose up facing east: back = west
    y1 = body.pos[1]
    outs, t = fly(mm, body, t, 3.0)
    sp = outs[-1].setpoint
    assert sp.pitch_rad == pytest.approx(math.radians(20)) and sp.yaw_rad == pytest.approx(math.pi / 2)
    assert body.pos[1] < y1 - 0.5 and body.vel[1] < -0.9
    # the reference's velocity is bounded: the setpoint never runs more than the lead plus v_max / K_p ahead
    lead = mm.config.manual_lead_m + 2.0 / KP_BODY
    assert all(abs(o.setpoint.pos_ned_m[1] - body.pos[1]) <= lead + 0.1 for o in outs[-50:])


# --- the GcsService path -----------------------------------------------------------------------------------
def test_messages_reach_the_stack_and_refusals_and_ignored_parts_are_said() -> None:
    rig = Rig()
    rig.step(60)
    assert rig.command(API, 400, 1, 21196).result == 0  # forced arm on the bench
    c = rig.client
    rig.send(c.set_position_target_local_ned_encode(0, 1, 1, 1, ALL_BUT["vel"], 0, 0, 0, 0.3, 0, 0, 0, 0, 0, 0, 0), GCS)
    assert rig.stack.state().offboard_target.vel_ned_m_s == (pytest.approx(0.3), 0.0, 0.0)
    assert not rig.outbox.pop("STATUSTEXT")
    accel = ALL_BUT["vel"] & ~ob.PT_AX
    for _ in range(3):  # named once, not per message
        rig.send(c.set_position_target_local_ned_encode(0, 1, 1, 1, accel, 0, 0, 0, 0.3, 0, 0, 1, 0, 0, 0, 0), GCS)
    (text,) = [m.text for _, m in rig.outbox.pop("STATUSTEXT")]
    assert "acceleration ignored" in text
    rig.send(c.set_position_target_local_ned_encode(0, 1, 1, 1, 0xFFF, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0), GCS)
    assert "invalid" in rig.outbox.pop("STATUSTEXT")[0][1].text
    rig.send(c.set_attitude_target_encode(0, 1, 1, ob.AT_RATES, _quat(0, 0.5, 0.2), 0, 0, 0, 0.5), GCS)
    got = rig.stack.state().offboard_target
    assert got.pitch_rad == pytest.approx(0.5) and got.yaw_rad == pytest.approx(0.2) and got.thrust_body == (0, 0, -0.5)
    rig.send(c.set_attitude_target_encode(0, 1, 1, ob.AT_ATTITUDE, (1, 0, 0, 0), 0, 0, 0.2, 0.5), GCS)
    assert "body-rate" in rig.outbox.pop("STATUSTEXT")[0][1].text
    assert rig.stack.state().offboard_target.pitch_rad == pytest.approx(0.5)  # a refusal changes nothing


def test_offboard_on_the_ground_idles_until_a_target_above_asks_to_climb() -> None:
    """As PX4 (its takeoff state machine): landed with the target on or below the ground, the motors idle (MAVSDK's
    offboard_position_ned ends with a target at z = 0, on the ground); a target above lifts off again."""
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    mm.arm()
    mm.offboard_setpoint(OffboardTarget(pos_ned_m=(0.0, 0.0, 0.0), yaw_rad=0.0))
    assert mm.set_mode(Px4MainMode.OFFBOARD, 0).ok
    outs, t = fly(mm, body, DT, 1.0)
    assert not outs[-1].engaged and outs[-1].flight_mode is FlightMode.OFFBOARD and outs[-1].armed
    mm.offboard_setpoint(OffboardTarget(pos_ned_m=(0.0, 0.0, -2.0), yaw_rad=3.0))
    outs, t = fly(mm, body, t, 4.0)
    assert outs[-1].engaged and body.pos[2] == pytest.approx(-2.0, abs=0.1)
    mm.offboard_setpoint(OffboardTarget(pos_ned_m=(0.0, 0.0, 0.3), yaw_rad=0.0))  # back down, into the ground
    outs, t = fly(mm, body, t, 5.0)
    assert body.pos[2] == pytest.approx(0.0, abs=0.01) and not outs[-1].engaged


# --- the ceiling (VOL_ALT_MAX) ---------------------------------------------------------------------------------
CEILING_M = 3.0  # above home (home: where the point mass armed, on the ground at z = 0)


@pytest.mark.parametrize("target", [OffboardTarget(vel_ned_m_s=(0.0, 0.0, -1.0)), _att(0, 0, 0, 0.8)],
                         ids=["velocity", "attitude"])
def test_a_climbing_target_stops_at_the_ceiling(target: OffboardTarget) -> None:
    """A velocity or an attitude target that keeps climbing: the setpoint stops VOL_ALT_MAX above home and the vehicle
    holds there (PX4's LNDMC_ALT_MAX); a descent afterwards starts at once (no wound-up climb to unwind)."""
    mm, body, t = _offboard(target)
    mm.set_mode_params(mm.config.takeoff_default_alt_m, mm.config.rtl_alt_m, mm.config.hover_thrust, CEILING_M)
    home_z = mm.home_ned_m[2]
    outs, t = fly(mm, body, t, 12.0)  # 1 m/s (or the attitude's acceleration) for long enough to pass it twice
    assert min(o.setpoint.pos_ned_m[2] for o in outs) >= home_z - CEILING_M - 1e-9
    assert body.pos[2] == pytest.approx(home_z - CEILING_M, abs=0.02) and abs(body.vel[2]) < 0.02
    mm.offboard_setpoint(OffboardTarget(vel_ned_m_s=(0.0, 0.0, 0.5)))
    z0 = body.pos[2]
    outs, t = fly(mm, body, t, 1.0)
    assert body.pos[2] > z0 + 0.3  # down within the second


def test_position_mode_climbs_to_the_ceiling_and_no_further() -> None:
    mm, body, t = flying()
    mm.set_mode_params(mm.config.takeoff_default_alt_m, mm.config.rtl_alt_m, mm.config.hover_thrust, CEILING_M)
    assert mm.set_mode(Px4MainMode.POSCTL, 0).ok
    mm.manual_input(0.0, 0.0, 1.0, 0.0)  # full throttle: climb 0.5 m/s
    outs, t = fly(mm, body, t, 10.0)
    assert min(o.setpoint.pos_ned_m[2] for o in outs) >= mm.home_ned_m[2] - CEILING_M - 1e-9
    assert body.pos[2] == pytest.approx(mm.home_ned_m[2] - CEILING_M, abs=0.02)


def test_acceleration_target_is_integrated_and_a_zero_acceleration_keeps_the_speed() -> None:
    """MAVSDK's set_acceleration_ned: 0.5 m/s^2 east for 2 s reaches 1 m/s (v = a t), then zero acceleration holds
    1 m/s (no drag: that is the attitude target's multicopter); the altitude holds (no z given)."""
    acc = OffboardTarget(acc_ned_m_s2=(math.nan, 0.5, math.nan))
    mm, body, t = _offboard(acc)
    z0 = body.pos[2]
    outs, t = fly(mm, body, t, 2.0)
    assert body.vel[1] == pytest.approx(1.0, abs=0.06) and body.pos[2] == pytest.approx(z0, abs=0.02)
    mm.offboard_setpoint(OffboardTarget(acc_ned_m_s2=(math.nan, 0.0, math.nan)))
    outs, t = fly(mm, body, t, 1.0)
    assert body.vel[1] == pytest.approx(1.0, abs=0.06)
