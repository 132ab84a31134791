"""The FC process's two strategies around its control step (docs/hil.md):

- what the sim link carries: `BundlePeer` (navig8-bridge's private bundle: pairing, sequencing and validation by the
  SimGuard, a stream's reads regrouped into one bundle each) or `Px4Peer` (PX4's simulator messages, HIL_SENSOR +
  HIL_STATE_QUATERNION, assembled into bundles; the simulator's address pinned, the same sequencing and validation;
  actuator states modelled unless the simulator sends them). Both turn received frames into `SimInput`s.
- when a step runs: `Lockstep` (at once, one per bundle; a duplicate is answered with the same command) or
  `Realtime` (the FC's own clock at INDI_RATE_HZ takes the newest bundle per tick: navig8_fc/shell/realtime.py).
"""

from __future__ import annotations

import socket
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from navig8_fc.core.controller import ActuatorCommand, ControllerConfig
from navig8_fc.flight import ArmRequest
from navig8_fc.links.mavlink_link import UdpLink
from navig8_fc.links.sim_guard import SimGuard, SimInput, StreamRegrouper
from navig8_fc.links.transport import StreamTransport
from navig8_fc.mavlink import codec, seam
from navig8_fc.mavlink.px4sim import ActuatorModel, Px4SimAssembler
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.params.registry import ParamRegistry
from navig8_fc.shell.realtime import TIMING_REALTIME, RealtimeClock


class BundlePeer:
    """navig8-bridge's bundle over the sim link, through the SimGuard (navig8_fc/links/sim_guard.py)."""

    answers_duplicates = True  # a re-sent bundle is answered with the same command (lockstep)

    def __init__(self, link: UdpLink, guard: SimGuard, bridge_target: tuple[str, int], stream: bool) -> None:
        self._link = link
        self.guard = guard
        self._bridge_target = bridge_target  # where the announcement goes until a bridge pairs
        self._stream = stream
        self._regroup = StreamRegrouper().split  # a stream's reads cut anywhere between frames: one bundle each
        self.sim_to: list[tuple[str, int]] | None = []  # answers go to the paired bridge only
        enc = link.mav  # the link's codec.Encoder: signs once a session has a key; announcements are never signed
        self._announcer = codec.Encoder(enc.codec, enc.sysid, enc.compid)
        self._keyed: bytes | None = None  # the session key the link signs and verifies with

    @property
    def incomplete(self) -> int:
        """Bundles dropped incomplete (PX4's assembler counts them; the private bundle comes whole)."""
        return 0

    def announce(self, to: tuple[str, int] | None = None) -> None:
        """Our announcement (unsigned: it carries the nonce the key comes from): to `to`, else to the bridge that
        asked to pair (until it echoes), else to the configured bridge."""
        self._link.send_raw(self._announcer.frame(*self.guard.announce_record()),
                            [to or self.guard.pair_asked_by or self._bridge_target])

    def _key_link(self) -> None:
        """A new session key: the link verifies incoming signatures and signs everything it sends with it."""
        key = self.guard.session_key
        if key is not self._keyed:
            self._keyed = key
            self._link.verify_key = key
            self._link.mav.signing = None if key is None else codec.FrameSigning(key)

    def inputs(self, received: list[Any], now: float) -> list[SimInput]:
        """The link's datagrams (codec.Message records per datagram) as SimInputs; a bridge that asks to pair gets
        our announcement with a fresh nonce."""
        guard = self.guard
        out = []
        for r in received:
            for msgs in (self._regroup(r.msg) if self._stream else (r.msg,)):
                inp, announce_to = guard.on_datagram(msgs, r.addr, now)
                if announce_to is not None:
                    self.announce(announce_to)
                if guard.peer is not None and self.sim_to[:1] != [guard.peer]:  # type: ignore[index]
                    self.sim_to = [guard.peer]
                self._key_link()
                out.append(inp)
        return out

    def reports(self, now: float) -> list[tuple[int, str]]:
        """The guard's refusals: the first of each kind at once, then one per kind and period."""
        return self.guard.reports(now) if self.guard.has_reports else []

    def on_wall_second(self, now: float) -> list[tuple[int, str]]:
        if self.guard.needs_announce(now):  # unpaired or the bridge silent: announce, for a bridge started after us
            self.announce()
        return self.guard.reports(now)  # counts held back within a period

    def commanded(self, cmd: ActuatorCommand, arm: ArmRequest | None) -> None:
        """The bridge applies the command itself (nothing to model here)."""


class Px4Peer(BundlePeer):
    """PX4's simulator messages (navig8_fc/mavlink/px4sim.py), through the same guard as the bridge's bundle: the
    simulator's address pinned (`SimGuard.admit_simulator`: the configured peer, else the first that sends; PX4's
    protocol has no nonce), frames from any other address dropped before they reach the assembler, every assembled
    step sequenced (only newer stamps) and validated (NaN, infinite, out of range, implausible groups replaced by
    their last good values, counted, reported, landing if it lasts); answers only to the pinned simulator."""

    answers_duplicates = False

    def __init__(self, link: UdpLink, guard: SimGuard, bridge_target: tuple[str, int], assembler: Px4SimAssembler,
                 configured_peer: tuple[str, int] | None) -> None:
        super().__init__(link, guard, bridge_target, stream=False)
        self._asm = assembler
        self._configured = configured_peer

    @property
    def incomplete(self) -> int:
        return self._asm.incomplete

    def inputs(self, received: list[Any], now: float) -> list[SimInput]:
        asm, guard = self._asm, self.guard
        out = []
        for r in received:
            if not guard.admit_simulator(r.addr, now, self._configured):
                continue  # another address: not one frame reaches the assembler (a forged pose would stay there)
            if self.sim_to[:1] != [guard.peer]:  # type: ignore[index]
                self.sim_to = [guard.peer]  # type: ignore[list-item]
            for m in r.msg:
                if m.name == "NAVIG8_SIM_STATUS":
                    out.append(SimInput("status", status=seam.decode_sim_status(m.fields)))
                    continue
                bundle = asm.add(m)
                if bundle is not None:
                    out.append(guard.accept_bundle(bundle, dict(asm.completed)))
        return out

    def commanded(self, cmd: ActuatorCommand, arm: ArmRequest | None) -> None:
        """The actuator model's input: what the simulator will hold (its actuator states are modelled)."""
        self._asm.command(cmd.tilt_rad, cmd.speed_rad_s)
        if arm is not None and arm.joint_target_rad is not None:
            self._asm.joint_target_rad = arm.joint_target_rad


