"""The read-only MAVFTP server (navig8_fc.gcs.ftp) and the parameter metadata it serves (navig8_fc.gcs.metadata),
through pymavlink messages as a ground station sends them. The download follows QGroundControl's
FTPDownloadStateMachine: OpenFileRO, BurstReadFile until NAK EOF, ResetSessions."""

from __future__ import annotations

import json
import struct
import zlib
from io import BytesIO
from typing import Any

import pytest
import yaml
from pymavlink.dialects.v20 import common as M

from navig8_fc.gcs.ftp import FTP_PAYLOAD_LEN, MAX_DATA, FtpServer, FtpService, PathRefused, normalise_path
from navig8_fc.gcs.metadata import GENERAL_PATH, PARAMETER_PATH, build_metadata
from navig8_fc.params.registry import ParamRegistry

HDR = struct.Struct("<HBBBBBBI")
BIG = bytes(range(256)) * 9 + b"tail"  # 2308 bytes: ten 239-byte packets and a short one


class Client:
    """A ground station's side of MAVFTP over pymavlink messages (seq counted as QGC does)."""

    def __init__(self, files: dict[str, bytes]) -> None:
        self.server = FtpServer(files)
        self.veh = M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
        self.gcs = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
        self.service = FtpService(self.veh, self.server)
        self.seq = 0

    def raw(self, msg: Any) -> list[Any]:
        got = self.service.handle(self.veh.decode(bytearray(msg.pack(self.gcs))))
        return [self.gcs.decode(bytearray(m.pack(self.veh))) for m in got]

    def request(self, opcode: int, session: int = 0, offset: int = 0, data: bytes = b"", size: int | None = None,
                target: tuple[int, int] = (1, 1)) -> list[tuple[int, ...]]:
        """Replies as (seq, session, opcode, size, req_opcode, burst_complete, offset, data)."""
        self.seq += 1
        payload = (HDR.pack(self.seq, session, opcode, len(data) if size is None else size, 0, 0, 0, offset)
                   + data).ljust(FTP_PAYLOAD_LEN, b"\0")
        out = []
        for r in self.raw(self.gcs.file_transfer_protocol_encode(0, *target, list(payload))):
            assert (r.target_network, r.target_system, r.target_component) == (0, 255, 190)
            raw = bytes(r.payload)
            seq, sess, op, sz, req, burst, _pad, off = HDR.unpack_from(raw)
            out.append((seq, sess, op, sz, req, burst, off, raw[HDR.size:HDR.size + sz]))
        return out

    def download(self, path: str) -> bytes:
        """As QGroundControl: OpenFileRO, BurstReadFile from 0 until NAK EOF (missing blocks by ReadFile),
        ResetSessions."""
        ((seq, session, op, size, req, _b, _o, data),) = self.request(M.MAV_FTP_OPCODE_OPENFILERO,
                                                                       data=path.encode())
        assert (op, req, size, seq) == (M.MAV_FTP_OPCODE_ACK, M.MAV_FTP_OPCODE_OPENFILERO, 4, self.seq + 1)
        (file_size,) = struct.unpack("<I", data)
        buf = bytearray(file_size)
        replies = self.request(M.MAV_FTP_OPCODE_BURSTREADFILE, session, 0, size=MAX_DATA)
        for k, (seq, sess, op, size, req, burst, off, data) in enumerate(replies):
            assert seq == self.seq + 1 + k and sess == session and req == M.MAV_FTP_OPCODE_BURSTREADFILE
            if op == M.MAV_FTP_OPCODE_NAK:
                assert data[0] == M.MAV_FTP_ERR_EOF and burst == 1 and k == len(replies) - 1
                break
            buf[off:off + size] = data
        ((_s, _ss, op, *_),) = self.request(M.MAV_FTP_OPCODE_RESETSESSION)
        assert op == M.MAV_FTP_OPCODE_ACK and self.server.open_sessions == 0
        return bytes(buf)


@pytest.fixture
def client() -> Client:
    return Client({"/navig8/big.bin": BIG, "/navig8/small.json": b'{"a": 1}'})


