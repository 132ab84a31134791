"""navig8-bridge: the plant behind MAVLink, in lockstep with navig8-fc (docs/bridge.md is the contract).

    navig8-bridge [--scenario NAME|FILE] [--seed N] [--speed X] [--instance N] [--until-done] [--duration S]
                  [--bridge-port P] [--fc-port P] [--host H] [--dt S] [--step-timeout S] [--stall-abort S]
                  [--ports-file PATH]

The bridge is the time master (DESIGN §4). Each step k it sends ONE datagram with the sensor bundle
stamped time_usec = round(k * dt * 1e6) + 1 (ODOMETRY, NAVIG8_ACTUATOR_STATE, NAVIG8_ARM_STATE, NAVIG8_TRUTH,
HIL_SENSOR last) and waits for the FC's single HIL_ACTUATOR_CONTROLS echoing that stamp; it then holds that
command for dt (zero-order hold), steps the plant and sends step k + 1. A thin I/O loop: no controller code.

Ports: --bridge-port 0 binds a free port; --ports-file PATH then receives {"bridge": port} (JSON, written
atomically after binding). Pairing (docs/bridge.md, "Pairing and sequencing"): until paired the bridge sends pair
requests to --fc-port at --host (none with --fc-port 0); the FC's announcement carries a session nonce, the bridge
echoes it and from then on talks only to that address and takes answers only from it.

Exit codes: 0 done (--until-done) or stopped by SIGINT/SIGTERM; 1 cannot start; 2 bad arguments or the
port in use; 3 navig8-fc stalled longer than --stall-abort; 4 the plant diverged.
"""

from __future__ import annotations

import argparse
import gc
import math
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from navig8_fc.links.mavlink_link import PortInUseError, bind_udp, write_ports_file
from navig8_fc.links.sim_guard import REPAIR_SILENCE_S, pairing_heartbeat
from navig8_fc.links.transport import StreamTransport, open_endpoint, parse_connection
from navig8_fc.mavlink import codec, dialect, seam
from sim_bridge.link_budget import LinkBudget, link_budget
from sim_bridge.messages import ActuatorCommand
from sim_bridge.plant import Plant, PlantDivergedError
from sim_bridge.scenario import Scenario
from sim_bridge.world import load_world, parse_world_items

BASE_BRIDGE_PORT = 4560  # + 2 N: the bridge binds here (PX4's simulator port)
BASE_FC_PORT = 4561  # + 2 N: the FC's sim link
STARTUP_RESEND_S = 0.1  # re-send step 0 this often until the FC answers
STREAM_STARTUP_RESEND_S = 1.0  # on TCP/serial: re-sent bundles queue in the stream, and the FC answers every one
STATUS_PERIOD_S = 1.0  # NAVIG8_SIM_STATUS period (wall)
REANCHOR_LAG_S = 0.5  # paced runs that fall this far behind (a stall) restart pacing instead of bursting
SPIN_S = 0.002  # busy-poll window at --speed 0 (see _receive)
MAX_DATAGRAM = 65535
MAX_ACCEPTED_DATAGRAM = 4096  # the FC sends ~70-byte frames; anything this big is not it (parse nothing)

EXIT_OK, EXIT_START, EXIT_USAGE, EXIT_STALL, EXIT_DIVERGED = 0, 1, 2, 3, 4


class _Shutdown(BaseException):
    """SIGINT/SIGTERM: leave the loop, close the socket, exit 0.

    A BaseException (like KeyboardInterrupt) so that no `except Exception` on the way (the datagram
    parser guards against pymavlink bugs with one) can swallow it.
    """


class _Stalled(Exception):
    pass


