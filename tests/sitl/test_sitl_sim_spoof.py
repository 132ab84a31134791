"""Spoofed source addresses on the sim link steer nothing: a real navig8-fc paired with this test as its bridge (the
bridge's own link code, sim_bridge.fc_link.FcLink, which signs every frame with the session key once paired), and
datagrams sent from a raw socket with the bridge's or the FC's address as their source (what any process with
CAP_NET_RAW can do on the host; skipped with the reason where raw sockets are not permitted).

- lockstep (`--until-done`): before each real bundle, a forged one for the same step from the bridge's address (a
  1 m/s ramp east), and a forged answer from the FC's address to the bridge; halfway, a forged "done". None of them
  may make a step, be taken as the answer, or end the run; the real "done" ends it.
- real time: one forged bundle stamped 1000 s ahead from the bridge's address, and later one from the bridge itself
  (signed): neither may make the FC refuse the real bundles after it as "older" (docs/bridge.md, "Authenticated
  bundles")."""

from __future__ import annotations

import json
import socket
import struct
import time
from pathlib import Path

import pytest
from sitl_helpers import bridge_answer, mcap_metadata, sensors_at_rest, sitl

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.mavlink import codec, dialect, seam
from navig8_fc.shell.mcap_log import read_mcap
from sim_bridge.bridge_options import BridgeOptions
from sim_bridge.fc_link import FcLink

SYSID = 1  # --instance 0
DT_US = 10_000
STEPS = 200
DONE_AT = 100
FIRST_ANSWER_TIMEOUT_S = 60.0  # the FC's first step loads its kernels (more on a loaded host)
ANSWER_TIMEOUT_S = 10.0
FORGED_QUALITY = 99  # ODOMETRY.quality of every forged bundle (the bridge sends 0): how the log tells them apart
FORGED_TILT = 0.77  # controls[0] of every forged answer
LEAP_US = 1_000_000_000  # 1000 s


def _raw_socket() -> socket.socket:
    try:
        return socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_RAW)
    except PermissionError as e:
        pytest.skip(f"sending from another address needs a raw socket (CAP_NET_RAW), not permitted here: {e}")


def _spoof(raw: socket.socket, src: tuple[str, int], dst: tuple[str, int], payload: bytes) -> None:
    """One UDP datagram from src to dst (IPv4 header by hand; the kernel fills the IP checksum; UDP checksum 0)."""
    udp = struct.pack("!HHHH", src[1], dst[1], 8 + len(payload), 0) + payload
    ip = struct.pack("!BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), 0, 0, 64, socket.IPPROTO_UDP, 0,
                     socket.inet_aton(src[0]), socket.inet_aton(dst[0]))
    raw.sendto(ip + udp, (dst[0], 0))


def _forged_bundle(enc: codec.Encoder, step: int, t_sim_us: int) -> bytes:
    """Step `step` of a forger (unsigned: it has no key), marked, the vehicle moving east at 1 m/s."""
    records = seam.bundle_records(step, sensors_at_rest(t_sim_us, (0.0, t_sim_us * 1e-6, 0.0)), None)
    name, values = records[0]
    records[0] = (name, (*values[:-1], FORGED_QUALITY))  # ODOMETRY's last field: quality
    return enc.frames(records)


def _fc_link() -> tuple[FcLink, seam.ControlsScale]:
    limits = seam.ControlsScale.from_vehicle(VehicleConfig.load(None))
    # fc_port 0: the FC's address comes with its announcement (as navig8-bridge --fc-port 0)
    return FcLink(BridgeOptions(bridge_port=0, fc_port=0, free_run=True, speed=1.0), DT_US, limits,
                  lambda _now: None), limits


def _flown_forged(log: Path) -> int:
    return sum(m["quality"] == FORGED_QUALITY for _, _, m in read_mcap(log, ["/mavlink/sim/in/ODOMETRY"]))


