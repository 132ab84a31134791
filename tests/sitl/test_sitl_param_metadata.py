"""QGroundControl's parameter metadata from navig8-fc, fetched with pymavlink exactly as QGroundControl fetches it
(src/Vehicle/ComponentInformation/RequestMetaDataTypeStateMachine.cc, src/Vehicle/FTP/FTPDownloadStateMachine.cc;
docs/gcs.md): MAV_CMD_REQUEST_MESSAGE(COMPONENT_METADATA) to compid 1, then the general metadata file by its
mftp URI over MAVFTP (OpenFileRO, BurstReadFile and the next burst from where one ends until NAK EOF,
ResetSessions; the FC paces the replies at ~2.5 KB/s), its CRC against file_crc, then the
parameter file by the URI and CRC the general file gives. Path traversal and writes are refused.

MAVLink only: runs against any FC by connection string (`make test-hil`, docs/hil.md); locally the FC alone
(no bridge: nothing flies)."""

from __future__ import annotations

import json
import struct
import time
import zlib
from typing import Any

import yaml
from sitl_helpers import FcTarget, wait_fc_heartbeat, wait_for

from navig8_fc.mavlink import dialect
from navig8_fc.params.registry import ParamRegistry

HDR = struct.Struct("<HBBBBBBI")
ACK, NAK = 128, 129
OPEN_RO, READ, BURST, RESET, CRC, WRITE, CREATE, REMOVE = 4, 5, 15, 2, 14, 7, 6, 8
ERR_EOF, ERR_PROTECTED = 6, 9
MAX_DATA = 239
FC_LOCAL = {"start_bridge": False}  # the local FC (conftest.py `fc`), no simulator needed