@dataclass(frozen=True)
class BridgeOptions:
    scenario: str = "ground"
    seed: int = 1
    speed: float = 1.0  # 1 real time, N x real time, 0 as fast as possible
    instance: int = 0
    bridge_port: int | None = None
    fc_port: int | None = None
    host: str = "127.0.0.1"
    until_done: bool = False
    duration_s: float | None = None
    dt_s: float = 0.01  # must equal 1 / INDI_RATE_HZ of the FC
    step_timeout_s: float = 2.0
    stall_abort_s: float = 20.0
    startup_timeout_s: float = 0.0  # 0: wait for the FC forever (reminding every 10 s)
    grab_mass_kg: float | None = None  # object mass a GRAB picks up (default: from the scenario)
    ports_file: Path | None = None  # written after binding: {"bridge": port}
    world: tuple[tuple[str, float], ...] = ()  # world overrides (sim_bridge.world), as navig8-sim --world
    free_run: bool = False  # real time: step on the wall clock with the newest answer, never wait (docs/hil.md)
    link: str | None = None  # connection string of the FC link (udpin:, udpout:, tcpin:, tcp:, serial:); None: UDP

    @property
    def sysid(self) -> int:
        return self.instance + 1

    @property
    def bridge_port_resolved(self) -> int:
        return self.bridge_port if self.bridge_port is not None else BASE_BRIDGE_PORT + 2 * self.instance

    @property
    def fc_port_resolved(self) -> int:
        return self.fc_port if self.fc_port is not None else BASE_FC_PORT + 2 * self.instance


@dataclass
class BridgeCounters:
    steps: int = 0  # plant steps taken
    bundles_sent: int = 0  # including re-sends
    resends: int = 0  # bundles sent again (startup and stalls)
    stalls: int = 0  # step timeouts
    answers: int = 0  # HIL_ACTUATOR_CONTROLS accepted
    stale_answers: int = 0  # HIL_ACTUATOR_CONTROLS for another step (duplicates, late answers)
    arm_cmds: int = 0
    bad_frames: int = 0  # malformed, bad CRC, unknown ids, truncated, signed (not verified here)
    garbage_bytes: int = 0  # bytes between frames
    foreign_frames: int = 0  # from another system or component
    wrong_sender: int = 0  # FC frames from an address other than the paired FC's (or before pairing)
    pair_refused: int = 0  # FC announcements from another address while the paired FC is live
    sessions: int = 0  # pairings with an FC (docs/bridge.md, "Pairing and sequencing")
    other_frames: int = 0  # valid FC frames the bridge does not use (HEARTBEAT, ...)
    datagrams_in: int = 0
    oversize: int = 0

    def line(self) -> str:
        return ", ".join(f"{k} {v}" for k, v in vars(self).items())


def default_grab_mass(sc: Scenario) -> float:
    """The object a GRAB picks up: the scenario's held object, else its first grasp event's, else nothing."""
    if sc.object_mass_kg > 0.0:
        return sc.object_mass_kg
    for ev in sc.events:
        if ev.kind in ("grasp", "mass") and ev.mass_kg > 0.0:
            return ev.mass_kg
    return 0.0


@dataclass
class _ArmState:
    joint_targets_rad: tuple[float, float, float] | None = None  # persistent override once commanded
    pending_gripper: list[int] = field(default_factory=list)


