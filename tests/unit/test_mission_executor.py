"""Mission execution (navig8_fc.mission.executor inside the mode manager's Mission mode) on a point-mass vehicle:
Mission selected while disarmed, arming starts it; takeoff, waypoints in local and global frames (the global
ones through the origin's projection, checked against its inverse), gripper / arm-joint / pitch-hold items,
DO_JUMP, loiter time, return to launch and landing at home, disarm; pause (Hold) and resume."""

from __future__ import annotations

import math

import pytest
from test_modes import DT, PointMass, fly

from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Cmd, Frame, MissionItem, Plan
from navig8_fc.modes import FlightMode, ModeManager
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode

ORIGIN = GeoOrigin()


def _global(n: float, e: float) -> tuple[int, int]:
    lat, lon, _ = ORIGIN.to_global((n, e, 0.0))
    return round(lat * 1e7), round(lon * 1e7)


def _plan() -> Plan:
    gx, gy = _global(0.0, 1.0)
    return Plan(0, (
        MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_TAKEOFF, 1, 0, 0, 0, math.nan, 0, 0, 2.0),  # 0
        MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0.5, 0.1, 0, 90.0, 10000, 0, -2.0),  # 1: N 1 m
        MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_WAYPOINT, 1, 0, 0.1, 0, math.nan, gx, gy, 2.5),  # 2
        MissionItem(Frame.MISSION, Cmd.DO_GRIPPER, 1, 1, 0, 0, 0, 0, 0, 0),  # 3
        MissionItem(Frame.MISSION, Cmd.NAVIG8_ARM_JOINTS, 1, 20, 20, 20, 1, 0, 0, 0),  # 4
        MissionItem(Frame.MISSION, Cmd.NAVIG8_PITCH_HOLD, 1, 30, 0.5, 0, 0, 0, 0, 0),  # 5
        MissionItem(Frame.MISSION, Cmd.DO_JUMP, 1, 4, 1, 0, 0, 0, 0, 0),  # 6: items 4-5 once more
        MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_LOITER_TIME, 1, 1.0, 0, 0, math.nan, 0, 0, 2.0),  # 7
        MissionItem(Frame.MISSION, Cmd.NAV_RETURN_TO_LAUNCH, 1, 0, 0, 0, 0, 0, 0, 0),  # 8
    ))


def test_plan_flown_from_arming_to_disarm_at_home() -> None:
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    assert not mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.MISSION).ok  # no plan yet
    mm.load_plan(_plan(), ORIGIN)
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.MISSION).ok  # while disarmed (PX4)
    out = mm.step(body.inputs(DT))
    assert out.flight_mode is FlightMode.MISSION and not out.armed and not out.engaged
    assert mm.arm().ok
    outs, t = fly(mm, body, 2 * DT, 40.0)
    reached = [seq for o in outs for _, seq in o.mission.reached_log if o is outs[-1]]
    assert reached == [0, 1, 2, 3, 4, 5, 6, 4, 5, 6, 7, 8]  # in order, the jump once
    actions = [a for o in outs for a in o.actions]
    q = math.radians(20)
    assert actions == [("gripper", "release"), ("joints", (q, q, q)), ("joints", (q, q, q))]
    sps = [o.setpoint for o in outs if o.flight_mode is FlightMode.MISSION and o.engaged]
    assert any(sp.pos_ned == pytest.approx((1.0, 0.0, -2.0)) and sp.yaw_rad == pytest.approx(math.pi / 2)
               for sp in sps)  # the local waypoint, yaw 90 deg
    assert any(sp.pos_ned == pytest.approx((0.0, 1.0, -2.5), abs=0.01) for sp in sps)  # E 1 m (degE7: ~1 cm)
    assert any(sp.pitch_rad == pytest.approx(math.radians(30)) for sp in sps)
    modes = [o.flight_mode for o in outs]
    assert FlightMode.LAND in modes and not outs[-1].armed and outs[-1].flight_mode is FlightMode.READY
    assert math.hypot(body.pos[0], body.pos[1]) < 0.15 and body.pos[2] == 0.0  # at home, on the ground
    assert outs[-1].mission.finished and outs[-1].mission.reached == 8


def test_hold_pauses_and_mission_resumes_at_the_same_item() -> None:
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    mm.load_plan(_plan(), ORIGIN)
    mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.MISSION)
    mm.arm()
    outs, t = fly(mm, body, DT, 3.2)
    item = outs[-1].mission.current
    assert item >= 1
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER).ok
    outs, t = fly(mm, body, t, 2.0)
    assert outs[-1].flight_mode is FlightMode.HOLD and not outs[-1].mission.active
    held = tuple(body.pos)
    outs, t = fly(mm, body, t, 1.0)
    assert math.dist(held, body.pos) < 0.05
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.MISSION).ok
    outs, t = fly(mm, body, t, 0.1)
    assert outs[-1].mission.active and outs[-1].mission.current == item
    assert any("resumed" in e for o in outs for e in o.events)


def test_a_plan_ending_without_land_holds_and_reports_finished() -> None:
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    mm.load_plan(Plan(0, _plan().items[:2]), ORIGIN)
    mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.MISSION)
    mm.arm()
    outs, _ = fly(mm, body, DT, 8.0)
    assert outs[-1].flight_mode is FlightMode.HOLD and outs[-1].armed and outs[-1].engaged
    assert outs[-1].mission.finished and not outs[-1].mission.active
    assert body.pos == pytest.approx([1.0, 0.0, -2.0], abs=0.05)
