"""Connection strings and the stream transports (TCP, serial over a pseudo-terminal pair), at their public
boundary: what one end writes arrives at the other as whole MAVLink frames, however the stream cuts it."""

from __future__ import annotations

import socket
import time

import pytest

from navig8_fc.links.mavlink_link import UdpLink
from navig8_fc.links.transport import (
    Connection,
    PortInUseError,
    TcpClientTransport,
    TcpServerTransport,
    open_endpoint,
    parse_connection,
)
from navig8_fc.mavlink import codec, seam
from navig8_tools.nullmodem import NullModem
from sim_bridge.bridge_options import BridgeOptions
from sim_bridge.link_budget import link_budget
from sim_bridge.lockstep import Bridge


@pytest.mark.parametrize(("text", "want"), [
    ("udpin:127.0.0.1:14550", Connection("udpin", "127.0.0.1", 14550, text="udpin:127.0.0.1:14550")),
    ("udp:0.0.0.0:14550", Connection("udpin", "0.0.0.0", 14550, text="udp:0.0.0.0:14550")),
    ("udpin://:14540", Connection("udpin", "0.0.0.0", 14540, text="udpin://:14540")),
    ("udpout:10.0.0.2:14550", Connection("udpout", "10.0.0.2", 14550, text="udpout:10.0.0.2:14550")),
    ("tcp:127.0.0.1:4560", Connection("tcp", "127.0.0.1", 4560, text="tcp:127.0.0.1:4560")),
    ("tcpin:0.0.0.0:0", Connection("tcpin", "0.0.0.0", 0, text="tcpin:0.0.0.0:0")),
    ("serial:/dev/ttyUSB0:921600", Connection("serial", device="/dev/ttyUSB0", baud=921600,
                                              text="serial:/dev/ttyUSB0:921600")),
    ("serial:///dev/ttyACM0:57600", Connection("serial", device="/dev/ttyACM0", baud=57600,
                                               text="serial:///dev/ttyACM0:57600")),
    ("serial:/dev/ttyS1", Connection("serial", device="/dev/ttyS1", baud=921600, text="serial:/dev/ttyS1")),
])
def test_parse_connection(text: str, want: Connection) -> None:
    assert parse_connection(text) == want


@pytest.mark.parametrize("text", ["127.0.0.1:14550", "udpin:127.0.0.1", "tcp::4560", "tcp:127.0.0.1:0",
                                  "udpout:h:99999", "serial:", "serial:/dev/x:fast", "ftp:a:1"])
def test_bad_connection_strings_are_refused(text: str) -> None:
    with pytest.raises(ValueError, match="connection"):
        parse_connection(text)


def _records(n: int) -> list[tuple[str, list]]:
    """n different seam messages (a status each: short frames, many per read)."""
    return [seam.encode_sim_status(seam.SimStatus(k + 1, k, 1, 1.0, 1.0, k)) for k in range(n)]


def _read_all(t, n: int, timeout_s: float = 5.0) -> tuple[list[codec.Message], codec.ParseCounters]:
    c = codec.seam_codec()
    counts = codec.ParseCounters()
    got: list[codec.Message] = []
    t.settimeout(0.2)
    deadline = time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < deadline:
        try:
            data, _ = t.recvfrom(65535)
        except (TimeoutError, BlockingIOError):
            continue
        got += c.parse(data, counts)
    return got, counts


def test_tcp_stream_hands_over_whole_frames_when_bytes_arrive_in_pieces() -> None:
    srv = TcpServerTransport("t", parse_connection("tcpin:127.0.0.1:0"))
    port = srv.getsockname()[1]
    cli = TcpClientTransport("t", parse_connection(f"tcp:127.0.0.1:{port}"))
    try:
        enc = codec.Encoder(codec.seam_codec(), 1, 1)
        data = b"\x00\x01garbage" + enc.frames(_records(40))
        # send in pieces that cut frames anywhere (1..17 bytes), each flushed on its own (TCP_NODELAY)
        deadline = time.monotonic() + 5.0
        while not cli.connected and time.monotonic() < deadline:
            cli.fileno()  # retries the connection
            time.sleep(0.01)
        i = k = 0
        while i < len(data):
            cut = 1 + (k * 7) % 17
            cli.sendto(data[i:i + cut])
            i, k = i + cut, k + 1
        got, counts = _read_all(srv, 40)
        assert [m.fields["step"] for m in got] == list(range(40))
        assert counts.truncated == 0 and counts.bad_crc == 0
        assert counts.garbage_bytes == len(b"\x00\x01garbage")
        # and back: to the placeholder address (a caller's target before anyone talked), every connection hears it
        srv.sendto(enc.frame(*_records(1)[0]), srv.peer)
        back, _ = _read_all(cli, 1)
        assert len(back) == 1
    finally:
        cli.close()
        srv.close()


