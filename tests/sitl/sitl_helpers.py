"""Start navig8-fc and navig8-bridge as real processes on loopback; a pymavlink GCS client.

The processes bind port 0 (a port the kernel picks, so no test races another for a port number) and report the
ports they got in a --ports-file (`wait_ports_file`). The bridge starts first; the FC is given the bridge's port
and announces itself, so the bridge learns the FC's address (it runs with --fc-port 0). Every wait is bounded;
`SitlRun.stop()` (called by the context manager) always ends both processes.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

PORTS_FILE_TIMEOUT_S = 60.0  # a first start may generate the dialect and compile numba kernels


def wait_ports_file(path: Path, proc: subprocess.Popen, timeout_s: float = PORTS_FILE_TIMEOUT_S) -> dict[str, int]:
    """The ports a child wrote to its --ports-file (written atomically after binding), waiting at most timeout_s;
    fails at once, with the child's output, if the child exits first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if path.is_file():
            return {k: int(v) for k, v in json.loads(path.read_text()).items()}
        if proc.poll() is not None:
            out = proc.stdout.read() if proc.stdout is not None else ""
            raise AssertionError(f"process exited ({proc.returncode}) before writing {path}: {out}")
        time.sleep(0.02)
    raise AssertionError(f"no ports file {path} within {timeout_s} s")


def free_udp_ports(n: int) -> list[int]:
    """Port numbers free right now (for sockets a test binds itself later: racy, so only where a child must be told
    a number in advance, like where the test's GCS listens)."""
    socks = []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(("127.0.0.1", 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


@dataclass
class SitlRun:
    fc: subprocess.Popen
    bridge: subprocess.Popen | None
    gcs_port: int  # where the FC sends GCS traffic (the test's GCS listens here)
    api_port: int
    gcs_bind_port: int  # the FC's GCS socket
    log: Path
    state_dir: Path
    extra: dict[str, Any] = field(default_factory=dict)
    ports: dict[str, int] = field(default_factory=dict)  # what the processes bound: sim, gcs, api (FC), bridge

    def stop(self, timeout_s: float = 10.0) -> tuple[int | None, int | None]:
        codes: list[int | None] = []
        for p in (self.bridge, self.fc):
            if p is None:
                codes.append(None)
                continue
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
                try:
                    p.wait(timeout=timeout_s)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait(timeout=timeout_s)
            codes.append(p.returncode)
            if p.stdout is not None:
                p.stdout.close()
        return codes[1], codes[0]


@contextmanager
def sitl(tmp: Path, scenario: str = "ground", speed: float = 1.0, fc_args: list[str] | None = None,
         bridge_args: list[str] | None = None, state_dir: Path | None = None, start_bridge: bool = True,
         log_name: str = "run.mcap") -> Iterator[SitlRun]:
    gcs, api = free_udp_ports(2)  # where the test's GCS / API clients will listen (the FC sends there)
    log = tmp / log_name
    state = state_dir or (tmp / "state")
    ports: dict[str, int] = {}
    br = None
    fc = None
    try:
        if start_bridge:
            br_ports = tmp / f"{log_name}.bridge-ports.json"
            br_cmd = [sys.executable, "-m", "sim_bridge.bridge", "--scenario", scenario, "--speed", str(speed),
                      "--bridge-port", "0", "--fc-port", "0", "--ports-file", str(br_ports), *(bridge_args or [])]
            br = subprocess.Popen(br_cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, cwd=tmp)
            ports.update(wait_ports_file(br_ports, br))
        else:
            (ports["bridge"],) = free_udp_ports(1)  # nobody there: the FC waits for bundles
        fc_ports = tmp / f"{log_name}.fc-ports.json"
        fc_cmd = [sys.executable, "-m", "navig8_fc.shell.fc_process", "--scenario", scenario, "--sim-port", "0",
                  "--bridge-port", str(ports["bridge"]), "--gcs-port", str(gcs), "--gcs-bind-port", "0",
                  "--api-port", str(api), "--api-bind-port", "0", "--log", str(log), "--state-dir", str(state),
                  "--ports-file", str(fc_ports), *(fc_args or [])]
        fc = subprocess.Popen(fc_cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              cwd=tmp)
        run = SitlRun(fc, br, gcs, api, 0, log, state, ports=ports)
    except BaseException:
        for p in (br, fc):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait(timeout=10)
        raise
    try:
        ports.update(wait_ports_file(fc_ports, fc))
        run.gcs_bind_port = ports["gcs"]
        yield run
    finally:
        run.stop()


def gcs_client(port: int, source_system: int = 255) -> Any:
    """A pymavlink GCS listening where the FC sends (like QGroundControl on 14550)."""
    return mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=source_system,
                                      source_component=190, dialect="common")


def wait_for(conn: Any, msg_type: str | list[str], timeout_s: float,
             cond: Callable[[Any], bool] | None = None) -> Any | None:
    """The next message of that type (and matching cond) within timeout_s, else None."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        m = conn.recv_match(type=msg_type, blocking=True, timeout=max(0.01, deadline - time.monotonic()))
        if m is None:
            continue
        if cond is None or cond(m):
            return m
    return None


def wait_heartbeat(conn: Any, timeout_s: float = 10.0) -> Any:
    hb = wait_for(conn, "HEARTBEAT", timeout_s, lambda m: m.get_srcComponent() == 1)
    assert hb is not None, "no HEARTBEAT from the FC (compid 1)"
    conn.target_system, conn.target_component = hb.get_srcSystem(), 1
    return hb
