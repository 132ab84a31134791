"""navig8-sitl as a user runs it: two vehicles side by side with --instance (sysid N+1, ports offset), each
stopped by a signal (SIGINT, SIGTERM) that it forwards to both of its processes, which stop cleanly and free
their ports; it prints where the log is."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from sitl_helpers import free_udp_ports, gcs_client, wait_for, wait_heartbeat

INSTANCES = (11, 12)


def _port_free(port: int) -> bool:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.bind(("127.0.0.1", port))
        return True
    except OSError:
        return False
    finally:
        s.close()


def _instance_ports(n: int) -> list[int]:
    """The UDP ports instance n binds: bridge 4560+2n, FC sim link 4561+2n, GCS link 18570+n, API link 14580+n."""
    return [4560 + 2 * n, 4561 + 2 * n, 18570 + n, 14580 + n]


def test_two_instances_side_by_side_stop_cleanly_on_signals(tmp_path: Path) -> None:
    gcs_ports = free_udp_ports(len(INSTANCES))
    procs: list[subprocess.Popen] = []
    clients = []
    try:
        for n, port in zip(INSTANCES, gcs_ports, strict=True):
            cmd = [sys.executable, "-m", "navig8_fc.shell.sitl", "--scenario", "hover", "--speed", "1",
                   "--instance", str(n), "--log-dir", str(tmp_path / f"logs{n}"), "--state-dir",
                   str(tmp_path / f"state{n}"), "--defaults", f"--fc-arg=--gcs-port={port}"]
            # its own process group, so a failed test can still kill the children navig8-sitl started
            procs.append(subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                          stderr=subprocess.PIPE, text=True, start_new_session=True))
            clients.append(gcs_client(port))
        for n, gcs in zip(INSTANCES, clients, strict=True):
            hb = wait_heartbeat(gcs, 30.0)
            assert hb.get_srcSystem() == n + 1  # sysid N+1, each vehicle on its own GCS port
            # the vehicle is flying its scenario (the bridge of this instance is stepping it)
            lp = wait_for(gcs, "LOCAL_POSITION_NED", 10.0)
            assert lp is not None and abs(lp.z + 2.0) < 0.5, lp
        for n in INSTANCES:
            assert not any(_port_free(p) for p in _instance_ports(n)), f"instance {n} is not bound where expected"
        for proc, sig in zip(procs, (signal.SIGINT, signal.SIGTERM), strict=True):
            proc.send_signal(sig)
        for n, proc in zip(INSTANCES, procs, strict=True):
            _, err = proc.communicate(timeout=30)
            assert proc.returncode == 0, err[-2000:]
            log_lines = [ln for ln in err.splitlines() if ln.startswith("navig8-sitl: log ")]
            assert log_lines, err[-2000:]
            log = Path(log_lines[-1].removeprefix("navig8-sitl: log "))
            assert log.is_file() and log.stat().st_size > 10_000 and log.parent == tmp_path / f"logs{n}"
            # both child processes are gone: their ports are free again
            deadline = time.monotonic() + 10.0
            while not all(_port_free(p) for p in _instance_ports(n)) and time.monotonic() < deadline:
                time.sleep(0.1)
            assert all(_port_free(p) for p in _instance_ports(n)), f"instance {n} left a process behind"
    finally:
        for gcs in clients:
            gcs.close()
        for proc in procs:
            try:
                os.killpg(proc.pid, signal.SIGKILL)  # no-op when all of the group already exited
            except ProcessLookupError:
                pass
            if proc.poll() is None:
                proc.wait(timeout=10)