def test_tcp_listen_port_in_use_is_named() -> None:
    srv = TcpServerTransport("sim", parse_connection("tcpin:127.0.0.1:0"))
    try:
        with pytest.raises(PortInUseError, match="sim link: TCP 127.0.0.1"):
            open_endpoint("sim", parse_connection(f"tcpin:127.0.0.1:{srv.getsockname()[1]}"))
    finally:
        srv.close()


def test_tcp_client_reconnects_to_a_restarted_server() -> None:
    srv = TcpServerTransport("t", parse_connection("tcpin:127.0.0.1:0"))
    port = srv.getsockname()[1]
    cli = TcpClientTransport("t", parse_connection(f"tcp:127.0.0.1:{port}"))
    enc = codec.Encoder(codec.seam_codec(), 1, 1)
    try:
        cli.sendto(enc.frame(*_records(1)[0]))
        assert len(_read_all(srv, 1)[0]) == 1
        srv.close()  # the peer goes away: the client notices on its next read, then reconnects
        srv = TcpServerTransport("t", parse_connection(f"tcpin:127.0.0.1:{port}"))
        deadline = time.monotonic() + 5.0
        got: list = []
        while not got and time.monotonic() < deadline:
            try:
                cli.settimeout(0.05)
                cli.recvfrom(65535)
            except (TimeoutError, BlockingIOError):
                pass
            try:
                cli.sendto(enc.frame(*_records(1)[0]))
            except OSError:
                continue
            got = _read_all(srv, 1, 0.3)[0]
        assert got and cli.reconnects == 1
    finally:
        cli.close()
        srv.close()


def test_serial_links_over_a_pty_null_modem_carry_frames_both_ways() -> None:
    with NullModem(921600) as nm:
        enc = codec.Encoder(codec.seam_codec(), 1, 1)
        a = UdpLink.connect("sim", enc, parse_connection(f"serial:{nm.paths[0]}:921600"), codec=codec.seam_codec())
        b = open_endpoint("bridge", parse_connection(f"serial:{nm.paths[1]}:921600")).sock
        try:
            for rec in _records(30):
                a.send(rec)
            got, counts = _read_all(b, 30)
            assert [m.fields["step"] for m in got] == list(range(30)) and counts.bad_frames == 0
            b.sendto(codec.Encoder(codec.seam_codec(), 1, 25).frames(_records(3)))
            deadline = time.monotonic() + 5.0
            rx: list = []
            while len(rx) < 3 and time.monotonic() < deadline:
                for r in a.receive():
                    rx += r.msg
                time.sleep(0.01)
            assert [m.fields["step"] for m in rx] == [0, 1, 2]
            assert a.counters.frames_in == 3 and a.counters.truncated == 0
        finally:
            a.close()
            b.close()


def test_serial_device_that_does_not_exist_is_a_clear_error() -> None:
    with pytest.raises(OSError, match="cannot open /dev/navig8-none"):
        open_endpoint("sim", parse_connection("serial:/dev/navig8-none:921600"))


def test_link_budget_against_the_line_rate() -> None:
    """The bundle's worst case by hand: five frames of 12 B overhead + 13 B signature + full payloads (common.xml /
    navig8.xml sizes: ODOMETRY 233, ACTUATOR_STATE 40 with its extension, ARM_STATE 37, TRUTH 208, HIL_SENSOR 65)."""
    c = codec.seam_codec()
    b = link_budget(c, parse_connection("serial:/dev/x:921600"), 100.0)
    assert b.bundle_bytes == 5 * (12 + 13) + 233 + 40 + 37 + 208 + 65 == 708
    assert b.capacity_bytes_s == pytest.approx(0.9 * 92160)
    assert "70.8 kB/s" in b.line()
    with pytest.raises(ValueError, match="does not fit.*at most 117 Hz"):
        link_budget(c, parse_connection("serial:/dev/x:921600"), 200.0)
    with pytest.raises(ValueError, match="does not fit"):
        link_budget(c, parse_connection("serial:/dev/x:57600"), 100.0)
    assert link_budget(c, parse_connection("tcp:127.0.0.1:4560"), 1000.0).capacity_bytes_s is None


def test_bridge_refuses_a_rate_its_serial_link_cannot_carry() -> None:
    """Refused before the device is opened (it does not exist here): the budget is the first check."""
    with pytest.raises(ValueError, match="does not fit"):
        Bridge(BridgeOptions(scenario="hover", dt_s=0.005, link="serial:/dev/navig8-none:921600"))


def test_udpout_sends_to_its_peer_from_a_free_port() -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5.0)
    ep = open_endpoint("gcs", parse_connection(f"udpout:127.0.0.1:{rx.getsockname()[1]}"))
    try:
        ep.sock.sendto(b"x", ep.targets[0])
        assert rx.recvfrom(10)[0] == b"x"
    finally:
        ep.sock.close()
        rx.close()


