"""MAVFTP NAK, TIMESYNC (the mission protocol: test_mission_protocol.py)."""

from __future__ import annotations

import struct
from io import BytesIO
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.gcs.misc import FTP_PAYLOAD_LEN, MiscProtocols, ftp_reply_payload

M = mavlink2


@pytest.fixture
def rig():
    veh = M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
    gcs = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
    return MiscProtocols(veh), veh, gcs


def send(rig, msg: Any, now_s: float = 0.0) -> list[Any]:
    proto, veh, gcs = rig
    return [gcs.decode(bytearray(m.pack(veh))) for m in proto.handle(veh.decode(bytearray(msg.pack(gcs))), now_s)]


def ftp_request(seq: int, session: int, opcode: int, offset: int = 0, data: bytes = b"") -> list[int]:
    header = struct.pack("<HBBBBBBI", seq, session, opcode, len(data), 0, 0, 0, offset)
    return list((header + data).ljust(FTP_PAYLOAD_LEN, b"\0"))


def parse_reply(payload: list[int]) -> tuple[int, ...]:
    return struct.unpack_from("<HBBBBBBIB", bytes(payload))  # ..., data[0]


@pytest.mark.parametrize(
    "opcode, error",
    [
        (M.MAV_FTP_OPCODE_OPENFILERO, M.MAV_FTP_ERR_FILENOTFOUND),
        (M.MAV_FTP_OPCODE_LISTDIRECTORY, M.MAV_FTP_ERR_FILENOTFOUND),
        (M.MAV_FTP_OPCODE_CALCFILECRC, M.MAV_FTP_ERR_FILENOTFOUND),
        (M.MAV_FTP_OPCODE_CREATEFILE, M.MAV_FTP_ERR_FAIL),
        (M.MAV_FTP_OPCODE_READFILE, M.MAV_FTP_ERR_INVALIDSESSION),
        (M.MAV_FTP_OPCODE_BURSTREADFILE, M.MAV_FTP_ERR_INVALIDSESSION),
        (77, M.MAV_FTP_ERR_UNKNOWNCOMMAND),
    ],
)
def test_ftp_requests_are_nakked(rig, opcode: int, error: int) -> None:
    _, _, gcs = rig
    out = send(rig, gcs.file_transfer_protocol_encode(0, 1, 1, ftp_request(41, 3, opcode, 0, b"@PARAM/param.pck")))
    (reply,) = out
    assert reply.get_type() == "FILE_TRANSFER_PROTOCOL"
    assert (reply.target_network, reply.target_system, reply.target_component) == (0, 255, 190)
    assert len(reply.payload) == FTP_PAYLOAD_LEN
    seq, session, op, size, req_op, burst, _pad, _offset, err = parse_reply(reply.payload)
    assert (seq, session, op, size, req_op, err) == (42, 3, M.MAV_FTP_OPCODE_NAK, 1, opcode, error)


def test_ftp_reset_and_terminate_are_acked_and_replies_ignored(rig) -> None:
    _, _, gcs = rig
    for opcode in (M.MAV_FTP_OPCODE_RESETSESSION, M.MAV_FTP_OPCODE_TERMINATESESSION):
        (reply,) = send(rig, gcs.file_transfer_protocol_encode(0, 1, 1, ftp_request(65535, 0, opcode)))
        seq, _session, op, size, req_op, *_ = parse_reply(reply.payload)
        assert (seq, op, size, req_op) == (0, M.MAV_FTP_OPCODE_ACK, 0, opcode)  # seq wraps
    for opcode in (M.MAV_FTP_OPCODE_ACK, M.MAV_FTP_OPCODE_NAK):
        assert send(rig, gcs.file_transfer_protocol_encode(0, 1, 1, ftp_request(1, 0, opcode))) == []
    assert send(rig, gcs.file_transfer_protocol_encode(0, 7, 1, ftp_request(1, 0, 4))) == []  # other system
    assert ftp_reply_payload(b"\x01\x02") is None


def test_timesync_request_answered(rig) -> None:
    _, _, gcs = rig
    (reply,) = send(rig, gcs.timesync_encode(0, 123456789), now_s=12.5)
    assert reply.tc1 == 12_500_000_000 and reply.ts1 == 123456789
    assert send(rig, gcs.timesync_encode(5, 1)) == []  # a response, not a request