class Bridge:
    """The lockstep I/O loop around one Plant."""

    def __init__(self, opts: BridgeOptions) -> None:
        if opts.speed < 0 or not math.isfinite(opts.speed):
            raise ValueError("--speed must be >= 0 (0: as fast as possible)")
        if opts.free_run and opts.speed <= 0:
            raise ValueError("--free-run needs a wall-clock pace: --speed > 0")
        if not (opts.step_timeout_s > 0 and opts.stall_abort_s > 0):
            raise ValueError("--step-timeout and --stall-abort must be > 0")
        self.opts = opts
        w = load_world(opts.scenario, dict(opts.world))
        self.scenario = w.scenario
        self.vehicle = w.vehicle
        self.plant = Plant(self.vehicle, w.plant, self.scenario, np.random.default_rng(opts.seed))
        self.dt_us = round(opts.dt_s * 1e6)
        if self.dt_us <= 0 or abs(self.dt_us - opts.dt_s * 1e6) > 1e-3 or self.dt_us % self.plant.physics_step_us:
            raise ValueError(f"--dt {opts.dt_s} s must be a positive multiple of the physics step "
                             f"{self.plant.physics_step_us} us")
        duration = self.scenario.duration_s if opts.duration_s is None else float(opts.duration_s)
        self.n_steps = int(round(duration * 1e6 / self.dt_us))
        self.limits = seam.ActuatorLimits.from_vehicle(self.vehicle)
        self.grab_mass_kg = default_grab_mass(self.scenario) if opts.grab_mass_kg is None else opts.grab_mass_kg
        self.codec = codec.seam_codec()
        self.mav = codec.Encoder(self.codec, opts.sysid, dialect.COMPID_BRIDGE)
        self._parse_counts = codec.ParseCounters()
        self.counters = BridgeCounters()
        self.arm = _ArmState()
        # None: --fc-port 0, nothing is sent until the FC announces itself (see _handle)
        self.fc_addr: tuple[str, int] | None = (opts.host, opts.fc_port_resolved) if opts.fc_port_resolved else None
        self.fc_nonce: int | None = None  # the paired FC's session nonce (None: not paired)
        self._fc_heard = -math.inf  # wall time of the paired FC's last frame
        self._resend_due = False  # a new pairing: send the current bundle at once
        self.budget: LinkBudget | None = None
        if opts.link is None:
            self.sock = bind_udp("bridge", (opts.host, opts.bridge_port_resolved))
        else:  # a connection string: UDP, TCP or serial (navig8_fc/links/transport.py); a serial line's budget first
            conn = parse_connection(opts.link)
            self.budget = link_budget(self.codec, conn, 1e6 / self.dt_us)  # ValueError: the rate does not fit
            ep = open_endpoint("bridge", conn)
            self.sock, self.fc_addr = ep.sock, (ep.targets[0] if ep.targets else None)
        self.port = int(self.sock.getsockname()[1])
        if opts.ports_file is not None:
            write_ports_file(opts.ports_file, {"bridge": self.port})
        self.step = 0
        self._newest_answer_us = 0
        self._wall_start: float | None = None  # when stepping began (answer to step 0)
        self._pace_anchor: tuple[float, int] = (0.0, 0)  # (wall, step) pacing is measured from
        self._status_due = 0.0
        self.state = seam.SIM_STATE_WAITING_FOR_FC

    # ---- wire ---------------------------------------------------------------------------------------
    @property
    def time_usec(self) -> int:
        return seam.time_usec_from_sim_us(self.plant.t_us)

    def _fc_text(self) -> str:
        return f"{self.fc_addr[0]}:{self.fc_addr[1]}" if self.fc_addr else "(port unknown until it announces itself)"

    def _send(self, data: bytes) -> None:
        """To the paired FC; before pairing, a pair request instead (to --fc-port, if known)."""
        if self.fc_nonce is None:
            data = self.mav.frame(*pairing_heartbeat(0))
        if self.fc_addr is None:
            return  # the FC's address is not known yet (--fc-port 0): its announcement will tell
        try:
            self.sock.sendto(data, self.fc_addr)
        except OSError:
            pass  # nobody listening yet (ICMP port unreachable surfaces here on Linux): the re-send covers it

    def _bundle(self) -> bytes:
        # the plain-float views of sense() and truth(): the same samples and bytes, no numpy views to convert back
        plant = self.plant
        return seam.encode_bundle(self.mav, self.step, plant.sense_wire(), plant.truth_wire())

    def rtf(self, now: float) -> float:
        if self._wall_start is None or now <= self._wall_start:
            return 0.0
        return (self.plant.t_us * 1e-6) / (now - self._wall_start)

    def _send_status(self, now: float, state: int | None = None) -> None:
        st = seam.SimStatus(self.time_usec, self.step, self.state if state is None else state,
                            self.opts.speed, self.rtf(now), self.counters.stalls)
        self._send(self.mav.frame(*seam.encode_sim_status(st)))
        self._status_due = now + STATUS_PERIOD_S

    def _receive(self, timeout_s: float) -> seam.ActuatorControls | None:
        """Wait up to timeout_s for datagrams; handle them; return the answer to the current step if it came.

        At --speed 0 the first SPIN_S are polled without blocking: waking a blocked process costs ~0.2 ms on
        these VMs, more than the FC's whole tick, and each of the two processes has a core of its own."""
        data = None
        if self.opts.speed == 0.0 and timeout_s > 0.0:
            self.sock.settimeout(0.0)
            spin_end = time.perf_counter() + min(SPIN_S, timeout_s)
            while data is None and time.perf_counter() < spin_end:
                try:
                    data, addr = self.sock.recvfrom(MAX_DATAGRAM)
                except (BlockingIOError, TimeoutError, ConnectionRefusedError):
                    data = None
        if data is None:
            self.sock.settimeout(max(timeout_s, 0.0))
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (TimeoutError, BlockingIOError, ConnectionRefusedError):
                # ConnectionRefused: an ICMP port-unreachable from an earlier send (FC not up yet)
                return None
        answer = self._handle(data, addr)
        # drain whatever else is already queued without waiting (keeps stale answers from piling up)
        self.sock.settimeout(0.0)
        while answer is None:
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, TimeoutError, ConnectionRefusedError):
                break
            answer = self._handle(data, addr)
        return answer

    def _handle(self, data: bytes, addr: tuple[str, int] | None = None) -> seam.ActuatorControls | None:
        """Count and decode one datagram (from addr); the answer to the current step if it holds it (else None).

        Pairing: the FC's HEARTBEAT carries its session nonce; the bridge pairs with that address (while unpaired,
        from the paired address itself, or once the paired FC has been silent REPAIR_SILENCE_S) and echoes the
        nonce. Answers and arm commands count only from the paired FC's address."""
        c = self.counters
        c.datagrams_in += 1
        if len(data) > MAX_ACCEPTED_DATAGRAM:
            c.oversize += 1
            return None
        pc = self._parse_counts
        msgs = self.codec.parse(data, pc)
        if pc.garbage_bytes or pc.bad_crc or pc.truncated or pc.unknown_id or pc.signed or pc.bad_flags:
            c.garbage_bytes += pc.garbage_bytes
            c.bad_frames += pc.bad_frames
            self._parse_counts = codec.ParseCounters()
        answer = None
        want = self.time_usec
        sysid = self.opts.sysid
        for m in msgs:
            if m.sysid != sysid or m.compid != dialect.COMPID_FC:
                c.foreign_frames += 1
                continue
            name = m.name
            if name == "HEARTBEAT":
                self._on_fc_heartbeat(int(m.fields["custom_mode"]), addr)
                continue
            if self.fc_nonce is None or addr != self.fc_addr:
                c.wrong_sender += 1
                continue
            self._fc_heard = time.perf_counter()
            if name == "HIL_ACTUATOR_CONTROLS":
                fields = m.fields
                t_ans = fields["time_usec"]
                if answer is None and (t_ans == want or self.opts.free_run and self._newest_answer_us < t_ans <= want):
                    answer = seam.decode_actuator_controls(fields, self.limits)
                    self._newest_answer_us = t_ans  # free run: the newest answer to any bundle sent so far
                    c.answers += 1
                else:
                    c.stale_answers += 1
            elif name == "NAVIG8_ARM_CMD":
                self._on_arm_cmd(m.fields)
            else:
                c.other_frames += 1
        return answer

    def _on_fc_heartbeat(self, nonce: int, addr: tuple[str, int] | None) -> None:
        """The FC's announcement: pair (echo its nonce), or refuse while another live FC is paired."""
        c = self.counters
        if nonce == 0 or addr is None:
            c.other_frames += 1
            return
        if addr == self.fc_addr and nonce == self.fc_nonce:
            return  # the same announcement again: already paired
        now = time.perf_counter()
        if self.fc_nonce is not None and addr != self.fc_addr and now - self._fc_heard < REPAIR_SILENCE_S:
            c.pair_refused += 1
            return
        self.fc_addr, self.fc_nonce, self._fc_heard = addr, nonce, now
        c.sessions += 1
        self._send(self.mav.frame(*pairing_heartbeat(nonce)))
        self._send_status(now)  # the new FC hears the status first, then the current bundle, at once
        self._resend_due = True

    def _on_arm_cmd(self, fields: dict[str, Any]) -> None:
        try:
            cmd = seam.decode_arm_cmd(fields)
        except ValueError:
            self.counters.bad_frames += 1
            return
        self.counters.arm_cmds += 1
        if cmd.joint_target_rad is not None:
            # the plant clamps to the joint limits and holds the last valid value of a non-finite entry
            self.arm.joint_targets_rad = cmd.joint_target_rad
        if cmd.gripper != seam.GRIPPER_NONE:
            self.arm.pending_gripper.append(cmd.gripper)

    def _apply_arm(self) -> None:
        """Gripper actions take effect at the start of the step being taken (deterministic: see docs)."""
        for g in self.arm.pending_gripper:
            self.plant.command_gripper(g == seam.GRIPPER_GRAB, self.grab_mass_kg)
        self.arm.pending_gripper.clear()

    # ---- loop ---------------------------------------------------------------------------------------
    def _wait_answer(self, data: bytes, first_sent: float, resend_every_s: float, startup: bool
                     ) -> seam.ActuatorControls:
        """Re-send `data` every resend_every_s until the matching answer arrives; raise _Stalled past the limit."""
        o = self.opts
        next_resend = first_sent + resend_every_s
        next_reminder = first_sent + 10.0
        while True:
            now = time.perf_counter()
            if now >= self._status_due:
                self._send_status(now)
            timeout = min(next_resend, self._status_due) - now
            ans = self._receive(timeout)
            if ans is not None:
                return ans
            if self._resend_due:
                self._resend_due = False
                self._send(data)
            now = time.perf_counter()
            if now >= next_resend:
                waited = now - first_sent
                if startup:
                    if o.startup_timeout_s > 0 and waited >= o.startup_timeout_s:
                        raise _Stalled(f"navig8-bridge: no answer from navig8-fc at {self._fc_text()}"
                                       f" within --startup-timeout {o.startup_timeout_s:g} s; "
                                       "is navig8-fc running with the same --instance/ports?")
                    if now >= next_reminder:
                        next_reminder = now + 10.0
                        print(f"navig8-bridge: still waiting for navig8-fc at {self._fc_text()} "
                              f"({waited:.0f} s)", file=sys.stderr, flush=True)
                else:
                    self.counters.stalls += 1
                    if waited >= o.stall_abort_s:
                        raise _Stalled(f"navig8-bridge: navig8-fc stalled: no actuator answer for step {self.step} "
                                       f"(t={self.plant.t_s:.3f} s) for {waited:.1f} s (--stall-abort "
                                       f"{o.stall_abort_s:g} s); stopping")
                    print(f"navig8-bridge: no actuator answer from navig8-fc for step {self.step} "
                          f"(t={self.plant.t_s:.3f} s) after {waited:.1f} s; re-sending", file=sys.stderr, flush=True)
                    self.state = seam.SIM_STATE_STALLED
                    self._send_status(now)
                self._send(data)
                self.counters.bundles_sent += 1
                self.counters.resends += 1
                next_resend = now + resend_every_s
                if not startup:
                    # the next timeout never reaches past the abort deadline by more than one step timeout
                    next_resend = min(next_resend, max(first_sent + o.stall_abort_s, now + 1e-3))

    def _pace(self) -> None:
        """At --speed N > 0, step k is not released before anchor + (t_k - t_anchor) / N."""
        if self.opts.speed <= 0:
            return
        w0, k0 = self._pace_anchor
        release = w0 + (self.step - k0) * self.dt_us * 1e-6 / self.opts.speed
        now = time.perf_counter()
        if now < release:
            time.sleep(release - now)
        elif now - release > REANCHOR_LAG_S:
            # after a stall, do not burst to catch up with wall time: continue at speed N from here
            self._pace_anchor = (now, self.step)

    def run(self) -> int:
        o = self.opts
        c = self.counters
        print(f"navig8-bridge: scenario {self.scenario.name} (seed {o.seed}), sysid {o.sysid}, dt {o.dt_s:g} s, "
              f"speed {o.speed:g}{' (as fast as possible)' if o.speed == 0 else 'x'}, "
              + (f"bound {o.host}:{self.port}" if o.link is None else f"link {o.link}") + f", FC at {self._fc_text()}"
              + (f", {self.budget.line()}" if self.budget is not None else "")
              + (f", until done at t={self.n_steps * self.dt_us * 1e-6:g} s" if o.until_done else ""),
              file=sys.stderr, flush=True)
        gc.collect()
        gc.freeze()  # start-up objects live for the whole run: keep them out of every later collection
        # startup: re-send step 0 until the FC answers it (the plant waits at t = 0)
        data = self._bundle()
        now = time.perf_counter()
        self._send_status(now)
        self._send(data)
        c.bundles_sent += 1
        ans = self._wait_answer(data, now, STREAM_STARTUP_RESEND_S if isinstance(self.sock, StreamTransport)
                                else STARTUP_RESEND_S, startup=True)
        now = time.perf_counter()
        self._wall_start = now
        self._pace_anchor = (now, 0)
        self.state = seam.SIM_STATE_RUNNING
        self._send_status(now)
        dt_us = self.dt_us
        plant, mav, arm, sock = self.plant, self.mav, self.arm, self.sock
        until_done, n_steps, paced, step_timeout_s = o.until_done, self.n_steps, o.speed > 0, o.step_timeout_s
        encode_bundle, perf_counter = seam.encode_bundle, time.perf_counter
        if o.free_run:
            return self._run_free(ans)
        while True:
            if until_done and self.step >= n_steps:
                break
            # zero-order hold of the answer for one control period
            cmd = ActuatorCommand(ans.tilt_rad, ans.speed_rad_s, arm.joint_targets_rad)
            if arm.pending_gripper:
                self._apply_arm()
            plant.step_us(cmd, dt_us)
            self.step += 1
            c.steps += 1
            data = encode_bundle(mav, self.step, plant.sense_wire(), plant.truth_wire())  # self._bundle()
            if paced:
                self._pace()
            now = perf_counter()
            try:  # self._send(data); fc_addr is known: the FC answered step 0
                sock.sendto(data, self.fc_addr)
            except OSError:
                pass
            c.bundles_sent += 1
            if now >= self._status_due:
                self._send_status(now)
            ans = self._receive(min(step_timeout_s, self._status_due - now))
            if ans is None:  # slow answer or status due: the careful path (status, re-sends, stall abort)
                ans = self._wait_answer(data, now, step_timeout_s, startup=False)
                self.state = seam.SIM_STATE_RUNNING
        now = time.perf_counter()
        self.state = seam.SIM_STATE_DONE
        for _ in range(3):  # the FC's --until-done exits on it: do not let one lost datagram hang it
            self._send_status(now)
        return EXIT_OK

    def _run_free(self, ans: seam.ActuatorControls) -> int:
        """Real time (--free-run): step k is released at anchor + t_k / speed whatever the FC does; the plant holds
        the newest answer (zero-order hold), answers to older bundles are counted stale. No answer for
        --stall-abort s: exit 3, as in lockstep."""
        o, c, plant, arm = self.opts, self.counters, self.plant, self.arm
        period = self.dt_us * 1e-6 / o.speed
        last_answer = anchor = time.perf_counter()
        k0 = 0
        while not (o.until_done and self.step >= self.n_steps):
            release = anchor + (self.step + 1 - k0) * period
            while (now := time.perf_counter()) < release:
                if now >= self._status_due:
                    self._send_status(now)
                got = self._receive(release - now)
                if got is not None:
                    ans, last_answer = got, time.perf_counter()
            if now - release > REANCHOR_LAG_S:  # fell behind (a stall): continue from here, no burst
                anchor, k0 = now, self.step
            if now - last_answer > o.stall_abort_s:
                raise _Stalled(f"navig8-bridge: navig8-fc stalled: no actuator answer for {now - last_answer:.1f} s "
                               f"(--stall-abort {o.stall_abort_s:g} s, free run); stopping")
            if arm.pending_gripper:
                self._apply_arm()
            plant.step_us(ActuatorCommand(ans.tilt_rad, ans.speed_rad_s, arm.joint_targets_rad), self.dt_us)
            self.step += 1
            c.steps += 1
            self._send(self._bundle())
            c.bundles_sent += 1
        self.state = seam.SIM_STATE_DONE
        for _ in range(3):
            self._send_status(time.perf_counter())
        return EXIT_OK

    def summary_line(self) -> str:
        now = time.perf_counter()
        wall = now - self._wall_start if self._wall_start is not None else 0.0
        return (f"navig8-bridge: {self.counters.steps} steps, t = {self.plant.t_s:.3f} s, wall {wall:.2f} s, "
                f"RTF {self.rtf(now):.1f}; {self.counters.line()}")

    def close(self) -> None:
        self.sock.close()