@pytest.mark.parametrize(("argv", "exit_code", "says"), [
    (["-m", "sim_bridge.bridge", "--link", "serial:/dev/navig8-none:921600", "--dt", "0.005"], 2, "does not fit"),
    (["-m", "sim_bridge.bridge", "--link", "tcp:nowhere"], 2, "expected tcp:HOST:PORT"),
    (["-m", "navig8_fc.shell.fc_process", "--sim-link", "serial:/dev/x:fast"], 2, "not a number"),
    (["-m", "navig8_fc.shell.fc_process", "--sim-link", "serial:/dev/navig8-none:921600", "--gcs-bind-port", "0",
      "--api-bind-port", "0"], 1, "cannot open /dev/navig8-none"),
])
def test_the_clis_refuse_bad_links_with_one_clear_line(argv: list[str], exit_code: int, says: str) -> None:
    import subprocess
    import sys

    p = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=120)
    assert p.returncode == exit_code and says in p.stderr, (p.returncode, p.stderr[-1500:])
    assert "Traceback" not in p.stderr


def _frames_by_sender(srv: TcpServerTransport, n: int, timeout_s: float = 5.0) -> dict[tuple[str, int], int]:
    """Whole frames read from a tcpin: server, counted by the sender (connection) they came from."""
    c, counts = codec.seam_codec(), codec.ParseCounters()
    got: dict[tuple[str, int], int] = {}
    srv.settimeout(0.1)
    deadline = time.monotonic() + timeout_s
    while sum(got.values()) < n and time.monotonic() < deadline:
        try:
            data, addr = srv.recvfrom(65535)
        except (TimeoutError, BlockingIOError):
            continue
        got[addr] = got.get(addr, 0) + len(c.parse(data, counts))
    return got


def test_a_tcpin_server_serves_several_connections_each_its_own_sender() -> None:
    srv = TcpServerTransport("t", parse_connection("tcpin:127.0.0.1:0"))
    port = srv.getsockname()[1]
    a, b = (socket.create_connection(("127.0.0.1", port), timeout=5.0) for _ in range(2))
    enc = codec.Encoder(codec.seam_codec(), 1, 1)
    try:
        a.sendall(enc.frames(_records(3)))
        b.sendall(enc.frames(_records(2)))
        got = _frames_by_sender(srv, 5)
        assert sorted(got.values()) == [2, 3] and srv.connections == 2  # two senders, neither displaced the other
        addr_a = next(addr for addr, n in got.items() if n == 3)
        srv.sendto(enc.frame(*_records(1)[0]), addr_a)  # a reply goes to its sender only
        a.settimeout(5.0)
        assert a.recv(4096)
        b.settimeout(0.3)
        with pytest.raises(TimeoutError):
            b.recv(4096)
    finally:
        a.close()
        b.close()
        srv.close()


def test_a_tcpin_server_keeps_its_peer_through_a_flood_of_connections(monkeypatch: pytest.MonkeyPatch) -> None:
    """100 connections (idle, or sending frames) never displace the kept peer; the count stays capped; idle
    connections that sent nothing are closed after TCP_UNPROVEN_IDLE_S."""
    from navig8_fc.links import transport

    monkeypatch.setattr(transport, "TCP_UNPROVEN_IDLE_S", 0.5)
    srv = TcpServerTransport("t", parse_connection("tcpin:127.0.0.1:0"))
    port = srv.getsockname()[1]
    enc = codec.Encoder(codec.seam_codec(), 1, 1)
    peer = socket.create_connection(("127.0.0.1", port), timeout=5.0)
    others: list[socket.socket] = []
    try:
        peer.sendall(enc.frames(_records(1)))
        (peer_addr,) = _frames_by_sender(srv, 1)
        srv.keep(peer_addr)  # the callers' paired peer
        for k in range(100):
            s = socket.create_connection(("127.0.0.1", port), timeout=5.0)
            if k % 2:
                s.sendall(enc.frames(_records(1)))  # proven, active connections too
            others.append(s)
            _frames_by_sender(srv, 1, 0.01)
        assert srv.connections <= transport.TCP_MAX_CONNECTIONS
        peer.sendall(enc.frames(_records(2)))
        assert _frames_by_sender(srv, 2).get(peer_addr, 0) >= 1  # still connected, still heard
        assert srv.evicted + srv.refused >= 100 - transport.TCP_MAX_CONNECTIONS
        idle = socket.create_connection(("127.0.0.1", port), timeout=5.0)  # never sends a frame
        others.append(idle)
        deadline = time.monotonic() + 5.0
        idle.settimeout(0.05)
        closed = False
        while not closed and time.monotonic() < deadline:
            _frames_by_sender(srv, 1, 0.05)
            try:
                closed = idle.recv(1) == b""
            except TimeoutError:
                pass
            except OSError:
                closed = True
        assert closed and srv.timed_out >= 1
    finally:
        for s in [peer, *others]:
            s.close()
        srv.close()
