"""A signed session over real processes (docs/security.md): SETUP_SIGNING provisions the key, the vehicle arms and
takes off on signed commands, unsigned, wrongly signed and foreign-sysid commands are refused, every frame the FC
sends is signed, and no byte of the key is anywhere in the log."""

from __future__ import annotations

import json
import math
import socket
import stat
import time
from io import BytesIO
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import gcs_client, sitl, wait_for, wait_heartbeat

from navig8_fc.links.signing import signing_timestamp
from navig8_fc.params.store import default_state_path
from navig8_fc.shell.mcap_log import read_mcap

M = mavlink2
KEY = bytes((i * 37 + 11) % 256 for i in range(32))
WRONG_KEY = bytes(reversed(KEY))


def _signer(sysid: int, key: bytes | None) -> mavlink2.MAVLink:
    mav = M.MAVLink(BytesIO(), srcSystem=sysid, srcComponent=190)
    if key is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing = key, True
        mav.signing.timestamp = signing_timestamp(time.time()) + 100_000
    return mav


def _cmd(gcs, command: int, *p: float) -> int | None:
    params = list(p) + [0.0] * (7 - len(p))
    gcs.mav.command_long_send(gcs.target_system, 1, command, 0, *params)
    ack = wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == command)
    return None if ack is None else ack.result


def test_a_signed_session_flies_and_unsigned_wrong_or_foreign_commands_are_refused(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="ground", speed=2.0) as run:
        gcs = gcs_client(run.gcs_port)
        other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        other.bind(("127.0.0.1", 0))
        other.settimeout(0.2)
        try:
            wait_heartbeat(gcs, 15.0)
            gcs.mav.setup_signing_send(1, 1, list(KEY), signing_timestamp(time.time()))
            assert wait_for(gcs, "STATUSTEXT", 5.0, lambda m: m.text == "Signing key set") is not None
            gcs.setup_signing(KEY, sign_outgoing=True)  # from here the client checks the FC's signatures too
            key_file = default_state_path(run.state_dir, 0, "fc_signing")
            assert stat.S_IMODE(key_file.stat().st_mode) == 0o600

            fc_addr = ("127.0.0.1", run.gcs_bind_port)
            arm = lambda mav: mav.command_long_encode(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0,
                                                      0).pack(mav)
            gcs.port.sendto(arm(_signer(255, None)), fc_addr)  # unsigned, from the ground station's own address
            gcs.port.sendto(arm(_signer(255, WRONG_KEY)), fc_addr)  # wrongly signed
            assert wait_for(gcs, "COMMAND_ACK", 2.0) is None, "an unsigned or wrongly signed command was answered"
            other.sendto(arm(_signer(200, KEY)), fc_addr)  # correctly signed, but system 200 may not command
            rx = _signer(255, KEY)
            rx.signing.timestamp = 0
            deadline, denied = time.monotonic() + 5.0, None
            while denied is None and time.monotonic() < deadline:
                try:
                    data, _ = other.recvfrom(4096)
                except TimeoutError:
                    continue
                for m in rx.parse_buffer(data) or []:
                    if m.get_type() == "COMMAND_ACK":
                        denied = m
            assert denied is not None and denied.result == M.MAV_RESULT_DENIED

            hb = wait_heartbeat(gcs, 5.0)
            assert not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
            deadline = time.monotonic() + 15.0
            while _cmd(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) != M.MAV_RESULT_ACCEPTED:
                assert time.monotonic() < deadline, "signed arming never accepted"
                time.sleep(0.3)
            assert _cmd(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 1.5) in \
                (M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS)  # a long-running command (docs/gcs.md)
            up = wait_for(gcs, "LOCAL_POSITION_NED", 20.0, lambda m: m.z < -1.2)
            assert up is not None, "the signed session did not take off"
            assert gcs.mav.signing.goodsig_count > 50 and gcs.mav.signing.badsig_count == 0
            assert run.fc.poll() is None
        finally:
            other.close()
            run.stop()
    # Every record, decompressed (the log's chunks are zstd): raw datagrams as bytes, decoded ones as JSON text.
    needles = (KEY, KEY.hex().encode(), KEY.hex().upper().encode(), json.dumps(list(KEY)).encode(),
               ", ".join(str(b) for b in KEY[:8]).encode())
    n_records, setup_logged = 0, False
    for topic, _, data in read_mcap(run.log):
        n_records += 1
        blob = bytes(data) if isinstance(data, bytes | bytearray) else json.dumps(data).encode()
        assert not [n for n in needles if n in blob], f"key bytes in {topic}"
        setup_logged |= topic == "/mavlink/gcs/in/SETUP_SIGNING"
    assert n_records > 1000 and setup_logged  # the log has the SETUP_SIGNING (key zeroed): that a key was set
    assert not [n for n in needles if n in run.log.read_bytes()]
    texts = [d.get("text") for _, _, d in read_mcap(run.log, ["/mavlink/gcs/out/STATUSTEXT"])]
    assert "Signing key set" in texts
