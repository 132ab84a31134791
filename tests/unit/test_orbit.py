"""Orbit (MAV_CMD_DO_ORBIT, navig8_fc.modes.orbit) against closed forms: PX4's defaults and limits, the speed bound
v^2 + (v^2 / (r K_v))^2 = OL_VEL_MAX^2 and v^2 / r = 0.8 a, the reference's frequency response, the circle the
shaped reference flies (radius, tangential speed, direction) with the vehicle on it, the heading per
ORBIT_YAW_BEHAVIOUR, and the command's decoding, volume check and ORBIT_EXECUTION_STATUS."""

from __future__ import annotations

import math
from dataclasses import replace
from io import BytesIO

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2
from test_mission_executor import flying

from navig8_fc.core import outer_loop
from navig8_fc.core.outer_loop import SH, OuterLoopConfig, shape_reference, shaper_config_array
from navig8_fc.gcs.commands import CommandRequest, orbit_from_request
from navig8_fc.gcs.telemetry import TelemetryBuilder, VehicleSnapshot
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.volume import OperatingVolume
from navig8_fc.modes import FlightMode, ModeInputs, ModeManager
from navig8_fc.modes.orbit import (
    CENTRIPETAL_SHARE,
    YAW_INITIAL,
    YAW_RC,
    YAW_TANGENT,
    YAW_TO_CENTRE,
    YAW_UNCONTROLLED,
    OrbitPlan,
    OrbitRequest,
    limited_speed,
    orbit_yaw,
    reference_response,
    resolve,
)
from navig8_fc.modes.records import ReferenceLimits

DT = 0.01
G = 9.80665
NAN = math.nan
# the default outer loop (OL_* defaults: shaping on)
OL = OuterLoopConfig(1.0, 3.0, 2.0, 4.0, 4.0, 8.0, 2.0, G, jerk_max_m_s3=5.0, ref_acc_max_m_s2=2.0,
                     att_rate_ref_rad_s=0.6, att_acc_ref_rad_s2=1.0, ff_level=1)
LIMITS = ReferenceLimits.of_outer_loop(OL, 1000.0)
HERE = (3.0, -4.0, -5.0)


# --- what a request means -------------------------------------------------------------------------------------
def test_a_first_orbit_takes_px4s_defaults_and_a_second_keeps_what_it_leaves_out() -> None:
    plan, why, note = resolve(OrbitRequest(), None, HERE, 0.7, LIMITS)
    assert plan is not None and not why and not note
    # PX4's activate(): 1 m, 1 m/s, clockwise, facing the centre; the centre where the vehicle is, its altitude
    assert (plan.radius_m, plan.speed_m_s, plan.clockwise, plan.yaw_behaviour, plan.sweep_rad) == (
        1.0, 1.0, True, YAW_TO_CENTRE, 0.0)
    assert plan.centre_ned_m == HERE and plan.initial_yaw_rad == 0.7
    flown, _, _ = resolve(OrbitRequest(-10.0, 1.5, YAW_TANGENT, 2.0, (20.0, 5.0), -8.0), None, HERE, 0.0, LIMITS)
    assert flown is not None and not flown.clockwise and flown.signed_radius_m == -10.0
    assert flown.signed_speed_m_s == -1.5 and flown.centre_ned_m == (20.0, 5.0, -8.0)
    again, _, _ = resolve(OrbitRequest(), flown, HERE, 0.3, LIMITS)  # all NaN while orbiting: the orbit flown
    assert again is not None and (again.centre_ned_m, again.signed_radius_m, again.speed_m_s, again.yaw_behaviour,
                                  again.sweep_rad) == ((20.0, 5.0, -8.0), -10.0, 1.5, YAW_TANGENT, 2.0)
    moved, _, _ = resolve(OrbitRequest(speed_m_s=0.5, centre_ne_m=(NAN, 9.0)), flown, HERE, 0.3, LIMITS)
    assert moved is not None and moved.centre_ned_m == flown.centre_ned_m and moved.speed_m_s == 0.5  # half a centre