class Lockstep:
    """One control step per bundle, at once."""

    realtime = False

    def offer(self, inp: SimInput, now: float) -> tuple[SimInput, int | None] | None:
        return inp, None

    def timeout_s(self, now: float) -> float:
        return 0.05

    def due(self, now: float) -> tuple[SimInput, int | None] | None:
        return None

    def report(self, now: float) -> str | None:
        return None

    def stats(self) -> dict[str, Any] | None:
        return None


class Realtime:
    """The FC's own clock (RealtimeClock): a bundle waits for the next tick, the newest one is flown."""

    realtime = True

    def __init__(self, clock: RealtimeClock) -> None:
        self.clock = clock

    def offer(self, inp: SimInput, now: float) -> tuple[SimInput, int | None] | None:
        self.clock.offer(inp.bundle, inp, now)
        return None

    def timeout_s(self, now: float) -> float:
        return min(0.05, self.clock.timeout_s(now))

    def due(self, now: float) -> tuple[SimInput, int | None] | None:
        got = self.clock.tick(now)
        return None if got is None else (got[1], got[2])  # (its SimInput, the FC's clock)

    def report(self, now: float) -> str | None:
        return self.clock.report(now)

    def stats(self) -> dict[str, Any] | None:
        return vars(self.clock.stats)


def configured_simulator(link: UdpLink, bridge_target: tuple[str, int], from_connection: bool
                         ) -> tuple[str, int] | None:
    """The PX4 simulator's address as configured, which Px4Peer pins: a tcp: stream's peer, udpout:'s, or the default
    UDP target (its host resolved as recvfrom reports it); None for udpin: (connection string without a target), where
    the first sender is pinned."""
    if from_connection and not link.targets:
        return None
    host, port = bridge_target
    if isinstance(link.sock, StreamTransport):
        return host, port
    try:
        return socket.gethostbyname(host), port
    except OSError:
        return host, port


def sim_peer_for(link: UdpLink, guard: SimGuard, bridge_target: tuple[str, int], messages: str,
                 from_connection: bool, config: ControllerConfig, origin: GeoOrigin) -> BundlePeer | Px4Peer:
    """What the sim link carries (`--sim-messages`): the bridge's bundle ("navig8"), or PX4's simulator messages
    ("px4": their own assembler, the simulator's address pinned instead of the nonce pairing, the same guard
    otherwise; docs/hil.md). `from_connection`: the link was given as a connection string."""
    if messages == "navig8":
        return BundlePeer(link, guard, bridge_target, isinstance(link.sock, StreamTransport))
    return Px4Peer(link, guard, bridge_target, px4_assembler(config, origin),
                   configured_simulator(link, bridge_target, from_connection))


def px4_assembler(config: ControllerConfig, origin: GeoOrigin) -> Px4SimAssembler:
    """PX4's simulator messages as the sensor source (navig8_fc/mavlink/px4sim.py, docs/hil.md): the actuator states
    modelled with the controller's actuator model (ACT_WN, ACT_ZETA at its rate) unless NAVIG8_ACTUATOR_STATE comes."""
    model = ActuatorModel(config.indi.act_wn_rad_s, config.indi.act_zeta, config.dt_s, (0.0,) * 5)
    return Px4SimAssembler(origin, model)


@dataclass(frozen=True)
class TimingSettings:
    """When a step runs, typed from the parameters (FC_TIMING and the real-time clock's)."""

    realtime: bool  # FC_TIMING = 1
    rate_hz: float  # INDI_RATE_HZ: the real-time clock's tick
    late_s: float  # RT_LATE_S
    spacing_tol: float  # RT_SPACING_TOL

    @staticmethod
    def from_params(values: Mapping[str, float]) -> TimingSettings:
        return TimingSettings(int(values["FC_TIMING"]) == TIMING_REALTIME, float(values["INDI_RATE_HZ"]),
                              float(values["RT_LATE_S"]), float(values["RT_SPACING_TOL"]))


def timing_from_params(registry: ParamRegistry, timing: str | None, now: float) -> Lockstep | Realtime:
    """When a step runs: FC_TIMING (set first from --timing, `timing`, when given): lockstep, or the real-time mode's
    clock at INDI_RATE_HZ (navig8_fc/shell/realtime.py)."""
    if timing is not None:
        registry.set("FC_TIMING", 1.0 if timing == "realtime" else 0.0)
    t = TimingSettings.from_params(registry.as_dict())
    return Realtime(RealtimeClock(t.rate_hz, t.late_s, t.spacing_tol, now)) if t.realtime else Lockstep()
