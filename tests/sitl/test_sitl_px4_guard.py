"""The PX4 simulator path (`navig8-fc --sim-messages px4`) behind the same guard as the bridge's bundle: a real
navig8-fc in the hover scenario (armed, holding 2 m) stepped by this test as a PX4-style simulator (HIL_STATE_QUATERNION
+ HIL_SENSOR each step, lockstep on the HIL_ACTUATOR_CONTROLS answer; the vehicle at rest at 2 m).

- over UDP, another local process sends its own HIL_STATE_QUATERNION (34 m away) and HIL_SENSOR between the
  simulator's steps: the simulator's address is pinned, so not one forged frame makes a step or reaches a step's
  pose, and no answer goes to the forger;
- over TCP (PX4's layout, the simulator listening), the simulator itself sends one HIL_SENSOR with a NaN gyro, one
  with a 1e6 m/s² specific force and one pose 1e6 m up: each is refused (the last good values flown), counted, the
  commands stay finite and where they were, and the loop still answers a real roll rate afterwards (flown, these
  samples froze it: the command held whatever the vehicle did).

"Steps flown on forged or bad data" are read from the FC's log, whose decoded `/mavlink/sim/in/...` records are the
very messages each step was made from (docs/hil.md, "PX4 simulator messages")."""

from __future__ import annotations

import json
import math
import os
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sitl_helpers import mcap_metadata, sitl

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as m2  # noqa: E402

from navig8_fc.mission.geo import GeoOrigin  # noqa: E402
from navig8_fc.shell.mcap_log import read_mcap  # noqa: E402

G_M_S2 = 9.80665
DT_US = 10_000
STEPS = 300
ANSWER_TIMEOUT_S = 20.0  # the FC's first step loads its kernels; later ones take ~1 ms (generous under load)
RESEND_S = 1.0
HOVER_NED_M = (0.0, 0.0, -2.0)
FORGED_NED_M = (34.0, 0.0, -2.0)
GYRO_MAX_RAD_S = 35.0  # the guard's limits (navig8_fc/links/sim_guard.py)
ACCEL_MAX_M_S2 = 16 * G_M_S2
RESPONSE_FROM, RESPONSE_RATE_RAD_S = 250, 0.5  # the TCP test's last steps: a measured roll rate the loop must answer


def frames(mav: Any, stamp: int, ned: tuple[float, float, float] = HOVER_NED_M,
           gyro: tuple[float, float, float] = (0.0, 0.0, 0.0),
           accel: tuple[float, float, float] = (0.0, 0.0, -G_M_S2)) -> bytes:
    """One step as a PX4 simulator sends it: the pose (HIL_STATE_QUATERNION), then HIL_SENSOR id 0 (the trigger)."""
    lat, lon, alt = GeoOrigin().to_global(ned)
    return (mav.hil_state_quaternion_encode(stamp, (1.0, 0.0, 0.0, 0.0), *gyro, round(lat * 1e7), round(lon * 1e7),
                                            round(alt * 1000), 0, 0, 0, 0, 0, 0, 0, -1000).pack(mav)
            + mav.hil_sensor_encode(stamp, *accel, *gyro, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0b111111, 0).pack(mav))


class Simulator:
    """This test's end of the sim link: `send` one step's datagram, `answer(stamp)` the FC's controls for it."""

    def __init__(self, send: Callable[[bytes], None], recv: Callable[[float], bytes | None]) -> None:
        self._send, self._recv = send, recv
        self.mav = m2.MAVLink(None, srcSystem=1, srcComponent=51)
        self._parser = m2.MAVLink(None)
        self.answers: list[tuple[int, tuple[float, ...]]] = []  # (stamp echoed, controls[:5]) of every answer

    def step(self, data: bytes, stamp: int) -> tuple[float, ...]:
        self._send(data)
        deadline, resend = time.monotonic() + ANSWER_TIMEOUT_S, time.monotonic() + RESEND_S
        while (now := time.monotonic()) < deadline:
            got = self._recv(min(resend, deadline) - now)
            for m in self._parser.parse_buffer(got) or [] if got else []:
                if m.get_type() == "HIL_ACTUATOR_CONTROLS":
                    self.answers.append((m.time_usec, tuple(m.controls[:5])))
                    if m.time_usec == stamp:
                        return self.answers[-1][1]
            if time.monotonic() >= resend:
                self._send(data)
                resend = time.monotonic() + RESEND_S
        raise AssertionError(f"no answer to the step stamped {stamp}")


def _udp_recv(sock: socket.socket) -> Callable[[float], bytes | None]:
    def recv(timeout_s: float) -> bytes | None:
        sock.settimeout(max(timeout_s, 1e-3))
        try:
            return sock.recv(4096)
        except TimeoutError:
            return None
    return recv


def _logged(log: Path, name: str) -> list[dict[str, Any]]:
    return [m for _, _, m in read_mcap(log, [f"/mavlink/sim/in/{name}"])]


