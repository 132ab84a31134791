"""Mission microservice (navig8_fc.mission) against the devguide's sequences, pymavlink building and parsing every
message on the wire: upload with retries and timeout, atomic replace, refusal codes, download equal to the
upload, legacy MISSION_ITEM, clear, set current, MISSION_CURRENT / MISSION_ITEM_REACHED, persistence."""

from __future__ import annotations

import json
import math
from io import BytesIO
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.gcs.mission_protocol import MissionProtocol, Progress
from navig8_fc.gcs.mission_status import MissionState
from navig8_fc.mission import plan as P
from navig8_fc.mission.plan import Cmd, Frame, MissionItem, MissionType, Result, plan_crc
from navig8_fc.mission.store import MissionStore

M = mavlink2


def test_plan_constants_are_mavlinks() -> None:
    """plan.py carries MAVLink numbers without importing pymavlink: they must equal common.xml's."""
    for c in Cmd:
        if not c.name.startswith("NAVIG8"):
            assert getattr(M, f"MAV_CMD_{c.name}") == c.value
    assert Cmd.NAVIG8_ARM_JOINTS == M.MAV_CMD_USER_1 and Cmd.NAVIG8_PITCH_HOLD == M.MAV_CMD_USER_2
    for r in Result:
        assert getattr(M, f"MAV_MISSION_{r.name}") == r.value
    for f in Frame:
        assert getattr(M, f"MAV_FRAME_{f.name}") == f.value
    for t in MissionType:
        assert getattr(M, f"MAV_MISSION_TYPE_{t.name}") == t.value
    assert (MissionState.NO_MISSION, MissionState.COMPLETE) == (M.MISSION_STATE_NO_MISSION, M.MISSION_STATE_COMPLETE)


class Rig:
    def __init__(self, store: MissionStore | None = None, mod: Any = M) -> None:
        self.veh = mod.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
        self.gcs = mod.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
        self.other = mod.MAVLink(BytesIO(), srcSystem=254, srcComponent=0)
        self.proto = MissionProtocol(self.veh, 1, 1, store)

    def wire(self, m: Any, src: Any) -> Any:
        return self.veh.decode(bytearray(m.pack(src)))

    def send(self, msg: Any, now_s: float = 0.0, src: Any = None) -> list[Any]:
        src = src or self.gcs
        return [self.wire(m, self.veh) for m in self.proto.handle(self.wire(msg, src), now_s, source="gcs")]

    def poll(self, now_s: float) -> list[tuple[Any, Any]]:
        return [(s, self.wire(m, self.veh)) for s, m in self.proto.poll(now_s)]


def item_msg(gcs: Any, seq: int, it: MissionItem, current: int = 0, mission_type: int = 0) -> Any:
    return gcs.mission_item_int_encode(1, 1, seq, it.frame, it.command, current, it.autocontinue, it.param1,
                                       it.param2, it.param3, it.param4, it.x, it.y, it.z, mission_type)


LAT0, LON0 = 473977420, 85455940
EIGHT = (
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_TAKEOFF, 1, 0, 0, 0, math.nan, LAT0, LON0, 2.0),
    MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 1.0, 0.25, 0, 90.0, 20000, 10000, -2.0),
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_WAYPOINT, 1, 0, 0.5, 0, math.nan, LAT0 + 90, LON0, 2.5),
    MissionItem(Frame.MISSION, Cmd.DO_GRIPPER, 1, 1, 0, 0, 0, 0, 0, 0),
    MissionItem(Frame.MISSION, Cmd.NAVIG8_ARM_JOINTS, 1, 20, 20, 20, 1, 0, 0, 0),
    MissionItem(Frame.MISSION, Cmd.NAVIG8_PITCH_HOLD, 1, 45, 3, 0, 0, 0, 0, 0),
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_LOITER_TIME, 1, 2, 0, 0, math.nan, LAT0, LON0, 2.0),
    MissionItem(Frame.MISSION, Cmd.NAV_RETURN_TO_LAUNCH, 1, 0, 0, 0, 0, 0, 0, 0),
)


