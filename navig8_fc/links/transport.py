"""Transports for every MAVLink link (sim, GCS, API): UDP, TCP or serial, chosen by a connection string.

    udpin:HOST:PORT      bind HOST:PORT, reply to whoever talks (udp: is the same, as in pymavlink's mavutil)
    udpout:HOST:PORT     send to HOST:PORT from a free local port
    tcpin:HOST:PORT      listen on HOST:PORT, several connections at once, each its own peer
    tcp:HOST:PORT        connect to HOST:PORT, reconnecting every RECONNECT_S while refused or dropped
    serial:DEVICE:BAUD   a UART through pyserial (serial:/dev/ttyUSB0:921600; BAUD defaults to 921600)

The `scheme://` spelling MAVSDK uses (`udpin://0.0.0.0:14540`, `serial:///dev/ttyUSB0:57600`) is read too; an
empty host means every interface. PX4's simulator interface is TCP port 4560, the simulator listening and PX4
connecting (PX4 `simulator_mavlink`): `navig8-bridge --link tcpin:127.0.0.1:4560`, `navig8-fc --sim-link
tcp:127.0.0.1:4560`.

A UDP endpoint is a plain socket (the lockstep path pays nothing for this module). A stream endpoint (TCP,
serial) is a `StreamTransport`: it quacks like the UDP socket its callers already use (`recvfrom`, `sendto`,
`fileno` for select, `settimeout`, `getsockname`, `close`), so `mavlink_link.UdpLink` and the bridge take either.
Over a byte stream MAVLink frames arrive in pieces: each `recvfrom` returns the bytes up to the end of the last
whole frame (the codec's framer, `codec.split_frames`, finds it) and keeps the partial tail for the next read, so
the callers' parsers see whole frames and count real garbage, never a frame cut by a read boundary.
"""

from __future__ import annotations

import errno
import select
import socket
import time
from dataclasses import dataclass
from typing import Any

from navig8_fc.mavlink.codec import split_frames

UDP_SCHEMES = ("udpin", "udpout")
STREAM_SCHEMES = ("tcp", "tcpin", "serial")
DEFAULT_BAUD = 921600
READ_CHUNK = 1024  # bytes per read: with a partial tail (< 280 B) a returned chunk stays under the links' 2048 B
RECONNECT_S = 0.2  # a tcp: client retries a refused or dropped connection this often
SERIAL_BITS_PER_BYTE = 10  # 8N1: start bit, 8 data bits, stop bit


class PortInUseError(OSError):
    """A port another socket holds (UDP bind or TCP listen)."""

    def __init__(self, link: str, host: str, port: int, proto: str = "UDP") -> None:
        super().__init__(errno.EADDRINUSE, f"{link} link: {proto} {host}:{port} is in use by another process")
        self.link, self.host, self.port, self.proto = link, host, port, proto


@dataclass(frozen=True)
class Connection:
    """A parsed connection string (`parse_connection`)."""

    scheme: str  # udpin, udpout, tcp, tcpin, serial
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0
    text: str = ""

    @property
    def stream(self) -> bool:
        return self.scheme in STREAM_SCHEMES

    @property
    def bytes_per_s(self) -> float | None:
        """What a serial line carries each way (8N1); None for the network links (not the limit here)."""
        return self.baud / SERIAL_BITS_PER_BYTE if self.scheme == "serial" else None


def parse_connection(text: str) -> Connection:
    """`udpin:H:P`, `udpout:H:P`, `udp:H:P`, `tcp:H:P`, `tcpin:H:P`, `serial:DEV[:BAUD]` (or `scheme://...`);
    ValueError naming what is wrong."""
    scheme, sep, rest = text.partition(":")
    scheme = scheme.strip().lower()
    if not sep:
        raise ValueError(f"connection {text!r}: expected SCHEME:..., e.g. udpin:127.0.0.1:14550, tcp:127.0.0.1:4560"
                         ", serial:/dev/ttyUSB0:921600")
    if rest.startswith("//"):
        rest = rest[2:]
    if scheme == "udp":
        scheme = "udpin"
    if scheme == "serial":
        device, baud = rest, DEFAULT_BAUD
        head, _, tail = rest.rpartition(":")
        if head and tail.isdigit():
            device, baud = head, int(tail)
        elif head and tail:
            raise ValueError(f"connection {text!r}: the baud rate {tail!r} is not a number")
        if not device or baud <= 0:
            raise ValueError(f"connection {text!r}: expected serial:DEVICE:BAUD, e.g. serial:/dev/ttyUSB0:921600")
        return Connection("serial", device=device, baud=baud, text=text)
    if scheme not in UDP_SCHEMES + ("tcp", "tcpin"):
        raise ValueError(f"connection {text!r}: unknown scheme {scheme!r} (udpin, udpout, udp, tcp, tcpin, serial)")
    host, _, port_text = rest.rpartition(":")
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise ValueError(f"connection {text!r}: expected {scheme}:HOST:PORT with a port 0..65535")
    port = int(port_text)
    if scheme in ("udpout", "tcp") and (not host or port == 0):
        raise ValueError(f"connection {text!r}: {scheme} needs the peer's host and port")
    return Connection(scheme, host=host or "0.0.0.0", port=port, text=text)