def test_radius_outside_one_metre_to_orb_rad_max_and_bad_values_are_refused() -> None:
    for r in (0.5, -0.2, 0.0, 1000.5):
        plan, why, _ = resolve(OrbitRequest(radius_m=r), None, HERE, 0.0, LIMITS)
        assert plan is None and "outside [1, 1000] m (ORB_RAD_MAX)" in why
    assert "speed" in resolve(OrbitRequest(5.0, -1.0), None, HERE, 0.0, LIMITS)[1]
    assert "param4" in resolve(OrbitRequest(5.0, sweep_rad=-1.0), None, HERE, 0.0, LIMITS)[1]
    assert "unknown" in resolve(OrbitRequest(5.0, yaw_behaviour=6), None, HERE, 0.0, LIMITS)[1]


def test_the_speed_gives_way_to_the_velocity_and_centripetal_limits() -> None:
    for r in (1.0, 2.0, 10.0, 50.0):
        v = limited_speed(r, 100.0, LIMITS)
        v_c = v * v + (v * v / (r * OL.vel_k)) ** 2 <= OL.vel_max_m_s ** 2 * (1 + 1e-12)  # the loop's velocity cap
        a_c = v * v / r <= CENTRIPETAL_SHARE * OL.ref_acc_max_m_s2 * (1 + 1e-12)
        assert v_c and a_c
        assert v * v + (v * v / (r * OL.vel_k)) ** 2 == pytest.approx(4.0) or v * v / r == pytest.approx(1.6)
    assert limited_speed(10.0, 2.0, LIMITS) == pytest.approx(1.99558, abs=1e-5)  # the example's 2 m/s at 10 m
    assert limited_speed(2.0, 5.0, LIMITS) == pytest.approx(math.sqrt(0.8 * 2.0 * 2.0))
    assert limited_speed(10.0, 0.7, LIMITS) == 0.7
    plan, _, note = resolve(OrbitRequest(2.0, 5.0), None, HERE, 0.0, LIMITS)
    assert plan is not None and plan.speed_m_s == pytest.approx(math.sqrt(3.2)) and "limited to 1.79 m/s" in note


