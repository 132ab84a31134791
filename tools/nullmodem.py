"""navig8-nullmodem: two pseudo-terminals wired back to back, paced at a serial line's byte rate (no socat needed).

    navig8-nullmodem [--baud 921600]      # prints the two device paths, relays until Ctrl-C

What one end writes, the other reads, each direction delayed by its transmission time at BAUD (8N1: ten bits a
byte), so a sender that outruns the line queues as it would on a UART. It is NOT a real line: no bit errors, no
UART FIFO gaps, no flow control, and the pty buffers (~4 KB) stand in for the UART's. Used by the serial-link
tests (tests/sitl/test_hil_serial.py) and to try `--link serial:` / `--sim-link serial:` by hand.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import subprocess
import sys
import threading
import time
import tty
from types import TracebackType

BITS_PER_BYTE = 10


class NullModem:
    """Two ptys (`paths`) joined by two relay threads pacing each direction at baud / 10 bytes per second."""

    def __init__(self, baud: int = 921600) -> None:
        self.baud = baud
        self._fds: list[int] = []
        ends = []
        for _ in range(2):
            master, slave = os.openpty()
            tty.setraw(slave)  # no echo, no line editing: bytes pass as they are (pyserial sets this too)
            self._fds += [master, slave]  # the slave stays open here: a pty whose slave no one holds reads EIO
            ends.append((master, os.ttyname(slave)))
        (self._m1, p1), (self._m2, p2) = ends
        self.paths = (p1, p2)
        self.bytes = [0, 0]  # relayed 1 -> 2, 2 -> 1
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._relay, args=(self._m1, self._m2, 0), daemon=True),
                         threading.Thread(target=self._relay, args=(self._m2, self._m1, 1), daemon=True)]
        self.started = time.monotonic()
        for t in self._threads:
            t.start()

    def _relay(self, src: int, dst: int, k: int) -> None:
        byte_s = BITS_PER_BYTE / self.baud
        free_at = 0.0  # when the line is done sending what it already carries
        while not self._stop.is_set():
            r, _, _ = select.select([src], [], [], 0.1)
            if not r:
                continue
            try:
                data = os.read(src, 4096)
            except OSError:
                time.sleep(0.01)  # the slave is not open (yet): nothing to relay
                continue
            now = time.monotonic()
            free_at = max(free_at, now) + len(data) * byte_s
            if free_at > now:
                time.sleep(free_at - now)  # the last byte leaves the line at free_at
            try:
                os.write(dst, data)
            except OSError:
                continue
            self.bytes[k] += len(data)

    def elapsed_s(self) -> float:
        return time.monotonic() - self.started

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        for fd in self._fds:
            try:
                os.close(fd)
            except OSError:
                pass

    def __enter__(self) -> NullModem:
        return self

    def __exit__(self, et: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None) -> None:
        self.close()


class NullModemProcess:
    """A NullModem in a process of its own (`navig8-nullmodem`), as a line is to the programs at its ends: its relay
    never waits for the caller's interpreter (a test client's garbage collection or MAVLink parsing held the relay
    threads of an in-process NullModem for tens of ms: the line went silent and a real-time hover swayed). Same
    `paths`, `bytes` (known once closed) and `elapsed_s()`."""

    def __init__(self, baud: int = 921600, timeout_s: float = 30.0) -> None:
        self.baud = baud
        self.bytes = [0, 0]
        self.started = time.monotonic()
        self._proc = subprocess.Popen([sys.executable, "-m", "navig8_tools.nullmodem", "--baud", str(baud)],
                                      stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True)
        r, _, _ = select.select([self._proc.stdout], [], [], timeout_s)
        line = self._proc.stdout.readline() if r else ""
        if " <-> " not in line:
            self._proc.kill()
            self._proc.wait(timeout=10)
            raise RuntimeError(f"navig8-nullmodem did not start within {timeout_s:g} s: {line!r}")
        p1, rest = line.split(" <-> ", 1)
        self.paths = (p1, rest.split(" ", 1)[0])
        self._ended: float | None = None

    def elapsed_s(self) -> float:
        return (self._ended or time.monotonic()) - self.started

    def close(self) -> None:
        if self._proc.poll() is None:
            self._proc.send_signal(signal.SIGTERM)
        try:
            _, err = self._proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            _, err = self._proc.communicate(timeout=10)
        self._ended = self._ended or time.monotonic()
        for ln in err.splitlines():
            if ln.startswith("relayed "):  # "relayed N B one way, M B back"
                f = ln.split()
                self.bytes = [int(f[1]), int(f[5])]

    def __enter__(self) -> NullModemProcess:
        return self

    def __exit__(self, et: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None) -> None:
        self.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="navig8-nullmodem", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baud", type=int, default=921600)
    a = ap.parse_args(argv)
    nm = NullModem(a.baud)
    print(f"{nm.paths[0]} <-> {nm.paths[1]} at {a.baud} baud (Ctrl-C ends)", flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    while not stop.wait(1.0):
        pass
    nm.close()
    print(f"relayed {nm.bytes[0]} B one way, {nm.bytes[1]} B back", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
