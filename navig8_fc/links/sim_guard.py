"""The FC's guard on the sim link: pairing with one bridge, strict step sequencing, sensor validation.

No sockets and no clocks of its own (the caller passes the source address of each datagram and its wall time),
so the fast-lane tests drive it directly; `fc_process` feeds it every sim-link datagram (docs/bridge.md,
"Pairing and sequencing", "Sensor validation").

Pairing (a session): the FC announces itself with a HEARTBEAT whose custom_mode is a fresh 32-bit session nonce;
the bridge answers with a HEARTBEAT (its component, 25) echoing the nonce. From then on the FC takes bundles and
NAVIG8_SIM_STATUS only from that address with the bridge's system and component ids, and sends its answers only
there. A bridge that starts later (or restarts) asks with a HEARTBEAT whose custom_mode is 0 (a pair request); the
FC answers it with a new nonce only while unpaired, when the request comes from the paired address itself (only
the process that owns that port can send from it), or when the paired bridge has been silent for REPAIR_SILENCE_S
(it sends NAVIG8_SIM_STATUS at 1 Hz at least, so a live bridge is never that silent). A new session is the only
way time may go back (the explicit reset). Once paired, every bundle and status must carry a MAVLink 2 signature
with the session's key (`session_key`, from the nonce): the source address alone authenticates nothing, since a
process with raw sockets can send from any address.

Sequencing: a bundle is one datagram holding exactly ODOMETRY, NAVIG8_ACTUATOR_STATE, NAVIG8_ARM_STATE,
(NAVIG8_TRUTH), HIL_SENSOR of one stamp, in that order (fragments never join across datagrams). The first bundle
of a session may carry any stamp; after it only the next step (step + 1, time_usec + the session's dt) runs the
controller, the current step again is a duplicate (the FC re-sends its answer), anything else is dropped. In real
time (and on PX4's simulator messages) any newer stamp is taken, but not one more than STAMP_LEAP_MAX_US ahead
unless STAMP_LEAP_CONFIRM bundles in a row continue from it: one far-future stamp cannot make every later bundle
"older".

Validation: every value finite, in the range a sensor of this vehicle can report, and (position) no faster than
MAX_SPEED_M_S from the last accepted sample, over at most MOCAP_GAP_MAX_S (SensorValidator). A group that fails
(IMU, motion capture, actuators, arm) is replaced by its last accepted values and counted; how long a group has been
failing (`bad_data_s`) feeds the FC's failsafe (navig8_fc/flight/failsafe.py, BAD_DATA_FAILSAFE_S). Truth that is
not finite is dropped from the log (it never reaches control).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from navig8_fc.mavlink import seam
from navig8_fc.mavlink.codec import Message
from navig8_fc.mavlink.dialect import COMPID_BRIDGE

REPAIR_SILENCE_S = 3.0  # wall s the paired bridge must be silent before another may pair
REPORT_PERIOD_S = 10.0  # wall s between STATUSTEXT reports of one kind of refusal
SEVERITY_WARNING, SEVERITY_INFO = 4, 6  # MAV_SEVERITY
# Physical limits of the sensors and the vehicle (a value outside is not a measurement of this vehicle):
GYRO_MAX_RAD_S = 35.0  # 2000 deg/s, the range of common MEMS gyros (ICM-42688: +-2000 dps)
ACCEL_MAX_M_S2 = 16 * 9.80665  # +-16 g, the same IMU's largest range
POS_MAX_M = 10_000.0  # the flight area (NED from the origin)
VEL_MAX_M_S = 50.0
MAX_SPEED_M_S = 30.0  # position jump between accepted samples <= MAX_SPEED_M_S * dt + MOCAP_JUMP_M
MOCAP_JUMP_M = 0.05  # 50 sigma of the motion capture's position noise (sim_bridge.params: 1 mm)
MOCAP_GAP_MAX_S = 0.5  # the jump check's dt at most this: the allowance stops growing (15 m) however long the gap
MOCAP_REANCHOR_SAMPLES = 10  # after a refused jump, this many mutually consistent samples are taken (re-acquired)
STAMP_LEAP_MAX_US = 1_000_000  # real time / PX4: a stamp this far past the last one is refused ...
STAMP_LEAP_CONFIRM = 10  # ... unless this many bundles in a row continue from it (the simulator really moved on)
SESSION_KEY_LABEL = b"navig8 sim link session key"
QUAT_NORM_TOL = 0.05  # |q| within 1 +- this (float32 and the mocap's attitude noise are far below)
ACTUATOR_MARGIN = 1.2  # measured tilt / speed up to 20 % beyond the command limits (overshoot)
JOINT_MARGIN_RAD = 0.5  # beyond the joint limit
JOINT_RATE_MAX_RAD_S = 50.0

_QUAT_N2_LO, _QUAT_N2_HI = (1.0 - QUAT_NORM_TOL) ** 2, (1.0 + QUAT_NORM_TOL) ** 2
_BUNDLE_NAMES = ["ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "NAVIG8_TRUTH", "HIL_SENSOR"]
_BUNDLE_NAMES_NO_TRUTH = ["ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "HIL_SENSOR"]
GROUPS = ("imu", "mocap", "actuators", "arm")


def pairing_heartbeat(nonce: int) -> seam.Record:
    """The sim link's pairing HEARTBEAT (seam.announce_record with custom_mode = nonce): the FC's announcement
    (its session nonce), the bridge's echo of it, or (nonce 0) the bridge's pair request."""
    name, v = seam.announce_record()  # HEARTBEAT values: type, autopilot, base_mode, custom_mode, ...
    return name, (*v[:3], int(nonce) & 0xFFFFFFFF, *v[4:])


def session_key(nonce: int, sysid: int) -> bytes:
    """The sim link's MAVLink 2 signing key for the session opened by `nonce` (both sides derive it: the FC from
    the nonce it announced, the bridge from the one it echoed). The nonce crosses the link once, in clear, to the
    bridge's address: a process that cannot read that traffic cannot sign (docs/bridge.md, "Authenticated
    bundles")."""
    return hashlib.sha256(SESSION_KEY_LABEL + (int(nonce) & 0xFFFFFFFF).to_bytes(4, "little")
                          + bytes((int(sysid) & 0xFF,))).digest()


