"""The operating volume (navig8_fc.mission.volume, VOL_*): mission and rally items refused on upload with the
MAV_MISSION_RESULT naming the coordinate, offboard targets ignored with a STATUSTEXT at most once a second, the
defaults leaving every plan and target the tests and examples fly alone."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from test_gcs_service import GCS, Rig
from test_offboard import ALL_BUT

from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Cmd, Frame, MissionItem, Result
from navig8_fc.mission.volume import OperatingVolume
from navig8_fc.params.registry import ParamRegistry

M = mavlink2
NAN = math.nan
ORIGIN = GeoOrigin()
HOME = (0.0, 0.0, 0.0)
INT32_MAX = 2**31 - 1
_LAT, _LON, _ = ORIGIN.to_global((30.0, -40.0, 0.0))
PLAN = (  # the kinds of item the mission tests fly, about the default origin
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_TAKEOFF, 1, 0, 0, 0, NAN, 0, 0, 2.0),
    MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 1.0, 0.25, 0, 90.0, 10000, 0, -2.0),
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_WAYPOINT, 1, 0, 0.25, 0, NAN, round(_LAT * 1e7),
                round(_LON * 1e7), 25.0),
    MissionItem(Frame.MISSION, Cmd.DO_GRIPPER, 1, 1, 0, 0, 0, 0, 0, 0),
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_LOITER_TIME, 1, 2, 0, 0, NAN, 0, 0, 2.0),
    MissionItem(Frame.MISSION, Cmd.NAV_RETURN_TO_LAUNCH, 1, 0, 0, 0, 0, 0, 0, 0),
)


def _volume() -> OperatingVolume:
    return OperatingVolume.from_params(ParamRegistry.from_defaults())


def _wp(frame: int, x: int, y: int, z: float, cmd: int = Cmd.NAV_WAYPOINT) -> MissionItem:
    return MissionItem(frame, cmd, 1, 0, 0.25, 0, NAN, x, y, z)


def test_defaults_are_generous_but_finite() -> None:
    v = _volume()
    assert (v.max_distance_m, v.max_altitude_m, v.min_altitude_m, v.max_speed_m_s) == (1000.0, 120.0, -2.0, 20.0)


def test_items_outside_the_volume_are_refused_with_the_coordinate_that_is_wrong() -> None:
    v = _volume()
    lat, lon, _ = ORIGIN.to_global((214e3, 0.0, 0.0))
    far = _wp(Frame.GLOBAL_RELATIVE_ALT_INT, round(lat * 1e7), round(lon * 1e7), 10.0)
    cases = {
        "1e9 m up": (_wp(Frame.LOCAL_NED, 0, 0, -1e9), Result.INVALID_PARAM7, "above VOL_ALT_MAX"),
        "214 km away": (far, Result.INVALID_PARAM5_X, "214 km from home"),
        "underground": (_wp(Frame.GLOBAL_RELATIVE_ALT_INT, 0, 0, -50.0), Result.INVALID_PARAM7, "below VOL_ALT_MIN"),
        "AMSL underground": (_wp(Frame.GLOBAL_INT, 0, 0, 1000.0), Result.INVALID_PARAM7, "-100 m above home"),
        "take-off 1 km up": (_wp(Frame.GLOBAL_RELATIVE_ALT_INT, 0, 0, 1000.0, Cmd.NAV_TAKEOFF),
                             Result.INVALID_PARAM7, "1000 m above home"),
        "landing 2 km away": (_wp(Frame.LOCAL_NED, 20_000_000, 0, 0.0, Cmd.NAV_LAND), Result.INVALID_PARAM5_X,
                              "2000 m from home"),
        "rally INT32_MAX": (MissionItem(Frame.GLOBAL_INT, Cmd.NAV_RALLY_POINT, 1, 0, 0, 0, 0, 900_000_000,
                                        INT32_MAX, 1110.0), Result.INVALID_PARAM5_X, "km from home"),
    }
    for name, (item, result, words) in cases.items():
        problem = v.item_problem(item, ORIGIN, HOME)
        assert problem is not None and problem.result == result and words in problem.reason, (name, problem)
    # inside: every item the mission tests fly, a landing's ignored altitude, "here" (x = y = 0)
    for item in (*PLAN, _wp(Frame.LOCAL_NED, 0, 0, 5.0, Cmd.NAV_LAND), _wp(Frame.GLOBAL_INT, 0, 0, 1125.0),
                 _wp(Frame.LOCAL_NED, 9_990_000, 0, -119.0)):
        assert v.item_problem(item, ORIGIN, HOME) is None, item
    # relative to home, not the origin: 50 m up a hill, a waypoint at the origin's height is 50 m below home
    assert v.item_problem(_wp(Frame.LOCAL_NED, 0, 0, 0.0), ORIGIN, (0.0, 0.0, -50.0)).result == Result.INVALID_PARAM7


def test_offboard_targets_outside_the_volume_are_named() -> None:
    v = _volume()
    assert "beyond VOL_DIST_MAX" in v.target_problem((1e9, 0.0, -2.0), (NAN, NAN, NAN), HOME)
    assert "above VOL_ALT_MAX" in v.target_problem((NAN, NAN, -1e9), (NAN, NAN, NAN), HOME)
    assert "beyond VOL_SPEED_MAX" in v.target_problem((NAN, NAN, NAN), (1e6, 0.0, 0.0), HOME)
    assert v.target_problem((50.0, 0.0, -10.0), (1.0, 0.0, 0.0), HOME) == ""  # MAVSDK's offboard examples
    assert v.target_problem((NAN, NAN, NAN), (5.0, 0.0, 0.0), HOME) == ""


def _upload(rig: Rig, items: tuple[MissionItem, ...]) -> list[object]:
    c = rig.client
    rig.send(c.mission_count_encode(1, 1, len(items), 0), GCS)
    for seq, it in enumerate(items):
        rig.send(c.mission_item_int_encode(1, 1, seq, it.frame, it.command, 0, it.autocontinue, it.param1, it.param2,
                                           it.param3, it.param4, it.x, it.y, it.z, 0), GCS)
    return [m for _d, m in rig.outbox.pop("MISSION_ACK")]


def test_through_the_gcs_service_refusals_change_nothing_and_are_said_once_a_second() -> None:
    rig = Rig()
    rig.step(60)
    assert rig.command(GCS, 400, 1, 21196).result == 0  # forced arm on the bench
    c = rig.client
    (ack,) = _upload(rig, (PLAN[0], _wp(Frame.LOCAL_NED, 0, 0, -1e9)))
    assert ack.type == M.MAV_MISSION_INVALID_PARAM7 and rig.gcs.mission.plan().items == ()
    assert "VOL_ALT_MAX" in "".join(m.text for _d, m in rig.outbox.pop("STATUSTEXT"))  # chunked
    (ack,) = _upload(rig, PLAN)
    assert ack.type == M.MAV_MISSION_ACCEPTED
    rig.send(c.set_position_target_local_ned_encode(0, 1, 1, 1, ALL_BUT["pos"], 1.0, 0, -2.0, 0, 0, 0, 0, 0, 0, 0, 0),
             GCS, 0.0)
    good = rig.stack.state().offboard_target
    rig.outbox.pop("STATUSTEXT")
    bad = [
        c.set_position_target_local_ned_encode(0, 1, 1, 1, ALL_BUT["pos"], 1e9, 0, -2.0, 0, 0, 0, 0, 0, 0, 0, 0),
        c.set_position_target_local_ned_encode(0, 1, 1, 1, ALL_BUT["vel"], 0, 0, 0, 1e6, 0, 0, 0, 0, 0, 0, 0),
        c.set_position_target_global_int_encode(0, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, ALL_BUT["pos"],
                                                INT32_MAX, INT32_MAX, 2.0, 0, 0, 0, 0, 0, 0, 0, 0),
    ]
    for k in range(30):  # 3 s of out-of-volume targets at 10 Hz
        rig.send(bad[k % 3], GCS, 0.1 * k + 0.05)
    texts = [m.text for _d, m in rig.outbox.pop("STATUSTEXT")]
    firsts = [t for t in texts if t.startswith("Offboard target ignored")]  # a long text comes in chunks
    assert 3 <= len(firsts) <= 4 and len(texts) <= 2 * len(firsts), texts
    assert rig.stack.state().offboard_target == good  # the last target accepted stays
    assert rig.gcs.last_offboard_setpoint == pytest.approx(0.0)  # an ignored target is no setpoint stream