def test_burst_download_returns_the_file_and_reads_and_crc_agree(client: Client) -> None:
    assert client.download("/navig8/big.bin") == BIG
    assert client.download("mftp://[;comp=1]/navig8/small.json") == b'{"a": 1}'
    ((_s, session, *_),) = client.request(M.MAV_FTP_OPCODE_OPENFILERO, data=b"navig8/big.bin")
    ((_s, _ss, op, size, _r, _b, off, data),) = client.request(M.MAV_FTP_OPCODE_READFILE, session, 1000, size=100)
    assert (op, size, off, data) == (M.MAV_FTP_OPCODE_ACK, 100, 1000, BIG[1000:1100])
    ((_s, _ss, op, _z, _r, _b, _o, data),) = client.request(M.MAV_FTP_OPCODE_READFILE, session, len(BIG), size=10)
    assert op == M.MAV_FTP_OPCODE_NAK and data[0] == M.MAV_FTP_ERR_EOF
    ((_s, _ss, op, *_),) = client.request(M.MAV_FTP_OPCODE_TERMINATESESSION, session)
    assert op == M.MAV_FTP_OPCODE_ACK and client.server.open_sessions == 0
    ((_s, _ss, op, _z, _r, _b, _o, data),) = client.request(M.MAV_FTP_OPCODE_TERMINATESESSION, session)
    assert op == M.MAV_FTP_OPCODE_NAK and data[0] == M.MAV_FTP_ERR_INVALIDSESSION
    ((_s, _ss, op, size, _r, _b, _o, data),) = client.request(M.MAV_FTP_OPCODE_CALCFILECRC, data=b"/navig8/big.bin")
    assert op == M.MAV_FTP_OPCODE_ACK and struct.unpack("<I", data)[0] == zlib.crc32(BIG)


def test_list_directory(client: Client) -> None:
    ((_s, _ss, op, _z, _r, _b, _o, data),) = client.request(M.MAV_FTP_OPCODE_LISTDIRECTORY, data=b"/")
    assert op == M.MAV_FTP_OPCODE_ACK and data.split(b"\0")[:-1] == [b"Dnavig8"]
    ((_s, _ss, op, _z, _r, _b, _o, data),) = client.request(M.MAV_FTP_OPCODE_LISTDIRECTORY, data=b"/navig8")
    assert data.split(b"\0")[:-1] == [f"Fbig.bin\t{len(BIG)}".encode(), b"Fsmall.json\t8"]
    ((_s, _ss, op, _z, _r, _b, _o, data),) = client.request(M.MAV_FTP_OPCODE_LISTDIRECTORY, offset=2,
                                                             data=b"/navig8")
    assert op == M.MAV_FTP_OPCODE_NAK and data[0] == M.MAV_FTP_ERR_EOF


@pytest.mark.parametrize("path", ["/navig8/../navig8/big.bin", "../etc/passwd", "/../../etc/passwd",
                                  "mftp://[;comp=1]/navig8/../../etc/shadow", "navig8\\..\\..\\x"])
def test_path_traversal_is_refused(client: Client, path: str) -> None:
    for opcode in (M.MAV_FTP_OPCODE_OPENFILERO, M.MAV_FTP_OPCODE_CALCFILECRC, M.MAV_FTP_OPCODE_LISTDIRECTORY):
        ((_s, _ss, op, size, req, _b, _o, data),) = client.request(opcode, data=path.encode())
        assert (op, size, req, data[0]) == (M.MAV_FTP_OPCODE_NAK, 1, opcode, M.MAV_FTP_ERR_FILEPROTECTED)
    assert client.server.open_sessions == 0
    with pytest.raises(PathRefused):
        normalise_path(path)


@pytest.mark.parametrize("opcode", [M.MAV_FTP_OPCODE_CREATEFILE, M.MAV_FTP_OPCODE_OPENFILEWO,
                                    M.MAV_FTP_OPCODE_WRITEFILE, M.MAV_FTP_OPCODE_CREATEDIRECTORY,
                                    M.MAV_FTP_OPCODE_REMOVEFILE, M.MAV_FTP_OPCODE_REMOVEDIRECTORY,
                                    M.MAV_FTP_OPCODE_RENAME, M.MAV_FTP_OPCODE_TRUNCATEFILE])
def test_writes_are_refused_at_once_and_change_nothing(client: Client, opcode: int) -> None:
    ((_s, session, *_),) = client.request(M.MAV_FTP_OPCODE_OPENFILERO, data=b"/navig8/small.json")
    before = dict(client.server.files)
    ((seq, _ss, op, size, req, _b, _o, data),) = client.request(opcode, session, 0, data=b"/navig8/small.json\0x")
    assert (seq, op, size, req, data[0]) == (client.seq + 1, M.MAV_FTP_OPCODE_NAK, 1, opcode,
                                             M.MAV_FTP_ERR_FILEPROTECTED)
    assert client.server.files == before and client.server.open_sessions == 1