def upload(rig: Rig, items: tuple[MissionItem, ...], t0: float = 0.0, mission_type: int = 0) -> list[Any]:
    """Client side of an upload; returns the final answer (MISSION_ACK and any STATUSTEXT)."""
    out = rig.send(rig.gcs.mission_count_encode(1, 1, len(items), mission_type), t0)
    for k in range(len(items)):
        req = out[0]
        if req.get_type() == "MISSION_ACK":
            return out  # refused
        assert req.get_type() == "MISSION_REQUEST_INT" and req.seq == k and req.mission_type == mission_type
        assert (req.target_system, req.target_component) == (255, 190)
        out = rig.send(item_msg(rig.gcs, k, items[k], int(k == 0), mission_type), t0 + 0.01 * (k + 1))
    return out


def download(rig: Rig, mission_type: int = 0, legacy: bool = False) -> list[Any]:
    (count,) = rig.send(rig.gcs.mission_request_list_encode(1, 1, mission_type))
    assert count.get_type() == "MISSION_COUNT"
    got = []
    for k in range(count.count):
        enc = rig.gcs.mission_request_encode if legacy else rig.gcs.mission_request_int_encode
        (it,) = rig.send(enc(1, 1, k, mission_type))
        assert it.get_type() == ("MISSION_ITEM" if legacy else "MISSION_ITEM_INT") and it.seq == k
        got.append(it)
    rig.send(rig.gcs.mission_ack_encode(1, 1, 0, mission_type))
    return got


def as_item(m: Any) -> MissionItem:
    return MissionItem(m.frame, m.command, m.autocontinue, m.param1, m.param2, m.param3, m.param4, m.x, m.y, m.z)


def same(a: MissionItem, b: MissionItem) -> bool:
    """Equal, NaN equal to NaN (float32 on the wire: the test values are exact in float32)."""
    fa = (a.param1, a.param2, a.param3, a.param4, a.z)
    fb = (b.param1, b.param2, b.param3, b.param4, b.z)
    return (a.frame, a.command, a.autocontinue, a.x, a.y) == (b.frame, b.command, b.autocontinue, b.x, b.y) and all(
        (math.isnan(u) and math.isnan(v)) or u == v for u, v in zip(fa, fb, strict=True))


def test_upload_then_download_equals_upload() -> None:
    rig = Rig()
    (ack,) = upload(rig, EIGHT)
    assert ack.get_type() == "MISSION_ACK" and ack.type == M.MAV_MISSION_ACCEPTED
    assert (ack.target_system, ack.target_component) == (255, 190)
    assert rig.proto.opaque_id() == plan_crc(EIGHT) != 0
    got = download(rig)
    assert len(got) == 8 and all(same(as_item(g), e) for g, e in zip(got, EIGHT, strict=True))
    assert [g.current for g in got] == [1, 0, 0, 0, 0, 0, 0, 0]


def test_opaque_id_on_the_wire_with_the_navig8_dialect_and_common_peers_still_decode() -> None:
    """The FC's dialect adds upstream's extension fields (navig8_fc.mavlink.dialect.COMMON_EXTENSIONS): the plan
    identity travels in MISSION_ACK / MISSION_COUNT opaque_id and MISSION_CURRENT mission_id / fence_id, while a
    peer on pymavlink's common.xml (no such fields, same CRC_EXTRA) decodes the same frames."""
    from navig8_fc.mavlink import dialect

    d = dialect.load()
    for name in ("mission_ack", "mission_count", "mission_current"):
        assert getattr(d, f"MAVLink_{name}_message").crc_extra == getattr(M, f"MAVLink_{name}_message").crc_extra
    rig = Rig(mod=d)
    (ack,) = upload(rig, EIGHT)
    assert ack.type == M.MAV_MISSION_ACCEPTED and ack.opaque_id == plan_crc(EIGHT) != 0
    (count,) = rig.send(rig.gcs.mission_request_list_encode(1, 1, 0))
    assert count.count == 8 and count.opaque_id == plan_crc(EIGHT)
    cur = rig.proto.mission_current()
    assert cur.mission_id == plan_crc(EIGHT) and cur.fence_id == 0  # no fence plan
    plain = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
    seen = plain.decode(bytearray(ack.pack(rig.veh)))
    assert seen.get_type() == "MISSION_ACK" and seen.type == M.MAV_MISSION_ACCEPTED and seen.mission_type == 0


