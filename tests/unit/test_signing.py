"""MAVLink 2 signing on a GCS link (navig8_fc.links.signing over a real UdpLink on loopback): SETUP_SIGNING sets
a key (owner-only file, never in what the link hands the log), then unsigned, wrongly signed and replayed frames
are refused except RADIO_STATUS, outgoing frames are signed, only the key holder can change the key; GCS_SIGN_REQ
refuses commands until a key is set."""

from __future__ import annotations

import json
import socket
import stat
import time
from io import BytesIO
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as M

from navig8_fc.links.mavlink_link import UdpLink
from navig8_fc.links.signing import STREAMS_KEPT, LinkSigning, redact_frame, signing_timestamp
from navig8_fc.shell.signing_keys import KeyFile

KEY = bytes(range(101, 133))
OTHER_KEY = bytes(range(1, 33))


def _client(sysid: int = 255, key: bytes | None = None) -> Any:
    mav = M.MAVLink(BytesIO(), srcSystem=sysid, srcComponent=190)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.timestamp = signing_timestamp(time.time())
    return mav


class Rig:
    def __init__(self, tmp: Path) -> None:
        self.link = UdpLink.open("gcs", M.MAVLink(None, srcSystem=1, srcComponent=1), ("127.0.0.1", 0))
        self.logged: list[bytes] = []
        self.logged_msgs: list[dict[str, Any]] = []
        self.link.on_datagram = lambda _l, _d, raw, _p: self.logged.append(bytes(raw))
        self.link.on_frame = lambda _l, _d, raw, msg, _a: (self.logged.append(bytes(raw)),
                                                          self.logged_msgs.append(msg.to_dict()))
        self.key_file = KeyFile(tmp / "fc_signing_0.json")
        self.signing = LinkSigning([self.link.mav], self.key_file)
        self.tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.tx.bind(("127.0.0.1", 0))
        self.tx.settimeout(2.0)

    def exchange(self, frames: list[bytes]) -> list[Any]:
        """Send each frame as a datagram; what the link delivers (bounded wait for every datagram to arrive)."""
        before = self.link.counters.datagrams_in
        for f in frames:
            self.tx.sendto(f, ("127.0.0.1", self.link.local_port))
        got: list[Any] = []
        deadline = time.monotonic() + 2.0
        while self.link.counters.datagrams_in < before + len(frames) and time.monotonic() < deadline:
            got += [r.msg for r in self.link.receive()]
            time.sleep(0.005)
        return got

    def close(self) -> None:
        self.link.close()
        self.tx.close()


def test_signed_link_refuses_unsigned_and_wrongly_signed_frames_and_keeps_the_key_out_of_the_log(tmp_path) -> None:
    rig = Rig(tmp_path)
    try:
        plain, signer, wrong = _client(), _client(key=KEY), _client(key=OTHER_KEY)
        wrong.signing.timestamp = 2**47  # a forged far-future stamp must not lock the genuine stream out
        setup = plain.setup_signing_encode(1, 1, list(KEY), signing_timestamp(time.time())).pack(plain)
        (got,) = rig.exchange([setup])  # no key yet: an unsigned SETUP_SIGNING is accepted (PX4's provisioning)
        assert got.get_type() == "SETUP_SIGNING"
        assert rig.signing.set_key(bytes(got.secret_key), got.initial_timestamp) == "Signing key set"
        mode = stat.S_IMODE(rig.key_file.path.stat().st_mode)
        assert mode == 0o600, oct(mode)
        assert bytes.fromhex(json.loads(rig.key_file.path.read_text())["key"]) == KEY

        cmd = lambda mav: mav.command_long_encode(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0).pack(mav)
        radio = plain.radio_status_encode(200, 190, 0, 0, 0, 0, 0).pack(plain)
        signed = cmd(signer)
        change = plain.setup_signing_encode(1, 1, list(OTHER_KEY), signing_timestamp(time.time())).pack(plain)
        got = rig.exchange([cmd(plain), cmd(wrong), signed, signed, radio, change])
        # delivered: the correctly signed command once (its replay has an old timestamp) and the unsigned radio
        assert [m.get_type() for m in got] == ["COMMAND_LONG", "RADIO_STATUS"]
        assert rig.link.counters.bad_signature == 4  # unsigned, wrong key, replay, unsigned key change
        assert rig.link.mav.signing.secret_key == KEY

        # Outgoing frames are signed with the key: a holder verifies them, a client with another key does not.
        rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        rx.bind(("127.0.0.1", 0))
        rx.settimeout(2.0)
        rig.link.send(M.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3), [rx.getsockname()])
        data, _ = rx.recvfrom(4096)
        rx.close()
        assert data[2] & 0x01  # MAVLINK_IFLAG_SIGNED
        verifier = _client(key=KEY)
        verifier.signing.timestamp = 0
        assert verifier.decode(bytearray(data)).get_type() == "HEARTBEAT"

        blob = b"".join(rig.logged) + json.dumps(rig.logged_msgs).encode()
        assert KEY not in blob and OTHER_KEY not in blob and KEY.hex().encode() not in blob
        assert any(d.get("mavpackettype") == "SETUP_SIGNING" for d in rig.logged_msgs)  # logged: that a key came

        again = LinkSigning([M.MAVLink(None, srcSystem=1, srcComponent=1)], rig.key_file)
        assert again.load() == [] and again.active  # the key survives a restart
        assert rig.signing.set_key(bytes(32), 0) == "Signing disabled" and not rig.key_file.path.exists()
        assert [m.get_type() for m in rig.exchange([cmd(plain)])] == ["COMMAND_LONG"]
    finally:
        rig.close()


