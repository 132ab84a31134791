"""A full log disk and a read-only log directory, for real: navig8-sitl runs inside a user and
mount namespace (`unshare -rm`, no root needed) whose log directory is a 256 KiB tmpfs (the disk fills within the
first second of flight: ENOSPC from the kernel) or a read-only tmpfs (EROFS at start). The vehicle must keep flying
to the end of the run (every step answered, hovering at 2 m on the GCS's telemetry) and the condition be reported
(STATUSTEXT to the GCS, a line on stderr)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from sitl_helpers import free_udp_ports, gcs_client, wait_for

INSTANCES = {"full": 16, "readonly": 17}


def _unshare_works() -> bool:
    if shutil.which("unshare") is None:
        return False
    r = subprocess.run(["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"], capture_output=True,
                       timeout=30)
    return r.returncode == 0


pytestmark = pytest.mark.skipif(not _unshare_works(), reason="needs user namespaces (unshare -rm) to mount a tmpfs")


def _texts(gcs, until: str, timeout_s: float) -> list[str]:
    seen: list[str] = []
    wait_for(gcs, "STATUSTEXT", timeout_s, lambda m: seen.append(m.text) is None and until in m.text)
    return seen


def test_full_disk_and_read_only_log_dir_keep_the_vehicle_flying(tmp_path: Path) -> None:
    procs, clients = {}, {}
    for kind, n in INSTANCES.items():
        logs = tmp_path / f"logs_{kind}"
        logs.mkdir()
        (gcs_port,) = free_udp_ports(1)
        opts = "size=256k" if kind == "full" else "ro"
        sitl = [sys.executable, "-m", "navig8_fc.shell.sitl", "--scenario", "hover", "--speed", "2", "--until-done",
                "--duration", "6", "--instance", str(n), "--log-dir", str(logs), "--state-dir",
                str(tmp_path / f"state_{kind}"), "--defaults", f"--fc-arg=--gcs-port={gcs_port}",
                f"--fc-arg=--api-port={gcs_port}"]
        script = f'mount -t tmpfs -o {opts} tmpfs "$0" && exec "$@"'
        procs[kind] = subprocess.Popen(["unshare", "-rm", "sh", "-c", script, str(logs), *sitl],
                                       stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                       text=True)
        clients[kind] = gcs_client(gcs_port)
    try:
        full = _texts(clients["full"], "Log stopped", 60.0)
        assert any("Log stopped: No space left on device" in t for t in full), full
        ro = _texts(clients["readonly"], "Log disabled", 60.0)
        assert any("Log disabled: Read-only file system" in t for t in ro), ro
        for kind, gcs in clients.items():  # after the log failed: still hovering at 2 m
            lp = wait_for(gcs, "LOCAL_POSITION_NED", 10.0)
            assert lp is not None and abs(lp.z + 2.0) < 0.1 and abs(lp.x) < 0.1 and abs(lp.y) < 0.1, (kind, lp)
        results = {kind: p.communicate(timeout=120) for kind, p in procs.items()}
    finally:
        for gcs in clients.values():
            gcs.close()
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait(timeout=10)
    for kind, (_out, err) in results.items():
        # the whole run: the bridge stepped to the end with every step answered, and navig8-sitl says so
        assert "navig8-bridge: 600 steps" in err and "stalls 0," in err, (kind, err[-3000:])
        assert "Traceback" not in err, (kind, err[-3000:])
    out, err = results["full"]
    assert procs["full"].returncode == 0, err[-3000:]
    assert "logging stopped (No space left on device)" in err and "records dropped" in err
    assert json.loads(out)["lost_control"] is False  # the summary of what the full disk kept
    out, err = results["readonly"]
    assert procs["readonly"].returncode == 0, err[-3000:]
    assert "cannot open the log: Read-only file system" in err and "no log was written" in err
