"""Mission execution (navig8_fc.mission.executor inside the mode manager's Mission mode) on a point-mass vehicle:
Mission selected while disarmed, arming starts it; takeoff, waypoints in local and global frames (the global
ones through the origin's projection, checked against its inverse), gripper / arm-joint / pitch-hold items,
DO_JUMP, loiter time, return to launch and landing at home, disarm; pause (Hold) and resume."""

from __future__ import annotations

import math

import pytest
from test_modes import DT, PointMass, fly

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Cmd, Frame, MissionItem, Plan
from navig8_fc.modes import FlightMode, ModeManager
from navig8_fc.modes.manager import ModeConfig
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
    assert any(sp.pos_ned_m == pytest.approx((1.0, 0.0, -2.0)) and sp.yaw_rad == pytest.approx(math.pi / 2)
               for sp in sps)  # the local waypoint, yaw 90 deg
    assert any(sp.pos_ned_m == pytest.approx((0.0, 1.0, -2.5), abs=0.01) for sp in sps)  # E 1 m (degE7: ~1 cm)
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


def flying() -> tuple[ModeManager, PointMass, float]:
    """A manager that has taken off, its point mass and time (test_offboard.py uses it too)."""
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    mm.arm()
    mm.takeoff(1.5)
    _, t = fly(mm, body, DT, 5.0)
    return mm, body, t


def test_return_mode_climbs_flies_home_lands_and_disarms() -> None:
    mm, body, t = flying()
    assert mm.reposition((2.0, -1.0, -1.5)).ok
    _, t = fly(mm, body, t, 5.0)
    assert body.pos == pytest.approx([2.0, -1.0, -1.5], abs=0.05)
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.RTL).ok
    outs, t = fly(mm, body, t, 20.0)
    modes = [o.flight_mode for o in outs]
    i_home = modes.index(FlightMode.LAND)
    assert modes[0] is FlightMode.RTL and outs[0].custom_mode == 0x05040000
    zs = [o.setpoint.pos_ned_m[2] for o in outs[:i_home]]
    assert min(zs) == pytest.approx(-ModeConfig().rtl_alt_m)  # climbed to the return altitude first
    assert not outs[-1].armed and math.hypot(body.pos[0], body.pos[1]) < 0.25 and body.pos[2] == 0.0


def test_offboard_needs_a_stream_follows_it_and_holds_when_it_stops() -> None:
    mm, body, t = flying()
    ok, reason = mm.set_mode(Px4MainMode.OFFBOARD, 0)
    assert not ok and "setpoint" in reason
    mm.offboard_setpoint(Setpoint((1.0, 1.0, -2.0), 0.0, 0.5))
    assert mm.set_mode(Px4MainMode.OFFBOARD, 0).ok
    outs, t = fly(mm, body, t, 4.0)
    assert outs[-1].flight_mode is FlightMode.OFFBOARD and outs[-1].setpoint.yaw_rad == 0.5
    assert body.pos == pytest.approx([1.0, 1.0, -2.0], abs=0.05)
    mm.offboard_setpoint(None)  # the stack's FS_OFFB_TOUT check: lost
    outs, t = fly(mm, body, t, 1.0)
    assert outs[-1].flight_mode is FlightMode.HOLD and body.pos == pytest.approx([1.0, 1.0, -2.0], abs=0.05)
    assert not mm.set_mode(Px4MainMode.OFFBOARD, 0).ok


def test_reposition_denied_on_the_ground_and_nan_keeps_coordinates() -> None:
    mm = ModeManager()
    body = PointMass()
    mm.step(body.inputs(0.0))
    assert not mm.reposition((1.0, 1.0, -1.0)).ok
    mm, body, t = flying()
    assert mm.reposition((math.nan, 1.0, math.nan), math.nan).ok
    outs, t = fly(mm, body, t, 3.0)
    assert outs[-1].flight_mode is FlightMode.HOLD and outs[-1].setpoint.pos_ned_m == pytest.approx((0.0, 1.0, -1.5))


def test_position_mode_sticks_move_the_setpoint_and_centred_sticks_hold() -> None:
    mm, body, t = flying()
    assert mm.set_mode(Px4MainMode.POSCTL, 0).ok
    mm.manual_input(1.0, 0.0, 0.5, 0.0)  # full forward; heading 0 = north
    outs, t = fly(mm, body, t, 2.0)
    assert outs[-1].flight_mode is FlightMode.POSCTL and outs[-1].custom_mode == 0x00030000
    assert body.pos[0] > 1.5 and abs(body.pos[1]) < 0.05  # ~1 m/s north for 2 s
    mm.manual_input(0.0, 0.0, 0.5, 0.0)
    _, t = fly(mm, body, t, 2.0)
    held = list(body.pos)
    _, t = fly(mm, body, t, 2.0)
    assert body.pos == pytest.approx(held, abs=0.01)
    mm.manual_input(0.0, 0.0, 1.0, 0.0)  # full throttle: climb 0.5 m/s
    outs, t = fly(mm, body, t, 1.0)
    assert outs[-1].setpoint.pos_ned_m[2] == pytest.approx(held[2] - 0.5, abs=0.02)  # the body lags (v / 2 m)


