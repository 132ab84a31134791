"""MAVLink endpoints for the FC's shell and the bridge: framing, decoding with counters, peers, sending.

A link is UDP by default (`UdpLink.open`); `UdpLink.connect` opens any connection string (UDP, TCP, serial:
navig8_fc.links.transport), whose stream transports stand in for the UDP socket and hand over whole frames.

Each datagram is split into frames by their own length fields (`codec.split_frames`: MAVLink 1 and 2, signed
or not), so a truncated or corrupt frame never poisons the next datagram. The sim link decodes with the codec
(`navig8_fc.mavlink.codec`: plain `codec.Message` records); the GCS links decode each frame with pymavlink (the
gcs/ handlers use its message objects). Bad input (garbage between frames, truncated frames, bad CRC, unknown
ids, oversize datagrams) is counted and dropped; nothing here raises on input.

Binding: no SO_REUSEADDR (on UDP it would let a second process bind the same port and take datagrams meant
for this one); a port in use raises `PortInUseError`, which names the link and its port. Port 0 binds a free
port (`local_port` tells which).
"""

from __future__ import annotations

import json
import os
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from navig8_fc.links.reflection import ReflectionBudget
from navig8_fc.links.signing import redact_frame, redacted_message
from navig8_fc.links.transport import Connection, PortInUseError, bind_udp, open_endpoint
from navig8_fc.mavlink.codec import Codec, Message, split_frames

__all__ = ["MAX_DATAGRAM", "LinkCounters", "PortInUseError", "Received", "UdpLink", "bind_udp", "write_ports_file"]

MAX_DATAGRAM = 2048  # larger datagrams are counted as oversize and dropped


def write_ports_file(path: Path, ports: dict[str, int]) -> None:
    """The bound ports as JSON (e.g. {"sim": 40123, ...}), published atomically: a reader polling for the file
    never sees a partial one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(ports))
    os.replace(tmp, path)


@dataclass
class LinkCounters:
    datagrams_in: int = 0
    frames_in: int = 0
    frames_out: int = 0
    bytes_in: int = 0
    bytes_out: int = 0
    garbage_bytes: int = 0
    truncated: int = 0
    bad_crc: int = 0  # includes unknown message ids (no CRC_EXTRA to check against)
    oversize: int = 0
    unknown_id: int = 0  # CRC could not be checked: a message id outside our dialect (or the sim link's codec)
    foreign: int = 0  # frames for another system id
    send_errors: int = 0
    signed: int = 0  # signed frames on the sim link that did not verify with its session key (or before one): dropped
    bad_flags: int = 0  # MAVLink 2 frames with an unknown incompat flag (the sim link)
    bad_signature: int = 0  # GCS links with a signing key: frames unsigned or wrongly signed (refused)
    reflection_capped: int = 0  # sends skipped: the address had used up its reflection budget (links.reflection)


_peer_texts: dict[tuple[tuple[str, int], ...], str] = {}


def _peer_text(dests: list[tuple[str, int]]) -> str:
    """ "host:port,host:port" of a destination list (cached: the same few lists recur every step)."""
    key = tuple(dests)
    text = _peer_texts.get(key)
    if text is None:
        text = _peer_texts[key] = ",".join(f"{h}:{p}" for h, p in key)
    return text


class Received(NamedTuple):
    """One received message, or a codec link's datagram of messages (a NamedTuple: made on every lockstep step)."""

    frame: bytes  # the frame (GCS links) or the datagram (codec links)
    msg: Any  # the pymavlink message (GCS links) or the datagram's codec.Message records, a list (codec links)
    addr: tuple[str, int]