@dataclass
class SimGuardCounters:
    """What the guard refused, by kind (logged in fc_stats and /fc/sim_guard, reported by STATUSTEXT)."""

    wrong_sender: int = 0  # bundles / status / acks from an address or ids other than the paired bridge
    pair_refused: int = 0  # pair requests while a live bridge is paired
    sessions: int = 0  # pairings (the first, and every reset)
    malformed: int = 0  # datagrams that are not exactly one bundle (fragments, extra or missing frames)
    out_of_order: int = 0  # bundles of the paired bridge that are neither the next step nor the current one
    duplicates: int = 0  # the current step again (a bridge re-send): answered again, control not re-run
    invalid: int = 0  # bundles with at least one group rejected (non-finite, out of range, implausible)
    invalid_imu: int = 0
    invalid_mocap: int = 0
    invalid_actuators: int = 0
    invalid_arm: int = 0
    invalid_truth: int = 0  # not finite: dropped from the log
    unpaired_bundles: int = 0  # bundles before any pairing
    repeated_echoes: int = 0  # the paired bridge's echo of the nonce it paired with, again (its re-echo): ignored
    unauthenticated: int = 0  # bundles / status from the paired address not signed with the session key
    stamp_leaps: int = 0  # bundles stamped more than STAMP_LEAP_MAX_US past the last one: refused
    mocap_reanchors: int = 0  # motion capture re-acquired after a refused jump (MOCAP_REANCHOR_SAMPLES consistent)