def test_spoofed_bridge_and_fc_addresses_steer_nothing_in_lockstep(tmp_path: Path) -> None:
    raw = _raw_socket()
    link, limits = _fc_link()
    forger = codec.Encoder(codec.seam_codec(), SYSID, dialect.COMPID_BRIDGE)
    fake_fc = codec.Encoder(codec.seam_codec(), SYSID, dialect.COMPID_FC)
    forged_answers_taken, answered, exit_code = 0, 0, None
    try:
        with sitl(tmp_path, scenario="ground", start_bridge=False, fc_args=["--until-done"],
                  fc_link_args=["--sim-port", "0", "--bridge-port", str(link.port)]) as run:
            first = seam.encode_bundle(link.mav, 0, sensors_at_rest(0), None)
            assert bridge_answer(link, first, seam.time_usec_from_sim_us(0), FIRST_ANSWER_TIMEOUT_S) is not None
            fc_addr, me = link.fc_addr, ("127.0.0.1", link.port)
            assert fc_addr is not None
            for k in range(1, STEPS + 1):
                t_us = k * DT_US
                want = seam.time_usec_from_sim_us(t_us)
                _spoof(raw, me, fc_addr, _forged_bundle(forger, k, t_us))  # first in the FC's queue
                if k == DONE_AT:
                    status = seam.SimStatus(want, k, seam.SIM_STATE_DONE, 1.0, 1.0, 0)
                    _spoof(raw, me, fc_addr, forger.frame(*seam.encode_sim_status(status)))
                cmd = type(sensors_at_rest(0))(tilt_rad=(FORGED_TILT * limits.tilt_max_abs_rad, 0.0),
                                               speed_rad_s=(0.0, 0.0, 0.0))
                _spoof(raw, fc_addr, me, seam.pack_actuator_controls(fake_fc, want, cmd, limits, armed=True))
                ans = bridge_answer(link, seam.encode_bundle(link.mav, k, sensors_at_rest(t_us), None), want,
                                    ANSWER_TIMEOUT_S)
                if ans is None:
                    break
                answered += 1
                forged_answers_taken += abs(ans.tilt_rad[0] - FORGED_TILT * limits.tilt_max_abs_rad) < 1e-3
            alive_after_forged_done = run.fc.poll() is None
            done = seam.SimStatus(seam.time_usec_from_sim_us(STEPS * DT_US), STEPS, seam.SIM_STATE_DONE, 1.0, 1.0, 0)
            for _ in range(3):
                link.send(link.mav.frame(*seam.encode_sim_status(done)))
            try:
                exit_code = run.fc.wait(timeout=30.0)  # the real "done" ends an --until-done FC
            except Exception:  # noqa: BLE001 - reported by the assertion below
                exit_code = None
            run.stop()
    finally:
        raw.close()
        link.close()
    flown = _flown_forged(run.log)
    stats = mcap_metadata(run.log, "fc_stats")
    guard, ticks = json.loads(stats["sim_guard"]), int(stats["ticks"])
    print(f"\nspoofed sources, lockstep: {flown} steps flown on {STEPS} forged bundles, {forged_answers_taken} forged "
          f"answers taken of {answered}, control steps {ticks} of {STEPS + 1} (a forged done ends them early), "
          f"exit on the real done: {exit_code}; bridge {link.counters.line()}; FC guard {guard}")
    # every real step flown, once: the forged "done" ended nothing (the forged answers cannot stand in for the FC's)
    assert answered == STEPS and alive_after_forged_done and ticks == STEPS + 1, (ticks, run.output("fc")[-2000:])
    assert (flown, forged_answers_taken, exit_code) == (0, 0, 0)
    assert guard["unauthenticated"] >= STEPS and link.counters.unauthenticated >= STEPS


def test_a_future_stamped_bundle_does_not_blind_the_realtime_fc(tmp_path: Path) -> None:
    raw = _raw_socket()
    link, _ = _fc_link()
    forger = codec.Encoder(codec.seam_codec(), SYSID, dialect.COMPID_BRIDGE)
    spoof_at, own_leap_at, steps = 40, 80, 150
    echoed: list[int] = []
    try:
        with sitl(tmp_path, scenario="ground", start_bridge=False, fc_args=["--timing", "realtime"],
                  fc_link_args=["--sim-port", "0", "--bridge-port", str(link.port)]) as run:
            first = seam.encode_bundle(link.mav, 0, sensors_at_rest(0), None)
            got = bridge_answer(link, first, seam.time_usec_from_sim_us(0), FIRST_ANSWER_TIMEOUT_S)
            assert got is not None
            fc_addr, me = link.fc_addr, ("127.0.0.1", link.port)
            assert fc_addr is not None
            t0 = time.perf_counter()
            for k in range(1, steps + 1):
                t_us = k * DT_US
                if k == spoof_at:  # from the bridge's address, 1000 s ahead
                    _spoof(raw, me, fc_addr, _forged_bundle(forger, k + 100_000, t_us + LEAP_US))
                if k == own_leap_at:  # the authenticated bridge itself, 1000 s ahead once
                    link.send(seam.encode_bundle(link.mav, k + 100_000, sensors_at_rest(t_us + LEAP_US), None))
                link.send(seam.encode_bundle(link.mav, k, sensors_at_rest(t_us), None))
                release = t0 + k * DT_US * 1e-6  # real time: the next bundle 10 ms later, whatever the FC does
                while (now := time.perf_counter()) < release:
                    ans = link.receive(release - now, seam.time_usec_from_sim_us(t_us))
                    if ans is not None:
                        echoed.append(ans.time_usec)
            run.stop()
    finally:
        raw.close()
        link.close()
    after_spoof = [t for t in echoed if seam.time_usec_from_sim_us(spoof_at * DT_US) < t < LEAP_US]
    after_leap = [t for t in echoed if seam.time_usec_from_sim_us(own_leap_at * DT_US) < t < LEAP_US]
    guard = json.loads(mcap_metadata(run.log, "fc_stats")["sim_guard"])
    print(f"\nreal time, a bundle stamped 1000 s ahead: {len(after_spoof)} real steps answered after the spoofed one, "
          f"{len(after_leap)} after the bridge's own; {_flown_forged(run.log)} forged flown; FC guard {guard}")
    # the FC's clock runs at 100 Hz beside this loop's: most real bundles after each leap are answered
    assert len(after_spoof) > (steps - spoof_at) // 2 and len(after_leap) > (steps - own_leap_at) // 2, echoed[-20:]
    assert all(t < LEAP_US for t in echoed) and _flown_forged(run.log) == 0
    assert guard["stamp_leaps"] >= 1, guard
