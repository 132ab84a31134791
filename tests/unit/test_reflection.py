"""links.reflection over a real UdpLink on loopback: an address nobody vouched for gets at most twice the bytes it
sent, the configured peer gets everything and keeps getting it when another address becomes a peer."""

from __future__ import annotations

import socket
import time

from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.links.mavlink_link import UdpLink
from navig8_fc.links.reflection import REFLECTION_RATIO, ReflectionBudget
from navig8_fc.shell.gcs_links import resolved_udp_address


def _udp() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(0.05)
    return s


def _drain(sock: socket.socket, timeout_s: float = 0.3) -> int:
    n, deadline = 0, time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            n += len(sock.recvfrom(65535)[0])
        except TimeoutError:
            continue
    return n


def test_budget_charges_what_goes_out_against_twice_what_came_in() -> None:
    budget = ReflectionBudget(lambda addr: addr == ("127.0.0.1", 1), sources_kept=2)
    a, b, c = ("127.0.0.1", 2), ("127.0.0.1", 3), ("127.0.0.1", 4)
    assert not budget.allows(a, 1)  # nothing in: nothing out
    budget.received(a, 21)
    assert budget.allows(a, 30) and budget.allows(a, 12) and not budget.allows(a, 1)
    assert budget.allows(("127.0.0.1", 1), 10_000)  # vouched for
    budget.received(b, 10)
    budget.received(c, 10)  # a is forgotten (least recently heard): it starts from nothing again
    assert not budget.allows(a, 1) and budget.allows(b, 20)


def test_a_spoofed_peer_gets_at_most_twice_its_bytes_and_the_configured_peer_keeps_its_stream() -> None:
    operator, spoofer = _udp(), _udp()
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    link = UdpLink.open("gcs", mav, ("127.0.0.1", 0), [operator.getsockname()])
    link.keep_targets = True
    link.budget = ReflectionBudget(lambda addr: addr in link.targets)
    try:
        client = mavlink2.MAVLink(None, srcSystem=250, srcComponent=190)
        hb = client.heartbeat_encode(6, 8, 0, 0, 0).pack(client)
        spoofer.sendto(hb, ("127.0.0.1", link.local_port))
        deadline = time.monotonic() + 2.0
        while not link.peers and time.monotonic() < deadline:
            link.receive()
            time.sleep(0.005)
        assert link.peers == [spoofer.getsockname()]
        att = mav.attitude_encode(0, 0.1, 0.2, 0.3, 0, 0, 0)
        size = len(att.pack(mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)))
        for _ in range(50):  # telemetry: both the configured peer and the new one are destinations
            link.send(att)
        got_operator, got_spoofer = _drain(operator), _drain(spoofer)
        assert got_operator == 50 * size
        assert 0 < got_spoofer <= REFLECTION_RATIO * len(hb)
        assert link.counters.reflection_capped == 50 - got_spoofer // size
    finally:
        link.close()
        operator.close()
        spoofer.close()


def test_a_configured_peer_given_by_name_is_recognised_by_its_address() -> None:
    assert resolved_udp_address(("localhost", 14550)) == ("127.0.0.1", 14550)
    assert resolved_udp_address(("name.invalid", 14550)) == ("name.invalid", 14550)  # kept: sendto will say
