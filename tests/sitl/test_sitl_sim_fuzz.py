"""The sim link under attack, with real processes on loopback: navig8-sitl flies the hover
scenario with --until-done while this test, from sockets of its own, sends the FC's sim port forged bundles (NaN,
Inf, 1e6, every next-step stamp of the run, another vehicle's replayed steps), fragments of bundles, a forged
NAVIG8_SIM_STATUS "done", and HEARTBEAT floods from 16 sockets; and sends the bridge forged answers and a pairing.
A second navig8-fc on the same instance is refused. The vehicle must hold its hover (max position error from the
log's truth), the run end only at its real end, the bridge never stall, and each kind be counted and reported.
A second test: navig8-sitl's exit codes (Ctrl-C to the whole process group early in the start: 0; the bridge
killed: non-zero) and no orphans after a kill -9 of navig8-sitl."""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from sitl_helpers import free_udp_ports, gcs_client, kernel_udp_drops, start_process, wait_for, wait_heartbeat

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.links.sim_guard import pairing_heartbeat
from navig8_fc.mavlink import codec, dialect, seam
from navig8_fc.shell.mcap_log import read_mcap, read_metadata
from sim_bridge.params import PlantParams
from sim_bridge.plant import Plant
from sim_bridge.scenario import load_scenario

INSTANCE = 13
HOVER_BOUND_M = 0.1  # the hover's own max position error is ~0.035 m; forged data moved it 6.36 m on an unguarded link


def _sitl(tmp: Path, instance: int, scenario: str, gcs_port: int, *extra: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "navig8_fc.shell.sitl", "--scenario", scenario, "--speed", "1", "--instance",
           str(instance), "--log-dir", str(tmp / "logs"), "--state-dir", str(tmp / "state"), "--defaults",
           f"--fc-arg=--gcs-port={gcs_port}", f"--fc-arg=--api-port={gcs_port}", *extra]
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)  # no-op when the whole group already exited
    except ProcessLookupError:
        pass
    if proc.poll() is None:
        proc.wait(timeout=10)


def _forged_bundles(sysid: int, seed: int, n: int, mutate=None) -> list[bytes]:
    """n consecutive step datagrams of a plant of our own (the bridge's encoder and ids)."""
    plant = Plant(VehicleConfig.load(), PlantParams.load(), load_scenario("hover"), np.random.default_rng(seed))
    enc = codec.Encoder(codec.seam_codec(), sysid, dialect.COMPID_BRIDGE)
    cmd = plant.trim_command()
    out = []
    for k in range(n):
        sw = plant.sense_wire()
        if mutate is not None:
            mutate(sw)
        out.append(seam.encode_bundle(enc, k, sw, plant.truth_floats()))
        plant.step_us(cmd, 10_000)
    return out


def _forged_traffic(sysid: int) -> tuple[list[bytes], bytes, list[bytes]]:
    """The forged datagrams for the FC's sim port and for the bridge, built before the flight: building them (2,000
    plant steps and 1,500 answers in this process) inside the 10 s hover would leave the attack less of it."""
    # forged steps: 1e6 at every stamp of the first 15 s (the next step of the run among them), NaN, Inf,
    # and another vehicle's run replayed from t = 0
    bad = [*_forged_bundles(sysid, 7, 1500, lambda sw: sw.pos_ned_m.__setitem__(2, 1e6)),
           *_forged_bundles(sysid, 8, 100, lambda sw: sw.joint_pos_rad.__setitem__(0, math.nan)),
           *_forged_bundles(sysid, 9, 100, lambda sw: sw.gyro_frd_rad_s.__setitem__(1, math.inf)),
           *_forged_bundles(sysid, 10, 300)]
    # the bridge: a pairing and full-throttle answers for every stamp of the first 15 s, from a stranger
    fc_enc = codec.Encoder(codec.seam_codec(), sysid, dialect.COMPID_FC)
    pairing = fc_enc.frame(*pairing_heartbeat(1234))
    veh = VehicleConfig.load()
    full = seam.ActuatorControls(0, (0.0, 0.0), (950.0, 0.0, 950.0), True)
    answers = [seam.pack_actuator_controls(fc_enc, k * 10_000 + 1, full, veh, armed=True) for k in range(1500)]
    return bad, pairing, answers


