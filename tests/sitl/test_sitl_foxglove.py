"""Foxglove from the flight controller (docs/foxglove.md): the SITL log's foxglove.* channels validate against
Foxglove's published JSON schemas and its transforms match the arm kinematics (1e-6 m); `navig8-sitl --foxglove`
streams the same channels live to a WebSocket client speaking Foxglove's protocol."""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sitl_helpers import free_udp_ports, sitl, wait_ports_file
from websockets.sync.client import connect

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "unit"))  # the oracles beside the unit tests

from foxglove_oracle import check_log, read_log, validate  # noqa: E402

from navig8_fc.core.vehicle import VehicleConfig  # noqa: E402


def test_sitl_log_foxglove_channels_validate_and_transforms_match_kinematics(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="paper", speed=0.0, fc_args=["--until-done"],
              bridge_args=["--until-done", "--duration", "2"]) as run:
        assert run.fc.wait(timeout=120) == 0
    counts = check_log(run.log, VehicleConfig.load(), {"/foxglove/tf": 18, "/foxglove/scene": 9,
                                                        "/foxglove/path": 4, "/foxglove/mission": 4})
    assert counts["/foxglove/tf"] <= 22  # 10 Hz of sim time, not every control step
    _, msgs = read_log(run.log)
    texts = [rec["text"] for topic, _t, rec in msgs if topic == "/fc/statustext"]
    logged = [rec["message"] for topic, _t, rec in msgs if topic == "/foxglove/log"]
    assert texts and all(t in logged for t in texts), (texts, logged)  # every STATUSTEXT as a foxglove.Log


FOXGLOVE_SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk's server speaks (Foxglove app >= 2.x)
MESSAGE_DATA = 0x01  # binary opcode: u8 op, u32 subscription id, u64 log time (ns), payload


def _instance_ports_free(n: int) -> bool:
    for port in (4560 + 2 * n, 4561 + 2 * n, 18570 + n, 14580 + n):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
        finally:
            s.close()
    return True


def test_navig8_sitl_foxglove_streams_transforms_live(tmp_path: Path) -> None:
    instance = 14  # navig8-sitl's own ports are per instance (test_sitl_launcher uses 11, 12)
    assert _instance_ports_free(instance)
    (gcs,) = free_udp_ports(1)
    ports_file = tmp_path / "fc-ports.json"
    cmd = [sys.executable, "-m", "navig8_fc.shell.sitl", "--scenario", "hover", "--speed", "1", "--instance",
           str(instance), "--log-dir", str(tmp_path / "logs"), "--state-dir", str(tmp_path / "state"), "--defaults",
           "--foxglove", "0", f"--fc-arg=--gcs-port={gcs}", f"--fc-arg=--ports-file={ports_file}"]
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        port = wait_ports_file(ports_file, proc)["foxglove"]
        assert port > 0
        with connect(f"ws://127.0.0.1:{port}", subprotocols=[FOXGLOVE_SUBPROTOCOL], open_timeout=10) as ws:
            assert ws.subprotocol == FOXGLOVE_SUBPROTOCOL
            channels: dict[str, dict] = {}
            deadline = time.monotonic() + 10.0
            while "/foxglove/tf" not in channels and time.monotonic() < deadline:
                msg = ws.recv(timeout=max(deadline - time.monotonic(), 0.01))
                if isinstance(msg, str):
                    m = json.loads(msg)
                    if m["op"] == "advertise":
                        channels.update({c["topic"]: c for c in m["channels"]})
            tf = channels["/foxglove/tf"]
            assert (tf["schemaName"], tf["encoding"]) == ("foxglove.FrameTransforms", "json")
            assert {"/foxglove/scene", "/foxglove/path", "/foxglove/log"} <= set(channels)
            assert channels["/foxglove/scene"]["schemaName"] == "foxglove.SceneUpdate"
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": tf["id"]}]}))
            log_times, records = [], []
            t_first = None
            deadline = time.monotonic() + 15.0
            while len(log_times) < 50 and time.monotonic() < deadline:
                msg = ws.recv(timeout=max(deadline - time.monotonic(), 0.01))
                if isinstance(msg, bytes) and msg[0] == MESSAGE_DATA:
                    sub_id, t_ns = struct.unpack_from("<IQ", msg, 1)
                    assert sub_id == 7
                    if t_first is None:
                        t_first = time.monotonic()
                    log_times.append(t_ns)
                    records.append(json.loads(msg[13:]))
            wall = time.monotonic() - t_first
        assert len(log_times) == 50, len(log_times)
        # 10 Hz of sim time, every record on the 100 ms grid, none skipped; at --speed 1 that is 10 Hz of wall time
        steps = {b - a for a, b in zip(log_times, log_times[1:], strict=False)}
        assert steps == {100_000_000}, steps
        assert 49 / wall == pytest.approx(10.0, rel=0.25), 49 / wall
        for rec in records[:: 10]:
            validate("foxglove.FrameTransforms", rec)
            frames = {t["child_frame_id"] for t in rec["transforms"]}
            assert {"base_link", "gripper", "est/base_link", "est/gripper"} <= frames
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)
    assert proc.returncode == 0, proc.stderr.read()[-2000:] if proc.stderr else ""


def test_busy_foxglove_port_is_refused_with_a_clear_error(tmp_path: Path) -> None:
    from navig8_fc.shell.foxglove_out import LiveServer

    holder = LiveServer("127.0.0.1", 0, "holder")  # the port is taken
    port = holder.port
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "navig8_fc.shell.fc_process", "--sim-port", "0", "--gcs-bind-port", "0",
             "--api-bind-port", "0", f"--foxglove={port}"],
            stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60, cwd=tmp_path)
    finally:
        holder.close()
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert f"Foxglove WebSocket port {port}" in proc.stderr and "--foxglove=PORT" in proc.stderr
