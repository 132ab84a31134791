"""Small GCS-facing services: MAVFTP answered with NAK, TIMESYNC.

MAVFTP (FILE_TRANSFER_PROTOCOL): we advertise no FTP capability and serve no files, but QGC and MAVSDK may
still try FTP (component metadata, parameter download via @PARAM/param.pck). Silence would cost them a
retry/timeout cycle per attempt; a NAK makes them fall back at once. Every request gets one reply with the
same session, seq + 1, opcode NAK (129), req_opcode = the request's opcode, size 1 and data[0] = the error:
- file/directory operations (OpenFileRO, ListDirectory, CalcFileCRC32, RemoveFile/Directory, Rename,
  TruncateFile): FileNotFound (there are no files);
- creating things (CreateFile, OpenFileWO, CreateDirectory): Fail (no writable storage);
- session operations (ReadFile, WriteFile, BurstReadFile): InvalidSession (none was ever opened);
- TerminateSession and ResetSessions: ACK (there is nothing to close, so "closed" is true);
- any other opcode: UnknownCommand. Our own replies (opcodes ACK/NAK) are never answered.

The mission protocol has its own module (navig8_fc.mission.protocol).

TIMESYNC: a request (tc1 == 0) is answered with tc1 = now_s in ns and ts1 echoed (TIMESYNC v2: addressed
to the requester when the dialect has the target fields). The shell chooses the clock: navig8-fc passes the
host's monotonic clock, the one time_boot_ms counts on (sim time stands still between lockstep steps).
"""

from __future__ import annotations

import struct
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.gcs.params import is_for_us
from navig8_fc.gcs.statustext import StatusTextEncoder

M = mavlink2
FTP_PAYLOAD_LEN = 251
_FTP_HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst_complete, padding, offset

_FTP_NOT_FOUND = frozenset({
    M.MAV_FTP_OPCODE_OPENFILERO, M.MAV_FTP_OPCODE_LISTDIRECTORY, M.MAV_FTP_OPCODE_CALCFILECRC,
    M.MAV_FTP_OPCODE_REMOVEFILE, M.MAV_FTP_OPCODE_REMOVEDIRECTORY, M.MAV_FTP_OPCODE_RENAME,
    M.MAV_FTP_OPCODE_TRUNCATEFILE,
})  # fmt: skip
_FTP_FAIL = frozenset({M.MAV_FTP_OPCODE_CREATEFILE, M.MAV_FTP_OPCODE_OPENFILEWO, M.MAV_FTP_OPCODE_CREATEDIRECTORY})
_FTP_NO_SESSION = frozenset({M.MAV_FTP_OPCODE_READFILE, M.MAV_FTP_OPCODE_WRITEFILE, M.MAV_FTP_OPCODE_BURSTREADFILE})
_FTP_ACKED = frozenset({M.MAV_FTP_OPCODE_TERMINATESESSION, M.MAV_FTP_OPCODE_RESETSESSION})


def ftp_error_for(opcode: int) -> int | None:
    """The MAV_FTP_ERR a request with `opcode` gets (None: it is ACKed)."""
    if opcode in _FTP_ACKED:
        return None
    if opcode in _FTP_NOT_FOUND:
        return M.MAV_FTP_ERR_FILENOTFOUND
    if opcode in _FTP_FAIL:
        return M.MAV_FTP_ERR_FAIL
    if opcode in _FTP_NO_SESSION:
        return M.MAV_FTP_ERR_INVALIDSESSION
    return M.MAV_FTP_ERR_UNKNOWNCOMMAND


def ftp_reply_payload(request_payload: bytes | list[int]) -> bytes | None:
    """The 251-byte reply payload to an FTP request payload (None for replies and runts)."""
    raw = bytes(request_payload)
    if len(raw) < _FTP_HEADER.size:
        return None
    seq, session, opcode, _size, _req, _burst, _pad, _offset = _FTP_HEADER.unpack_from(raw)
    if opcode in (M.MAV_FTP_OPCODE_ACK, M.MAV_FTP_OPCODE_NAK):
        return None
    error = ftp_error_for(opcode)
    reply_seq = (seq + 1) & 0xFFFF
    if error is None:
        header = _FTP_HEADER.pack(reply_seq, session, M.MAV_FTP_OPCODE_ACK, 0, opcode, 0, 0, 0)
        return header.ljust(FTP_PAYLOAD_LEN, b"\0")
    header = _FTP_HEADER.pack(reply_seq, session, M.MAV_FTP_OPCODE_NAK, 1, opcode, 0, 0, 0)
    return (header + bytes([error])).ljust(FTP_PAYLOAD_LEN, b"\0")


class MiscProtocols:
    """MAVFTP NAK and TIMESYNC for one component (module docstring)."""

    def __init__(
        self,
        mav: Any,
        sysid: int | None = None,
        compid: int | None = None,
        *,
        statustext: StatusTextEncoder | None = None,
    ) -> None:
        self._mav = mav
        self._sysid = int(mav.srcSystem if sysid is None else sysid)
        self._compid = int(mav.srcComponent if compid is None else compid)
        self._text = statustext or StatusTextEncoder(mav)

    def handle(self, msg: Any, now_s: float) -> list[Any]:
        kind = msg.get_type()
        if kind == "TIMESYNC":
            return self._timesync(msg, now_s)
        if kind not in _HANDLED or not is_for_us(msg, self._sysid, self._compid):
            return []
        if kind == "FILE_TRANSFER_PROTOCOL":
            if getattr(msg, "target_network", 0) != 0:
                return []
            payload = ftp_reply_payload(msg.payload)
            if payload is None:
                return []
            src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
            return [self._mav.file_transfer_protocol_encode(0, src_sys, src_comp, list(payload))]
        return []

    def _timesync(self, msg: Any, now_s: float) -> list[Any]:
        if int(msg.tc1) != 0:
            return []  # a response (possibly to someone else): nothing to answer
        target = (int(getattr(msg, "target_system", 0)), int(getattr(msg, "target_component", 0)))
        if target[0] not in (0, self._sysid) or target[1] not in (0, self._compid):
            return []
        reply = self._mav.timesync_encode(int(now_s * 1e9), int(msg.ts1))
        if "target_system" in reply.fieldnames:  # TIMESYNC v2 (newer common.xml): address the requester
            reply.target_system = msg.get_srcSystem()
            reply.target_component = msg.get_srcComponent()
        return [reply]


_HANDLED = frozenset({"FILE_TRANSFER_PROTOCOL"})
