"""MAV_CMD_DO_ORBIT over SITL with plain pymavlink, as a PX4 script sends it (COMMAND_INT, x/y degE7, z AMSL)
against `navig8-fc --autopilot px4`: ACCEPTED at once, HEARTBEAT custom mode POSCTL.ORBIT (main 3, sub 1),
ORBIT_EXECUTION_STATUS with the signed radius, the centre and the altitude, and the radius held within 0.5 m over a
full clockwise turn (bearings from the centre swept through more than 2 pi); Hold ends it (docs/gcs.md, "Orbit")."""

from __future__ import annotations

import math
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import FcTarget, arm, wait_for

M = mavlink2
FC_LOCAL = {"speed": 2.0, "fc_args": ["--autopilot", "px4"]}  # the local pair (conftest.py `fc`)
EARTH_RADIUS_M = 6_371_000.0  # the FC's flat-earth projection (docs/gcs.md, "Global position")
ORBIT_MODE = (3 << 16) | (1 << 24)  # PX4 POSCTL.ORBIT
HOLD_MODE = (4 << 16) | (3 << 24)
RADIUS_M, SPEED_M_S, EAST_M, HEIGHT_M = 4.0, 1.5, 5.0, 3.0


def _until(gcs: Any, kind: str, pred: Any, timeout_s: float, what: str) -> Any:
    m = wait_for(gcs, kind, timeout_s, pred)
    assert m is not None, f"timed out waiting for {what}"
    return m


def _fc_hb(pred: Any) -> Any:
    return lambda m: m.get_srcComponent() == 1 and pred(m)


def _arm_and_take_off(gcs: Any, home_amsl_m: float) -> None:
    arm(gcs, 20.0)
    gcs.mav.command_long_send(gcs.target_system, 1, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, math.nan, math.nan, math.nan,
                              home_amsl_m + HEIGHT_M)
    _until(gcs, "GLOBAL_POSITION_INT", lambda m: m.relative_alt > (HEIGHT_M - 0.2) * 1000, 40.0, "the takeoff height")


def test_do_orbit_command_int_flies_a_circle_and_reports_it_as_px4(fc: FcTarget) -> None:
    fc.require_flight()
    with fc.session() as gcs:
        _until(gcs, "HEARTBEAT", _fc_hb(lambda m: m.autopilot == M.MAV_AUTOPILOT_PX4), 10.0, "a PX4 heartbeat")
        gcs.mav.command_long_send(gcs.target_system, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                  M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0)
        home = _until(gcs, "HOME_POSITION", None, 20.0, "HOME_POSITION")
        home_amsl_m = home.altitude * 1e-3
        _arm_and_take_off(gcs, home_amsl_m)
        # The centre 5 m east of home, at the takeoff height: the vehicle is 1 m outside the 4 m circle.
        lat_deg = home.latitude * 1e-7
        lon_deg = home.longitude * 1e-7 + math.degrees(EAST_M / (EARTH_RADIUS_M * math.cos(math.radians(lat_deg))))
        x, y = home.latitude, round(lon_deg * 1e7)
        gcs.mav.command_int_send(gcs.target_system, 1, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_DO_ORBIT, 0, 0, RADIUS_M,
                                 SPEED_M_S, M.ORBIT_YAW_BEHAVIOUR_HOLD_FRONT_TO_CIRCLE_CENTER, 0.0, x, y,
                                 home_amsl_m + HEIGHT_M)
        ack = _until(gcs, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_ORBIT, 5.0, "the DO_ORBIT ACK")
        assert ack.result == M.MAV_RESULT_ACCEPTED  # at once, as PX4's Commander (no IN_PROGRESS)
        _until(gcs, "HEARTBEAT", _fc_hb(lambda m: m.custom_mode == ORBIT_MODE), 5.0, "POSCTL.ORBIT in HEARTBEAT")
        st = _until(gcs, "ORBIT_EXECUTION_STATUS", None, 5.0, "ORBIT_EXECUTION_STATUS")
        assert st.radius == RADIUS_M and st.frame == M.MAV_FRAME_GLOBAL  # positive: clockwise
        assert st.x == x and abs(st.y - y) <= 1, (st.x, st.y, x, y)  # degE7, through the FC's projection and back
        assert abs(st.z - (home_amsl_m + HEIGHT_M)) < 0.01
        centre = (home.x, home.y + EAST_M)
        # Circling once within 1 m of the circle; then a full turn sampled: the radius and the direction.
        _until(gcs, "LOCAL_POSITION_NED", lambda m: abs(math.hypot(m.x - centre[0], m.y - centre[1]) - RADIUS_M)
               < 0.5 and abs(m.vx * -(m.y - centre[1]) + m.vy * (m.x - centre[0])) > 0.5 * RADIUS_M, 60.0,
               "the vehicle circling")
        radii, bearings = [], []
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and (not bearings or abs(bearings[-1] - bearings[0]) < 2.0 * math.pi):
            lp = _until(gcs, "LOCAL_POSITION_NED", None, 5.0, "LOCAL_POSITION_NED")
            dn, de = lp.x - centre[0], lp.y - centre[1]
            radii.append(math.hypot(dn, de))
            b = math.atan2(de, dn)
            bearings.append(b if not bearings else bearings[-1] + (b - bearings[-1] + math.pi) % (2 * math.pi)
                            - math.pi)
        swept = bearings[-1] - bearings[0]
        assert swept >= 2.0 * math.pi, f"only {math.degrees(swept):.0f} deg in 60 s"  # clockwise: the bearing grows
        worst = max(abs(r - RADIUS_M) for r in radii)
        print(f"\norbit: {len(radii)} samples over {math.degrees(swept):.0f} deg, radius {min(radii):.3f}.."
              f"{max(radii):.3f} m (worst error {worst:.3f} m)")
        assert worst < 0.5
        # Hold ends it: the mode changes and the status stream stops.
        gcs.mav.command_long_send(gcs.target_system, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 4, 3, 0, 0, 0, 0)
        ack = _until(gcs, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_SET_MODE, 5.0, "the Hold ACK")
        assert ack.result == M.MAV_RESULT_ACCEPTED
        _until(gcs, "HEARTBEAT", _fc_hb(lambda m: m.custom_mode == HOLD_MODE), 5.0, "Hold in HEARTBEAT")
        wait_for(gcs, "HEARTBEAT", 1.5)  # a status already in flight at the switch
        assert wait_for(gcs, "ORBIT_EXECUTION_STATUS", 2.0) is None
        gcs.mav.command_long_send(gcs.target_system, 1, M.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0)
        _until(gcs, "EXTENDED_SYS_STATE", lambda m: m.landed_state == M.MAV_LANDED_STATE_ON_GROUND, 60.0, "touchdown")
