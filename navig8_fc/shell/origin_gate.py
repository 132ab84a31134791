"""A gate in front of the Foxglove WebSocket server that refuses foreign browser origins (docs/foxglove.md,
"Who may connect").

A web page open in the operator's browser may open a WebSocket to any address, loopback included, and the browser
sends the page's `Origin` with the handshake; a server that does not check it streams the vehicle's pose to that
page. foxglove-sdk 0.30 has no origin check or hook (`foxglove.start_server` takes none), so the SDK's server listens
on a loopback port of its own and this gate listens where the operator asked: it reads the HTTP upgrade request
(at most 8 KiB, within 5 s), answers `403 Forbidden` when its `Origin` is present and not allowed, and otherwise
passes the request and then the bytes both ways to the SDK's server.

Allowed by default: no `Origin` (a client that is not a browser page: the `websockets` library, Foxglove's desktop
app as far as it sends none) and Foxglove's web app (`https://app.foxglove.dev`). `--foxglove-allow-origin ORIGIN`
adds one (repeatable; `*` allows any). `null` (sandboxed frames, `file://` pages) is not allowed unless named.
At most MAX_CONNECTIONS at once. The refusals are counted and the first of each origin printed on stderr, so an
operator whose client is refused learns what to allow.
"""

from __future__ import annotations

import socket
import sys
import threading
from collections.abc import Iterable

DEFAULT_ALLOWED_ORIGINS = frozenset({"https://app.foxglove.dev"})
ANY_ORIGIN = "*"
MAX_REQUEST_BYTES = 8192
REQUEST_TIMEOUT_S = 5.0
MAX_CONNECTIONS = 16
FORBIDDEN = (b"HTTP/1.1 403 Forbidden\r\nContent-Type: text/plain\r\nConnection: close\r\nContent-Length: 19\r\n\r\n"
             b"origin not allowed\n")


def request_origin(head: bytes) -> str | None:
    """The `Origin` header of an HTTP request head (None: absent). Header names are case-insensitive."""
    for line in head.split(b"\r\n")[1:]:
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == b"origin":
            return value.strip().decode("latin-1")
    return None


def origin_allowed(origin: str | None, allowed: Iterable[str]) -> bool:
    """Whether a handshake with this Origin may pass (module docstring): absent, or named (case-insensitively,
    without a trailing slash), or `*` allowed."""
    if origin is None:
        return True
    names = {a.rstrip("/").lower() for a in allowed}
    return ANY_ORIGIN in names or origin.rstrip("/").lower() in names


class OriginGate:
    """Listens on (host, port), passes allowed handshakes on to 127.0.0.1:backend_port (module docstring)."""

    def __init__(self, host: str, port: int, backend_port: int, allowed: Iterable[str] = DEFAULT_ALLOWED_ORIGINS
                 ) -> None:
        self.allowed = frozenset(allowed)
        self._backend = ("127.0.0.1", int(backend_port))
        self._sock = socket.create_server((host, int(port)))  # OSError (address in use) to the caller
        self.port = int(self._sock.getsockname()[1])
        self.n_refused = 0
        self._told: set[str] = set()
        self._slots = threading.BoundedSemaphore(MAX_CONNECTIONS)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, name="foxglove-origin-gate", daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _addr = self._sock.accept()
            except OSError:
                return  # closed
            if not self._slots.acquire(blocking=False):
                conn.close()  # at the cap: refused at once
                continue
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        try:
            head = self._read_head(conn)
            if head is None:
                return
            origin = request_origin(head)
            if not origin_allowed(origin, self.allowed):
                self.n_refused += 1
                if origin not in self._told and len(self._told) < 64:
                    self._told.add(str(origin))
                    print(f"navig8-fc: Foxglove WebSocket: origin {origin!r} refused (--foxglove-allow-origin "
                          "allows it)", file=sys.stderr)
                conn.sendall(FORBIDDEN)
                return
            backend = socket.create_connection(self._backend, timeout=REQUEST_TIMEOUT_S)
            backend.settimeout(None)
            conn.settimeout(None)
            backend.sendall(head)
            pump = threading.Thread(target=_pump, args=(backend, conn), daemon=True)
            pump.start()
            _pump(conn, backend)
            pump.join()
        except OSError:
            pass
        finally:
            conn.close()
            self._slots.release()

    @staticmethod
    def _read_head(conn: socket.socket) -> bytes | None:
        """The request up to and including its blank line (None: too long, too slow, or closed first)."""
        conn.settimeout(REQUEST_TIMEOUT_S)
        head = b""
        while b"\r\n\r\n" not in head:
            if len(head) >= MAX_REQUEST_BYTES:
                return None
            data = conn.recv(MAX_REQUEST_BYTES - len(head))
            if not data:
                return None
            head += data
        return head

    def close(self) -> None:
        self._stop.set()
        self._sock.close()


def _pump(src: socket.socket, dst: socket.socket) -> None:
    """Bytes from src to dst until src ends; then dst's sending side is shut (the other pump ends in turn)."""
    try:
        while data := src.recv(65536):
            dst.sendall(data)
    except OSError:
        pass
    finally:
        for s, how in ((dst, socket.SHUT_WR), (src, socket.SHUT_RD)):
            try:
                s.shutdown(how)
            except OSError:
                pass


__all__ = ["DEFAULT_ALLOWED_ORIGINS", "OriginGate", "origin_allowed", "request_origin"]