# --- the circle flown ---------------------------------------------------------------------------------------------
def test_reference_response_is_the_shapers_and_the_loops_transfer_function() -> None:
    """H(i w) against the linear cascades integrated in time: a sinusoid in, amplitude and phase out."""
    for limits in (LIMITS, ReferenceLimits(jerk_k_1_s=0.0)):
        w, dt = 0.4, 1e-3
        x = np.zeros(3)  # p, p', p''
        kp, kv, kj = limits.pos_k_1_s, limits.vel_k_1_s, limits.jerk_k_1_s
        n = int(60.0 / dt)
        out = np.empty(n)
        for k in range(n):
            sp = math.sin(w * k * dt)
            if kj > 0.0:
                acc_dot = kj * (kv * (kp * (sp - x[0]) - x[1]) - x[2])
                x += dt * np.array([x[1], x[2], acc_dot])
            else:
                x[2] = kv * (kp * (sp - x[0]) - x[1])
                x[:2] += dt * np.array([x[1], x[2]])
            out[k] = x[0]
        t = np.arange(n)[n // 2:] * dt
        h = reference_response(w, limits)
        np.testing.assert_allclose(out[n // 2:], abs(h) * np.sin(w * t + np.angle(h)), atol=2e-3)
    assert reference_response(-0.3, LIMITS) == pytest.approx(reference_response(0.3, LIMITS).conjugate())


def _shaped_flight(mm: ModeManager, pos, seconds: float, t0: float):
    """The manager's setpoints through the command shaper (the controller's own kernel), the vehicle on the shaped
    reference (the loop's feed-forwards fly it there); a mode entry resyncs it as FlightStack does."""
    shc = shaper_config_array(OL, DT)
    st = SH.zeros()
    sp_out, ff = outer_loop.OSP.zeros(), outer_loop.OFF.zeros()
    p, v, quat = np.array(pos, dtype=float), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
    outs, track = [], []
    entries = None
    for k in range(int(round(seconds / DT))):
        out = mm.step(ModeInputs(t0 + k * DT, tuple(p), tuple(v), float(sp_out[4]) if k else 0.0, 1.0))
        if entries is not None and out.entries != entries:
            st[SH.INIT] = 2.0
        entries = out.entries
        sp = out.setpoint
        shape_reference(shc, st, outer_loop.OSP.pack(pos=sp.pos_ned_m, pitch=sp.pitch_rad, yaw=sp.yaw_rad), p, v, quat,
                        sp_out, ff)
        p, v = sp_out[0:3].copy(), ff[outer_loop.OFF.VEL.sl].copy()
        outs.append(out)
        track.append((*p, *v))
    return outs, np.array(track), t0 + seconds


def _orbiting(req: OrbitRequest, seconds: float):
    mm, body, t = flying()
    mm.set_reference_limits(LIMITS)
    assert mm.orbit(req).ok
    return mm, *_shaped_flight(mm, body.pos, seconds, t)


@pytest.mark.parametrize("radius", [10.0, -10.0])
def test_the_shaped_reference_flies_the_commanded_circle_at_the_commanded_speed(radius: float) -> None:
    """From 20 m away: the approach, then a circle of radius 10 m (to 1 cm) at the limited 1.996 m/s (to 1 cm/s),
    clockwise for a positive radius (the bearing from north grows), the front to the centre (closed form)."""
    centre = (-12.0, 18.0, -6.0)
    mm, outs, track, _ = _orbiting(OrbitRequest(radius, 2.0, YAW_TO_CENTRE, 0.0, centre[:2], centre[2]), 90.0)
    assert all(o.flight_mode is FlightMode.ORBIT for o in outs) and outs[-1].custom_mode == 0x01030000
    assert any("circling" in e for o in outs for e in o.events)
    steady = track[-4000:]  # the last 40 s: more than a turn (31.5 s)
    dn, de = steady[:, 0] - centre[0], steady[:, 1] - centre[1]
    np.testing.assert_allclose(np.hypot(dn, de), abs(radius), atol=0.01)
    np.testing.assert_allclose(steady[:, 2], centre[2], atol=1e-3)
    np.testing.assert_allclose(np.hypot(steady[:, 3], steady[:, 4]), limited_speed(10.0, 2.0, LIMITS), atol=0.01)
    bearing = np.unwrap(np.arctan2(de, dn))
    assert np.sign(bearing[-1] - bearing[0]) == np.sign(radius) and abs(bearing[-1] - bearing[0]) > 2 * math.pi
    tangential = (-np.sin(bearing) * steady[:, 3] + np.cos(bearing) * steady[:, 4]) * np.sign(radius)
    assert np.all(tangential > 1.9)
    for o, row in zip(outs[-4000:], np.vstack([track[-4001:-1]]), strict=True):  # the position the step saw
        assert o.setpoint.yaw_rad == pytest.approx(math.atan2(centre[1] - row[1], centre[0] - row[0]), abs=1e-9)
    plan = mm.orbit_plan
    assert plan is not None and plan.signed_radius_m == radius


def test_the_loop_without_shaping_flies_the_circle_too() -> None:
    limits = ReferenceLimits(jerk_k_1_s=0.0, acc_max_m_s2=4.0)
    r, w = 5.0, limited_speed(5.0, 1.5, limits) / 5.0
    x = np.zeros(4)  # n, e, vn, ve: p'' = K_v (K_p (sp - p) - p')
    for k in range(int(60.0 / DT)):
        theta = w * k * DT
        z = r * complex(math.cos(theta), math.sin(theta)) / reference_response(w, limits)
        a = limits.vel_k_1_s * (limits.pos_k_1_s * (np.array([z.real, z.imag]) - x[:2]) - x[2:])
        x[2:] += DT * a
        x[:2] += DT * x[2:]
    assert math.hypot(x[0], x[1]) == pytest.approx(r, abs=0.01)


def test_an_angle_to_fly_ends_in_hold_and_orbit_can_be_chosen_as_a_mode() -> None:
    mm, outs, track, t = _orbiting(OrbitRequest(3.0, 1.0, YAW_TO_CENTRE, math.pi, (0.0, 3.0), NAN), 40.0)
    i = next(i for i, o in enumerate(outs) if o.flight_mode is FlightMode.HOLD)
    assert any("3.14 rad flown: holding" in e for e in outs[i].events)
    dn, de = track[i, 0], track[i, 1] - 3.0  # half a turn clockwise from the start (west of the centre): east of it
    assert math.atan2(de, dn) == pytest.approx(math.pi / 2, abs=0.15)
    assert math.hypot(dn, de) == pytest.approx(3.0, abs=0.05)
    mm2, body, t2 = flying()
    assert mm2.set_mode(3, 1).ok  # DO_SET_MODE POSCTL.ORBIT: PX4's defaults around where the vehicle is
    out = mm2.step(body.inputs(t2))
    plan = mm2.orbit_plan
    assert out.flight_mode is FlightMode.ORBIT and plan is not None and plan.radius_m == 1.0
    assert plan.centre_ned_m == pytest.approx(tuple(body.pos), abs=1e-4)  # where it was at the command
    assert mm2.set_mode(4, 3).ok and mm2.step(body.inputs(t2 + DT)).flight_mode is FlightMode.HOLD  # Hold leaves it
    assert mm2.orbit_plan is None


def test_orbit_is_refused_on_the_ground_and_outside_the_volume() -> None:
    mm = ModeManager()
    mm.step(ModeInputs(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0))
    assert "not flying" in mm.orbit(OrbitRequest(5.0)).reason
    vol = OperatingVolume(1000.0, 120.0, -2.0, 20.0)
    home = (0.0, 0.0, 0.0)
    assert vol.orbit_problem((990.0, 0.0, -5.0), 10.0, home) == ""
    assert "reaches 1001 m from home (centre 991 m, radius 10 m), beyond VOL_DIST_MAX 1000 m" in vol.orbit_problem(
        (991.0, 0.0, -5.0), 10.0, home)
    assert "above VOL_ALT_MAX" in vol.orbit_problem((0.0, 0.0, -130.0), 10.0, home)
    mm2, body, t = flying()
    v = mm2.orbit(OrbitRequest(10.0, centre_ne_m=(995.0, 0.0)), lambda p: vol.orbit_problem(p.centre_ned_m, p.radius_m,
                                                                                             home))
    assert not v.ok and v.reason.startswith("Orbit refused: circle reaches 1005 m")
    assert mm2.step(body.inputs(t)).flight_mode is FlightMode.HOLD


# --- heading ------------------------------------------------------------------------------------------------------
def test_heading_per_orbit_yaw_behaviour() -> None:
    c = (1.0, 2.0, -3.0)
    north_of = (11.0, 2.0, -3.0)  # 10 m north of the centre
    assert abs(orbit_yaw(YAW_TO_CENTRE, c, north_of, True, 0.4, 0.1)) == pytest.approx(math.pi)  # facing south
    assert orbit_yaw(YAW_TANGENT, c, north_of, True, 0.4, 0.1) == pytest.approx(math.pi / 2)  # clockwise: east
    assert orbit_yaw(YAW_TANGENT, c, north_of, False, 0.4, 0.1) == pytest.approx(-math.pi / 2)  # west
    east_of = (1.0, 12.0, -3.0)
    assert orbit_yaw(YAW_TO_CENTRE, c, east_of, True, 0.4, 0.1) == pytest.approx(-math.pi / 2)
    assert orbit_yaw(YAW_TANGENT, c, east_of, True, 0.4, 0.1) == pytest.approx(math.pi)  # clockwise from east: south
    assert orbit_yaw(YAW_INITIAL, c, east_of, True, 0.4, 0.1) == 0.4
    assert orbit_yaw(YAW_UNCONTROLLED, c, east_of, True, 0.4, 0.1) == 0.1
    assert orbit_yaw(YAW_RC, c, east_of, True, 0.4, 0.1) == 0.1  # the mode turns it with the yaw stick


# --- MAVLink ------------------------------------------------------------------------------------------------------
def _req(params, is_int=True, frame=mavlink2.MAV_FRAME_GLOBAL_INT) -> CommandRequest:
    return CommandRequest(34, tuple(float(p) for p in params), is_int, frame, 0, 255, 190)  # type: ignore[arg-type]


def test_do_orbit_parameters_are_read_as_px4_reads_them() -> None:
    o = orbit_from_request(_req((10, 2, NAN, NAN, 473980362, 85450146, 498.0), frame=3), z_amsl=True)
    assert (o.radius_m, o.speed_m_s, o.yaw_behaviour) == (10.0, 2.0, 5)  # NaN yaw: unchanged
    assert o.lat_deg == pytest.approx(47.3980362) and o.lon_deg == pytest.approx(8.5450146)
    assert o.alt_m == 498.0 and not o.relative_alt  # MAVSDK's AMSL altitude in frame 3: AMSL, as PX4
    assert orbit_from_request(_req((10, 2, 0, 0, 1, 1, 5.0), frame=6), z_amsl=False).relative_alt  # the frame's
    here = orbit_from_request(_req((5, NAN, 3, 0, 2**31 - 1, 2**31 - 1, NAN)), z_amsl=True)
    assert math.isnan(here.lat_deg) and math.isnan(here.lon_deg) and here.yaw_behaviour == 3
    long = orbit_from_request(_req((5, 1, 1, 0, 47.1, 8.2, 500.0), is_int=False, frame=0), z_amsl=True)
    assert (long.lat_deg, long.lon_deg, long.alt_m) == (47.1, 8.2, 500.0)
    for bad in ((5, 1, 0, 0, 0x7FF80000, 0x7FF80000, 5.0), (5, 1, 7, 0, 1, 1, 5.0), (math.inf, 1, 0, 0, 1, 1, 5.0)):
        with pytest.raises(ValueError):
            orbit_from_request(_req(bad), z_amsl=True)
    with pytest.raises(ValueError):
        orbit_from_request(_req((5, 1, 0, 0, 1, 1, 5.0), frame=1), z_amsl=True)  # not a global frame


def test_orbit_execution_status_reports_the_orbit_as_px4_does() -> None:
    mav = mavlink2.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
    builder = TelemetryBuilder(mav, 1, 1)
    origin = GeoOrigin(47.397742, 8.545594, 488.0)
    snap = VehicleSnapshot(True, 1, 0x01030000, 4, 2, (0.0, 0.0, -5.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
                           (0.0, 0.0, 0.0), origin=origin)
    assert builder.build(builder_id := mavlink2.MAVLINK_MSG_ID_ORBIT_EXECUTION_STATUS, snap, 1000) == []
    plan = OrbitPlan((32.7, -43.7, -10.0), 10.0, 1.99, False, 0, 0.0, 0.0)
    (m,) = builder.build(builder_id, replace(snap, orbit=plan), 1000)
    lat, lon, alt = origin.to_global(plan.centre_ned_m)
    assert m.radius == -10.0 and m.frame == mavlink2.MAV_FRAME_GLOBAL and m.time_usec == 1_000_000
    assert (m.x, m.y) == (round(lat * 1e7), round(lon * 1e7)) and m.z == pytest.approx(498.0)
