"""The read-only MAVFTP server (navig8_fc.gcs.ftp) and the parameter metadata it serves (navig8_fc.gcs.metadata),
through pymavlink messages as a ground station sends them. The download follows QGroundControl's
FTPDownloadStateMachine: OpenFileRO, BurstReadFile (the next burst from where one ended) until NAK EOF,
ResetSessions; the replies paced per source (navig8_fc.gcs.ftp_pacing)."""

from __future__ import annotations

import json
import struct
import zlib
from io import BytesIO
from typing import Any

import pytest
import yaml
from pymavlink.dialects.v20 import common as M

from navig8_fc.gcs.ftp import (
    FTP_PAYLOAD_LEN,
    MAX_DATA,
    SESSION_IDLE_S,
    FtpServer,
    FtpService,
    PathRefused,
    normalise_path,
)
from navig8_fc.gcs.ftp_pacing import ReplyBudget, ReplyPacer, frame_bytes
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
        offset, eof = 0, False
        while not eof:  # a burst that ends before the file (burst_complete) is followed by the next, as MAVSDK's
            replies = self.request(M.MAV_FTP_OPCODE_BURSTREADFILE, session, offset, size=MAX_DATA)
            for k, (seq, sess, op, size, req, burst, off, data) in enumerate(replies):
                assert seq == self.seq + 1 + k and sess == session and req == M.MAV_FTP_OPCODE_BURSTREADFILE
                if op == M.MAV_FTP_OPCODE_NAK:
                    assert data[0] == M.MAV_FTP_ERR_EOF and burst == 1 and k == len(replies) - 1
                    eof = True
                    break
                buf[off:off + size] = data
                offset = off + size
                assert burst == int(k == len(replies) - 1 or replies[k + 1][2] == M.MAV_FTP_OPCODE_NAK)
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
    for _ in range(client.server.max_sessions_per_owner):
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


def _request(seq: int, opcode: int, session: int = 0, offset: int = 0, data: bytes = b"", size: int | None = None
             ) -> bytes:
    return (HDR.pack(seq, session, opcode, len(data) if size is None else size, 0, 0, 0, offset)
            + data).ljust(FTP_PAYLOAD_LEN, b"\0")


def _op_err(payloads: list[bytes]) -> tuple[int, int]:
    ((seq, sess, op, size, _req, _b, _pad, _off),) = [HDR.unpack_from(p) for p in payloads]
    return op, payloads[0][HDR.size] if op == M.MAV_FTP_OPCODE_NAK else sess


def test_sessions_belong_to_who_opened_them_capped_per_owner_and_idle_ones_reclaimed() -> None:
    server = FtpServer({"/f.bin": BIG})
    alice, mallory = (255, 190, ("gcs", ("127.0.0.1", 1))), (255, 190, ("gcs", ("127.0.0.1", 2)))
    op, session = _op_err(server.handle(_request(1, M.MAV_FTP_OPCODE_OPENFILERO, data=b"/f.bin"), alice, 0.0))
    assert op == M.MAV_FTP_OPCODE_ACK
    # Another requester (same ids, another address) can neither read, nor close, nor reset it.
    for opcode in (M.MAV_FTP_OPCODE_READFILE, M.MAV_FTP_OPCODE_BURSTREADFILE, M.MAV_FTP_OPCODE_TERMINATESESSION):
        assert _op_err(server.handle(_request(2, opcode, session, size=10), mallory, 0.5)) == (
            M.MAV_FTP_OPCODE_NAK, M.MAV_FTP_ERR_INVALIDSESSION)
    server.handle(_request(3, M.MAV_FTP_OPCODE_RESETSESSION), mallory, 0.5)
    assert server.open_sessions == 1
    # The cap per owner: mallory gets two, the third is refused, and alice still has hers (4 in all).
    for k in range(2):
        assert _op_err(server.handle(_request(4 + k, M.MAV_FTP_OPCODE_OPENFILERO, data=b"/f.bin"), mallory,
                                     1.0))[0] == M.MAV_FTP_OPCODE_ACK
    assert _op_err(server.handle(_request(6, M.MAV_FTP_OPCODE_OPENFILERO, data=b"/f.bin"), mallory, 1.0)) == (
        M.MAV_FTP_OPCODE_NAK, M.MAV_FTP_ERR_NOSESSIONSAVAILABLE)
    other = (250, 1, ("gcs", ("127.0.0.1", 3)))
    assert _op_err(server.handle(_request(7, M.MAV_FTP_OPCODE_OPENFILERO, data=b"/f.bin"), other, 1.0))[0] == (
        M.MAV_FTP_OPCODE_ACK)
    assert server.open_sessions == 4
    # All taken: a fifth owner gets one only once a session has been idle SESSION_IDLE_S (alice's, used at 0).
    late = (251, 1, ("gcs", ("127.0.0.1", 4)))
    assert _op_err(server.handle(_request(8, M.MAV_FTP_OPCODE_OPENFILERO, data=b"/f.bin"), late, 1.5)) == (
        M.MAV_FTP_OPCODE_NAK, M.MAV_FTP_ERR_NOSESSIONSAVAILABLE)
    assert _op_err(server.handle(_request(9, M.MAV_FTP_OPCODE_OPENFILERO, data=b"/f.bin"), late,
                                 SESSION_IDLE_S + 0.1))[0] == M.MAV_FTP_OPCODE_ACK
    assert _op_err(server.handle(_request(10, M.MAV_FTP_OPCODE_READFILE, session, size=10), alice, 3.0)) == (
        M.MAV_FTP_OPCODE_NAK, M.MAV_FTP_ERR_INVALIDSESSION)