def test_legacy_mission_item_upload_and_download_convert_xy() -> None:
    rig = Rig()
    wp = MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0, 0.2, 0, 0, 0, 0, -2.0)
    (req,) = rig.send(rig.gcs.mission_count_encode(1, 1, 1, 0))
    assert req.get_type() == "MISSION_REQUEST_INT"
    (ack,) = rig.send(rig.gcs.mission_item_encode(1, 1, 0, wp.frame, wp.command, 1, 1, 0, 0.2, 0, 0, 1.5, -2.25,
                                                   -2.0, 0))
    assert ack.type == M.MAV_MISSION_ACCEPTED
    assert (rig.proto.plan().items[0].x, rig.proto.plan().items[0].y) == (15000, -22500)  # metres * 1e4
    (it,) = download(rig, legacy=True)
    assert (it.x, it.y) == (1.5, -2.25)


def test_unsupported_ack_switches_the_upload_to_mission_request() -> None:
    rig = Rig()
    rig.send(rig.gcs.mission_count_encode(1, 1, 1, 0))
    (req,) = rig.send(rig.gcs.mission_ack_encode(1, 1, M.MAV_MISSION_UNSUPPORTED, 0))
    assert req.get_type() == "MISSION_REQUEST" and req.seq == 0


def test_lost_request_is_repeated_every_250_ms_and_upload_times_out_after_5_s() -> None:
    rig = Rig()
    upload(rig, EIGHT[:2])
    before = rig.proto.plan()
    rig.send(rig.gcs.mission_count_encode(1, 1, 3, 0), 10.0)
    rig.send(item_msg(rig.gcs, 0, EIGHT[0], 1), 10.1)  # -> request 1, which the "radio" loses
    assert not [m for _, m in rig.poll(10.2) if m.get_type() == "MISSION_REQUEST_INT"]  # < 250 ms: nothing
    again = [(s, m) for s, m in rig.poll(10.36) if m.get_type() == "MISSION_REQUEST_INT"]
    assert [(s, m.seq) for s, m in again] == [("gcs", 1)]  # repeated, to the uploader
    # The uploader vanishes: 5 s after its last message the upload ends, the old plan stays in force.
    assert rig.proto.busy
    rig.poll(15.05)
    assert rig.proto.busy
    texts = [m.text for _, m in rig.poll(15.11) if m.get_type() == "STATUSTEXT"]
    assert not rig.proto.busy and any("timed out" in t for t in texts)
    assert rig.proto.plan() == before and len(download(rig)) == 2


def test_out_of_order_and_duplicate_items_are_ignored_and_the_request_repeated() -> None:
    rig = Rig()
    rig.send(rig.gcs.mission_count_encode(1, 1, 2, 0))
    (req,) = rig.send(item_msg(rig.gcs, 0, EIGHT[0], 1))
    assert req.seq == 1
    assert rig.send(item_msg(rig.gcs, 0, EIGHT[0], 1)) == []  # duplicate
    assert rig.send(item_msg(rig.gcs, 5, EIGHT[1])) == []  # ahead
    (ack,) = rig.send(item_msg(rig.gcs, 1, EIGHT[1]))
    assert ack.type == M.MAV_MISSION_ACCEPTED
    # The ground station lost that ACK and sends the last item again: the same ACK again.
    (ack2,) = rig.send(item_msg(rig.gcs, 1, EIGHT[1]))
    assert ack2.get_type() == "MISSION_ACK" and ack2.type == M.MAV_MISSION_ACCEPTED