def test_unknown_opcodes_sessions_replies_and_addressing(client: Client) -> None:
    ((_s, _ss, op, _z, req, _b, _o, data),) = client.request(77)
    assert (op, req, data[0]) == (M.MAV_FTP_OPCODE_NAK, 77, M.MAV_FTP_ERR_UNKNOWNCOMMAND)
    ((_s, _ss, op, _z, _r, _b, _o, data),) = client.request(M.MAV_FTP_OPCODE_OPENFILERO, data=b"/nope.json")
    assert op == M.MAV_FTP_OPCODE_NAK and data[0] == M.MAV_FTP_ERR_FILENOTFOUND
    ((_s, _ss, op, _z, _r, _b, _o, data),) = client.request(M.MAV_FTP_OPCODE_BURSTREADFILE, 9)
    assert op == M.MAV_FTP_OPCODE_NAK and data[0] == M.MAV_FTP_ERR_INVALIDSESSION
    for _ in range(client.server.max_sessions):
        ((_s, _ss, op, *_),) = client.request(M.MAV_FTP_OPCODE_OPENFILERO, data=b"/navig8/small.json")
        assert op == M.MAV_FTP_OPCODE_ACK
    ((_s, _ss, op, _z, _r, _b, _o, data),) = client.request(M.MAV_FTP_OPCODE_OPENFILERO, data=b"/navig8/small.json")
    assert op == M.MAV_FTP_OPCODE_NAK and data[0] == M.MAV_FTP_ERR_NOSESSIONSAVAILABLE
    client.seq = 65534  # seq wraps
    ((seq, _ss, op, *_),) = client.request(M.MAV_FTP_OPCODE_RESETSESSION)
    assert (seq, op) == (0, M.MAV_FTP_OPCODE_ACK) and client.server.open_sessions == 0
    client.seq = 0
    for opcode in (M.MAV_FTP_OPCODE_ACK, M.MAV_FTP_OPCODE_NAK):  # replies are never answered
        assert client.request(opcode) == []
    assert client.request(M.MAV_FTP_OPCODE_OPENFILERO, data=b"/navig8/small.json", target=(7, 1)) == []
    assert client.server.handle(b"\x01\x02") == []


def test_parameter_metadata_lists_every_yaml_parameter_with_units_and_ranges() -> None:
    yaml_params = yaml.safe_load(ParamRegistry.definitions_text())["params"]
    files = build_metadata(ParamRegistry.from_defaults().definitions).files
    client = Client(files)
    general = json.loads(client.download(GENERAL_PATH))
    (entry,) = general["metadataTypes"]
    assert general["version"] == 1 and entry["type"] == 1  # COMP_METADATA_TYPE_PARAMETER
    assert entry["uri"] == "mftp://[;comp=1]" + PARAMETER_PATH
    raw = client.download(normalise_path(entry["uri"]))
    assert zlib.crc32(raw) == entry["fileCrc"]
    meta = json.loads(raw)
    assert meta["version"] == 1
    by_name = {p["name"]: p for p in meta["parameters"]}
    assert list(by_name) == [p["name"] for p in yaml_params]
    for p in yaml_params:
        m = by_name[p["name"]]
        assert m["type"] == {"REAL32": "Float", "INT32": "Int32"}[p["type"]]
        assert m.get("units", "") == p["units"]
        # (PyYAML reads 1.0e12 as a string: float() as the registry does)
        assert (m["min"], m["max"], m["default"]) == tuple(float(p[k]) for k in ("min", "max", "default"))
        assert m["longDesc"] == p["description"] and m["shortDesc"]
        assert m["group"] == p["name"].split("_")[0] and m["rebootRequired"] is False
        # decimals: enough to show default, min and max exactly; integers none
        assert m["decimalPlaces"] == 0 if p["type"] == "INT32" else 1 <= m["decimalPlaces"] <= 6
        for v in (float(p["default"]), float(p["min"]), float(p["max"])):
            assert float(f"{v:.{m['decimalPlaces']}f}") == pytest.approx(v, abs=1e-12)