class SimInput(NamedTuple):
    """What one datagram means to the FC."""

    kind: str  # "step", "duplicate", "status", "none"
    bundle: seam.StepBundle | None = None  # "step": the validated bundle (rejected groups hold the last good values)
    wire: dict[str, Message] | None = None  # "step": the bundle's messages for the log (None if a group failed)
    status: seam.SimStatus | None = None  # "status"
    bad_groups: tuple[str, ...] = ()  # "step": the groups replaced by their last good values
    time_usec: int = 0  # "duplicate": the stamp sent again (answered again only if it is the step last flown)


@dataclass(frozen=True)
class SensorLimits:
    tilt_max_rad: float
    duct_speed_max_rad_s: float
    tail_speed_max_rad_s: float
    joint_limit_rad: float

    @staticmethod
    def from_vehicle(vehicle: Any) -> SensorLimits:
        lim = seam.ControlsScale.from_vehicle(vehicle)
        return SensorLimits(lim.tilt_max_abs_rad * ACTUATOR_MARGIN, lim.duct_speed_max_rad_s * ACTUATOR_MARGIN,
                            lim.tail_speed_max_rad_s * ACTUATOR_MARGIN, float(vehicle.joint_limit_rad)
                            + JOINT_MARGIN_RAD)


def _within3(v: Sequence[float], bound: float) -> bool:
    """The 3 entries finite and |x| <= bound (a NaN fails every comparison, so it fails here too). Unrolled: it runs
    several times on every lockstep step."""
    return -bound <= v[0] <= bound and -bound <= v[1] <= bound and -bound <= v[2] <= bound


def _finite_values(values: Sequence[Any]) -> bool:
    """Every float in a message's values (arrays as tuples) finite: a NaN or an infinity makes the sum non-finite
    (a sum that overflows would need values near 1e308, not finite measurements either)."""
    total = 0.0
    for x in values:
        t = type(x)
        if t is tuple:
            total += sum(x)
        elif t is float:
            total += x
    return total - total == 0.0


class StreamRegrouper:
    """A stream link's (TCP, serial) frames cut into datagram-like groups for `SimGuard.on_datagram`: a read ends
    anywhere between frames, so a bundle may span two reads. A HEARTBEAT or NAVIG8_SIM_STATUS between bundles is a
    group of its own; a bundle ends with its last message (HIL_SENSOR). A group longer than a bundle is handed on
    as it is, for the guard to count as malformed."""

    def __init__(self) -> None:
        self._pending: list[Message] = []

    def split(self, msgs: list[Message]) -> list[list[Message]]:
        out: list[list[Message]] = []
        pending = self._pending
        for m in msgs:
            name = m.name
            if not pending and name in ("HEARTBEAT", "NAVIG8_SIM_STATUS"):
                out.append([m])
                continue
            pending.append(m)
            if name == _BUNDLE_NAMES[-1] or len(pending) >= len(_BUNDLE_NAMES):
                out.append(pending)
                pending = self._pending = []
        return out