def _attack(sim: tuple[str, int], bridge: tuple[str, int], sysid: int, bad: list[bytes], pairing: bytes,
            answers: list[bytes]) -> dict[str, int]:
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(17)]
    sent = {"heartbeats": 0, "forged": 0, "fragments": 0, "to_bridge": 0}
    try:
        attacker = socks[16]
        br_enc = codec.Encoder(codec.seam_codec(), sysid, dialect.COMPID_BRIDGE)
        gcs_enc = codec.Encoder(codec.seam_codec(), 255, 190)
        # 16 sockets: pair requests with the bridge's ids, and GCS heartbeats (the old 8-entry peer table)
        for _ in range(40):
            for s in socks[:16]:
                s.sendto(br_enc.frame(*pairing_heartbeat(0)), sim)
                s.sendto(gcs_enc.frame(*seam.announce_record()), sim)
                sent["heartbeats"] += 2
        for i, data in enumerate(bad):  # forged steps (_forged_traffic)
            attacker.sendto(data, sim)
            sent["forged"] += 1
            frames, _, _ = codec.split_frames(data)
            if i % 5 == 0:  # fragments: the parts in separate datagrams, and with garbage between them
                for fr in frames:
                    attacker.sendto(fr, sim)
                attacker.sendto(b"\xfd\x30garbage" + frames[0] + frames[-1], sim)
                sent["fragments"] += len(frames) + 1
            if i % 100 == 0:
                time.sleep(0.01)  # spread over the flight, not one burst
        done = seam.SimStatus(1, 0, seam.SIM_STATE_DONE, 0.0, 1.0, 0)
        for _ in range(3):
            attacker.sendto(br_enc.frame(*seam.encode_sim_status(done)), sim)
        # the bridge: full-throttle answers for every stamp of the first 15 s and a pairing, from a stranger
        attacker.sendto(pairing, bridge)
        for data in answers:
            attacker.sendto(data, bridge)
            sent["to_bridge"] += 1
    finally:
        for s in socks:
            s.close()
    return sent