def test_replies_are_paced_per_source_and_a_repeated_burst_replaces_the_running_one() -> None:
    budget = ReplyBudget()
    files = {"/f.bin": BIG * 20}  # 46 KB
    veh = M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
    gcs = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
    service = FtpService(veh, FtpServer(files), pacer=ReplyPacer(budget))
    flooder, bystander = ("gcs", ("127.0.0.1", 1)), ("gcs", ("127.0.0.1", 2))

    def send(payload: bytes, source: object, now_s: float) -> tuple[int, list[Any]]:
        msg = gcs.file_transfer_protocol_encode(0, 1, 1, list(payload))
        return len(msg.pack(gcs)), service.handle(veh.decode(bytearray(msg.pack(gcs))), source, now_s)

    size_in, opened = send(_request(1, M.MAV_FTP_OPCODE_OPENFILERO, data=b"/f.bin"), flooder, 0.0)
    session = HDR.unpack_from(bytes(opened[0].payload))[1]
    bytes_in, bytes_out = size_in, sum(frame_bytes(bytes(m.payload)) for m in opened)
    bytes_to_bystander = 0
    t, dt = 0.0, 0.001
    for k in range(6000):  # 6 s: a BurstReadFile every 10 ms (100 requests/s), the service polled every 1 ms
        t = k * dt
        if k % 10 == 0:
            n, got = send(_request(2 + k, M.MAV_FTP_OPCODE_BURSTREADFILE, session, size=MAX_DATA), flooder, t)
            bytes_in += n
            bytes_out += sum(frame_bytes(bytes(m.payload)) for m in got)
        if k == 3000:  # someone else's request meanwhile is answered at once: budgets are per source
            _n, got = send(_request(9, M.MAV_FTP_OPCODE_CALCFILECRC, data=b"/f.bin"), bystander, t)
            assert len(got) == 1
            bytes_to_bystander += len(got)
        polled = service.poll(t)
        assert len(polled) <= budget.packets_per_poll
        bytes_out += sum(frame_bytes(bytes(m.payload)) for src, m in polled if src == flooder)
    assert bytes_out <= budget.burst_bytes + 6.0 * budget.bytes_per_s
    assert bytes_out <= 2 * bytes_in, (bytes_out, bytes_in)
    assert bytes_to_bystander == 1


def test_a_paced_burst_continues_over_later_polls_and_the_client_gets_the_whole_file() -> None:
    files = {"/f.bin": BIG * 4}  # 9.2 KB
    veh = M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
    gcs = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
    budget = ReplyBudget(bytes_per_s=3000.0, burst_bytes=1500.0)
    service = FtpService(veh, FtpServer(files), pacer=ReplyPacer(budget))
    src = ("gcs", ("127.0.0.1", 5))

    def handle(payload: bytes, now_s: float) -> list[Any]:
        return service.handle(veh.decode(bytearray(gcs.file_transfer_protocol_encode(0, 1, 1, list(payload))
                                                    .pack(gcs))), src, now_s)

    (opened,) = handle(_request(1, M.MAV_FTP_OPCODE_OPENFILERO, data=b"/f.bin"), 0.0)
    session = HDR.unpack_from(bytes(opened.payload))[1]
    got = handle(_request(2, M.MAV_FTP_OPCODE_BURSTREADFILE, session, size=MAX_DATA), 0.0)
    assert 0 < len(got) * 266 <= budget.burst_bytes  # what the bucket holds, not the file
    buf = bytearray(len(files["/f.bin"]))
    t, seq, eof = 0.0, 2, False
    while t < 10.0 and not eof:
        for m in got:
            _seq, _ss, op, size, _r, burst, _p, off = HDR.unpack_from(bytes(m.payload))
            eof = op == M.MAV_FTP_OPCODE_NAK
            buf[off:off + size] = bytes(m.payload)[HDR.size:HDR.size + size] if not eof else b""
            if burst and not eof:  # a burst ended before the file: the next one from there (MAVSDK)
                seq += 1
                got = handle(_request(seq, M.MAV_FTP_OPCODE_BURSTREADFILE, session, off + size, size=MAX_DATA), t)
                break
        else:
            t += 0.01
            got = [m for _s, m in service.poll(t)]
    assert eof and bytes(buf) == files["/f.bin"]
    assert 2.0 < t < 3.5  # 9.2 KB of data, ~10 KB on the wire, at 3 KB/s after the first 1.5 KB


def test_the_operators_station_downloads_at_a_ground_stations_pace_and_others_stay_paced() -> None:
    """Over 2 s of 1 ms service polls: the operator's configured station draws a 62.6 KB file's worth of packets,
    any other address at most 2.5 KB/s plus its 1.5 KB burst (ftp_pacing.ReplyBudget)."""
    from navig8_fc.gcs.ftp_pacing import ReplyPacer, frame_bytes

    packet = bytes(range(1, 240)) + b"\1" * 12  # a full FILE_TRANSFER_PROTOCOL payload
    n_packets = 62_600 // 239 + 1
    pacer = ReplyPacer(operator=lambda key: key == "operator")
    for key in ("operator", "stranger"):
        pacer.add(key, (255, 190), 0.0, [], iter([packet] * n_packets), session=0)
    got = {"operator": 0, "stranger": 0}
    for k in range(2000):
        for key, _to, payload in pacer.take(k * 0.001):
            got[key] += frame_bytes(payload)
    assert got["operator"] >= n_packets * frame_bytes(packet)  # the whole file within 2 s
    assert got["stranger"] <= 1500 + 2500 * 2.0 + frame_bytes(packet)