def test_redact_frame_zeroes_only_the_key() -> None:
    mav = _client()
    frame = mav.setup_signing_encode(1, 1, list(KEY), 12345).pack(mav)
    red = redact_frame(frame)
    assert len(red) == len(frame) and KEY not in red and red[:20] == frame[:20]
    hb = mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav)
    assert redact_frame(hb) is hb


def test_a_world_readable_key_file_is_made_owner_only(tmp_path: Path) -> None:
    kf = KeyFile(tmp_path / "k.json")
    kf.save(KEY, 5)
    kf.path.chmod(0o644)
    key, ts, streams, problem = kf.load()
    assert key == KEY and ts == 5 and streams == {} and problem and "owner-only" in problem
    assert stat.S_IMODE(kf.path.stat().st_mode) == 0o600
    kf.path.write_text("{garbage")
    key, _, _, problem = kf.load()
    assert key is None and problem and "corrupt" in problem


def _signed_frame(mav: Any) -> bytes:
    return mav.param_set_encode(1, 1, b"OL_POS_K", 1.1, M.MAV_PARAM_TYPE_REAL32).pack(mav)


def _accepts(signing_mav: Any, frame: bytes) -> bool:
    try:
        return signing_mav.decode(bytearray(frame)).get_type() == "PARAM_SET"
    except Exception:  # noqa: BLE001 - pymavlink raises on a refused signature
        return False


def test_a_signed_frame_does_not_replay_on_the_other_link_nor_after_a_restart(tmp_path: Path) -> None:
    """The signing spec's stream rule across both links and across a restart: the stream table is one for both
    links and is kept beside the key (checkpoint, shutdown), so a captured frame is as old everywhere."""
    key_file = KeyFile(tmp_path / "fc_signing_0.json")
    gcs, api = M.MAVLink(None, srcSystem=1, srcComponent=1), M.MAVLink(None, srcSystem=1, srcComponent=1)
    signing = LinkSigning([gcs, api], key_file)
    assert signing.set_key(KEY, signing_timestamp(time.time())) == "Signing key set"
    client = _client(key=KEY)
    captured, later = _signed_frame(client), _signed_frame(client)
    assert _accepts(gcs, captured) and _accepts(gcs, later)
    assert not _accepts(api, captured)  # replayed on the other link
    signing.checkpoint(100.0)
    signing.save_timestamp()  # a clean stop (joins the checkpoint writer)
    assert key_file.load().streams == {(0, 255, 190): int.from_bytes(later[-12:-6], "little")}

    gcs2, api2 = M.MAVLink(None, srcSystem=1, srcComponent=1), M.MAVLink(None, srcSystem=1, srcComponent=1)
    again = LinkSigning([gcs2, api2], key_file)
    assert again.load() == []
    assert not _accepts(gcs2, captured) and not _accepts(api2, later)  # replayed after the restart
    assert _accepts(gcs2, _signed_frame(client))  # the genuine stream goes on
    # a stream first seen after the restart must be newer than what the FC saw before it (not a minute of grace)
    other = _client(sysid=254, key=KEY)
    other.signing.timestamp = int.from_bytes(later[-12:-6], "little") - 1000
    assert not _accepts(api2, _signed_frame(other))
    other.signing.timestamp = signing_timestamp(time.time()) + 10
    assert _accepts(api2, _signed_frame(other))


def test_the_stream_table_is_bounded_and_a_forgotten_stream_cannot_come_back_older() -> None:
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    LinkSigning([mav], None).set_key(KEY, 0)
    now = signing_timestamp(time.time())
    frames = []
    for i in range(STREAMS_KEPT + 1):
        c = _client(sysid=i + 1, key=KEY)
        c.signing.timestamp = now + i
        frames.append(_signed_frame(c))
    for f in frames:
        assert _accepts(mav, f)
    assert not _accepts(mav, frames[0])  # the first stream was forgotten: the floor keeps its frames out