class Ftp:
    """The GCS side of MAVFTP over a pymavlink connection (seq counted, replies matched on seq and req_opcode)."""

    def __init__(self, conn: Any) -> None:
        self.conn = conn
        self.seq = 100

    def send(self, opcode: int, session: int = 0, offset: int = 0, data: bytes = b"", size: int | None = None
             ) -> int:
        self.seq += 1
        payload = (HDR.pack(self.seq, session, opcode, len(data) if size is None else size, 0, 0, 0, offset)
                   + data).ljust(251, b"\0")
        self.conn.mav.file_transfer_protocol_send(0, self.conn.target_system, 1, list(payload))
        return self.seq

    def replies(self, seq: int, opcode: int, timeout_s: float = 5.0) -> Any:
        """Replies to the request seq (each FTP reply counts on from seq + 1), until a NAK or timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            m = wait_for(self.conn, "FILE_TRANSFER_PROTOCOL", deadline - time.monotonic())
            if m is None:
                break
            raw = bytes(m.payload)
            rseq, sess, op, size, req, burst, _pad, off = HDR.unpack_from(raw)
            if req != opcode or rseq <= seq:
                continue
            yield rseq, sess, op, size, burst, off, raw[HDR.size:HDR.size + size]

    def one(self, opcode: int, **kw: Any) -> tuple:
        seq = self.send(opcode, **kw)
        for r in self.replies(seq, opcode):
            assert r[0] == seq + 1
            return r
        raise AssertionError(f"no reply to FTP opcode {opcode}")

    def download(self, uri: str) -> bytes:
        path = uri.removeprefix("mftp://")
        path = path[path.index("]") + 1:] if path.startswith("[") else path  # QGC drops "[;comp=N]"
        _seq, session, op, _size, _b, _o, data = self.one(OPEN_RO, data=path.encode())
        assert op == ACK, data
        (file_size,) = struct.unpack("<I", data[:4])
        buf = bytearray(file_size)
        have = bytearray(file_size)  # 1 where a reply filled the byte
        offset, more = 0, True
        while more:  # a burst that ends before the file (burst_complete) is followed by the next, as MAVSDK's client
            more = False
            seq = self.send(BURST, session=session, offset=offset, size=MAX_DATA)
            for _rseq, _sess, op, size, burst, off, chunk in self.replies(seq, BURST):
                if op == NAK:
                    assert chunk[0] == ERR_EOF and burst == 1
                    break
                buf[off:off + size] = chunk
                have[off:off + size] = b"\1" * size
                if burst and off + size < file_size:
                    offset, more = off + size, True
                    break
        # QGC fills the holes lost datagrams left with ReadFile (FTPDownloadStateMachine's missing-data list); a
        # loaded machine drops loopback datagrams when the reader falls behind a burst
        while (hole := have.find(0)) >= 0:
            _s, _ss, op, size, _b, off, chunk = self.one(READ, session=session, offset=hole, size=MAX_DATA)
            assert op == ACK and off == hole and size > 0
            buf[off:off + size] = chunk
            have[off:off + size] = b"\1" * size
        assert self.one(RESET)[2] == ACK
        return bytes(buf)


def _command_ack(conn: Any, command: int) -> Any:
    ack = wait_for(conn, "COMMAND_ACK", 5.0, lambda m: m.command == command)
    assert ack is not None
    return ack


def test_qgc_style_parameter_metadata_download_over_mavftp(fc: FcTarget) -> None:
    conn = fc.connect()
    d = dialect.load()
    conn.mav = d.MAVLink(conn, srcSystem=255, srcComponent=190)  # COMPONENT_METADATA is in navig8.xml
    conn.mav.robust_parsing = True
    try:
        wait_fc_heartbeat(conn, fc.sysid)
        req = d.MAV_CMD_REQUEST_MESSAGE
        conn.mav.command_long_send(conn.target_system, 1, req, 0, 397, 0, 0, 0, 0, 0, 0)
        assert _command_ack(conn, req).result == d.MAV_RESULT_ACCEPTED
        meta = wait_for(conn, "COMPONENT_METADATA", 5.0)
        assert meta is not None and meta.uri.startswith("mftp://")
        conn.mav.command_long_send(conn.target_system, 1, req, 0, 395, 0, 0, 0, 0, 0, 0)  # the deprecated twin
        assert _command_ack(conn, req).result == d.MAV_RESULT_ACCEPTED
        info = wait_for(conn, "COMPONENT_INFORMATION", 5.0)
        assert info is not None and (info.general_metadata_uri, info.general_metadata_file_crc) == (
            meta.uri, meta.file_crc)

        ftp = Ftp(conn)
        general_raw = ftp.download(meta.uri)
        assert zlib.crc32(general_raw) == meta.file_crc
        general = json.loads(general_raw)
        assert general["version"] == 1
        (ptype,) = [t for t in general["metadataTypes"] if t["type"] == 1]  # COMP_METADATA_TYPE_PARAMETER
        params_raw = ftp.download(ptype["uri"])
        assert zlib.crc32(params_raw) == ptype["fileCrc"]
        _s, _ss, op, _z, _b, _o, data = ftp.one(CRC, data=ptype["uri"].removeprefix("mftp://[;comp=1]").encode())
        assert op == ACK and struct.unpack("<I", data[:4])[0] == ptype["fileCrc"]
        meta_params = {p["name"]: p for p in json.loads(params_raw)["parameters"]}
        yaml_params = yaml.safe_load(ParamRegistry.definitions_text())["params"]
        assert sorted(meta_params) == sorted(p["name"] for p in yaml_params)
        for p in yaml_params:
            m = meta_params[p["name"]]
            assert m.get("units", "") == p["units"], p["name"]
            assert (m["min"], m["max"], m["default"]) == tuple(float(p[k]) for k in ("min", "max", "default"))

        for path in (b"/navig8/../../etc/passwd", b"../navig8/parameters.json"):
            _s, _ss, op, _z, _b, _o, data = ftp.one(OPEN_RO, data=path)
            assert op == NAK and data[0] == ERR_PROTECTED
        for opcode in (CREATE, WRITE, REMOVE):
            _s, _ss, op, _z, _b, _o, data = ftp.one(opcode, data=b"/navig8/parameters.json")
            assert op == NAK and data[0] == ERR_PROTECTED
        assert ftp.download(ptype["uri"]) == params_raw  # unchanged
    finally:
        conn.close()
