"""navig8-bridge's link to navig8-fc: the socket (UDP, or a TCP/serial connection string), the ports file, pairing
with one FC by its announcement (docs/bridge.md, "Pairing and sequencing"), and every datagram counted and decoded.

The link knows nothing of the plant or of time steps: the lockstep loop (sim_bridge/lockstep.py) asks it for the
answer stamped with the step it waits for (`receive(timeout_s, want_usec)`), and the link hands the arm commands it
received to the loop in `arm` (applied at the next step).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from navig8_fc.links.mavlink_link import bind_udp, write_ports_file
from navig8_fc.links.sim_guard import REPAIR_SILENCE_S, pairing_heartbeat, session_key
from navig8_fc.links.transport import open_endpoint, parse_connection
from navig8_fc.mavlink import codec, dialect, seam
from sim_bridge.bridge_options import BridgeOptions
from sim_bridge.link_budget import LinkBudget, link_budget

SPIN_S = 0.002  # busy-poll window at --speed 0 (see FcLink.receive)
MAX_DATAGRAM = 65535
MAX_ACCEPTED_DATAGRAM = 4096  # the FC sends ~70-byte frames; anything this big is not it (parse nothing)


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
    unauthenticated: int = 0  # frames from the paired FC's address not signed with the session key (spoofed)
    pair_refused: int = 0  # FC announcements from another address while the paired FC is live
    sessions: int = 0  # pairings with an FC (docs/bridge.md, "Pairing and sequencing")
    echoes_repeated: int = 0  # nonce echoes sent again (the FC announced the same nonce again: the echo was lost)
    other_frames: int = 0  # valid FC frames the bridge does not use (HEARTBEAT, ...)
    datagrams_in: int = 0
    oversize: int = 0

    def line(self) -> str:
        return ", ".join(f"{k} {v}" for k, v in vars(self).items())


@dataclass
class ArmState:
    """The FC's arm commands so far: joint targets (a persistent override once commanded), gripper actions pending
    for the next step."""

    joint_targets_rad: tuple[float, float, float] | None = None
    pending_gripper: list[int] = field(default_factory=list)


class FcLink:
    """The bridge's socket to one navig8-fc: sending, receiving, pairing, decoding and counting.

    `on_paired(now)` is called when an FC pairs (after the echo of its nonce), so the loop can send its status at
    once; `resend_due` is then set: the loop sends the current bundle at once."""

    def __init__(self, opts: BridgeOptions, dt_us: int, limits: seam.ControlsScale,
                 on_paired: Callable[[float], None]) -> None:
        self.opts = opts
        self.limits = limits
        self.on_paired = on_paired
        self.codec = codec.seam_codec()
        self.mav = codec.Encoder(self.codec, opts.sysid, dialect.COMPID_BRIDGE)  # signs once paired (session key)
        self._pairing = codec.Encoder(self.codec, opts.sysid, dialect.COMPID_BRIDGE)  # pair requests, echoes: unsigned
        self.session_key: bytes | None = None  # the paired FC's frames must be signed with it (sim_guard.session_key)
        self._parse_counts = codec.ParseCounters()
        self.counters = BridgeCounters()
        self.arm = ArmState()
        # None: --fc-port 0, nothing is sent until the FC announces itself (see handle_datagram)
        self.fc_addr: tuple[str, int] | None = (opts.host, opts.fc_port_resolved) if opts.fc_port_resolved else None
        self.fc_nonce: int | None = None  # the paired FC's session nonce (None: not paired)
        self._fc_heard = -math.inf  # wall time of the paired FC's last frame
        self.resend_due = False  # a new pairing: send the current bundle at once
        self._newest_answer_us = 0
        self.budget: LinkBudget | None = None
        if opts.link is None:
            self.sock = bind_udp("bridge", (opts.host, opts.bridge_port_resolved))
        else:  # a connection string: UDP, TCP or serial (navig8_fc/links/transport.py); a serial line's budget first
            conn = parse_connection(opts.link)
            self.budget = link_budget(self.codec, conn, 1e6 / dt_us)  # ValueError: the rate does not fit
            ep = open_endpoint("bridge", conn)
            self.sock, self.fc_addr = ep.sock, (ep.targets[0] if ep.targets else None)
        self.port = int(self.sock.getsockname()[1])
        if opts.ports_file is not None:
            write_ports_file(opts.ports_file, {"bridge": self.port})

    def fc_text(self) -> str:
        return f"{self.fc_addr[0]}:{self.fc_addr[1]}" if self.fc_addr else "(port unknown until it announces itself)"

    def send(self, data: bytes) -> None:
        """To the paired FC (signed with the session's key: a datagram built before the session is signed again);
        before pairing, a pair request instead (to --fc-port, if known)."""
        if self.fc_nonce is None:
            data = self._pairing.frame(*pairing_heartbeat(0))
        elif self.session_key is not None and not self._signed_now(data):
            data = self.mav.resign(data)
        if self.fc_addr is None:
            return  # the FC's address is not known yet (--fc-port 0): its announcement will tell
        try:
            self.sock.sendto(data, self.fc_addr)
        except OSError:
            pass  # nobody listening yet (ICMP port unreachable surfaces here on Linux): the re-send covers it

    def _signed_now(self, data: bytes) -> bool:
        """Whether data's first frame is signed with the current session key."""
        frames = codec.split_frames(data)[0]
        key = self.session_key
        return bool(frames) and key is not None and frames[0][2] == codec.IFLAG_SIGNED and codec.verify_frame(
            key, frames[0])

    def receive(self, timeout_s: float, want_usec: int) -> seam.ActuatorControls | None:
        """Wait up to timeout_s for datagrams; handle them; return the answer stamped want_usec if it came.

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
        answer = self.handle_datagram(data, addr, want_usec)
        # drain whatever else is already queued without waiting (keeps stale answers from piling up)
        self.sock.settimeout(0.0)
        while answer is None:
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, TimeoutError, ConnectionRefusedError):
                break
            answer = self.handle_datagram(data, addr, want_usec)
        return answer

    def handle_datagram(self, data: bytes, addr: tuple[str, int] | None, want_usec: int,
                        now: float | None = None) -> seam.ActuatorControls | None:
        """Count and decode one datagram from addr, received at wall time now (time.perf_counter(), the default);
        the answer stamped want_usec (the step the loop waits for) if it holds it, else None.

        Pairing: the FC's HEARTBEAT carries its session nonce; the link pairs with that address (while unpaired,
        from the paired address itself, or once the paired FC has been silent REPAIR_SILENCE_S) and echoes the
        nonce. Answers and arm commands count only from the paired FC's address."""
        c = self.counters
        c.datagrams_in += 1
        if len(data) > MAX_ACCEPTED_DATAGRAM:
            c.oversize += 1
            return None
        msgs = self._parse(data)
        now = time.perf_counter() if now is None else now
        answer = None
        sysid = self.opts.sysid
        for m in msgs:
            if m.sysid != sysid or m.compid != dialect.COMPID_FC:
                c.foreign_frames += 1
                continue
            name = m.name
            if name == "HEARTBEAT":
                self._on_fc_heartbeat(int(m.fields["custom_mode"]), addr, now)
                continue
            if self.fc_nonce is None or addr != self.fc_addr:
                c.wrong_sender += 1
                continue
            if not m.signed:  # the paired FC's address, not its key: a spoofed source
                c.unauthenticated += 1
                continue
            self._fc_heard = now
            if name == "HIL_ACTUATOR_CONTROLS":
                got = self._on_answer(m.fields, want_usec, answer is None)
                answer = answer if got is None else got
            elif name == "NAVIG8_ARM_CMD":
                self._on_arm_cmd(m.fields)
            else:
                c.other_frames += 1
        return answer

    def _parse(self, data: bytes) -> list[codec.Message]:
        """The datagram's frames; what is wrong with it counted (garbage bytes, bad frames)."""
        pc = self._parse_counts
        msgs = self.codec.parse(data, pc, self.session_key)
        if pc.garbage_bytes or pc.bad_crc or pc.truncated or pc.unknown_id or pc.signed or pc.bad_flags:
            self.counters.garbage_bytes += pc.garbage_bytes
            self.counters.bad_frames += pc.bad_frames
            self._parse_counts = codec.ParseCounters()
        return msgs

    def _on_answer(self, fields: dict[str, Any], want_usec: int, first: bool) -> seam.ActuatorControls | None:
        """A HIL_ACTUATOR_CONTROLS: the answer if it is the first of this datagram for want_usec (in free run, for
        any bundle newer than the last answer's), else counted stale."""
        t_ans = fields["time_usec"]
        if first and (t_ans == want_usec or self.opts.free_run and self._newest_answer_us < t_ans <= want_usec):
            answer = seam.decode_actuator_controls(fields, self.limits)
            self._newest_answer_us = t_ans  # free run: the newest answer to any bundle sent so far
            self.counters.answers += 1
            return answer
        self.counters.stale_answers += 1
        return None

    def _on_fc_heartbeat(self, nonce: int, addr: tuple[str, int] | None, now: float) -> None:
        """The FC's announcement: pair (echo its nonce), or refuse while another live FC is paired."""
        c = self.counters
        if nonce == 0 or addr is None:
            c.other_frames += 1
            return
        if addr == self.fc_addr and nonce == self.fc_nonce:
            # the same announcement again: the FC announces only while unpaired, so our echo was lost: echo again
            # (one HEARTBEAT for one, to the paired address only)
            c.echoes_repeated += 1
            self._send_echo(nonce)
            return
        if self.fc_nonce is not None and addr != self.fc_addr and now - self._fc_heard < REPAIR_SILENCE_S:
            c.pair_refused += 1
            return
        self.fc_addr, self.fc_nonce, self._fc_heard = addr, nonce, now
        keep = getattr(self.sock, "keep", None)  # a tcpin: server never evicts the paired FC for a newer connection
        if keep is not None:
            keep(addr)
        c.sessions += 1
        self._send_echo(nonce)
        # from now on both sides sign every frame with the session's key and take only frames signed with it
        self.session_key = session_key(nonce, self.opts.sysid)
        self.mav.signing = codec.FrameSigning(self.session_key)
        self.on_paired(now)  # the new FC hears the status first, then the current bundle, at once
        self.resend_due = True

    def _send_echo(self, nonce: int) -> None:
        """The nonce echoed, unsigned (the FC derives the key from the nonce it announced)."""
        if self.fc_addr is not None:
            try:
                self.sock.sendto(self._pairing.frame(*pairing_heartbeat(nonce)), self.fc_addr)
            except OSError:
                pass  # the FC announces again, and the echo follows

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

    def close(self) -> None:
        self.sock.close()
