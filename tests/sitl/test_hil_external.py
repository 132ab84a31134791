"""Issue 12 must-show: the interop tests pass when pointed, through connection strings, at a pair started outside
pytest. This test starts navig8-bridge and navig8-fc itself (the FC's GCS link as tcpin: on a free port, as a
companion computer would serve it), then runs `pytest tests/sitl/test_hil_interop.py --fc-gcs=tcp:... --fc-api=
udpin:... --bridge=...` as a separate process: everything but the local-log check must pass."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from sitl_helpers import free_udp_ports, wait_ports_file

ROOT = Path(__file__).resolve().parents[2]


def test_interop_suite_against_a_pair_started_outside_pytest(tmp_path: Path) -> None:
    (api,) = free_udp_ports(1)
    br_ports, fc_ports = tmp_path / "br.json", tmp_path / "fc.json"
    procs: list[subprocess.Popen] = []
    try:
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "sim_bridge.bridge", "--scenario", "ground", "--speed", "1", "--link",
             "tcpin:127.0.0.1:0", "--ports-file", str(br_ports)],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path))
        bridge = wait_ports_file(br_ports, procs[0])["bridge"]
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "navig8_fc.shell.fc_process", "--scenario", "ground", "--sim-link",
             f"tcp:127.0.0.1:{bridge}", "--gcs-link", "tcpin:127.0.0.1:0", "--api-port", str(api),
             "--api-bind-port", "0", "--state-dir", str(tmp_path / "state"), "--ports-file", str(fc_ports)],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path))
        gcs = wait_ports_file(fc_ports, procs[1])["gcs"]
        inner = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/sitl/test_hil_interop.py",
             f"--fc-gcs=tcp:127.0.0.1:{gcs}", f"--fc-api=udpin:127.0.0.1:{api}",
             f"--bridge=tcpin:127.0.0.1:{bridge}"],
            cwd=ROOT, capture_output=True, text=True, timeout=240)
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
            p.wait(timeout=20)
    tail = inner.stdout[-3000:]
    assert inner.returncode == 0, tail
    assert re.search(r"\b6 passed, 1 skipped\b", tail), tail
    assert "its log is not here" in tail, tail
