"""Rally points: the RALLY plan in the mission microservice (frames, storage limit, download, clear, opaque ids,
persistence), the Return destination (PX4's RTL_TYPE 0 rule, navigator/rtl.cpp) against hand-computed distances,
Return and a plan's return item flying there, MIS_TAKEOFF_ALT / RTL_RETURN_ALT reconfiguring the flight stack, and a
QGroundControl .plan's rallyPoints."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as M
from test_mission_executor import flying
from test_mission_protocol import LAT0, LON0, Rig, as_item, download, item_msg, same, upload
from test_modes import fly

from navig8_fc.core import vehicle as vm
from navig8_fc.flight import FlightStack
from navig8_fc.flight.commands import Takeoff
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Cmd, Frame, MissionItem, MissionType, Plan, plan_crc
from navig8_fc.mission.rally import RallyPoint, rally_positions, return_destination
from navig8_fc.mission.store import MissionStore
from navig8_fc.modes import FlightMode
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode
from navig8_fc.params.registry import ParamRegistry
from navig8_tools.mission import read_qgc_plan

RALLY = MissionType.RALLY
# MAVSDK's import of example-mission.plan: frame GLOBAL_RELATIVE_ALT (3) in MISSION_ITEM_INT, x/y degE7, z 0
EXAMPLE = (MissionItem(Frame.GLOBAL_RELATIVE_ALT, Cmd.NAV_RALLY_POINT, 0, 0, 0, 0, 0, 473975777, 85452625, 0.0),
           MissionItem(Frame.GLOBAL_RELATIVE_ALT, Cmd.NAV_RALLY_POINT, 0, 0, 0, 0, 0, 473988286, 85452344, 0.0))


def _rp(frame: int, x: int = LAT0, y: int = LON0, z: float = 5.0) -> MissionItem:
    return MissionItem(frame, Cmd.NAV_RALLY_POINT, 0, 0, 0, 0, 0, x, y, z)


# --- the protocol -----------------------------------------------------------------------------------------
def test_rally_upload_download_ids_and_clear_like_the_fence() -> None:
    from navig8_fc.mavlink import dialect

    rig = Rig(mod=dialect.load())
    (ack,) = upload(rig, EXAMPLE, mission_type=RALLY)
    assert ack.type == M.MAV_MISSION_ACCEPTED and ack.mission_type == RALLY and ack.opaque_id == plan_crc(EXAMPLE)
    got = download(rig, RALLY)
    assert len(got) == 2 and all(same(as_item(g), e) for g, e in zip(got, EXAMPLE, strict=True))
    assert [g.current for g in got] == [0, 0]  # current marks a mission's start item only
    (count,) = rig.send(rig.gcs.mission_request_list_encode(1, 1, RALLY))
    assert count.count == 2 and count.opaque_id == plan_crc(EXAMPLE)
    cur = rig.proto.mission_current()
    assert cur.rally_points_id == plan_crc(EXAMPLE) and cur.fence_id == 0 and cur.mission_id == 0
    assert not rig.proto.plan(MissionType.MISSION).items  # the mission is a separate plan
    (ack,) = rig.send(rig.gcs.mission_clear_all_encode(1, 1, MissionType.FENCE))
    assert ack.type == M.MAV_MISSION_ACCEPTED and rig.proto.plan(RALLY).items  # FENCE only
    (ack,) = rig.send(rig.gcs.mission_clear_all_encode(1, 1, RALLY))
    assert ack.type == M.MAV_MISSION_ACCEPTED and rig.proto.opaque_id(RALLY) == 0
    upload(rig, EXAMPLE, mission_type=RALLY)
    (ack,) = rig.send(rig.gcs.mission_clear_all_encode(1, 1, M.MAV_MISSION_TYPE_ALL))
    assert ack.type == M.MAV_MISSION_ACCEPTED and not rig.proto.plan(RALLY).items
    assert rig.proto.mission_current().rally_points_id == 0


@pytest.mark.parametrize("frame", [Frame.GLOBAL, Frame.GLOBAL_INT, Frame.GLOBAL_RELATIVE_ALT,
                                   Frame.GLOBAL_RELATIVE_ALT_INT])
def test_rally_points_in_every_global_frame_are_accepted(frame: int) -> None:
    rig = Rig()
    assert upload(rig, (_rp(frame),), mission_type=RALLY)[0].type == M.MAV_MISSION_ACCEPTED


@pytest.mark.parametrize(("item", "result"), [
    (_rp(Frame.MISSION), M.MAV_MISSION_UNSUPPORTED),  # PX4: MAV_FRAME_MISSION -> UNSUPPORTED
    (_rp(Frame.LOCAL_NED), M.MAV_MISSION_UNSUPPORTED_FRAME),
    (_rp(7), M.MAV_MISSION_UNSUPPORTED_FRAME),  # MAV_FRAME_LOCAL_ENU
    (_rp(Frame.GLOBAL_INT, x=91 * 10**7), M.MAV_MISSION_INVALID_PARAM5_X),
    (_rp(Frame.GLOBAL_INT, z=math.inf), M.MAV_MISSION_INVALID_PARAM7),
    (MissionItem(Frame.GLOBAL_INT, Cmd.NAV_WAYPOINT, 1, 0, 0, 0, 0, LAT0, LON0, 2.0), M.MAV_MISSION_UNSUPPORTED),
])
def test_bad_rally_items_are_refused_with_the_result_that_names_them(item: MissionItem, result: int) -> None:
    rig = Rig()
    ack = upload(rig, (item,), mission_type=RALLY)[0]
    assert ack.type == result and not rig.proto.plan(RALLY).items


def test_a_rally_point_in_a_mission_and_too_many_rally_points_are_refused() -> None:
    rig = Rig()
    assert upload(rig, (_rp(Frame.GLOBAL_INT),))[0].type == M.MAV_MISSION_UNSUPPORTED
    assert rig.send(rig.gcs.mission_count_encode(1, 1, 33, RALLY))[0].type == M.MAV_MISSION_NO_SPACE
    assert upload(rig, (_rp(Frame.GLOBAL_INT),) * 32, mission_type=RALLY)[0].type == M.MAV_MISSION_ACCEPTED
    assert rig.send(item_msg(rig.gcs, 31, _rp(Frame.GLOBAL_INT), 0, RALLY))[0].type == M.MAV_MISSION_ACCEPTED


def test_rally_plan_persists_and_reloads(tmp_path) -> None:
    path = tmp_path / "fc_mission_0.json"
    rig = Rig(MissionStore(path))
    upload(rig, EXAMPLE, mission_type=RALLY)
    again = Rig(MissionStore(path))
    assert again.proto.load_stored() is None and again.proto.opaque_id(RALLY) == plan_crc(EXAMPLE)
    assert all(same(a, b) for a, b in zip(again.proto.plan(RALLY).items, EXAMPLE, strict=True))


# --- the choice -------------------------------------------------------------------------------------------
def test_example_rally_points_in_local_ned_by_hand() -> None:
    """n = dlat * pi/180 * 6 371 000; e = dlon * pi/180 * 6 371 000 * cos(47.397742 deg) (flat earth, geo.py);
    z: above home (relative frame) or AMSL."""
    origin = GeoOrigin(47.397742, 8.545594, 488.0)
    home = (1.0, 2.0, -0.5)
    pts = rally_positions(Plan(RALLY, (*EXAMPLE, _rp(Frame.GLOBAL_INT, 0, 0, 3.0),
                                       _rp(Frame.GLOBAL_INT, 473977420, 85455940, 490.0))), origin, home)
    assert [p.seq for p in pts] == [0, 1, 3]  # null island (0, 0) skipped, as PX4
    # point 0: dlat -0.0001643 deg -> -18.27 m; dlon -0.0003315 deg -> -24.95 m; 0 m above home -> home's z
    assert pts[0].pos_ned_m == pytest.approx((-18.27, -24.95, -0.5), abs=0.01)
    assert pts[1].pos_ned_m == pytest.approx((120.83, -27.07, -0.5), abs=0.01)  # +0.0010866 deg, -0.0003596 deg
    assert pts[2].pos_ned_m == pytest.approx((0.0, 0.0, -2.0), abs=1e-6)  # the origin, 490 m AMSL = 2 m above it


def test_return_destination_is_px4s_rtl_type_0_rule() -> None:
    home = (0.0, 0.0, 0.0)
    a, b, c = RallyPoint(0, (30.0, 0.0, 0.0)), RallyPoint(1, (0.0, -50.0, -1.0)), RallyPoint(2, (6.0, 8.0, 0.0))
    pts = (a, b, c)
    assert return_destination((20.0, 0.0, -3.0), home, pts).seq == 0  # home 20 m, A 10 m
    assert return_destination((0.0, -30.0, -3.0), home, pts).seq == 1  # home 30 m, B 20 m, A 42.4 m
    d = return_destination((3.0, 4.0, -3.0), home, pts)  # home 5 m; C also 5 m but only 10 m from home: not used
    assert d.is_home and d.pos_ned_m == home
    assert return_destination((16.5, 0.0, -3.0), home, pts).seq == 0  # A 13.5 + 2 < home 16.5
    assert return_destination((15.5, 0.0, -3.0), home, pts).is_home  # A 14.5 m: closer, not by 2 m
    assert return_destination((29.0, -1.0, -30.0), home, pts).seq == 0  # horizontal distances: the height is not
    assert return_destination((20.0, 0.0, -3.0), home, ()).is_home


# --- flown ------------------------------------------------------------------------------------------------
ORIGIN = GeoOrigin()


def _rally_plan(n: float, e: float, alt: float = 0.0) -> Plan:
    lat, lon, _ = ORIGIN.to_global((n, e, 0.0))
    return Plan(RALLY, (_rp(Frame.GLOBAL_RELATIVE_ALT_INT, round(lat * 1e7), round(lon * 1e7), alt),))


def test_return_mode_flies_to_the_closest_rally_point_and_lands_there() -> None:
    mm, body, t = flying()
    mm.load_rally(_rally_plan(12.0, 0.0), ORIGIN)
    assert mm.reposition((8.0, 0.0, -1.5)).ok  # home 8 m, the rally point 4 m
    _, t = fly(mm, body, t, 8.0)
    assert mm.return_to_launch().ok
    outs, t = fly(mm, body, t, 25.0)
    events = [e for o in outs for e in o.events]
    assert "Return: landing at rally point 0" in events
    i_land = [o.flight_mode for o in outs].index(FlightMode.LAND)
    assert min(o.setpoint.pos_ned_m[2] for o in outs[:i_land]) == pytest.approx(-2.5)  # RTL_RETURN_ALT above it
    assert not outs[-1].armed and body.pos == pytest.approx([12.0, 0.0, 0.0], abs=0.25)
    assert mm.task is not None and mm.task.kind == "return" and mm.task.state == 1  # DONE at touchdown


def test_a_plan_return_item_and_a_near_rally_point_go_home() -> None:
    """A rally point within 10 m of home is never used (PX4): the plan's return item lands at home."""
    mm, body, t = flying()
    mm.load_rally(_rally_plan(9.0, 0.0), ORIGIN)
    mm.load_plan(Plan(0, (MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0, 0, 0, math.nan, 70000, 0, -1.5),
                          MissionItem(Frame.MISSION, Cmd.NAV_RETURN_TO_LAUNCH, 1, 0, 0, 0, 0, 0, 0, 0))), ORIGIN)
    assert mm.set_mode(Px4MainMode.AUTO, Px4AutoSubMode.MISSION).ok
    outs, _ = fly(mm, body, t, 30.0)
    assert "Mission: returning to launch" in [e for o in outs for e in o.events]
    assert not outs[-1].armed and math.hypot(body.pos[0], body.pos[1]) < 0.25