def bind_udp(name: str, bind: tuple[str, int]) -> socket.socket:
    """A UDP socket bound to `bind` (port 0: any free port), without SO_REUSEADDR (on UDP it would let a second
    process bind the same port and take the datagrams); PortInUseError if taken."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.bind(bind)
    except OSError as e:
        s.close()
        if e.errno == errno.EADDRINUSE:
            raise PortInUseError(name, bind[0], bind[1]) from e
        raise
    return s


@dataclass
class Endpoint:
    """An opened connection: `sock` (a UDP socket or a StreamTransport) and where to send before a peer talks."""

    sock: Any
    targets: list[tuple[str, int]]

    @property
    def stream(self) -> bool:
        return isinstance(self.sock, StreamTransport)


def open_endpoint(name: str, conn: Connection) -> Endpoint:
    """Bind, listen, connect or open as `conn` says (PortInUseError for a taken port, OSError for a device)."""
    if conn.scheme == "udpin":
        return Endpoint(bind_udp(name, (conn.host, conn.port)), [])
    if conn.scheme == "udpout":
        local = "127.0.0.1" if conn.host.startswith("127.") or conn.host == "localhost" else "0.0.0.0"
        return Endpoint(bind_udp(name, (local, 0)), [(conn.host, conn.port)])
    t: StreamTransport
    if conn.scheme == "tcpin":
        t = TcpServerTransport(name, conn)
    elif conn.scheme == "tcp":
        t = TcpClientTransport(name, conn)
    else:
        t = SerialTransport(name, conn)
    return Endpoint(t, [t.peer])


class StreamTransport:
    """A byte stream behind the UDP socket interface its callers use (see the module docstring).

    recvfrom: whole frames only (plus any garbage before them, for the parser to count), the partial tail kept;
    BlockingIOError when nothing whole is there (timeout 0), TimeoutError after a timeout. sendto ignores the
    address: a stream has one peer. A send while nothing is connected raises ConnectionError (callers count it)."""

    def __init__(self, name: str, conn: Connection) -> None:
        self.name, self.conn = name, conn
        self.peer: tuple[str, int] = (conn.text, 0)  # the one peer's address, as recvfrom reports it
        self._buf = b""
        self._timeout: float | None = 0.0
        self.reconnects = 0  # connections (re)established after the first
        self.bytes_dropped = 0  # partial-frame bytes lost with a dropped connection

    # --- the socket interface ------------------------------------------------------------------------------
    def fileno(self) -> int:
        raise NotImplementedError

    def settimeout(self, timeout_s: float | None) -> None:
        self._timeout = timeout_s

    def setblocking(self, flag: bool) -> None:
        self._timeout = None if flag else 0.0

    def getsockname(self) -> tuple[str, int]:
        return (self.conn.host or self.conn.device, self.conn.port)

    def recvfrom(self, bufsize: int = 65535) -> tuple[bytes, tuple[str, int]]:
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        while True:
            whole = self._take_whole()
            if whole:
                return whole, self.peer
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            r, _, _ = select.select([self], [], [], wait)
            if not r:
                if self._timeout == 0.0:
                    raise BlockingIOError(errno.EAGAIN, "no whole frame waiting")
                raise TimeoutError(f"{self.name} link: no whole frame within {self._timeout} s")
            data = self._read()
            if data is None:  # nothing readable after all (a new connection accepted, a spurious wake-up)
                if deadline is not None and time.monotonic() >= deadline:
                    raise BlockingIOError(errno.EAGAIN, "no whole frame waiting")
                continue
            self._buf += data

    def sendto(self, data: bytes, _addr: Any = None) -> int:
        self._write(data)
        return len(data)

    def send(self, data: bytes) -> int:
        return self.sendto(data)

    def close(self) -> None:
        raise NotImplementedError

    # --- the byte stream -------------------------------------------------------------------------------------
    def _take_whole(self) -> bytes:
        """The buffer up to the end of its last whole frame (garbage included); the partial tail stays."""
        buf = self._buf
        if not buf:
            return b""
        frames, garbage, _ = split_frames(buf)
        end = sum(map(len, frames)) + garbage  # every byte the framer consumed is garbage or part of a frame
        self._buf = buf[end:]
        return buf[:end]

    def _read(self) -> bytes | None:
        """Bytes readable now (None: nothing, e.g. the peer went away and the connection was reset)."""
        raise NotImplementedError

    def _write(self, data: bytes) -> None:
        raise NotImplementedError

    def _lost(self) -> None:
        """The connection dropped: a partial frame cannot be completed by the next connection's bytes."""
        self.bytes_dropped += len(self._buf)
        self._buf = b""


