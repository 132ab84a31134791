"""Ports as real processes see them: port 0 everywhere with the ports files, end to end (the bridge learns the FC's
address from its announcement), and a busy port refused with a clear error (no SO_REUSEADDR: a second FC cannot
share the first one's port and take its datagrams)."""

from __future__ import annotations

import time
from pathlib import Path

from sitl_helpers import Proc, gcs_client, sitl, start_process, wait_heartbeat, wait_ports_file

from navig8_fc.shell.mcap_log import read_mcap


def _fc(tmp: Path, *args: str) -> Proc:
    return start_process("navig8_fc.shell.fc_process", ["--state-dir", str(tmp / "state"), "--defaults", *args], tmp,
                         text=True)


def test_two_fcs_cannot_share_a_port(tmp_path: Path) -> None:
    first = _fc(tmp_path, "--sim-port", "0", "--gcs-bind-port", "0", "--api-bind-port", "0", "--ports-file",
                str(tmp_path / "a.json"))
    try:
        ports = wait_ports_file(tmp_path / "a.json", first)
        assert set(ports) == {"sim", "gcs", "api"} and all(p > 0 for p in ports.values())
        for option, name in (("--sim-port", "sim"), ("--gcs-bind-port", "gcs"), ("--api-bind-port", "api")):
            zeros = {"--sim-port": "0", "--gcs-bind-port": "0", "--api-bind-port": "0", option: str(ports[name])}
            second = _fc(tmp_path, *[x for kv in zeros.items() for x in kv])
            out, _ = second.communicate(timeout=120)
            assert second.returncode == 2, out
            assert f"127.0.0.1:{ports[name]} is in use" in out and option in out, out
            assert "Traceback" not in out, out
        assert first.poll() is None  # the first FC is untouched
    finally:
        first.terminate()
        first.wait(timeout=20)


def test_port_zero_end_to_end(tmp_path: Path) -> None:
    """Bridge and FC on kernel-chosen ports: bundles flow (the bridge learnt the FC's port from its announcement),
    a GCS sees the FC, and both exit cleanly at the end of the run."""
    with sitl(tmp_path, scenario="hover", speed=0.0, bridge_args=["--until-done", "--duration", "2"],
              fc_args=["--until-done", "--defaults"]) as run:
        assert set(run.ports) == {"bridge", "sim", "gcs", "api"}
        assert len(set(run.ports.values())) == 4 and run.gcs_bind_port == run.ports["gcs"]
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, timeout_s=30.0)
        finally:
            gcs.close()
        deadline = time.monotonic() + 120.0
        while run.fc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert run.fc.returncode == 0 and run.bridge is not None and run.bridge.wait(timeout=30) == 0
        out = run.bridge.stdout.read().decode()
    assert "FC at (port unknown until it announces itself)" in out
    assert "200 steps" in out, out
    steps = [rec["time_usec"] for _, _, rec in read_mcap(run.log, ["/mavlink/sim/in/HIL_SENSOR"])]
    assert len(steps) == 201 and steps[-1] == 2_000_001


def test_bridge_started_after_the_fc_finds_it(tmp_path: Path) -> None:
    """The FC comes up first and keeps announcing itself on the sim link (once a second until bundles flow); a
    bridge started later with --fc-port 0 learns the FC's address from that announcement and the run completes."""
    from sitl_helpers import free_udp_ports

    (bridge_port,) = free_udp_ports(1)
    fc = _fc(tmp_path, "--sim-port", "0", "--gcs-bind-port", "0", "--api-bind-port", "0", "--bridge-port",
             str(bridge_port), "--scenario", "hover", "--until-done", "--ports-file", str(tmp_path / "fc.json"))
    bridge = None
    try:
        wait_ports_file(tmp_path / "fc.json", fc)  # the FC is up (its first announcement already went nowhere)
        bridge = start_process("sim_bridge.bridge", ["--scenario", "hover", "--speed", "0", "--bridge-port",
                                                     str(bridge_port), "--fc-port", "0", "--until-done", "--duration",
                                                     "1"], tmp_path, text=True)
        out, _ = bridge.communicate(timeout=120)
        assert bridge.returncode == 0, out
        assert "100 steps" in out, out
        assert fc.wait(timeout=60) == 0
    finally:
        for p in (bridge, fc):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait(timeout=20)