def test_mis_takeoff_alt_and_rtl_return_alt_reconfigure_the_stack_live() -> None:
    reg = ParamRegistry.from_defaults()
    stack = FlightStack(vm.VehicleConfig.load(), reg)
    assert (stack.mode_config.takeoff_default_alt_m, stack.mode_config.rtl_alt_m) == (2.5, 2.5)
    d = reg.definition("MIS_TAKEOFF_ALT")
    assert (d.min, d.max) == (pytest.approx(0.1), 20.0) and reg.definition("RTL_RETURN_ALT").max == 20.0
    assert reg.set("MIS_TAKEOFF_ALT", 10.0).accepted and reg.set("RTL_RETURN_ALT", 6.0).accepted
    assert not reg.set("MIS_TAKEOFF_ALT", 25.0).accepted  # above what this vehicle takes off to
    stack.reconfigure()
    assert (stack.mode_config.takeoff_default_alt_m, stack.mode_config.rtl_alt_m) == (10.0, 6.0)
    # appended after every earlier parameter (whose indices stayed), before the ones appended since
    assert (reg.index_of("MIS_TAKEOFF_ALT"), reg.index_of("RTL_RETURN_ALT")) == (102, 103)
    assert not stack.command(Takeoff()).ok  # disarmed; the altitude itself is checked by the manager


def test_qgc_plan_rally_points_become_rally_items() -> None:
    doc = {"fileType": "Plan", "mission": {"items": []},
           "rallyPoints": {"version": 2, "points": [[47.3975777095593, 8.545262530782963, 0],
                                                    [47.39882862292046, 8.545234383318984, 3.5]]}}
    pf = read_qgc_plan(doc)
    assert [(it.command, it.frame, it.x, it.y, it.z) for it in pf.rally] == [
        (Cmd.NAV_RALLY_POINT, Frame.GLOBAL_RELATIVE_ALT, 473975777, 85452625, 0.0),
        (Cmd.NAV_RALLY_POINT, Frame.GLOBAL_RELATIVE_ALT, 473988286, 85452344, 3.5)]
    assert pf.fence == () and read_qgc_plan({"fileType": "Plan"}).rally == ()
