"""navig8-fc's run loop in a thread, with this test as its bridge over real loopback UDP: pairing by nonce, bad sensor
data from the paired bridge (NaN, Inf, 1e6) rejected and reported while every step is answered, persistent bad data
landing, an exception in the tick contained, and a log that cannot be written (a real ENOSPC from /dev/full, a
log directory that cannot be created) reported while the FC keeps answering."""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from test_sim_guard import Wire, set_field

from navig8_fc.links.sim_guard import pairing_heartbeat, session_key
from navig8_fc.mavlink import codec, dialect, seam
from navig8_fc.shell.fc_options import FcOptions
from navig8_fc.shell.fc_process import FlightControllerProcess
from navig8_fc.shell.mcap_log import read_mcap, read_metadata

TIMEOUT_S = 30.0


def _udp() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(TIMEOUT_S)
    return s


class FakeBridgeSide:
    """This test's end of the sim link (a real socket; the bundles come from a real plant, see test_sim_guard.Wire)
    and a GCS socket where the FC's STATUSTEXTs arrive."""

    def __init__(self) -> None:
        self.sock, self.gcs = _udp(), _udp()
        self.gcs.settimeout(0.0)
        self.wire = Wire()
        self.codec = codec.seam_codec()
        self.fc_addr: tuple[str, int] | None = None
        self.key: bytes | None = None
        self.texts: list[str] = []
        self._gcs_mav = dialect.new_mav(255, 190)

    def pair(self) -> None:
        data, addr = self.sock.recvfrom(4096)  # the FC's announcement
        (m,) = self.codec.parse(data, codec.ParseCounters())
        assert m.name == "HEARTBEAT" and m.fields["custom_mode"] != 0
        self.fc_addr = addr
        self.sock.sendto(self.wire.frame(pairing_heartbeat(m.fields["custom_mode"])), addr)
        # both sides now sign with the session key derived from the nonce (docs/bridge.md, "Authenticated bundles")
        self.key = session_key(m.fields["custom_mode"], self.wire.enc.sysid)
        self.wire.enc.signing = codec.FrameSigning(self.key)

    def step(self, mutate=None) -> seam.ActuatorControls:
        """Send the next bundle; the FC's answer to it (waiting at most TIMEOUT_S)."""
        data = self.wire.next(mutate)
        want = self.codec.parse(data, codec.ParseCounters(), self.key)[0].fields["time_usec"]
        self.sock.sendto(data, self.fc_addr)
        deadline = time.monotonic() + TIMEOUT_S
        while time.monotonic() < deadline:
            got, _ = self.sock.recvfrom(4096)
            for m in self.codec.parse(got, codec.ParseCounters(), self.key):
                if m.name == "HIL_ACTUATOR_CONTROLS" and m.fields["time_usec"] == want:
                    return seam.decode_actuator_controls(m.fields, self.wire.plant.vehicle)
        raise AssertionError(f"no answer to step {self.wire.step}")

    def statustexts(self) -> list[str]:
        while True:
            try:
                data = self.gcs.recv(65535)
            except BlockingIOError:
                return self.texts
            for m in self._gcs_mav.parse_buffer(data) or []:
                if m.get_type() == "STATUSTEXT":
                    self.texts.append(m.text)

    def wait_text(self, part: str) -> str:
        deadline = time.monotonic() + TIMEOUT_S
        while time.monotonic() < deadline:
            hits = [t for t in self.statustexts() if part in t]
            if hits:
                return hits[0]
            time.sleep(0.02)
        raise AssertionError(f"no STATUSTEXT with {part!r} in {self.texts}")

    def close(self) -> None:
        self.sock.close()
        self.gcs.close()


