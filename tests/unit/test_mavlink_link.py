"""Frame splitting and counting of bad input on a real loopback UDP socket."""

from __future__ import annotations

import socket
import time

from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.shell.mavlink_link import UdpLink, split_frames


def _mav(sysid: int = 1) -> mavlink2.MAVLink:
    return mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=1)


def test_split_frames_handles_garbage_truncation_and_both_versions() -> None:
    m = _mav()
    hb = m.heartbeat_encode(2, 8, 0, 0, 0).pack(m)
    st = m.statustext_encode(6, b"hello").pack(m)
    v1 = bytes([0xFE, 0]) + bytes(6)  # a zero-length MAVLink 1 frame (garbage content, right size)
    frames, garbage, truncated = split_frames(b"xx" + hb + st + v1 + hb[:5])
    assert frames == [hb, st, v1] and garbage == 2 and truncated == 1
    signed = bytearray(hb)
    signed[2] |= 0x01
    frames, _, truncated = split_frames(bytes(signed) + bytes(13))
    assert len(frames) == 1 and len(frames[0]) == len(hb) + 13 and truncated == 0


def test_link_counts_and_drops_bad_datagrams() -> None:
    link = UdpLink.open("t", _mav(), ("127.0.0.1", 0))
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.bind(("127.0.0.1", 0))
    try:
        m = _mav(7)
        good = m.heartbeat_encode(2, 8, 0, 0, 0).pack(m)
        bad_crc = bytearray(good)
        bad_crc[-1] ^= 0xFF
        addr = ("127.0.0.1", link.local_port)
        unknown = bytes([0xFD, 4, 0, 0, 0, 255, 190, 0xAA, 0xBB, 0xCC]) + bytes(6)  # an id outside the dialect
        for payload in (good, bytes(bad_crc), b"\x00" * 50, good[:7], b"\xfd" * 3000, good + good, unknown):
            tx.sendto(payload, addr)
        got = []
        deadline = time.monotonic() + 2.0
        while len(got) < 3 and time.monotonic() < deadline:
            got += link.receive()
            time.sleep(0.01)
        c = link.counters
        assert [r.msg.get_type() for r in got] == ["HEARTBEAT"] * 3
        assert c.bad_crc == 1 and c.garbage_bytes == 50 and c.truncated == 1 and c.oversize == 1
        deadline = time.monotonic() + 1.0
        while c.unknown_id == 0 and time.monotonic() < deadline:
            link.receive()
            time.sleep(0.01)
        assert c.unknown_id == 1
        assert link.peers == [("127.0.0.1", tx.getsockname()[1])]
    finally:
        tx.close()
        link.close()


def test_fast_decode_keeps_the_counters() -> None:
    """The sim link's fast path (seam.fast_decode) decodes seam frames; bad and unknown frames count as before."""
    from navig8_fc.mavlink import dialect, seam

    d = dialect.load()
    results = []
    for fast in (None, seam.fast_decode):
        link = UdpLink.open("t", d.MAVLink(None, srcSystem=1, srcComponent=1), ("127.0.0.1", 0))
        link.fast_decode = fast
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tx.bind(("127.0.0.1", 0))
        try:
            m = dialect.new_mav(1, 25)
            good = d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 0).pack(m)
            hb = d.MAVLink_heartbeat_message(2, 8, 0, 0, 0, 3).pack(m)
            bad_crc = bytearray(good)
            bad_crc[-1] ^= 0xFF
            unknown = bytes([0xFD, 4, 0, 0, 0, 255, 190, 0xAA, 0xBB, 0xCC]) + bytes(6)
            for payload in (good + bytes(bad_crc) + hb, unknown + good):
                tx.sendto(payload, ("127.0.0.1", link.local_port))
            got = []
            deadline = time.monotonic() + 2.0
            while len(got) < 3 and time.monotonic() < deadline:
                got += link.receive()
                time.sleep(0.01)
            c = link.counters
            results.append(([(r.msg.get_type(), r.msg.to_dict()) for r in got], c.bad_crc, c.unknown_id, c.frames_in))
        finally:
            tx.close()
            link.close()
    assert results[0] == results[1]
    assert results[0][1:] == (1, 1, 3)