def test_forged_sim_traffic_neither_crashes_nor_steers_the_vehicle(tmp_path: Path) -> None:
    (gcs_port,) = free_udp_ports(1)
    sysid = INSTANCE + 1
    bad, pairing, answers = _forged_traffic(sysid)
    proc = _sitl(tmp_path, INSTANCE, "hover", gcs_port, "--until-done")
    gcs = gcs_client(gcs_port)
    try:
        assert wait_heartbeat(gcs, 60.0).get_srcSystem() == sysid
        lp = wait_for(gcs, "LOCAL_POSITION_NED", 10.0)
        assert lp is not None and abs(lp.z + 2.0) < 0.2, lp
        sim_port, bridge_port = 4561 + 2 * INSTANCE, 4560 + 2 * INSTANCE
        sent = _attack(("127.0.0.1", sim_port), ("127.0.0.1", bridge_port), sysid, bad, pairing,
                       answers)
        # a second FC on the same instance: a clear error, and the first keeps flying
        second = start_process("navig8_fc.shell.fc_process", ["--instance", str(INSTANCE), "--defaults",
                                                              "--state-dir", str(tmp_path / "state2")], tmp_path,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            _, second_err = second.communicate(timeout=120)
        finally:
            if second.poll() is None:
                second.kill()
                second.wait(timeout=10)
        assert second.returncode == 2 and "is in use by another process" in second_err, second_err
        assert "Traceback" not in second_err
        assert proc.poll() is None, "the forged done (or anything else) ended the run early"
        lp = wait_for(gcs, "LOCAL_POSITION_NED", 10.0)
        assert lp is not None and abs(lp.z + 2.0) < 0.2, lp
        # a flood overruns a receive buffer (net.core.rmem_max caps SO_RCVBUF): what the kernel dropped nobody counts
        fc_drops, bridge_drops = kernel_udp_drops(sim_port), kernel_udp_drops(bridge_port)
        assert fc_drops is not None and bridge_drops is not None, "no socket on the sim ports"
        out, err = proc.communicate(timeout=120)
    finally:
        gcs.close()
        _kill_group(proc)
    assert proc.returncode == 0, err[-3000:]
    summary = json.loads(out)
    assert summary["sim_time_s"] >= 9.99 and not summary["lost_control"], summary
    assert summary["max_pos_error_m"] < HOVER_BOUND_M, summary  # from the log's truth: the plant never moved
    bridge_line = next(ln for ln in err.splitlines() if ln.startswith("navig8-bridge: 1000 steps"))
    counts = dict(kv.rsplit(" ", 1) for kv in bridge_line.split("; ", 1)[1].split(", "))
    # never stalled (a dropped bundle is re-sent within 0.1 s), never re-paired
    assert counts["stalls"] == "0" and counts["sessions"] == "1", bridge_line
    assert int(counts["wrong_sender"]) + bridge_drops >= sent["to_bridge"], (bridge_line, bridge_drops)
    assert int(counts["wrong_sender"]) > 0 and counts["pair_refused"] == "1", bridge_line
    log = Path(summary["log"])
    guard = read_metadata(log)["fc_stats"]["sim_guard"]
    assert guard["sessions"] == 1 and guard["tick_errors"] == 0 and guard["log_errors"] == 0, guard
    # every kind counted; what was sent is counted or was dropped by the kernel before anyone read it
    assert min(guard["wrong_sender"], guard["pair_refused"], guard["malformed"]) > 0, guard
    assert guard["wrong_sender"] + fc_drops >= sent["forged"] + sent["heartbeats"] // 2, (guard, fc_drops)
    assert guard["pair_refused"] + fc_drops >= sent["heartbeats"] // 2, (guard, fc_drops)
    assert guard["malformed"] + fc_drops >= sent["fragments"] // 2, (guard, fc_drops)
    assert guard["invalid"] == 0 and guard["out_of_order"] == 0, guard  # the paired bridge itself sent no bad step
    texts = [d["text"] for _t, _n, d in read_mcap(log, topics=["/fc/statustext"])]
    for part in ("Sim link paired", "Sim link: dropped", "Sim link: pairing refused", "Sim link: partial bundle"):
        assert any(part in t for t in texts), (part, texts)
    assert len([t for t in texts if t.startswith("Sim link")]) < 20, texts  # a flood is not a STATUSTEXT flood


def _children(pid: int) -> list[int]:
    """The processes whose parent is pid and that have started their program (exec done)."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat, cmd = (d / "stat").read_text(), (d / "cmdline").read_bytes()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid and (b"fc_process" in cmd or b"sim_bridge" in cmd):
                out.append(int(d.name))
    return out


def test_sitl_exit_codes(tmp_path: Path) -> None:
    """Ctrl-C in a terminal reaches the whole process group, while the FC may still be starting: exit 0. A child
    that dies (the bridge killed) ends navig8-sitl with a non-zero code and a line naming it."""
    (gcs_port,) = free_udp_ports(1)
    proc = _sitl(tmp_path, INSTANCE + 1, "ground", gcs_port)
    try:
        deadline = time.monotonic() + 30.0
        while len(_children(proc.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        _kill_group(proc)
    assert proc.returncode == 0, err[-3000:]
    assert "Traceback" not in err, err[-3000:]
    proc = _sitl(tmp_path, INSTANCE + 1, "ground", gcs_port)
    gcs = gcs_client(gcs_port)
    try:
        wait_heartbeat(gcs, 60.0)
        (bridge,) = [p for p in _children(proc.pid) if "sim_bridge" in Path(f"/proc/{p}/cmdline").read_text()]
        os.kill(bridge, signal.SIGKILL)
        _, err = proc.communicate(timeout=60)
    finally:
        gcs.close()
        _kill_group(proc)
    assert proc.returncode == 128 + signal.SIGKILL, err[-3000:]
    assert "navig8-bridge ended by itself (exit -9)" in err
    # navig8-sitl itself killed: its children do not live on (they get SIGTERM when their parent dies)
    proc = _sitl(tmp_path, INSTANCE + 1, "ground", gcs_port)
    try:
        deadline = time.monotonic() + 30.0
        while len(kids := _children(proc.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        proc.kill()
        proc.wait(timeout=10)
        deadline = time.monotonic() + 30.0
        while any(Path(f"/proc/{k}").exists() for k in kids) and time.monotonic() < deadline:
            time.sleep(0.1)
        alive = {k: Path(f"/proc/{k}/stat").read_text() for k in kids if Path(f"/proc/{k}").exists()}
        assert len(kids) == 2 and not alive, alive
    finally:
        _kill_group(proc)
