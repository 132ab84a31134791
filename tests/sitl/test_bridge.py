"""navig8-bridge as a real process on loopback UDP, driven by a minimal fake FC written with the dialect.

The fake FC answers each bundle with the hover trim (what the plant would hold at rest), so these tests
check the bridge's lockstep mechanics, not a controller: stamps and step counters, duplicates ignored,
stall reporting and abort, SIGTERM. The bridge binds port 0 and runs with --fc-port 0: it learns the fake FC's
address from the FC's announcement (HEARTBEAT). Every wait is bounded; the process is always killed in a finally.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from sitl_helpers import Proc, start_process, wait_ports_file

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.links.sim_guard import pairing_heartbeat, session_key
from navig8_fc.mavlink import codec, dialect, seam
from sim_bridge import Plant, PlantParams, load_scenario

ROOT = Path(__file__).resolve().parents[2]
SYSID = 1
DT_US = 10_000


class FakeFc:
    """Binds a free port, parses bundles with the codec and the seam, answers with HIL_ACTUATOR_CONTROLS."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.bridge = ("127.0.0.1", 0)  # set once the bridge has written its ports file
        self.codec = codec.seam_codec()
        self.mav = codec.Encoder(self.codec, SYSID, dialect.COMPID_FC)  # signs once announced (the session key)
        self.plain = codec.Encoder(self.codec, SYSID, dialect.COMPID_FC)  # the announcement is never signed
        self.key: bytes | None = None
        self.counts = codec.ParseCounters()
        self.vehicle = VehicleConfig.load()
        self.statuses: list[seam.SimStatus] = []

    def recv_bundle(self, timeout_s: float) -> seam.StepBundle | None:
        """The next complete bundle within timeout_s (status messages are collected on the way)."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self.sock.settimeout(left)
            try:
                data, _ = self.sock.recvfrom(65535)
            except TimeoutError:
                return None
            msgs = self.codec.parse(data, self.counts, self.key)
            for m in msgs:
                if m.name == "NAVIG8_SIM_STATUS":
                    self.statuses.append(seam.decode_sim_status(m.fields))
            b = seam.decode_bundle(msgs)
            if b is not None:
                return b

    def announce(self, nonce: int = 0x5EED) -> None:
        """The pairing announcement (docs/bridge.md): the bridge pairs with this address and echoes the nonce; both
        then sign with the session key derived from it ("Authenticated bundles")."""
        self.send_raw(self.plain.frame(*pairing_heartbeat(nonce)))
        self.key = session_key(nonce, SYSID)
        self.mav.signing = codec.FrameSigning(self.key)

    def answer(self, b: seam.StepBundle, cmd, *, time_usec: int | None = None) -> None:
        self.sock.sendto(seam.pack_actuator_controls(self.mav, b.time_usec if time_usec is None else time_usec, cmd,
                                                     self.vehicle, armed=True), self.bridge)

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.bridge)

    def close(self) -> None:
        self.sock.close()


@contextmanager
def bridge_process(*args: str) -> Iterator[tuple[Proc, FakeFc]]:
    fc = FakeFc()
    with tempfile.TemporaryDirectory(prefix="navig8-bridge-test-") as tmp:
        ports_file = Path(tmp) / "ports.json"
        proc = start_process("sim_bridge.bridge", ["--bridge-port", "0", "--fc-port", "0", "--ports-file",
                                                   str(ports_file), *args], ROOT, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
        try:
            fc.bridge = ("127.0.0.1", wait_ports_file(ports_file, proc)["bridge"])
        except BaseException:
            proc.kill()
            proc.wait(timeout=10)
            fc.close()
            raise
    fc.announce()
    try:
        yield proc, fc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)
        fc.close()


def _trim(scenario: str):
    return Plant(VehicleConfig.load(), PlantParams.load(), load_scenario(scenario),
                 np.random.default_rng(0)).trim_command()


def test_lockstep_hover_with_fake_fc() -> None:
    trim = _trim("hover")
    n = 200
    with bridge_process("--scenario", "hover", "--speed", "0", "--until-done", "--duration", str(n * 0.01)) as (
        proc,
        fc,
    ):
        b0 = fc.recv_bundle(30.0)  # first start may generate the dialect and compile numba kernels
        assert b0 is not None, proc.stderr.read() if proc.poll() is not None else "no bundle"
        assert b0.step == 0 and b0.time_usec == 1 and b0.t_us == 0
        # startup: without an answer the bridge re-sends step 0 (same stamp) every 0.1 s
        again = fc.recv_bundle(2.0)
        assert again is not None and again.step == 0 and again.time_usec == 1
        stamps = [b0.time_usec]
        steps = [b0.step]
        b = again
        t0 = time.perf_counter()
        while True:
            fc.answer(b, trim)
            if b.step == 5:
                fc.answer(b, trim)  # a duplicate answer: must be dropped, not taken for step 6
            nxt = fc.recv_bundle(5.0)
            if nxt is None:
                break
            if nxt.time_usec == b.time_usec:
                continue  # a re-sent bundle 0 from the startup phase
            b = nxt
            stamps.append(b.time_usec)
            steps.append(b.step)
            if b.step == n:
                fc.answer(b, trim)
                break
        wall = time.perf_counter() - t0
        assert proc.wait(timeout=10) == 0
        err = proc.stderr.read()
        assert fc.recv_bundle(0.3) is None  # nothing after the last step; the final statuses are collected
    assert steps == list(range(n + 1))
    assert np.all(np.diff(stamps) == DT_US)
    assert b.truth is not None
    pos = np.array(b.truth.pos_ned_m)
    assert np.linalg.norm(pos - np.array([0.0, 0.0, -2.0])) < 0.1, pos
    assert abs(b.pos_ned_m[2] + 2.0) < 0.1
    assert "stale_answers" in err and "stale_answers 0" not in err  # the duplicate was counted
    assert "answers 201" in err
    assert fc.statuses[-1].state == seam.SIM_STATE_DONE and fc.statuses[-1].step == n
    print(f"bridge + fake FC: {n / wall:.0f} steps/s")


def test_bad_datagrams_are_counted_and_dropped() -> None:
    trim = _trim("hover")
    with bridge_process("--scenario", "hover", "--speed", "0") as (proc, fc):
        b = fc.recv_bundle(30.0)
        assert b is not None
        fc.send_raw(b"\x00garbage\xfd\x09")  # garbage and a truncated frame
        fc.send_raw(os.urandom(300))
        fc.send_raw(b"\xfd" * 5000)  # oversize: dropped unparsed
        other = codec.Encoder(codec.seam_codec(), SYSID + 7, dialect.COMPID_FC)  # another vehicle's answer
        fc.send_raw(seam.pack_actuator_controls(other, b.time_usec, trim, fc.vehicle, armed=True))
        fc.answer(b, trim, time_usec=b.time_usec + 12345)  # an answer for no bundle
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as spoof:  # the right ids from another socket
            spoof.sendto(seam.pack_actuator_controls(fc.mav, b.time_usec, trim, fc.vehicle, armed=True), fc.bridge)
            spoof.sendto(fc.mav.frame(*pairing_heartbeat(99)), fc.bridge)  # and a pairing while ours is live
        for _ in range(20):
            fc.answer(b, trim)
            b2 = fc.recv_bundle(5.0)
            assert b2 is not None
            while b2.time_usec == b.time_usec:  # startup re-sends of step 0
                b2 = fc.recv_bundle(5.0)
                assert b2 is not None
            assert b2.time_usec == b.time_usec + DT_US
            b = b2
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        err = proc.stderr.read()
    assert "SIGTERM" in err
    assert "foreign_frames 1" in err
    assert "wrong_sender 1," in err and "pair_refused 1," in err and "sessions 1," in err
    assert "oversize 1" in err
    assert "bad_frames 0" not in err


def test_stall_is_reported_and_aborts() -> None:
    trim = _trim("hover")
    with bridge_process("--scenario", "hover", "--speed", "0", "--step-timeout", "0.3", "--stall-abort", "1.2") as (
        proc,
        fc,
    ):
        b = fc.recv_bundle(30.0)
        assert b is not None
        for _ in range(3):
            fc.answer(b, trim)
            b2 = fc.recv_bundle(5.0)
            while b2 is not None and b2.time_usec == b.time_usec:
                b2 = fc.recv_bundle(5.0)
            assert b2 is not None
            b = b2
        # stop answering: re-sends of the same step, a stall line per timeout, exit 3 after --stall-abort
        t0 = time.monotonic()
        resent = fc.recv_bundle(2.0)
        assert resent is not None and resent.time_usec == b.time_usec
        while (again := fc.recv_bundle(1.0)) is not None:  # re-sent every 0.1 s until the abort (statuses collected)
            assert again.time_usec == b.time_usec
        rc = proc.wait(timeout=10)
        elapsed = time.monotonic() - t0
        err = proc.stderr.read()
    assert rc == 3
    assert 0.8 < elapsed < 5.0
    assert f"no actuator answer from navig8-fc for step {b.step}" in err
    assert "re-sending" in err
    assert "navig8-fc stalled" in err
    assert any(s.state == seam.SIM_STATE_STALLED for s in fc.statuses)


def test_a_lost_bundle_is_sent_again_without_a_stall() -> None:
    """A bundle the FC never got (a datagram lost) comes again long before the step timeout: no stall counted."""
    trim = _trim("hover")
    with bridge_process("--scenario", "hover", "--speed", "0", "--until-done", "--duration", "0.05",
                        "--step-timeout", "60") as (proc, fc):
        answered: set[int] = set()
        ignored = False
        while len(answered) < 6:
            b = fc.recv_bundle(10.0)  # far below the 60 s step timeout: only a re-send can bring step 2 again
            assert b is not None, (sorted(answered), "the unanswered bundle was not sent again")
            if b.step == 2 and not ignored:
                ignored = True  # not answered: as if it had never arrived
                continue
            fc.answer(b, trim)
            answered.add(b.step)
        assert proc.wait(timeout=10) == 0
        err = proc.stderr.read()
    assert "stalls 0," in err and "resends 0," not in err, err


def test_sigterm_while_waiting_for_fc() -> None:
    with bridge_process("--scenario", "ground") as (proc, fc):
        b = fc.recv_bundle(30.0)
        assert b is not None and b.step == 0
        assert fc.statuses and fc.statuses[0].state == seam.SIM_STATE_WAITING_FOR_FC
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        err = proc.stderr.read()
    assert "navig8-bridge: scenario ground" in err


@pytest.mark.parametrize("speed", ["1"])
def test_real_time_pacing(speed: str) -> None:
    trim = _trim("hover")
    with bridge_process("--scenario", "hover", "--speed", speed) as (proc, fc):
        b = fc.recv_bundle(30.0)
        assert b is not None
        fc.answer(b, trim)
        t0 = time.perf_counter()
        k0 = None
        while True:
            nb = fc.recv_bundle(5.0)
            assert nb is not None
            if nb.time_usec == b.time_usec:
                continue
            b = nb
            if k0 is None:
                k0, t0 = b.step, time.perf_counter()
            fc.answer(b, trim)
            if b.step - k0 >= 100:
                break
        wall = time.perf_counter() - t0
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    # 100 steps of 10 ms at real time. The bridge keeps to its schedule, so after a stall (our answer late on a loaded
    # machine) it catches up in a burst: 30 steps once took 0.24 s. The lower bound leaves 0.2 s of such catching up
    # and still fails a bridge that ignores --speed 1 (100 steps in well under 0.1 s); the upper bound fails one that
    # paces at a fifth of real time or slower.
    assert 0.8 < wall < 5.0


def test_arm_command_moves_joints_and_releases_the_object() -> None:
    """NAVIG8_ARM_CMD sent before the step's answer takes effect on that step (deterministic)."""
    trim = _trim("hover")
    target = (0.3, -0.2, 0.1)
    with bridge_process("--scenario", "hover", "--speed", "0") as (proc, fc):
        b = fc.recv_bundle(30.0)
        assert b is not None and b.gripper_closed and b.truth.object_mass_kg == 1.0
        arm = seam.encode_arm_cmd(seam.ArmCommand(b.time_usec, target, seam.GRIPPER_RELEASE))
        fc.send_raw(fc.mav.frame(*arm))
        fc.answer(b, trim)
        seen_release_at = None
        for _ in range(150):
            nb = fc.recv_bundle(5.0)
            assert nb is not None
            if nb.time_usec == b.time_usec:
                continue
            b = nb
            if seen_release_at is None and not b.gripper_closed:
                seen_release_at = b.step
            fc.answer(b, trim)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        err = proc.stderr.read()
    assert seen_release_at == 1  # applied on the step answered right after the command
    assert b.truth.object_mass_kg == 0.0
    np.testing.assert_allclose(b.truth.joint_pos_rad, target, atol=0.02)  # the servo got there within 1.5 s
    assert "arm_cmds 1" in err


def test_a_busy_port_is_refused_clearly() -> None:
    """No SO_REUSEADDR: a second bridge cannot bind the port and take the first one's datagrams."""
    holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    holder.bind(("127.0.0.1", 0))
    port = holder.getsockname()[1]
    try:
        out = subprocess.run([sys.executable, "-m", "sim_bridge.bridge", "--bridge-port", str(port)], cwd=ROOT,
                             capture_output=True, text=True, timeout=60)
    finally:
        holder.close()
    assert out.returncode == 2, out.stderr
    assert f"127.0.0.1:{port} is in use" in out.stderr and "--bridge-port" in out.stderr
    assert "Traceback" not in out.stderr
