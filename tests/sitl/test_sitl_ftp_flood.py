"""A MAVFTP flood over real processes (docs/security.md, "MAVFTP"): a ground station with an allowed id, confirmed by
its HEARTBEAT, opens the parameter metadata and sends 100 BurstReadFile requests a second for 6 s while the vehicle
hovers at real time. The FTP replies it gets stay under twice the bytes it sent, the control steps stay at most
20 ms apart (p99, wall clock; on a host loaded by other jobs: no worse than the same FC's spacing in the 4 s without
the flood just after), and another client's session can be neither read nor closed by it.
"""

from __future__ import annotations

import struct
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import RawPeer, sitl

from navig8_fc.gcs.metadata import PARAMETER_PATH
from navig8_fc.shell.mcap_log import read_mcap_records

M = mavlink2
HDR = struct.Struct("<HBBBBBBI")
FLOOD_S = 6.0
FLOOD_HZ = 100.0
MAX_DATA = 239
BASELINE_S = 4.0


def _ftp(peer: RawPeer, seq: int, opcode: int, session: int = 0, data: bytes = b"", size: int | None = None) -> None:
    payload = (HDR.pack(seq, session, opcode, len(data) if size is None else size, 0, 0, 0, 0) + data).ljust(251, b"\0")
    peer.send(peer.mav.file_transfer_protocol_encode(0, 1, 1, list(payload)))


def _ftp_replies(peer: RawPeer) -> list[tuple[int, ...]]:
    """(seq, session, opcode, size, req_opcode, burst, offset, first data byte) of every FTP reply received."""
    out = []
    for m in peer.got:
        if m.get_type() == "FILE_TRANSFER_PROTOCOL":
            raw = bytes(m.payload)
            out.append((*HDR.unpack_from(raw)[:6], HDR.unpack_from(raw)[7], raw[HDR.size]))
    return out


class CountingPeer(RawPeer):
    """RawPeer that also counts the bytes of the FTP replies alone (a confirmed peer gets telemetry too)."""

    def __init__(self, sysid: int, fc_port: int, local_port: int = 0) -> None:
        super().__init__(sysid, fc_port, local_port)
        self.ftp_bytes_in = 0

    def received(self, msg: object) -> None:
        super().received(msg)
        if msg.get_type() == "FILE_TRANSFER_PROTOCOL":  # type: ignore[attr-defined]
            self.ftp_bytes_in += len(msg.get_msgbuf())  # type: ignore[attr-defined]