def build_arg_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="navig8-bridge", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="ground", help="scenario name (params/scenarios) or YAML file")
    ap.add_argument("--seed", type=int, default=1, help="sensor-noise seed")
    ap.add_argument("--speed", type=float, default=1.0, help="1 real time, N N x real time, 0 as fast as possible")
    ap.add_argument("--instance", type=int, default=0, help="vehicle N: sysid N+1, ports 4560+2N / 4561+2N")
    ap.add_argument("--bridge-port", type=int, default=None,
                    help="UDP port the bridge binds (default 4560+2N; 0: any free port, see --ports-file)")
    ap.add_argument("--fc-port", type=int, default=None,
                    help="UDP port navig8-fc listens on (default 4561+2N; 0: learn it from the FC's announcement)")
    ap.add_argument("--host", default="127.0.0.1", help="address to bind and of the FC")
    ap.add_argument("--free-run", action="store_true",
                    help="real time: step on the wall clock at --speed with the newest answer, never wait for the FC "
                         "(for navig8-fc --timing realtime or a board; docs/hil.md)")
    ap.add_argument("--link", default=None, metavar="CONN",
                    help="the FC link as a connection string instead of --bridge-port/--fc-port: udpin:H:P, "
                         "udpout:H:P, tcpin:H:P (PX4's simulator side, 4560), tcp:H:P, serial:DEVICE:BAUD "
                         "(the bundle must fit the line: docs/hil.md)")
    ap.add_argument("--until-done", action="store_true",
                    help="stop at the scenario's duration, send NAVIG8_SIM_STATUS done and exit 0")
    ap.add_argument("--duration", type=float, default=None, help="override the scenario's duration (s)")
    ap.add_argument("--dt", type=float, default=0.01, help="control period (s); must equal 1/INDI_RATE_HZ of the FC")
    ap.add_argument("--step-timeout", type=float, default=2.0, help="wall s to wait for an answer before re-sending")
    ap.add_argument("--stall-abort", type=float, default=20.0,
                    help="wall s without an answer for one step before exiting with code 3")
    ap.add_argument("--startup-timeout", type=float, default=0.0,
                    help="wall s to wait for the FC's first answer (0: forever)")
    ap.add_argument("--grab-mass", type=float, default=None,
                    help="mass (kg) of the object a gripper GRAB picks up (default: the scenario's object)")
    ap.add_argument("--ports-file", default=None, help='after binding, write {"bridge": port} here as JSON')
    ap.add_argument("--world", action="append", default=[], metavar="NAME=VALUE",
                    help="override the plant/scenario/vehicle (NAME*=VALUE scales; names: sim_bridge/world.py)")
    ap.add_argument("--write-fc-vehicle", default=None, metavar="FILE",
                    help="write the vehicle the flight controller should know in this world (the vehicle file with "
                         "the --world overrides of vehicle.* and fc_vehicle.* applied) to FILE for navig8-fc "
                         "--vehicle, and exit")
    return ap