def test_planned_path_for_display() -> None:
    """The path drawn on /foxglove/mission: home, then each position item's target in order (the takeoff climbs
    over home, the global waypoint through the origin's inverse projection, the loiter where the vehicle is, the
    return at home); non-position items and DO_JUMP add nothing."""
    from navig8_fc.mission.executor import planned_path

    home = (0.5, -0.5, -0.1)
    path = planned_path(_plan(), ORIGIN, home)
    want = [home, (0.5, -0.5, -2.1), (1.0, 0.0, -2.0), (0.0, 1.0, -2.6), (0.0, 1.0, -2.1), home]
    assert len(path) == len(want)
    for got, exp in zip(path, want, strict=True):
        # the global point is stored as int32 1e-7 deg: 1e-7 deg of longitude is 7 mm here (1.1 cm of latitude)
        assert got == pytest.approx(exp, abs=0.012)


def _fly_exec(plan: Plan, seconds: float, start=(0.0, 0.0, -2.0)):
    """The executor alone on a vehicle that is wherever the setpoint is (perfect tracking): its setpoints, its steps."""
    from navig8_fc.mission.executor import ExecConfig, MissionExecutor

    ex = MissionExecutor(plan, ORIGIN, (0.0, 0.0, 0.0), Setpoint(start, 0.0, 0.0), ExecConfig())
    pos, yaw, out = start, 0.0, []
    for k in range(int(round(seconds / DT))):
        st = ex.step(k * DT, pos, yaw, DT)
        pos, yaw = st.setpoint.pos_ned_m, st.setpoint.yaw_rad
        out.append(st)
        if st.land:
            break
    return ex, out


def test_change_speed_delay_yaw_loiter_unlim_and_land_items() -> None:
    wp = MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0, 0.1, 0, math.nan, 20000, 0, -2.0)  # N 2 m
    plan = Plan(0, (
        MissionItem(Frame.MISSION, Cmd.DO_CHANGE_SPEED, 1, 1, 0.5, -1, 0, 0, 0, 0),  # 0: 0.5 m/s
        wp,  # 1
        MissionItem(Frame.MISSION, Cmd.CONDITION_DELAY, 1, 1.5, 0, 0, 0, 0, 0, 0),  # 2: 1.5 s
        MissionItem(Frame.MISSION, Cmd.CONDITION_YAW, 1, 90, 0, 1, 0, 0, 0, 0),  # 3: absolute 90 deg
        MissionItem(Frame.MISSION, Cmd.CONDITION_YAW, 1, 30, 0, -1, 1, 0, 0, 0),  # 4: relative -30 deg
        MissionItem(Frame.LOCAL_NED, Cmd.NAV_LAND, 1, 0, 0, 0, math.nan, 20000, 10000, 0),  # 5: land at N 2, E 1
    ))
    ex, out = _fly_exec(plan, 20.0)
    xs = [s.setpoint.pos_ned_m[0] for s in out]
    steps = [b - a for a, b in zip(xs, xs[1:], strict=False) if b != a]
    assert max(steps) == pytest.approx(0.5 * DT)  # DO_CHANGE_SPEED: the setpoint moves at 0.5 m/s
    assert [seq for _, seq in ex.progress.reached_log] == [0, 1, 2, 3, 4, 5]  # in order, NAV_LAND at the hand-over
    yaws = [s.setpoint.yaw_rad for s in out]
    assert math.radians(90) in [pytest.approx(y) for y in yaws] and yaws[-1] == pytest.approx(math.radians(60))
    # the waypoint took 2 m / 0.5 m/s = 4 s; the delay 1.5 s more before the yaw was commanded
    i_yaw = next(i for i, y in enumerate(yaws) if y != 0.0)
    assert i_yaw * DT == pytest.approx(4.0 + 1.5, abs=0.05)
    assert out[-1].land and out[-1].setpoint.pos_ned_m[:2] == pytest.approx((2.0, 1.0))  # NAV_LAND hands over there
    # NAV_LOITER_UNLIM never completes.
    loiter = Plan(0, (MissionItem(Frame.LOCAL_NED, Cmd.NAV_LOITER_UNLIM, 1, 0, 0, 0, math.nan, 0, 0, -2.0),))
    ex, out = _fly_exec(loiter, 30.0)
    assert not ex.finished and len(out) == round(30.0 / DT) and not out[-1].land