@dataclass
class SensorValidator:
    """One session's sensor checks (module docstring): each group finite, in range and plausible, a failing group
    replaced by its last accepted values. The motion capture's jump allowance grows with the time since its last
    accepted sample only up to MOCAP_GAP_MAX_S; a sample beyond it is refused until MOCAP_REANCHOR_SAMPLES samples in
    a row agree with each other (the vehicle re-acquired where it now is), so no gap makes any position plausible."""

    limits: SensorLimits
    counters: SimGuardCounters
    good: seam.StepBundle | None = None  # the last bundle's accepted values, per group
    pos_good_us: int = 0  # time_usec of the last accepted motion-capture sample
    candidate: tuple[tuple[float, float, float], int, int] | None = None  # refused jump: (pos, time_usec, run length)

    def _mocap_ok(self, b: seam.StepBundle) -> bool:
        q = b.quat_wxyz
        n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]  # NaN fails the comparison, inf the bound
        if not (_within3(b.pos_ned_m, POS_MAX_M) and _within3(b.vel_ned_m_s, VEL_MAX_M_S)
                and _QUAT_N2_LO <= n2 <= _QUAT_N2_HI):
            return False
        prev = self.good
        gap_s = min((b.time_usec - self.pos_good_us) * 1e-6, MOCAP_GAP_MAX_S)
        if prev is None or _near(prev.pos_ned_m, b.pos_ned_m, gap_s):
            self.candidate = None
            return True
        cand = self.candidate
        run = cand[2] + 1 if cand is not None and _near(cand[0], b.pos_ned_m, (b.time_usec - cand[1]) * 1e-6) else 1
        self.candidate = (b.pos_ned_m, b.time_usec, run)  # type: ignore[assignment]
        if run < MOCAP_REANCHOR_SAMPLES:
            return False
        self.candidate = None
        self.counters.mocap_reanchors += 1
        return True

    def check(self, b: seam.StepBundle) -> tuple[seam.StepBundle, tuple[str, ...]]:
        """The bundle with every failing group replaced by its last good values, and the failing groups. With no
        good values yet a failing group keeps its (bad) values: the caller then must not run control on it."""
        lim = self.limits
        prev = self.good
        bad: list[str] = []
        if not (_within3(b.gyro_frd_rad_s, GYRO_MAX_RAD_S) and _within3(b.accel_frd_m_s2, ACCEL_MAX_M_S2)):
            bad.append("imu")
        if self._mocap_ok(b):
            self.pos_good_us = b.time_usec
        else:
            bad.append("mocap")
        sp, tilt = b.prop_speed_rad_s, b.duct_tilt_rad
        tb, db, tlb = lim.tilt_max_rad, lim.duct_speed_max_rad_s, lim.tail_speed_max_rad_s
        if not (-tb <= tilt[0] <= tb and -tb <= tilt[1] <= tb and -db <= sp[0] <= db and -tlb <= sp[1] <= tlb
                and -db <= sp[2] <= db):
            bad.append("actuators")
        if not (_within3(b.joint_pos_rad, lim.joint_limit_rad) and _within3(b.joint_rate_rad_s, JOINT_RATE_MAX_RAD_S)):
            bad.append("arm")
        if not bad:
            self.good = b
            return b, ()
        if prev is None:
            return b, tuple(bad)
        fix: dict[str, Any] = {}
        if "imu" in bad:
            fix.update(gyro_frd_rad_s=prev.gyro_frd_rad_s, accel_frd_m_s2=prev.accel_frd_m_s2)
        if "mocap" in bad:
            fix.update(pos_ned_m=prev.pos_ned_m, vel_ned_m_s=prev.vel_ned_m_s, quat_wxyz=prev.quat_wxyz)
        if "actuators" in bad:
            fix.update(duct_tilt_rad=prev.duct_tilt_rad, prop_speed_rad_s=prev.prop_speed_rad_s)
        if "arm" in bad:
            fix.update(joint_pos_rad=prev.joint_pos_rad, joint_rate_rad_s=prev.joint_rate_rad_s)
        good = b._replace(**fix)
        self.good = good._replace(truth=None)
        return good, tuple(bad)


def _near(p0: Sequence[float], p1: Sequence[float], dt_s: float) -> bool:
    """p1 within MAX_SPEED_M_S * dt_s + MOCAP_JUMP_M of p0 on every axis."""
    jump = MAX_SPEED_M_S * dt_s + MOCAP_JUMP_M
    return abs(p1[0] - p0[0]) <= jump and abs(p1[1] - p0[1]) <= jump and abs(p1[2] - p0[2]) <= jump