@pytest.mark.parametrize("bad, result, word", [
    (MissionItem(Frame.MISSION, 183, 1, 0, 0, 0, 0, 0, 0, 0), Result.UNSUPPORTED, "command 183"),  # DO_SET_SERVO
    (MissionItem(Frame.MISSION, Cmd.NAV_WAYPOINT, 1, 0, 0, 0, 0, 0, 0, 0), Result.UNSUPPORTED_FRAME, "frame"),
    (MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, -1, 0, 0, 0, 0, 0, 0), Result.INVALID_PARAM1, "hold"),
    (MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, math.nan, 0, 0, 0, 0, 0, 0), Result.INVALID_PARAM1, "param1"),
    (MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0, 0, 0, 0, 0, 0, math.inf), Result.INVALID_PARAM7, "z"),
    (MissionItem(Frame.GLOBAL_INT, Cmd.NAV_WAYPOINT, 1, 0, 0, 0, 0, 95 * 10**7, 0, 5), Result.INVALID_PARAM5_X,
     "latitude"),
    (MissionItem(Frame.MISSION, Cmd.DO_JUMP, 1, 9, 1, 0, 0, 0, 0, 0), Result.INVALID_PARAM1, "target"),
    (MissionItem(Frame.MISSION, Cmd.DO_GRIPPER, 1, 1, 3, 0, 0, 0, 0, 0), Result.INVALID_PARAM2, "action"),
    (MissionItem(Frame.MISSION, Cmd.NAVIG8_PITCH_HOLD, 1, 75, 3, 0, 0, 0, 0, 0), Result.INVALID_PARAM1, "pitch"),
    (MissionItem(Frame.MISSION, Cmd.NAVIG8_ARM_JOINTS, 1, 0, 0, 0, 0, 0, 0, 0), Result.INVALID_PARAM4, "apply"),
    (MissionItem(Frame.MISSION, Cmd.DO_CHANGE_SPEED, 1, 1, math.nan, -1, 0, 0, 0, 0), Result.INVALID_PARAM2,
     "param2"),  # NaN where the command reads it
    (MissionItem(Frame.MISSION, Cmd.NAV_RETURN_TO_LAUNCH, 1, math.inf, 0, 0, 0, 0, 0, 0), Result.INVALID_PARAM1,
     "param1"),  # an unused parameter may be NaN ("not given"), not infinite
])  # fmt: skip
def test_a_bad_item_refuses_the_whole_upload_with_the_result_that_names_it(bad, result, word) -> None:
    rig = Rig()
    upload(rig, EIGHT)
    old_id = rig.proto.opaque_id()
    out = upload(rig, (*EIGHT[:3], bad, *EIGHT[4:]))
    ack, *texts = out
    assert ack.get_type() == "MISSION_ACK" and ack.type == result
    assert texts and texts[0].get_type() == "STATUSTEXT" and word in texts[0].text and "Item 3" in texts[0].text
    assert not rig.proto.busy and rig.proto.opaque_id() == old_id  # the old plan is in force
    assert len(download(rig)) == 8


def test_mavsdk_mission_items_with_nan_in_what_they_do_not_use_are_stored_as_sent() -> None:
    """The items MAVSDK's Mission plugin builds for examples/mission.py (MissionImpl::convert_to_int_items):
    waypoints with a NaN yaw, DO_CHANGE_SPEED with a NaN z, and the return-to-launch item with p1..p4 NaN."""
    rig = Rig()
    nan = math.nan
    items = (MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_WAYPOINT, 1, 0, 3.0, 0, nan, LAT0, LON0, 25.0),
             MissionItem(Frame.MISSION, Cmd.DO_CHANGE_SPEED, 1, 1, 10, -1, 0, 0, 0, nan),
             MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_TAKEOFF, 1, nan, nan, nan, nan, LAT0, LON0, 2.0),
             MissionItem(Frame.MISSION, Cmd.NAV_RETURN_TO_LAUNCH, 1, nan, nan, nan, nan, 0, 0, 0))
    (ack,) = upload(rig, items)
    assert ack.type == M.MAV_MISSION_ACCEPTED
    back = download(rig)
    assert len(back) == 4 and all(same(as_item(a), b) for a, b in zip(back, items, strict=True))


def test_fence_kinds_px4_accepts_exclusions_return_point_and_the_empty_circle() -> None:
    """MAVSDK's geofence example adds an empty circle (radius 0 at 0, 0); QGC's plans have exclusion zones and a
    return point. All are stored (PX4 stores them unchecked but for the vertex count)."""
    rig = Rig()
    g = Frame.GLOBAL_INT
    poly = [MissionItem(g, Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION, 1, 3, 0, 0, 0, LAT0 + d, LON0, 0)
            for d in (0, 100, 200)]
    items = (MissionItem(g, Cmd.NAV_FENCE_CIRCLE_INCLUSION, 0, 0.0, 0, 0, 0, 0, 0, 0),
             MissionItem(g, Cmd.NAV_FENCE_CIRCLE_EXCLUSION, 0, 5.0, 0, 0, 0, LAT0, LON0, 0), *poly,
             MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_FENCE_RETURN_POINT, 0, 0, 0, 0, 0, LAT0, LON0, 10))
    (ack,) = upload(rig, items, mission_type=1)
    assert ack.type == M.MAV_MISSION_ACCEPTED and len(download(rig, 1)) == 6
    mixed = (*poly[:2], MissionItem(g, Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, 1, 3, 0, 0, 0, LAT0, LON0, 0))
    assert upload(rig, mixed, mission_type=1)[0].type == M.MAV_MISSION_INVALID_PARAM1  # a polygon of one kind
    bad = MissionItem(g, Cmd.NAV_FENCE_CIRCLE_EXCLUSION, 0, -1.0, 0, 0, 0, LAT0, LON0, 0)
    assert upload(rig, (bad,), mission_type=1)[0].type == M.MAV_MISSION_INVALID_PARAM1