class _TcpTransport(StreamTransport):
    def __init__(self, name: str, conn: Connection) -> None:
        super().__init__(name, conn)
        self._conn: socket.socket | None = None
        self._connections = 0

    def _attach(self, s: socket.socket) -> None:
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # lockstep: every step's frames go out at once
        s.settimeout(1.0)  # bounds a send to a peer that stopped reading; reads only follow select
        if self._conn is not None:
            self._drop()
        self._conn = s
        self._connections += 1
        if self._connections > 1:
            self.reconnects += 1

    def _drop(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        self._lost()

    def _read(self) -> bytes | None:
        if self._conn is None:
            return None
        try:
            data = self._conn.recv(READ_CHUNK)
        except (BlockingIOError, InterruptedError, TimeoutError):
            return None
        except OSError:
            data = b""
        if not data:  # EOF or reset: the peer went away
            self._drop()
            return None
        return data

    def _write(self, data: bytes) -> None:
        if self._conn is None:
            raise ConnectionError(errno.ENOTCONN, f"{self.name} link: {self.conn.text} is not connected")
        try:
            self._conn.sendall(data)
        except OSError:
            self._drop()
            raise

    @property
    def connected(self) -> bool:
        return self._conn is not None


TCP_MAX_CONNECTIONS = 8  # a tcpin: server's connections at once; more evict (below) or are refused
TCP_UNPROVEN_IDLE_S = 60.0  # a connection that has sent no whole frame this long after it opened is closed
TCP_IDLE_S = 30.0  # a connection silent this long is closed (peers send HEARTBEATs at 1 Hz, a lockstep peer more)
_HOUSEKEEPING_S = 0.5


class _Connection:
    """One accepted connection of a TcpServerTransport: its socket, address and partial tail."""

    def __init__(self, sock: socket.socket, addr: tuple[str, int], now: float) -> None:
        self.sock, self.addr, self.buf = sock, addr, b""
        self.opened_s = self.heard_s = now
        self.proven = False  # has sent a whole frame


class TcpServerTransport(StreamTransport):
    """tcpin: listen, and serve several connections at once, each its own peer: `recvfrom` returns a connection's
    whole frames with that connection's (host, port), `sendto(data, addr)` writes to that connection, and to every
    connection for the placeholder address `peer` (a caller's target before anyone talked: open_endpoint). So the
    callers' pairing and peer checks work as over UDP (a second connection is a different sender, never the paired
    one), one idle or hostile connection blinds nobody, and a peer that reconnects is simply a new sender.

    At most TCP_MAX_CONNECTIONS: a new connection beyond them evicts the newest that has sent no whole frame (so a
    flood of connections replaces only its own, never a client that listens before it talks), else the least
    recently heard one the callers have not `keep`-ed (their paired or confirmed peer), else it is refused; a
    connection that sends no whole frame within TCP_UNPROVEN_IDLE_S, or nothing for TCP_IDLE_S, is closed.
    SO_REUSEADDR here is the TCP one: it lets a restarted process listen again past TIME_WAIT and never lets
    two sockets listen on one port (Linux). Linux: the connections are watched with one epoll, whose descriptor is
    what `fileno` gives the callers' select."""

    def __init__(self, name: str, conn: Connection) -> None:
        super().__init__(name, conn)
        srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            srv.bind((conn.host, conn.port))
            srv.listen(TCP_MAX_CONNECTIONS)
        except OSError as e:
            srv.close()
            if e.errno == errno.EADDRINUSE:
                raise PortInUseError(name, conn.host, conn.port, "TCP") from e
            raise
        srv.setblocking(False)
        self._srv = srv
        self._ep = select.epoll()
        self._ep.register(srv.fileno(), select.EPOLLIN)
        self._conns: dict[int, _Connection] = {}  # by file descriptor
        self._by_addr: dict[tuple[str, int], _Connection] = {}
        self._kept: set[tuple[str, int]] = set()
        self._next_housekeeping = 0.0
        self._turn = 0  # round robin over connections with whole frames waiting
        self.accepted = self.evicted = self.refused = self.timed_out = 0

    # --- the socket interface ------------------------------------------------------------------------------
    def fileno(self) -> int:
        return self._ep.fileno()

    def getsockname(self) -> tuple[str, int]:
        return self._srv.getsockname()

    @property
    def connected(self) -> bool:
        return bool(self._conns)

    @property
    def connections(self) -> int:
        return len(self._conns)

    def has_connection(self, addr: object) -> bool:
        """`addr` is one of the live connections (a TCP peer's address cannot be spoofed)."""
        return addr in self._by_addr

    def keep(self, addr: tuple[str, int]) -> None:
        """The callers' paired or confirmed peer: never evicted for a newer connection (it still times out)."""
        if addr in self._by_addr:
            self._kept.add(addr)

    def recvfrom(self, bufsize: int = 65535) -> tuple[bytes, tuple[str, int]]:
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        while True:
            got = self._take_any()
            if got is not None:
                return got
            self._service()
            got = self._take_any()
            if got is not None:
                return got
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            if wait == 0.0:
                if self._timeout == 0.0:
                    raise BlockingIOError(errno.EAGAIN, "no whole frame waiting")
                raise TimeoutError(f"{self.name} link: no whole frame within {self._timeout} s")
            select.select([self._ep], [], [], wait if wait is None else min(wait, _HOUSEKEEPING_S))

    def sendto(self, data: bytes, addr: Any = None) -> int:
        if addr is None or addr == self.peer:
            targets = list(self._conns.values())
            if not targets:
                raise ConnectionError(errno.ENOTCONN, f"{self.name} link: nothing is connected to {self.conn.text}")
        else:
            c = self._by_addr.get(tuple(addr))
            if c is None:
                raise ConnectionError(errno.ENOTCONN, f"{self.name} link: {addr} is not connected")
            targets = [c]
        for c in targets:
            try:
                c.sock.sendall(data)
            except OSError:
                self._close(c)
                if len(targets) == 1:
                    raise
        return len(data)

    def close(self) -> None:
        for c in list(self._conns.values()):
            self._close(c)
        self._ep.close()
        self._srv.close()

    # --- connections -----------------------------------------------------------------------------------------
    def _take_any(self) -> tuple[bytes, tuple[str, int]] | None:
        conns = list(self._conns.values())
        n = len(conns)
        for i in range(n):
            c = conns[(self._turn + i) % n]
            if not c.buf:
                continue
            frames, garbage, _ = split_frames(c.buf)
            end = sum(map(len, frames)) + garbage
            if end == 0:
                continue
            whole, c.buf = c.buf[:end], c.buf[end:]
            if frames:
                c.proven, c.heard_s = True, time.monotonic()
            self._turn = (self._turn + i + 1) % n
            return whole, c.addr
        return None

    def _service(self) -> None:
        """Accept and read what is ready now; close idle connections (at most every _HOUSEKEEPING_S)."""
        srv_fd = self._srv.fileno()
        for fd, _ in self._ep.poll(0):
            if fd == srv_fd:
                self._accept_all()
                continue
            c = self._conns.get(fd)
            if c is None:
                continue
            try:
                data = c.sock.recv(READ_CHUNK)
            except (BlockingIOError, InterruptedError, TimeoutError):
                continue
            except OSError:
                data = b""
            if not data:  # EOF or reset: the peer went away
                self._close(c)
                continue
            c.buf += data
            if len(c.buf) > 8 * READ_CHUNK:  # no frame in 8 kB: not MAVLink, or a peer that floods
                self.bytes_dropped += len(c.buf)
                c.buf = b""
        now = time.monotonic()
        if now >= self._next_housekeeping:
            self._next_housekeeping = now + _HOUSEKEEPING_S
            for c in list(self._conns.values()):
                if now - c.heard_s > (TCP_IDLE_S if c.proven else TCP_UNPROVEN_IDLE_S):
                    self.timed_out += 1
                    self._close(c)

    def _accept_all(self) -> None:
        while True:
            try:
                s, addr = self._srv.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # EMFILE and the like: try again on the next wake-up
                return
            if len(self._conns) >= TCP_MAX_CONNECTIONS and not self._evict_one():
                self.refused += 1
                s.close()
                continue
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # lockstep: every step's frames go out at once
            s.settimeout(1.0)  # bounds a send to a peer that stopped reading; reads only follow epoll
            c = _Connection(s, (str(addr[0]), int(addr[1])), time.monotonic())
            self._conns[s.fileno()] = c
            self._by_addr[c.addr] = c
            self._ep.register(s.fileno(), select.EPOLLIN)
            self.accepted += 1
            if self.accepted > 1:
                self.reconnects += 1

    def _evict_one(self) -> bool:
        conns = list(self._conns.values())
        unproven = [c for c in conns if not c.proven]
        if unproven:
            victim = max(unproven, key=lambda c: c.opened_s)
        else:
            free = [c for c in conns if c.addr not in self._kept]
            if not free:
                return False
            victim = min(free, key=lambda c: c.heard_s)
        self.evicted += 1
        self._close(victim)
        return True

    def _close(self, c: _Connection) -> None:
        fd = c.sock.fileno()
        if self._conns.pop(fd, None) is None:
            return
        self._by_addr.pop(c.addr, None)
        self._kept.discard(c.addr)
        try:
            self._ep.unregister(fd)
        except (OSError, ValueError):
            pass
        c.sock.close()
        self.bytes_dropped += len(c.buf)


class TcpClientTransport(_TcpTransport):
    """tcp: connect to the peer; while refused or after a drop, retry every RECONNECT_S (on each read or send)."""

    def __init__(self, name: str, conn: Connection) -> None:
        super().__init__(name, conn)
        self._idle_a, self._idle_b = socket.socketpair()  # select's fd while unconnected: never readable
        self._next_try = 0.0
        self._try_connect()

    def fileno(self) -> int:
        self._try_connect()
        return self._conn.fileno() if self._conn is not None else self._idle_a.fileno()

    def getsockname(self) -> tuple[str, int]:
        return self._conn.getsockname() if self._conn is not None else ("", 0)

    def _try_connect(self) -> None:
        now = time.monotonic()
        if self._conn is not None or now < self._next_try:
            return
        self._next_try = now + RECONNECT_S
        try:
            s = socket.create_connection((self.conn.host, self.conn.port), timeout=1.0)
        except OSError:
            return
        self._attach(s)

    def _write(self, data: bytes) -> None:
        self._try_connect()
        super()._write(data)

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
        self._idle_a.close()
        self._idle_b.close()


class SerialTransport(StreamTransport):
    """serial: a UART (or a pseudo-terminal) through pyserial, raw 8N1 at the given baud, opened exclusively."""

    def __init__(self, name: str, conn: Connection) -> None:
        super().__init__(name, conn)
        import serial  # pyserial: only the serial links need it

        self._serial_error = serial.SerialException
        try:
            self._ser = serial.Serial(conn.device, conn.baud, timeout=0, write_timeout=1.0, exclusive=True)
        except (serial.SerialException, ValueError) as e:
            raise OSError(errno.ENODEV, f"{name} link: cannot open {conn.device} at {conn.baud} baud: {e}") from e
        self.read_errors = 0

    def fileno(self) -> int:
        return int(self._ser.fileno())

    def _read(self) -> bytes | None:
        try:
            data = self._ser.read(min(max(self._ser.in_waiting, 1), READ_CHUNK))
        except (self._serial_error, OSError):
            # pyserial raises when the device reports data but returns none (the other end of a pty closed)
            self.read_errors += 1
            time.sleep(0.01)  # do not spin on a dead line
            return None
        return data or None

    def _write(self, data: bytes) -> None:
        try:
            self._ser.write(data)
        except (self._serial_error, OSError) as e:
            raise ConnectionError(errno.EIO, f"{self.name} link: write to {self.conn.device} failed: {e}") from e

    def close(self) -> None:
        self._ser.close()


def serial_budget(bytes_per_step: int, rate_hz: float, conn: Connection, headroom: float) -> tuple[float, float]:
    """(bytes/s needed, bytes/s the line may carry = headroom x baud / 10) for a serial connection."""
    cap = conn.bytes_per_s
    assert cap is not None, "only a serial connection has a byte budget"
    return bytes_per_step * rate_hz, headroom * cap


__all__ = ["DEFAULT_BAUD", "Connection", "Endpoint", "PortInUseError", "SerialTransport", "StreamTransport",
           "TcpClientTransport", "TcpServerTransport", "bind_udp", "open_endpoint", "parse_connection",
           "serial_budget"]