# Its control-step check is on the wall clock: run alone, with the real-time tests after the parallel SITL lane
# (make test); beside other workers a p99 step spacing is the host's load as much as the flood's.
@pytest.mark.realtime
@pytest.mark.local_only("reads the FC's log for the control steps' wall times")
def test_mavftp_flood_is_paced_and_sessions_belong_to_their_owner(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="hover", speed=1.0, bridge_args=["--duration", "30"]) as run:
        # the owner: the operator's station, where the FC sends (its configured GCS); the flooder anywhere else
        owner = CountingPeer(250, run.gcs_bind_port, run.gcs_port)
        flooder = CountingPeer(255, run.gcs_bind_port)
        try:
            for peer in (owner, flooder):
                peer.send(peer.mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0))
            # The owner opens a session; the flooder (another id and address) can neither read nor close it.
            _ftp(owner, 1, M.MAV_FTP_OPCODE_OPENFILERO, data=PARAMETER_PATH.encode())
            owner.drain(5.0, lambda p: any(r[4] == M.MAV_FTP_OPCODE_OPENFILERO for r in _ftp_replies(p)))
            ((_s, owner_session, op, *_),) = [r for r in _ftp_replies(owner) if r[4] == M.MAV_FTP_OPCODE_OPENFILERO]
            assert op == M.MAV_FTP_OPCODE_ACK
            for k, opcode in enumerate((M.MAV_FTP_OPCODE_TERMINATESESSION, M.MAV_FTP_OPCODE_READFILE)):
                _ftp(flooder, 10 + 2 * k, opcode, owner_session, size=MAX_DATA)
            _ftp(flooder, 20, M.MAV_FTP_OPCODE_RESETSESSION)
            flooder.drain(5.0, lambda p: len(_ftp_replies(p)) >= 3)
            naks = {r[4]: (r[2], r[7]) for r in _ftp_replies(flooder)}
            assert naks[M.MAV_FTP_OPCODE_TERMINATESESSION] == (M.MAV_FTP_OPCODE_NAK, M.MAV_FTP_ERR_INVALIDSESSION)
            assert naks[M.MAV_FTP_OPCODE_READFILE] == (M.MAV_FTP_OPCODE_NAK, M.MAV_FTP_ERR_INVALIDSESSION)
            _ftp(owner, 2, M.MAV_FTP_OPCODE_READFILE, owner_session, size=MAX_DATA)
            owner.drain(5.0, lambda p: any(r[4] == M.MAV_FTP_OPCODE_READFILE for r in _ftp_replies(p)))
            assert [r[2] for r in _ftp_replies(owner) if r[4] == M.MAV_FTP_OPCODE_READFILE] == [M.MAV_FTP_OPCODE_ACK]

            # The flood: its own session, then BurstReadFile at 100 Hz for 6 s, reading as it goes.
            _ftp(flooder, 30, M.MAV_FTP_OPCODE_OPENFILERO, data=PARAMETER_PATH.encode())
            flooder.drain(5.0, lambda p: any(r[4] == M.MAV_FTP_OPCODE_OPENFILERO for r in _ftp_replies(p)))
            (opened,) = [r for r in _ftp_replies(flooder) if r[4] == M.MAV_FTP_OPCODE_OPENFILERO]
            assert opened[2] == M.MAV_FTP_OPCODE_ACK
            sent_before, got_before = flooder.bytes_out, flooder.ftp_bytes_in
            t0_ns = time.time_ns()
            start = time.monotonic()
            n = 0
            while (now := time.monotonic()) < start + FLOOD_S:
                while n < (now - start) * FLOOD_HZ:
                    _ftp(flooder, 100 + n, M.MAV_FTP_OPCODE_BURSTREADFILE, opened[1], size=MAX_DATA)
                    n += 1
                flooder.drain(0.005)
            flooder.drain(1.0)  # what was still on its way
            t1_ns = time.time_ns()
            sent = flooder.bytes_out - sent_before
            got = flooder.ftp_bytes_in - got_before
            flooder.drain(BASELINE_S)  # the same FC without a flood: the host's own step spacing
            t2_ns = time.time_ns()
            assert flooder.ftp_bytes_in == got_before + got  # nothing more came
            assert run.fc.poll() is None, "navig8-fc died"
        finally:
            owner.close()
            flooder.close()
            run.stop()
    pubs = [pub for _, _, pub, _d in read_mcap_records(run.log, ["/mavlink/sim/in/HIL_SENSOR"])]
    rec = [p for p in pubs if t0_ns <= p <= t1_ns]
    gaps = sorted((b - a) * 1e-9 for a, b in zip(rec, rec[1:], strict=False))
    quiet = [p for p in pubs if t1_ns < p <= t2_ns]
    quiet_gaps = sorted((b - a) * 1e-9 for a, b in zip(quiet, quiet[1:], strict=False))
    p99, quiet_p99 = gaps[int(0.99 * len(gaps))], quiet_gaps[int(0.99 * len(quiet_gaps))]
    print(f"\nMAVFTP flood: {n} BurstReadFile in {FLOOD_S:.0f} s, {sent} B sent, {got} B of FTP replies back "
          f"({got / sent:.2f}x); control steps {len(rec)}, wall gap median {gaps[len(gaps) // 2] * 1e3:.1f} ms, "
          f"p99 {p99 * 1e3:.1f} ms, max {gaps[-1] * 1e3:.1f} ms; without the flood just after: p99 "
          f"{quiet_p99 * 1e3:.1f} ms, max {quiet_gaps[-1] * 1e3:.1f} ms")
    assert n >= 0.9 * FLOOD_S * FLOOD_HZ
    assert got <= 2 * sent, (got, sent)
    assert len(rec) >= 0.8 * FLOOD_S * 100
    # <= 20 ms, or (a host loaded by other jobs) no worse than the same FC's own spacing without the flood
    assert p99 <= max(0.020, 1.25 * quiet_p99), (p99, quiet_p99)