def test_upload_limits_types_and_busy() -> None:
    rig = Rig()
    (ack,) = rig.send(rig.gcs.mission_count_encode(1, 1, 10_000, 0))[:1]
    assert ack.type == M.MAV_MISSION_NO_SPACE
    (ack,) = rig.send(rig.gcs.mission_count_encode(1, 1, 33, M.MAV_MISSION_TYPE_RALLY))[:1]
    assert ack.type == M.MAV_MISSION_NO_SPACE  # PX4's DM_KEY_SAFE_POINTS_MAX
    (ack,) = rig.send(rig.gcs.mission_count_encode(1, 1, 1, 3))[:1]
    assert ack.type == M.MAV_MISSION_UNSUPPORTED  # no such mission type
    rig.send(rig.gcs.mission_count_encode(1, 1, 2, 0))
    ack = rig.send(rig.other.mission_count_encode(1, 1, 2, 0), src=rig.other)[0]
    assert ack.type == M.MAV_MISSION_DENIED and ack.target_system == 254  # another GCS: busy
    assert rig.send(item_msg(rig.other, 0, EIGHT[0], 1), src=rig.other) == []  # not the uploader's
    (req,) = rig.send(rig.gcs.mission_count_encode(1, 1, 1, 0), 0.1)  # the uploader restarts
    assert req.seq == 0
    assert rig.send(rig.gcs.mission_count_encode(2, 1, 1, 0)) == []  # another vehicle's


def test_mission_item_in_wrong_mission_type_during_upload_is_an_error() -> None:
    rig = Rig()
    rig.send(rig.gcs.mission_count_encode(1, 1, 1, 0))
    ack = rig.send(item_msg(rig.gcs, 0, EIGHT[0], 1, mission_type=1))[0]
    assert ack.type == M.MAV_MISSION_ERROR and not rig.proto.busy


def test_fence_upload_is_separate_and_polygons_are_checked() -> None:
    rig = Rig()
    upload(rig, EIGHT)
    circle = MissionItem(Frame.GLOBAL_INT, Cmd.NAV_FENCE_CIRCLE_INCLUSION, 1, 10.0, 0, 0, 0, LAT0, LON0, 0)
    vertex = MissionItem(Frame.GLOBAL_INT, Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, 1, 3, 0, 0, 0, LAT0, LON0, 0)
    (ack,) = upload(rig, (circle, vertex, vertex, vertex), mission_type=1)
    assert ack.type == M.MAV_MISSION_ACCEPTED and ack.mission_type == 1
    assert len(download(rig, 1)) == 4 and len(download(rig, 0)) == 8
    ack = upload(rig, (vertex, vertex), mission_type=1)[0]
    assert ack.type == M.MAV_MISSION_INVALID_PARAM1
    ack = upload(rig, (EIGHT[0],), mission_type=1)[0]  # a mission command in a fence
    assert ack.type == M.MAV_MISSION_UNSUPPORTED
    assert len(rig.proto.plan(1).items) == 4


def test_clear_all_and_count_zero() -> None:
    rig = Rig()
    upload(rig, EIGHT)
    upload(rig, (MissionItem(Frame.GLOBAL_INT, Cmd.NAV_FENCE_CIRCLE_INCLUSION, 1, 10.0, 0, 0, 0, 1, 1, 0),), 0, 1)
    (ack,) = rig.send(rig.gcs.mission_clear_all_encode(1, 1, 0))
    assert ack.type == M.MAV_MISSION_ACCEPTED and not rig.proto.plan().items and rig.proto.plan(1).items
    (ack,) = rig.send(rig.gcs.mission_clear_all_encode(1, 1, M.MAV_MISSION_TYPE_ALL))
    assert ack.type == M.MAV_MISSION_ACCEPTED and not rig.proto.plan(1).items
    upload(rig, EIGHT)
    (ack,) = rig.send(rig.gcs.mission_count_encode(1, 1, 0, 0))
    assert ack.type == M.MAV_MISSION_ACCEPTED and rig.proto.opaque_id() == 0
    assert rig.send(rig.gcs.mission_request_list_encode(1, 1, 0))[0].count == 0