def test_a_foreign_process_cannot_inject_px4_simulator_frames_over_udp(tmp_path: Path) -> None:
    sim_sock, forger = (socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2))
    sim_sock.bind(("127.0.0.1", 0))
    forger.bind(("127.0.0.1", 0))
    forger.setblocking(False)
    forged_stamps: set[int] = set()
    try:
        with sitl(tmp_path, scenario="hover", start_bridge=False,
                  fc_link_args=["--sim-messages", "px4", "--sim-link", "udpin:127.0.0.1:0"]) as run:
            fc = ("127.0.0.1", run.ports["sim"])
            sim = Simulator(lambda d: sim_sock.sendto(d, fc), _udp_recv(sim_sock))
            forge = m2.MAVLink(None, srcSystem=1, srcComponent=51)
            for k in range(STEPS):
                stamp = 1 + k * DT_US
                sim.step(frames(sim.mav, stamp), stamp)
                if k >= 50 and k % 5 == 0:  # between two of the simulator's steps: a newer stamp, a pose 34 m off
                    forged_stamps.add(stamp + DT_US // 2)
                    forger.sendto(frames(forge, stamp + DT_US // 2, FORGED_NED_M, gyro=(0.0, 0.0, 2.0)), fc)
            run.stop()
        to_forger = 0
        while True:
            try:
                to_forger += len(forger.recv(4096)) > 0
            except BlockingIOError:
                break
    finally:
        sim_sock.close()
        forger.close()
    forged_lat = round(GeoOrigin().to_global(FORGED_NED_M)[0] * 1e7)
    answered_forged = sum(t in forged_stamps for t, _ in sim.answers)
    # a step on a forged HIL_SENSOR echoes its stamp (answered, or logged); a step on a forged pose logs it
    forged_steps = {t for t, _ in sim.answers if t in forged_stamps} | {
        m["time_usec"] for m in _logged(run.log, "HIL_SENSOR") if m["time_usec"] in forged_stamps}
    on_forged = len(forged_steps) + sum(m["lat"] == forged_lat for m in _logged(run.log, "HIL_STATE_QUATERNION"))
    guard = json.loads(mcap_metadata(run.log, "fc_stats")["sim_guard"])
    print(f"\nPX4 path over UDP, {len(forged_stamps)} forged steps from another socket: {on_forged} steps flown on "
          f"forged data, {answered_forged} forged stamps answered, {to_forger} datagrams to the forger; {guard}")
    assert (on_forged, answered_forged, to_forger) == (0, 0, 0), guard
    assert guard["wrong_sender"] >= len(forged_stamps) and guard["sessions"] == 1, guard
    assert len(_logged(run.log, "HIL_SENSOR")) >= STEPS - 5


def test_nan_and_huge_samples_from_the_px4_simulator_itself_are_refused_over_tcp(tmp_path: Path) -> None:
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    srv.settimeout(60.0)
    conn: socket.socket | None = None
    bad_at = {100: "nan_gyro", 150: "huge_accel", 200: "pose_1e6_up"}
    controls: dict[int, tuple[float, ...]] = {}
    try:
        with sitl(tmp_path, scenario="hover", start_bridge=False,
                  fc_link_args=["--sim-messages", "px4", "--sim-link", f"tcp:127.0.0.1:{srv.getsockname()[1]}"]) as run:
            conn, _ = srv.accept()  # PX4's layout: the simulator listens, the autopilot connects
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sim = Simulator(conn.sendall, _udp_recv(conn))
            for k in range(STEPS):
                stamp = 1 + k * DT_US
                kind = bad_at.get(k)
                roll_rate = RESPONSE_RATE_RAD_S if k >= RESPONSE_FROM else 0.0  # a real motion: the loop must react
                data = frames(sim.mav, stamp,
                              gyro=(math.nan, 0.0, 0.0) if kind == "nan_gyro" else (roll_rate, 0.0, 0.0),
                              accel=(1e6, 0.0, -G_M_S2) if kind == "huge_accel" else (0.0, 0.0, -G_M_S2),
                              ned=(0.0, 0.0, -1e6) if kind == "pose_1e6_up" else HOVER_NED_M)
                controls[k] = sim.step(data, stamp)
            run.stop()
    finally:
        if conn is not None:
            conn.close()
        srv.close()
    sensors = _logged(run.log, "HIL_SENSOR")
    poses = _logged(run.log, "HIL_STATE_QUATERNION")
    hover_alt_mm = round(GeoOrigin().to_global(HOVER_NED_M)[2] * 1000)

    def bad_imu(m: dict[str, Any]) -> bool:
        vals = [m[f] for f in ("xgyro", "ygyro", "zgyro", "xacc", "yacc", "zacc")]
        return any(v is None or not math.isfinite(v) for v in vals) or any(abs(v) > GYRO_MAX_RAD_S for v in vals[:3]) \
            or any(abs(v) > ACCEL_MAX_M_S2 for v in vals[3:])

    on_bad = sum(bad_imu(m) for m in sensors) + sum(abs(m["alt"] - hover_alt_mm) > 1000 for m in poses)
    finite = all(math.isfinite(c) for cs in controls.values() for c in cs)
    # the commands after each refused sample stay where they were before it (the static vehicle's steady command)
    jumps = {kind: max(abs(a - b) for k2 in range(k, k + 10) for a, b in zip(controls[k2], controls[k - 1],
                                                                             strict=True))
             for k, kind in bad_at.items()}
    response = max(abs(a - b) for a, b in zip(controls[STEPS - 1], controls[RESPONSE_FROM - 1], strict=True))
    guard = json.loads(mcap_metadata(run.log, "fc_stats")["sim_guard"])
    print(f"\nPX4 path over TCP, bad samples from the simulator itself {sorted(bad_at.values())}: {on_bad} steps flown "
          f"on them, controls finite {finite}, largest change in the 10 steps after each {jumps}, answer to a real "
          f"roll rate after them {response:.3f}; {guard}")
    assert on_bad == 0 and finite, (on_bad, guard)
    assert guard["invalid_imu"] == 2 and guard["invalid_mocap"] == 1, guard
    assert all(j < 0.05 for j in jumps.values()), jumps
    assert response > 0.05, response  # the loop still flies: not frozen on poisoned state