@contextmanager
def fc_with_test_bridge(log_path: Path | None) -> Iterator[tuple[FlightControllerProcess, FakeBridgeSide]]:
    side = FakeBridgeSide()
    proc = FlightControllerProcess(FcOptions(
        scenario="hover", sim_port=0, bridge_port=side.sock.getsockname()[1], gcs_bind_port=0, api_bind_port=0,
        gcs_port=side.gcs.getsockname()[1], api_port=side.gcs.getsockname()[1], log_path=log_path))
    errors: list[BaseException] = []

    def run() -> None:
        try:
            proc.run()
        except BaseException as e:  # noqa: BLE001 - reported by the test below
            errors.append(e)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    try:
        side.pair()
        yield proc, side
    finally:
        proc.request_stop()
        t.join(timeout=TIMEOUT_S)
        side.close()
    assert not t.is_alive() and not errors, errors


def _finite(a: seam.ActuatorControls) -> bool:
    return all(math.isfinite(x) for x in (*a.tilt_rad, *a.speed_rad_s))


def test_bad_sensor_data_is_rejected_reported_and_lands(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    with fc_with_test_bridge(log) as (proc, side):
        good = [side.step() for _ in range(80)]  # armed by the hover scenario, past the estimator's warm-up
        assert all(a.armed and _finite(a) for a in good[60:])
        ref = good[-1].speed_rad_s
        # how much the command moves from one good step to the next (the open-loop plant drifts from trim)
        normal = max(abs(x - y) for a, b in zip(good[60:-1], good[61:], strict=True)
                     for x, y in zip(a.speed_rad_s, b.speed_rad_s, strict=True))
        bad = [side.step(set_field("joint_pos_rad", 0, math.nan)), side.step(set_field("gyro_frd_rad_s", 1, math.inf)),
               side.step(set_field("pos_ned_m", 0, 1e6))]
        # every step answered, from the last good values: the command stays where the good data had it
        assert all(_finite(a) for a in bad)
        # (a 1e6 m position error would saturate the rotors: 950 rad/s away)
        assert max(abs(x - y) for a in bad for x, y in zip(a.speed_rad_s, ref, strict=True)) < 3 * normal + 5.0, normal
        for _ in range(25):  # 0.25 s of NaN in the arm state: the failsafe lands
            assert _finite(side.step(set_field("joint_rate_rad_s", 1, math.nan)))
        assert proc.stack.state().flight_mode.name == "LAND"
        side.step()
        # an exception in the tick (fault injection: no real input makes the stack raise any more) is contained
        real = proc.stack.step
        proc.stack.step = lambda *a, **k: (_ for _ in ()).throw(RuntimeError("injected"))
        held = side.step()
        proc.stack.step = real
        assert _finite(held) and held.armed
        assert _finite(side.step())
        for text in ("Sim link: invalid arm data", "Sim link: invalid imu data", "Sim link: invalid mocap data",
                     "Bad sensor data (arm) 0.2", "Sensor data valid again", "Control error RuntimeError (1x)"):
            side.wait_text(text)
    stats = read_metadata(log)["fc_stats"]["sim_guard"]
    assert (stats["invalid_arm"], stats["invalid_imu"], stats["invalid_mocap"]) == (26, 1, 1)
    assert stats["tick_errors"] == 1 and stats["sessions"] == 1 and stats["wrong_sender"] == 0
    logged = [d for topic, _t, d in read_mcap(log, topics=["/mavlink/sim/in/NAVIG8_ARM_STATE"])]
    assert logged and all(all(math.isfinite(x) for x in d["joint_pos"] + d["joint_rate"]) for d in logged)


def test_a_log_that_cannot_be_written_is_reported_and_the_fc_keeps_answering(tmp_path: Path) -> None:
    with fc_with_test_bridge(Path("/dev/full")) as (proc, side):  # every write: OSError ENOSPC from the kernel
        for _ in range(150):  # a 64 KiB chunk fills within these steps: its write fails
            assert _finite(side.step())
        side.wait_text("Log stopped: No space left on device")
        assert proc.logger is not None and proc.logger.dropped > 0
    (tmp_path / "file").write_text("not a directory")
    with fc_with_test_bridge(tmp_path / "file" / "run.mcap") as (proc, side):
        assert proc.logger is None
        for _ in range(20):
            assert _finite(side.step())
        side.wait_text("Log disabled: File exists")  # mkdir of a path that is a file