def test_download_of_a_missing_seq_is_invalid_sequence() -> None:
    rig = Rig()
    upload(rig, EIGHT[:2])
    (ack,) = rig.send(rig.gcs.mission_request_int_encode(1, 1, 2, 0))
    assert ack.get_type() == "MISSION_ACK" and ack.type == M.MAV_MISSION_INVALID_SEQUENCE


def test_mission_current_streams_and_follows_set_current_and_progress() -> None:
    rig = Rig()
    cur = [m for _, m in rig.poll(0.0) if m.get_type() == "MISSION_CURRENT"]
    assert [(c.seq, c.total, c.mission_state) for c in cur] == [(0, 65535, M.MISSION_STATE_NO_MISSION)]
    assert not [m for _, m in rig.poll(0.5) if m.get_type() == "MISSION_CURRENT"]  # 1 Hz
    upload(rig, EIGHT, 0.6)
    cur = [m for _, m in rig.poll(0.7) if m.get_type() == "MISSION_CURRENT"]  # changed: at once
    assert [(c.seq, c.total, c.mission_state, c.mission_mode) for c in cur] == [(0, 8, M.MISSION_STATE_NOT_STARTED, 2)]
    rig.send(rig.gcs.mission_set_current_encode(1, 1, 3), 0.8)
    cur = [m for s, m in rig.poll(0.9) if m.get_type() == "MISSION_CURRENT" and s is None]
    assert [c.seq for c in cur] == [3] and rig.proto.plan().current == 3
    out = rig.send(rig.gcs.mission_set_current_encode(1, 1, 8), 1.0)
    assert out[0].get_type() == "STATUSTEXT" and rig.proto.plan().current == 3
    rig.proto.report(Progress(current=4, reached=3, active=True, reached_log=((1, 2), (2, 3))))
    msgs = [m for _, m in rig.poll(1.1)]
    cur = [m for m in msgs if m.get_type() == "MISSION_CURRENT"]
    assert [(c.seq, c.mission_state, c.mission_mode) for c in cur] == [(4, M.MISSION_STATE_ACTIVE, 1)]
    reached = [m.seq for m in msgs if m.get_type() == "MISSION_ITEM_REACHED"]
    assert reached == [2, 3]  # every reached item, in order, even two between polls
    n_repeats = sum(m.get_type() == "MISSION_ITEM_REACHED" for t in range(2, 20) for _, m in rig.poll(float(t)))
    assert n_repeats == 10  # then once a second, 10 more times (PX4)
    rig.proto.report(Progress(current=7, reached=7, active=False, finished=True))
    cur = [m for _, m in rig.poll(30.0) if m.get_type() == "MISSION_CURRENT"]
    assert cur[0].mission_state == M.MISSION_STATE_COMPLETE


def test_plans_persist_atomically_and_reload(tmp_path) -> None:
    path = tmp_path / "fc_mission_0.json"
    rig = Rig(MissionStore(path))
    upload(rig, EIGHT)
    rig.send(rig.gcs.mission_set_current_encode(1, 1, 2))
    doc = json.loads(path.read_text())
    assert doc["format"] == "navig8-fc-mission" and len(doc["plans"]["0"]["items"]) == 8
    assert [p.name for p in tmp_path.iterdir()] == ["fc_mission_0.json"]  # no temporary file left
    again = Rig(MissionStore(path))
    assert again.proto.load_stored() is None
    assert again.proto.plan().current == 2 and again.proto.opaque_id() == plan_crc(EIGHT)
    assert all(same(a, b) for a, b in zip(again.proto.plan().items, EIGHT, strict=True))


