"""Start navig8-fc and navig8-bridge as real processes on free loopback ports; a pymavlink GCS client.

Every wait is bounded; `SitlRun.stop()` (called by the context manager) always ends both processes.
"""

from __future__ import annotations

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


def free_udp_ports(n: int) -> list[int]:
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
    sim, bridge, gcs, gcs_bind, api, api_bind = free_udp_ports(6)
    log = tmp / log_name
    state = state_dir or (tmp / "state")
    fc_cmd = [sys.executable, "-m", "navig8_fc.shell.fc_process", "--scenario", scenario, "--sim-port", str(sim),
              "--bridge-port", str(bridge), "--gcs-port", str(gcs), "--gcs-bind-port", str(gcs_bind),
              "--api-port", str(api), "--api-bind-port", str(api_bind), "--log", str(log),
              "--state-dir", str(state), *(fc_args or [])]
    fc = subprocess.Popen(fc_cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          cwd=tmp)
    br = None
    run = SitlRun(fc, None, gcs, api, gcs_bind, log, state)
    try:
        if start_bridge:
            time.sleep(0.3)
            br_cmd = [sys.executable, "-m", "sim_bridge.bridge", "--scenario", scenario, "--speed", str(speed),
                      "--bridge-port", str(bridge), "--fc-port", str(sim), *(bridge_args or [])]
            br = subprocess.Popen(br_cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, cwd=tmp)
            run.bridge = br
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