@dataclass
class SimGuard:
    """One FC's view of its sim link (module docstring). `new_nonce` gives session nonces (nonzero 32-bit)."""

    sysid: int
    limits: SensorLimits
    new_nonce: Callable[[], int]
    counters: SimGuardCounters = field(default_factory=SimGuardCounters)
    # real-time mode: any newer step is taken (a lost datagram leaves a gap); lockstep: only the next one
    monotonic: bool = False
    peer: tuple[str, int] | None = None
    nonce: int = 0
    last_heard_s: float = -math.inf  # wall time of the last datagram from the paired bridge
    _step: int | None = None
    _time_usec: int | None = None
    _dt_us: int | None = None
    _pair_asked_by: tuple[str, int] | None = None  # a pair request answered, its echo not yet come
    _spent_nonce: int = 0  # the nonce the current session was opened with (its echo again is a re-echo)
    # the session's signing key (None: no session, or PX4's simulator messages, which carry no nonce to derive it)
    session_key: bytes | None = None
    _values: SensorValidator | None = None
    _leap: tuple[int, int] | None = None  # (time_usec, count) of stamps leaping ahead, to confirm
    _bad_since_us: int | None = None  # sim time the current run of invalid bundles began
    _asm: seam.BundleAssembler = field(default_factory=seam.BundleAssembler)  # one per guard: building one costs
    _notices: dict[str, tuple[str, int]] = field(default_factory=dict)  # kind -> (latest text, count unreported)
    _reported_s: dict[str, float] = field(default_factory=dict)  # kind -> wall time of its last report

    def __post_init__(self) -> None:
        self.nonce = self._fresh_nonce()
        self._values = SensorValidator(self.limits, self.counters)

    def _fresh_nonce(self) -> int:
        n = int(self.new_nonce()) & 0xFFFFFFFF
        return n if n else 1

    # --- pairing -----------------------------------------------------------------------------------------
    def announce_record(self) -> seam.Record:
        """The FC's HEARTBEAT on the sim link: custom_mode carries the session nonce the bridge must echo."""
        return pairing_heartbeat(self.nonce)

    def may_pair(self, addr: tuple[str, int], now_s: float) -> bool:
        return self.peer is None or addr == self.peer or now_s - self.last_heard_s >= REPAIR_SILENCE_S

    def needs_announce(self, now_s: float) -> bool:
        """Announce (every wall second) while unpaired, after the bridge fell silent, or while a pair request is
        unanswered by its echo (the echo or our answer was lost: the bridge echoes again when it hears us again)."""
        return self.peer is None or self._pair_asked_by is not None or now_s - self.last_heard_s >= REPAIR_SILENCE_S

    @property
    def pair_asked_by(self) -> tuple[str, int] | None:
        """Who asked to pair (a pair request answered) and has not echoed our nonce yet: where announcements go."""
        return self._pair_asked_by

    def _on_heartbeat(self, m: Message, addr: tuple[str, int], now_s: float) -> tuple[str, int] | None:
        """A bridge HEARTBEAT: a pair request (custom_mode 0) gets the announcement back (returns where to send it);
        the echo of our nonce opens a session. The paired bridge echoes again when our announcement comes again (an
        echo lost on the way): an echo of the nonce this session was opened with is that re-echo, ignored."""
        custom = int(m.fields["custom_mode"])
        if not self.may_pair(addr, now_s):
            self.counters.pair_refused += 1
            self._notice("pair_refused", f"Sim link: pairing refused {addr[0]}:{addr[1]}")
            return None
        if custom == 0:
            self._pair_asked_by = addr
            return addr
        if addr == self.peer and custom == self._spent_nonce:
            self.counters.repeated_echoes += 1
            self.last_heard_s = now_s
            return None
        if custom != self.nonce:
            self.counters.wrong_sender += 1
            self._notice("wrong_sender", f"Sim link: wrong nonce from {addr[0]}:{addr[1]}")
            return None
        self._spent_nonce = custom
        self.nonce = self._fresh_nonce()  # the echoed nonce is spent: a replayed ack cannot open another session
        self._open_session(addr, now_s)
        self.session_key = session_key(custom, self.sysid)  # from now on every bundle and status must be signed
        return None

    def _open_session(self, addr: tuple[str, int], now_s: float) -> None:
        """A new session with the peer at addr: sequencing and the last good values start afresh."""
        self.peer = addr
        self.last_heard_s = now_s
        self._pair_asked_by = None
        self._step = self._time_usec = self._dt_us = None
        self._leap = None
        self.session_key = None
        self._values = SensorValidator(self.limits, self.counters)
        self._bad_since_us = None
        self.counters.sessions += 1
        self._notice("session", f"Sim link paired: {addr[0]}:{addr[1]} ({self.counters.sessions})")

    def admit_simulator(self, addr: tuple[str, int], now_s: float, configured: tuple[str, int] | None) -> bool:
        """PX4's simulator messages carry no nonce, so the peer is pinned instead: the configured one (a tcp: or
        udpout: connection, the default UDP target) or else the first that sends. Every datagram from another
        address is refused and counted; without a configured peer another may take over only once the pinned one
        has been silent for REPAIR_SILENCE_S (a restarted simulator on a new port), as a bridge may re-pair."""
        if addr == self.peer:
            self.last_heard_s = now_s
            return True
        if (configured is None or addr == configured) and (self.peer is None
                                                             or now_s - self.last_heard_s >= REPAIR_SILENCE_S):
            self._open_session(addr, now_s)
            return True
        self.counters.wrong_sender += 1
        self._notice("wrong_sender", f"Sim link: dropped {addr[0]}:{addr[1]} (not the simulator)")
        return False

    # --- datagrams -----------------------------------------------------------------------------------------
    def on_datagram(self, msgs: list[Message], addr: tuple[str, int], now_s: float
                    ) -> tuple[SimInput, tuple[str, int] | None]:
        """One datagram's codec records from addr at wall time now_s -> (what it means, where to send an
        announcement in reply or None)."""
        c = self.counters
        n = len(msgs)
        m0 = msgs[0] if n else None
        if m0 is None:
            return _NONE, None  # nothing decoded (garbage): counted by the link's parser
        name0 = m0.name
        single = n == 1 and name0 in ("HEARTBEAT", "NAVIG8_SIM_STATUS")
        if not single:
            names = [m.name for m in msgs]
            if names != _BUNDLE_NAMES and names != _BUNDLE_NAMES_NO_TRUTH:
                c.malformed += 1  # whoever sent it: parts never join across datagrams
                self._notice("malformed", f"Sim link: partial bundle from {addr[0]}:{addr[1]}")
                return _NONE, None
        sysid = self.sysid
        for m in msgs:
            if m.sysid != sysid or m.compid != COMPID_BRIDGE:
                c.wrong_sender += 1
                self._notice("wrong_sender", f"Sim link: dropped {addr[0]}:{addr[1]} (ids)")
                return _NONE, None
        if name0 == "HEARTBEAT":
            return _NONE, self._on_heartbeat(m0, addr, now_s)
        if addr != self.peer:
            if self.peer is None:
                c.unpaired_bundles += 1
            else:
                c.wrong_sender += 1
                self._notice("wrong_sender", f"Sim link: dropped {addr[0]}:{addr[1]} (not paired)")
            return _NONE, None
        if self.session_key is not None and not all(m.signed for m in msgs):
            c.unauthenticated += 1  # the paired address, but not the paired bridge's key: a spoofed source
            self._notice("unauthenticated", f"Sim link: unsigned data from {addr[0]}:{addr[1]} dropped")
            return _NONE, None
        if single:
            self.last_heard_s = now_s
            return SimInput("status", status=seam.decode_sim_status(m0.fields)), None
        self.last_heard_s = now_s
        asm = self._asm
        asm.clear()
        for m in msgs:
            b = asm.add(m)
        if b is None:  # parts of different stamps
            c.malformed += 1
            self._notice("malformed", "Sim link: bundle parts disagree on the time")
            return _NONE, None
        return self.accept_bundle(b, asm.completed), None

    def accept_bundle(self, b: seam.StepBundle, wire: dict[str, Message]) -> SimInput:
        """A bundle of the paired peer (whole: one datagram here, or assembled from PX4's simulator messages),
        sequenced and validated: a step, a duplicate, or nothing (counted)."""
        c = self.counters
        step, tu = b.step, b.time_usec
        if self._step is not None:
            if step == self._step and tu == self._time_usec:
                c.duplicates += 1
                return SimInput("duplicate", time_usec=tu)
            dt = self._dt_us
            if self.monotonic:  # real time (FC_TIMING = 1): gaps are losses, counted by the real-time clock
                if step <= self._step or tu <= self._time_usec:
                    c.out_of_order += 1
                    return _NONE
                if tu - self._time_usec > STAMP_LEAP_MAX_US and not self._leap_confirmed(tu):
                    c.stamp_leaps += 1  # one far-future stamp must not make every later real bundle "older"
                    self._notice("stamp_leaps", f"Sim link: step stamped {(tu - self._time_usec) * 1e-6:.1f} s ahead "
                                 "refused")
                    return _NONE
            elif step != self._step + 1 or tu <= self._time_usec or (dt is not None and tu - self._time_usec != dt):
                c.out_of_order += 1
                self._notice("out_of_order", f"Sim link: step {step} out of order (at {self._step})")
                return _NONE
            self._dt_us = tu - self._time_usec
        self._step, self._time_usec = step, tu
        self._leap = None
        assert self._values is not None
        good, bad = self._values.check(b)
        truth = wire.get("NAVIG8_TRUTH")
        if truth is not None and not _finite_values(truth.values):
            c.invalid_truth += 1
            self._notice("invalid_truth", "Sim link: non-finite truth, not logged")
            good = good._replace(truth=None)
            wire.pop("NAVIG8_TRUTH", None)
        if bad:
            c.invalid += 1
            for g in bad:
                setattr(c, f"invalid_{g}", getattr(c, f"invalid_{g}") + 1)
                self._notice(f"invalid_{g}", f"Sim link: invalid {g} data, last good used")
            if self._bad_since_us is None:
                self._bad_since_us = tu
        else:
            self._bad_since_us = None
        return SimInput("step", good, None if bad else wire, bad_groups=bad)

    def bad_data_s(self) -> float:
        """How long (sim s) the sensor data has been invalid without a break (0.0 when the last bundle was good)."""
        if self._bad_since_us is None or self._time_usec is None:
            return 0.0
        return (self._time_usec - self._bad_since_us) / 1e6

    def _leap_confirmed(self, tu: int) -> bool:
        """A leaping stamp counts towards a re-sync only when it continues the leaping ones before it (newer, within
        STAMP_LEAP_MAX_US of the last): STAMP_LEAP_CONFIRM of them in a row are the simulator's new time."""
        leap = self._leap
        n = leap[1] + 1 if leap is not None and 0 < tu - leap[0] <= STAMP_LEAP_MAX_US else 1
        self._leap = (tu, n)
        return n >= STAMP_LEAP_CONFIRM

    @property
    def has_good(self) -> bool:
        """Whether every group has had good values in this session (control may run on substituted groups)."""
        return self._values is not None and self._values.good is not None

    # --- reports -------------------------------------------------------------------------------------------
    def _notice(self, kind: str, text: str) -> None:
        got = self._notices.get(kind)
        self._notices[kind] = (text, 1 if got is None else got[1] + 1)

    @property
    def has_reports(self) -> bool:
        return bool(self._notices)

    def reports(self, now_s: float) -> list[tuple[int, str]]:
        """(severity, text) to announce now: each kind at once the first time, then at most every REPORT_PERIOD_S
        with the count since its last report (a flood costs one STATUSTEXT per kind and period, not one each)."""
        out: list[tuple[int, str]] = []
        for kind, (text, n) in list(self._notices.items()):
            last = self._reported_s.get(kind)
            if kind != "session" and last is not None and now_s - last < REPORT_PERIOD_S:
                continue
            del self._notices[kind]
            self._reported_s[kind] = now_s
            more = f" (x{n})" if n > 1 else ""
            out.append((SEVERITY_INFO if kind == "session" else SEVERITY_WARNING, text + more))
        return out


_NONE = SimInput("none")


__all__ = ["COMPID_BRIDGE", "GROUPS", "REPAIR_SILENCE_S", "SensorLimits", "SensorValidator", "SimGuard",
           "SimGuardCounters", "SimInput", "pairing_heartbeat", "session_key"]
