"""The empty mission, TIMESYNC (MAVFTP: test_gcs_ftp.py)."""

from __future__ import annotations

from io import BytesIO
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.gcs.misc import MiscProtocols

M = mavlink2


@pytest.fixture
def rig():
    veh = M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
    gcs = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
    return MiscProtocols(veh), veh, gcs


def send(rig, msg: Any, now_s: float = 0.0) -> list[Any]:
    proto, veh, gcs = rig
    return [gcs.decode(bytearray(m.pack(veh))) for m in proto.handle(veh.decode(bytearray(msg.pack(gcs))), now_s)]


def test_mission_download_is_empty(rig) -> None:
    _, _, gcs = rig
    for mission_type in (M.MAV_MISSION_TYPE_MISSION, M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY):
        (count,) = send(rig, gcs.mission_request_list_encode(1, 1, mission_type))
        assert count.get_type() == "MISSION_COUNT" and count.count == 0 and count.mission_type == mission_type
        assert (count.target_system, count.target_component) == (255, 190)
    (ack,) = send(rig, gcs.mission_request_int_encode(1, 1, 0))
    assert ack.get_type() == "MISSION_ACK" and ack.type == M.MAV_MISSION_INVALID_SEQUENCE


def test_mission_upload_and_clear(rig) -> None:
    _, _, gcs = rig
    (ack,) = send(rig, gcs.mission_count_encode(1, 1, 0, 0))
    assert ack.type == M.MAV_MISSION_ACCEPTED
    out = send(rig, gcs.mission_count_encode(1, 1, 3, 0))
    assert out[0].get_type() == "MISSION_ACK" and out[0].type == M.MAV_MISSION_UNSUPPORTED
    assert out[1].get_type() == "STATUSTEXT"
    (ack,) = send(rig, gcs.mission_clear_all_encode(1, 1, M.MAV_MISSION_TYPE_ALL))
    assert ack.type == M.MAV_MISSION_ACCEPTED and ack.mission_type == M.MAV_MISSION_TYPE_ALL
    assert send(rig, gcs.mission_request_list_encode(9, 1, 0)) == []  # not for us


def test_timesync_request_answered(rig) -> None:
    _, _, gcs = rig
    (reply,) = send(rig, gcs.timesync_encode(0, 123456789), now_s=12.5)
    assert reply.tc1 == 12_500_000_000 and reply.ts1 == 123456789
    assert send(rig, gcs.timesync_encode(5, 1)) == []  # a response, not a request