@dataclass
class UdpLink:
    """One UDP endpoint. `targets` get our output until a peer talks to us; then replies go to the peers."""

    name: str
    sock: socket.socket
    # packs what `send` is given and owns our sequence number: a pymavlink MAVLink object (GCS links), or the
    # codec.Encoder of a codec link (its records are (name, values) tuples)
    mav: Any
    targets: list[tuple[str, int]] = field(default_factory=list)
    peers: list[tuple[str, int]] = field(default_factory=list)
    sysid_filter: int | None = None  # drop frames not from... (kept None: we accept any source)
    # Which senders become peers (telemetry goes to them): None = any decoded frame; else asked (msg, addr) (a codec
    # link: (the datagram's records, addr)), so a spoofed source gets no stream until the GCS service confirms it
    # (docs/security.md); the FC's sim link admits none (its guard picks the one peer its answers go to).
    admit_peer: Callable[[Any, tuple[str, int]], bool] | None = None
    counters: LinkCounters = field(default_factory=LinkCounters)
    max_peers: int = 8
    # GCS links: the configured targets keep getting our output when peers talk (the operator's station need not
    # send anything to be served), and what goes to any other address is capped by its bytes in (reflection).
    keep_targets: bool = False
    budget: ReflectionBudget | None = None
    # Logging hooks. on_datagram: every datagram in (up to MAX_DATAGRAM bytes) and out, raw, once, as it crossed
    # the link (a datagram holds one or more frames). on_frame: every frame that decoded (link, dir, raw, msg, peer).
    on_datagram: Callable[[str, str, bytes, str], None] | None = None  # (link, dir, raw, "host:port[,host:port]")
    on_frame: Callable[[str, str, bytes, Any, tuple[str, int]], None] | None = None
    # The sim link: decode every datagram with this codec (codec.Message records) instead of pymavlink.
    codec: Codec | None = None
    # -1: receive() drains the socket. The sim link takes one datagram per call: in lockstep one is due per step,
    # and the drain's final, failing recvfrom (~1 us) would be paid on every step.
    max_datagrams: int = -1
    # A codec link's signing key (the sim link once paired): signed frames that verify with it decode with
    # Message.signed set; other signed frames are counted (`signed`) and dropped.
    verify_key: bytes | None = None

    @staticmethod
    def open(name: str, mav: Any, bind: tuple[str, int], targets: list[tuple[str, int]] | None = None,
             codec: Codec | None = None) -> UdpLink:
        """Bind (PortInUseError if the port is taken; port 0: a free one). With `codec`, a codec link: `mav`
        is that codec's Encoder and received datagrams decode to codec.Message records."""
        s = bind_udp(name, bind)
        s.setblocking(False)
        return UdpLink(name=name, sock=s, mav=mav, targets=list(targets or []), codec=codec)

    @staticmethod
    def connect(name: str, mav: Any, conn: Connection, codec: Codec | None = None) -> UdpLink:
        """A link over a connection string's transport (navig8_fc.links.transport: UDP, TCP or serial). A stream
        (TCP, serial) has one peer, always the destination; its reads hand over whole frames only."""
        ep = open_endpoint(name, conn)
        if not ep.stream:
            ep.sock.setblocking(False)
        return UdpLink(name=name, sock=ep.sock, mav=mav, targets=ep.targets, codec=codec)

    @property
    def local_port(self) -> int:
        return int(self.sock.getsockname()[1])

    def destinations(self) -> list[tuple[str, int]]:
        if not self.peers:
            return self.targets
        if self.keep_targets and self.targets:
            return self.targets + [p for p in self.peers if p not in self.targets]
        return self.peers

    def receive(self) -> list[Received]:
        """What is waiting on the socket (non-blocking), split and decoded: every datagram, or at most
        `max_datagrams` (the rest stays readable for the caller's next select)."""
        out: list[Received] = []
        c = self.counters
        left = self.max_datagrams
        while left != 0:
            left -= 1
            try:
                data, addr = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
            c.datagrams_in += 1
            c.bytes_in += len(data)
            if self.budget is not None:
                self.budget.received(addr, len(data))
            if len(data) > MAX_DATAGRAM:
                c.oversize += 1
                continue
            if self.codec is not None:
                if self.on_datagram:
                    self.on_datagram(self.name, "in", data, f"{addr[0]}:{addr[1]}")
                self._receive_records(data, addr, out)
                continue
            frames, garbage, truncated = split_frames(data)
            c.garbage_bytes += garbage
            c.truncated += truncated
            if self.on_datagram:  # a SETUP_SIGNING's key never reaches the log (signing.redact_frame)
                logged = data
                for fr in frames:
                    if (red := redact_frame(fr)) is not fr:
                        logged = logged.replace(fr, red)
                self.on_datagram(self.name, "in", logged, f"{addr[0]}:{addr[1]}")
            for fr in frames:
                try:
                    msg = self.mav.decode(bytearray(fr))
                except Exception as exc:  # noqa: BLE001 - any decode failure is bad input: count, drop
                    if "signature" in str(exc).lower():
                        c.bad_signature += 1
                    else:
                        c.bad_crc += 1
                    continue
                if msg.get_type().startswith(("UNKNOWN_", "BAD_DATA")):
                    c.unknown_id += 1  # pymavlink hands these back undecoded: not a peer, not an input
                    continue
                c.frames_in += 1
                if self.admit_peer is None or self.admit_peer(msg, addr):
                    self._note_peer(addr)
                if self.on_frame:
                    self.on_frame(self.name, "in", redact_frame(fr), redacted_message(msg), addr)
                out.append(Received(fr, msg, addr))
        return out

    def _receive_records(self, data: bytes, addr: tuple[str, int], out: list[Received]) -> None:
        """A codec link's datagram: ONE Received whose msg is the list of its codec.Message records (a lockstep
        step is one datagram of five), the rest counted."""
        assert self.codec is not None
        msgs: list[Message] = self.codec.parse(data, self.counters, self.verify_key)
        if msgs:
            self.counters.frames_in += len(msgs)
            if self.admit_peer is None or self.admit_peer(msgs, addr):
                self._note_peer(addr)
            out.append(Received(data, msgs, addr))

    def _note_peer(self, addr: tuple[str, int]) -> None:
        if addr not in self.peers:
            if len(self.peers) >= self.max_peers:
                self.peers.pop(0)
            self.peers.append(addr)
            keep = getattr(self.sock, "keep", None)  # a tcpin: server never evicts a peer for a newer connection
            if keep is not None:
                keep(addr)

    def send(self, msg: Any, dest: list[tuple[str, int]] | None = None) -> None:
        """Send one message: a pymavlink message (GCS links) or a (name, values) record (codec links)."""
        if type(msg) is tuple:
            self.send_raw(self.mav.frame(*msg), dest)
        else:
            self.send_raw(msg.pack(self.mav), dest, msg)

    def send_raw(self, buf: bytes, dest: list[tuple[str, int]] | None = None, msg: Any = None) -> None:
        """Send one datagram; `msg` (the decoded form of a one-frame datagram) goes to on_frame for the log."""
        dests = dest if dest is not None else self.destinations()
        self._sendto(buf, dests)
        self.counters.frames_out += 1
        if self.on_datagram:
            self.on_datagram(self.name, "out", buf, _peer_text(dests))
        if msg is not None and self.on_frame:
            self.on_frame(self.name, "out", buf, msg, ("", 0))

    def _sendto(self, data: bytes, dest: list[tuple[str, int]] | None) -> None:
        for addr in dest if dest is not None else self.destinations():
            if self.budget is not None and not self.budget.allows(addr, len(data)):
                self.counters.reflection_capped += 1
                continue
            try:
                self.sock.sendto(data, addr)
                self.counters.bytes_out += len(data)
            except OSError:  # a peer that went away (ICMP unreachable): counted, never fatal
                self.counters.send_errors += 1

    def close(self) -> None:
        self.sock.close()
