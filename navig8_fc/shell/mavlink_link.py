"""UDP MAVLink endpoints for the shell: frame splitting, decoding with counters, peers, sending.

Each datagram is split into frames by their own length fields (MAVLink 1 0xFE and MAVLink 2 0xFD,
signed or not), so a truncated or corrupt frame never poisons the next datagram, and every frame's
raw bytes are available for the log. Bad input (garbage between frames, truncated frames, bad CRC,
unknown ids, oversize datagrams) is counted and dropped; nothing here raises on input.
"""

from __future__ import annotations

import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

MAX_DATAGRAM = 2048  # larger datagrams are counted as oversize and dropped
V1_MAGIC, V2_MAGIC = 0xFE, 0xFD
V1_OVERHEAD, V2_OVERHEAD, SIGNATURE_LEN = 8, 12, 13


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
    unknown_id: int = 0  # CRC could not be checked: a message id outside our dialect
    foreign: int = 0  # frames for another system id
    send_errors: int = 0


def split_frames(data: bytes) -> tuple[list[bytes], int, int]:
    """Frames found in a datagram, the count of garbage bytes skipped, and 1 if it ends truncated."""
    frames: list[bytes] = []
    i, n, garbage, truncated = 0, len(data), 0, 0
    while i < n:
        b = data[i]
        if b == V2_MAGIC:
            if i + 3 > n:
                truncated = 1
                break
            length = V2_OVERHEAD + data[i + 1] + (SIGNATURE_LEN if data[i + 2] & 0x01 else 0)
        elif b == V1_MAGIC:
            if i + 2 > n:
                truncated = 1
                break
            length = V1_OVERHEAD + data[i + 1]
        else:
            garbage += 1
            i += 1
            continue
        if i + length > n:
            truncated = 1
            break
        frames.append(bytes(data[i : i + length]))
        i += length
    return frames, garbage, truncated


_peer_texts: dict[tuple[tuple[str, int], ...], str] = {}


def _peer_text(dests: list[tuple[str, int]]) -> str:
    """ "host:port,host:port" of a destination list (cached: the same few lists recur every step)."""
    key = tuple(dests)
    text = _peer_texts.get(key)
    if text is None:
        text = _peer_texts[key] = ",".join(f"{h}:{p}" for h, p in key)
    return text


@dataclass(frozen=True)
class Received:
    frame: bytes
    msg: Any | None  # decoded pymavlink message (or the datagram_decoder's object for a whole datagram)
    addr: tuple[str, int]


@dataclass
class UdpLink:
    """One UDP endpoint. `targets` get our output until a peer talks to us; then replies go to the peers."""

    name: str
    sock: socket.socket
    mav: Any  # pymavlink MAVLink object used for packing (owns our seq counter)
    targets: list[tuple[str, int]] = field(default_factory=list)
    peers: list[tuple[str, int]] = field(default_factory=list)
    sysid_filter: int | None = None  # drop frames not from... (kept None: we accept any source)
    counters: LinkCounters = field(default_factory=LinkCounters)
    max_peers: int = 8
    # Logging hooks. on_datagram: every datagram in (up to MAX_DATAGRAM bytes) and out, raw, once, as it crossed
    # the link (a datagram holds one or more frames). on_frame: every frame that decoded (link, dir, raw, msg, peer).
    on_datagram: Callable[[str, str, bytes, str], None] | None = None  # (link, dir, raw, "host:port[,host:port]")
    on_frame: Callable[[str, str, bytes, Any, tuple[str, int]], None] | None = None
    # Optional fast path tried before pymavlink (the sim link: navig8_fc.mavlink.seam.fast_decode): a decoded
    # message, or None to let pymavlink decode (and count) the frame as usual.
    fast_decode: Callable[[bytes], Any | None] | None = None
    # Optional whole-datagram path tried first (the sim link: seam.decode_step_datagram): (object, frame count),
    # delivered as one Received whose msg is that object, or None to split and decode frame by frame.
    datagram_decoder: Callable[[bytes], tuple[Any, int] | None] | None = None

    @staticmethod
    def open(name: str, mav: Any, bind: tuple[str, int], targets: list[tuple[str, int]] | None = None) -> UdpLink:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.bind(bind)
        s.setblocking(False)
        return UdpLink(name=name, sock=s, mav=mav, targets=list(targets or []))

    @property
    def local_port(self) -> int:
        return int(self.sock.getsockname()[1])

    def destinations(self) -> list[tuple[str, int]]:
        return self.peers if self.peers else self.targets

    def receive(self) -> list[Received]:
        """Everything waiting on the socket (non-blocking), split and decoded."""
        out: list[Received] = []
        c = self.counters
        while True:
            try:
                data, addr = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
            c.datagrams_in += 1
            c.bytes_in += len(data)
            if len(data) > MAX_DATAGRAM:
                c.oversize += 1
                continue
            if self.on_datagram:
                self.on_datagram(self.name, "in", data, f"{addr[0]}:{addr[1]}")
            if self.datagram_decoder is not None:
                whole = self.datagram_decoder(data)
                if whole is not None:
                    c.frames_in += whole[1]
                    self._note_peer(addr)
                    out.append(Received(data, whole[0], addr))
                    continue
            frames, garbage, truncated = split_frames(data)
            c.garbage_bytes += garbage
            c.truncated += truncated
            fast = self.fast_decode
            for fr in frames:
                msg = fast(fr) if fast is not None else None
                if msg is None:
                    try:
                        msg = self.mav.decode(bytearray(fr))
                    except Exception:  # noqa: BLE001 - any decode failure is bad input: count, drop
                        c.bad_crc += 1
                        continue
                    if msg.get_type().startswith(("UNKNOWN_", "BAD_DATA")):
                        c.unknown_id += 1  # pymavlink hands these back undecoded: not a peer, not an input
                        continue
                c.frames_in += 1
                self._note_peer(addr)
                if self.on_frame:
                    self.on_frame(self.name, "in", fr, msg, addr)
                out.append(Received(fr, msg, addr))
        return out

    def _note_peer(self, addr: tuple[str, int]) -> None:
        if addr not in self.peers:
            if len(self.peers) >= self.max_peers:
                self.peers.pop(0)
            self.peers.append(addr)

    def send(self, msg: Any, dest: list[tuple[str, int]] | None = None) -> None:
        buf = msg.pack(self.mav)
        self.send_raw(buf, dest, msg)

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
            try:
                self.sock.sendto(data, addr)
                self.counters.bytes_out += len(data)
            except OSError:  # a peer that went away (ICMP unreachable): counted, never fatal
                self.counters.send_errors += 1

    def close(self) -> None:
        self.sock.close()