def test_a_stored_plan_the_rules_refuse_is_not_loaded(tmp_path) -> None:
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"format": "navig8-fc-mission", "version": 1, "plans": {
        "0": {"current": 0, "items": [[2, 183, 1, 0, 0, 0, 0, 0, 0, 0]]}}}))
    rig = Rig(MissionStore(path))
    reason = rig.proto.load_stored()
    assert reason and "not supported" in reason and not rig.proto.plan().items
    path.write_text("{not json")
    assert "unreadable" in (Rig(MissionStore(path)).proto.load_stored() or "")


def test_check_item_accepts_every_item_of_the_eight_item_plan() -> None:
    assert all(P.check_item(it, 0, 8) is None for it in EIGHT)


def _from(rig: Rig, msg: Any, now_s: float, source: Any, src: Any = None) -> list[Any]:
    """A message from `source` (where it came from), sent with `src`'s ids (default the ground station's)."""
    return [rig.wire(m, rig.veh) for m in rig.proto.handle(rig.wire(msg, src or rig.gcs), now_s, source=source)]


def test_the_upload_lock_belongs_to_its_sender_and_repeated_counts_do_not_hold_it() -> None:
    rig = Rig()
    upload(rig, EIGHT[:2])
    impostor = ("gcs", ("127.0.0.1", 9999))  # the operator's ids, another address
    # The impostor sends MISSION_COUNT and never an item, again every 0.5 s.
    (req,) = _from(rig, rig.gcs.mission_count_encode(1, 1, 5, 0), 0.0, impostor)
    assert req.get_type() == "MISSION_REQUEST_INT"
    # While it is fresh, the operator (another source) is denied, and its items are not the uploader's.
    ack = _from(rig, rig.gcs.mission_count_encode(1, 1, 2, 0), 0.3, "gcs")[0]
    assert ack.type == M.MAV_MISSION_DENIED
    assert _from(rig, rig.gcs.mission_count_encode(1, 1, 5, 0), 0.5, impostor)[0].get_type() == "MISSION_REQUEST_INT"
    assert _from(rig, item_msg(rig.gcs, 0, EIGHT[0], 1), 0.6, "gcs") == []
    # Its restarts do not extend the lock: 1 s after its start the operator takes over (the stale upload is
    # abandoned and said so) and uploads.
    assert _from(rig, rig.gcs.mission_count_encode(1, 1, 5, 0), 0.9, impostor)[0].get_type() == "MISSION_REQUEST_INT"
    out = _from(rig, rig.gcs.mission_count_encode(1, 1, 2, 0), 1.05, "gcs")
    assert [m.get_type() for m in out] == ["STATUSTEXT", "MISSION_REQUEST_INT"] and "abandoned" in out[0].text
    (req,) = _from(rig, item_msg(rig.gcs, 0, EIGHT[0], 1), 1.06, "gcs")
    # the impostor meanwhile: denied, the operator's upload progresses
    assert _from(rig, rig.gcs.mission_count_encode(1, 1, 5, 0), 1.07, impostor)[0].type == M.MAV_MISSION_DENIED
    (ack,) = _from(rig, item_msg(rig.gcs, 1, EIGHT[1]), 1.08, "gcs")
    assert ack.type == M.MAV_MISSION_ACCEPTED and len(rig.proto.plan().items) == 2
    # Alone, repeating its MISSION_COUNT every 0.5 s, the impostor's upload still times out 5 s after it began.
    _from(rig, rig.gcs.mission_count_encode(1, 1, 5, 0), 2.0, impostor)
    texts = []
    for k in range(1, 12):
        _from(rig, rig.gcs.mission_count_encode(1, 1, 5, 0), 2.0 + 0.5 * k, impostor) if 0.5 * k < 5 else None
        texts += [m.text for _, m in rig.poll(2.0 + 0.5 * k) if m.get_type() == "STATUSTEXT"]
    assert not rig.proto.busy and any("timed out" in t for t in texts)


def test_the_item_check_refuses_an_item_with_its_reason() -> None:
    def check(it: MissionItem, mission_type: int) -> P.Problem | None:
        return P.Problem(Result.INVALID_PARAM7, "NAV_WAYPOINT: too high") if it.z < -100 else None

    rig = Rig()
    rig.proto = MissionProtocol(rig.veh, 1, 1, item_check=check)
    high = MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0, 0.25, 0, math.nan, 0, 0, -1e9)
    ack, text = upload(rig, (EIGHT[0], high))
    assert ack.type == M.MAV_MISSION_INVALID_PARAM7 and "too high" in text.text and rig.proto.plan().items == ()
