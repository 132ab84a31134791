"""Frame splitting, counting of bad input and binding on real loopback UDP sockets."""

from __future__ import annotations

import errno
import json
import socket
import time

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.links.mavlink_link import PortInUseError, UdpLink, bind_udp, split_frames, write_ports_file
from navig8_fc.mavlink import codec, dialect, seam


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


def _send_and_receive(link: UdpLink, datagrams: list[bytes], n_msgs: int) -> list:
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.bind(("127.0.0.1", 0))
    try:
        for payload in datagrams:
            tx.sendto(payload, ("127.0.0.1", link.local_port))
        got: list = []
        deadline = time.monotonic() + 2.0
        while (len(got) < n_msgs or link.counters.datagrams_in < len(datagrams)) and time.monotonic() < deadline:
            got += link.receive()
            time.sleep(0.01)
        return got
    finally:
        tx.close()


def test_codec_link_decodes_records_and_counts_like_the_pymavlink_link() -> None:
    """The sim link (codec records) and a GCS link (pymavlink objects) over the same bad input: the same messages,
    the same counters, except that a frame the codec does not handle counts as unknown there."""
    d = dialect.load()
    m = dialect.new_mav(1, 25)
    good = d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 0).pack(m)
    hb = d.MAVLink_heartbeat_message(2, 8, 0, 0, 0, 3).pack(m)
    text = d.MAVLink_statustext_message(6, b"hi").pack(m)  # in the dialect, not a seam message
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    unknown = bytes([0xFD, 4, 0, 0, 0, 255, 190, 0xAA, 0xBB, 0xCC]) + bytes(6)
    datagrams = [good + bytes(bad_crc) + hb, unknown + good, b"xy" + good[:9], text]
    results = []
    for c in (None, codec.seam_codec()):
        mav = codec.Encoder(c, 1, 1) if c is not None else d.MAVLink(None, srcSystem=1, srcComponent=1)
        link = UdpLink.open("t", mav, ("127.0.0.1", 0), codec=c)
        try:
            got = _send_and_receive(link, datagrams, 2 if c is not None else 4)
        finally:
            link.close()
        k = link.counters
        if c is None:
            msgs = [(r.msg.get_type(), {a: b for a, b in r.msg.to_dict().items() if a != "mavpackettype"}) for r in got]
        else:
            assert [r.frame for r in got] == [datagrams[0], datagrams[1]]  # one Received per datagram
            got = [m for r in got for m in r.msg]
            assert all(isinstance(m, codec.Message) and m.sysid == 1 and m.compid == 25 for m in got)
            msgs = [(m.name, {a: list(b) if isinstance(b, tuple) else b for a, b in m.fields.items()}) for m in got]
        results.append((msgs, k.bad_crc, k.unknown_id, k.garbage_bytes, k.truncated, k.frames_in))
    pym, cod = results
    assert pym[0] == cod[0] + [("STATUSTEXT", pym[0][-1][1])]
    assert pym[1:] == (1, 1, 2, 1, 4) and cod[1:] == (1, 2, 2, 1, 3)


def test_codec_link_sends_records() -> None:
    c = codec.seam_codec()
    link = UdpLink.open("sim", codec.Encoder(c, 1, 1), ("127.0.0.1", 0), codec=c)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(2.0)
    try:
        link.targets = [rx.getsockname()]
        link.send(seam.encode_sim_status(seam.SimStatus(5, 1, 1, 0.0, 2.0, 0)))
        data = rx.recv(2048)
        ref = dialect.load().MAVLink_navig8_sim_status_message(5, 1, 1, 0.0, 2.0, 0).pack(dialect.new_mav(1, 1))
        assert data == ref and link.counters.frames_out == 1
    finally:
        rx.close()
        link.close()


def test_a_busy_port_is_refused_with_its_name() -> None:
    a = UdpLink.open("sim", _mav(), ("127.0.0.1", 0))
    try:
        port = a.local_port
        with pytest.raises(PortInUseError) as e:
            UdpLink.open("sim", _mav(), ("127.0.0.1", port))  # a second FC on the same port
        assert (e.value.link, e.value.port) == ("sim", port)
        assert e.value.errno == errno.EADDRINUSE and f"127.0.0.1:{port}" in e.value.strerror
        with pytest.raises(PortInUseError):
            bind_udp("bridge", ("127.0.0.1", port))
    finally:
        a.close()


def test_port_zero_binds_a_free_port_and_the_ports_file_is_written_whole(tmp_path) -> None:
    links = [UdpLink.open(n, _mav(), ("127.0.0.1", 0)) for n in ("sim", "gcs", "api")]
    try:
        ports = {ln.name: ln.local_port for ln in links}
        assert len(set(ports.values())) == 3 and all(p > 0 for p in ports.values())
        path = tmp_path / "sub" / "ports.json"
        write_ports_file(path, ports)
        assert json.loads(path.read_text()) == ports
        assert [p.name for p in path.parent.iterdir()] == ["ports.json"]  # no temporary left behind
    finally:
        for ln in links:
            ln.close()


def test_max_datagrams_leaves_the_rest_readable() -> None:
    c = codec.seam_codec()
    link = UdpLink.open("sim", codec.Encoder(c, 1, 1), ("127.0.0.1", 0), codec=c)
    link.max_datagrams = 1
    status = [codec.Encoder(c, 1, 25).frame(*seam.encode_sim_status(seam.SimStatus(k, k, 1, 0.0, 1.0, 0)))
              for k in range(3)]
    try:
        got = _send_and_receive(link, status[:1], 1)
        assert [r.msg[0].fields["step"] for r in got] == [0]
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            for s in status[1:]:
                tx.sendto(s, ("127.0.0.1", link.local_port))
        finally:
            tx.close()
        steps = []
        deadline = time.monotonic() + 2.0
        while len(steps) < 2 and time.monotonic() < deadline:
            got = link.receive()
            assert len(got) <= 1
            steps += [r.msg[0].fields["step"] for r in got]
        assert steps == [1, 2]
    finally:
        link.close()
