"""TIMESYNC (the mission protocol: test_mission_protocol.py; MAVFTP: test_gcs_ftp.py)."""

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




def test_timesync_request_answered(rig) -> None:
    _, _, gcs = rig
    (reply,) = send(rig, gcs.timesync_encode(0, 123456789), now_s=12.5)
    assert reply.tc1 == 12_500_000_000 and reply.ts1 == 123456789
    assert send(rig, gcs.timesync_encode(5, 1)) == []  # a response, not a request