def options_from_args(a: argparse.Namespace) -> BridgeOptions:
    return BridgeOptions(
        scenario=a.scenario, seed=a.seed, speed=a.speed, instance=a.instance, bridge_port=a.bridge_port,
        fc_port=a.fc_port, host=a.host, until_done=a.until_done, duration_s=a.duration, dt_s=a.dt,
        step_timeout_s=a.step_timeout, stall_abort_s=a.stall_abort, startup_timeout_s=a.startup_timeout,
        grab_mass_kg=a.grab_mass, ports_file=Path(a.ports_file) if a.ports_file else None,
        world=tuple(parse_world_items(a.world).items()), link=a.link, free_run=a.free_run,
    )


def _raise_shutdown(signum: int, _frame: Any) -> None:
    raise _Shutdown(signal.Signals(signum).name)


def main(argv: list[str] | None = None) -> int:
    ap = build_arg_parser()
    args = ap.parse_args(argv)
    if args.scenario.endswith((".yaml", ".yml")) and not Path(args.scenario).is_file():
        ap.error(f"no scenario file {args.scenario}")
    if args.link:
        try:
            parse_connection(args.link)
        except ValueError as e:
            ap.error(str(e))
    if args.write_fc_vehicle:
        import yaml

        from sim_bridge.world import world_documents

        try:
            docs = world_documents(args.scenario, parse_world_items(args.world))
        except (ValueError, FileNotFoundError) as e:
            ap.error(str(e))
        Path(args.write_fc_vehicle).parent.mkdir(parents=True, exist_ok=True)
        Path(args.write_fc_vehicle).write_text(yaml.safe_dump(docs["fc_vehicle"], sort_keys=False))
        return 0
    signal.signal(signal.SIGINT, _raise_shutdown)
    signal.signal(signal.SIGTERM, _raise_shutdown)
    bridge: Bridge | None = None
    try:
        try:
            bridge = Bridge(options_from_args(args))
        except (ValueError, FileNotFoundError) as e:
            print(f"navig8-bridge: {e}", file=sys.stderr)
            return EXIT_USAGE
        except PortInUseError as e:
            print(f"navig8-bridge: {e.proto} {e.host}:{e.port} is in use by another process; choose another with "
                  + ("--link" if args.link else "--bridge-port (0: any free port) or --instance"), file=sys.stderr)
            return EXIT_USAGE
        except OSError as e:
            where = args.link or f"{args.host}:{args.bridge_port or BASE_BRIDGE_PORT + 2 * args.instance}"
            print(f"navig8-bridge: cannot open {where}: {e}", file=sys.stderr)
            return EXIT_START
        rc = bridge.run()
        print(bridge.summary_line(), file=sys.stderr)
        return rc
    except _Shutdown as e:
        if bridge is not None:
            print(f"navig8-bridge: {e}, stopping; " + bridge.summary_line().removeprefix("navig8-bridge: "),
                  file=sys.stderr)
        return EXIT_OK
    except _Stalled as e:
        print(str(e), file=sys.stderr)
        if bridge is not None:
            print(bridge.summary_line(), file=sys.stderr)
        return EXIT_STALL
    except PlantDivergedError as e:
        print(f"navig8-bridge: plant diverged: {e}", file=sys.stderr)
        return EXIT_DIVERGED
    finally:
        if bridge is not None:
            bridge.close()
        # a second signal during shutdown (the terminal's Ctrl-C and navig8-sitl's forward) must neither print a
        # traceback nor kill us on the way out
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["Bridge", "BridgeCounters", "BridgeOptions", "build_arg_parser", "default_grab_mass", "main"]
