"""The FC's two ground-station links (GCS, API) as the GCS service's Outbox: binding them, keeping the FC's own echo
and other vehicles' traffic out of the service, and sending to every peer (`broadcast`) or to the one a request came
from (`reply`). Every STATUSTEXT sent also goes to the Foxglove log panel (/foxglove/log)."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterator
from typing import Any

from navig8_fc.links.mavlink_link import UdpLink
from navig8_fc.links.reflection import ReflectionBudget
from navig8_fc.links.transport import TcpServerTransport, parse_connection
from navig8_fc.shell.fc_options import FcOptions
from navig8_fc.shell.foxglove_out import FoxgloveOutput
from navig8_fc.shell.telemetry_service import Source

GCS_DATAGRAMS_PER_PASS = 16  # ~2-5 ms of GCS work at most between two looks at the sim link


def resolved_udp_address(addr: tuple[str, int]) -> tuple[str, int]:
    """(host name, port) as the IPv4 address recvfrom reports for it (`host.docker.internal` -> its IP), so a
    configured peer is recognised when it talks; the name itself when it does not resolve."""
    try:
        infos = socket.getaddrinfo(addr[0], addr[1], socket.AF_INET, socket.SOCK_DGRAM)
    except (OSError, UnicodeError):
        return addr
    return (str(infos[0][4][0]), int(infos[0][4][1])) if infos else addr


class ConfiguredSources:
    """The links' configured peers as sources ((link name, address)), and every live connection of a link served on
    TCP (tcpin:): a TCP peer's address cannot be spoofed, and the operator chose to serve the link there, so each
    connection is trusted as the link's one connection was before it served several (docs/security.md, "TCP
    links")."""

    def __init__(self, links: tuple[UdpLink, ...]) -> None:
        self._static = frozenset((link.name, t) for link in links for t in link.targets)
        self._servers = {link.name: link.sock for link in links if isinstance(link.sock, TcpServerTransport)}

    def __contains__(self, source: object) -> bool:
        if source in self._static:
            return True
        if not (isinstance(source, tuple) and len(source) == 2):
            return False
        server = self._servers.get(source[0])
        return server is not None and server.has_connection(source[1])

    def __iter__(self) -> Iterator[Source]:
        return iter(self._static)


class GcsLinks:
    """The GCS and API links (GcsService's Outbox). `fox` mirrors STATUSTEXT; `sim_ns` stamps it on sim time."""

    def __init__(self, opts: FcOptions, mav: Callable[[], Any], compid: int, fox: FoxgloveOutput | None,
                 sim_ns: Callable[[], int]) -> None:
        o = opts
        self.sysid, self.compid = o.sysid, compid
        self.gcs = (UdpLink.connect("gcs", mav(), parse_connection(o.gcs_link)) if o.gcs_link else
                    UdpLink.open("gcs", mav(), (o.bind_host, o.port("gcs_bind")), [(o.gcs_host, o.gcs_port)]))
        self.api = (UdpLink.connect("api", mav(), parse_connection(o.api_link)) if o.api_link else
                    UdpLink.open("api", mav(), (o.bind_host, o.port("api_bind")), [(o.gcs_host, o.port("api"))]))
        self.links = (self.gcs, self.api)
        for link in self.links:  # a GCS flood is handled a slice per loop pass, between control steps
            link.max_datagrams = GCS_DATAGRAMS_PER_PASS
            link.keep_targets = True  # the configured peer is served whoever else talks (docs/security.md)
            if not isinstance(link.sock, socket.socket):
                continue  # a stream's one peer: already the address its frames arrive from
            link.targets = [resolved_udp_address(t) for t in link.targets]  # as recvfrom will report it
        self._fox, self._sim_ns = fox, sim_ns

    def guard(self, admit_peer: Callable[[Any, tuple[str, int]], bool], signing_on: Callable[[], bool]) -> None:
        """Telemetry only to the peers `admit_peer` confirms (GcsService.admits_peer), and to an address other than
        a link's configured peers at most twice what that address sent (links.reflection) until `signing_on()` says
        every frame that gets in carries the key (docs/security.md)."""
        trusted = self.trusted_sources()
        for link in self.links:
            link.admit_peer = admit_peer
            link.budget = ReflectionBudget(
                lambda addr, name=link.name: (name, addr) in trusted or signing_on())

    def trusted_sources(self) -> ConfiguredSources:
        """The configured peers of both links and the connections of a TCP-served one (GcsService trusts them before
        they speak)."""
        return ConfiguredSources(self.links)

    def mine(self, link: UdpLink, received: list[Any]) -> list[tuple[Any, Source | None]]:
        """The received messages meant for this FC, each with its source: our own echo or another vehicle's
        traffic is counted on the link, never acted on."""
        out = []
        for r in received:
            m = r.msg
            if m.get_srcSystem() == self.sysid and m.get_srcComponent() == self.compid:
                link.counters.foreign += 1
                continue
            out.append((m, (link.name, r.addr) if r.addr is not None else None))
        return out

    # --- Outbox (GcsService) ---------------------------------------------------------------------
    def broadcast(self, msgs: list[Any], exclude: frozenset[Source] = frozenset()) -> None:
        """To every peer of both GCS-facing links (telemetry, HEARTBEAT, STATUSTEXT, PARAM_VALUE announcements),
        except the sources in `exclude` (source = (link name, address)). Every STATUSTEXT (the FC's events and the
        GCS service's refusal reasons alike) also goes to /foxglove/log."""
        for link in self.links:
            dest = None
            if exclude:
                dest = [a for a in link.destinations() if (link.name, a) not in exclude]
                if not dest:
                    continue
            for m in msgs:
                link.send(m, dest)
        if self._fox is not None:
            for m in msgs:
                if m.get_type() == "STATUSTEXT":
                    text = m.text.decode(errors="replace") if isinstance(m.text, bytes) else str(m.text)
                    self._fox.statustext(self._sim_ns(), int(m.severity), text.rstrip("\0"), time.time_ns())

    def reply(self, source: Source, msgs: list[Any]) -> None:
        """To the one peer a request came from, on its link: source = (link name, sender address)."""
        name, addr = source  # type: ignore[misc]
        link = self.api if name == self.api.name else self.gcs
        dest = [addr]
        for m in msgs:
            link.send(m, dest)
