"""The FC's ground-station side: wires the pure protocol pieces (navig8_fc.gcs) to the vehicle and the links.

Depends on three seams only: the vehicle's published `VehicleState` (a callable returning the latest
snapshot), its `VehicleCommands` (the FlightStack answers arm, takeoff, land, modes, gripper, arm joints) and
an `Outbox` (broadcast / reply to the sender; the process implements it over its links), plus the parameter
registry and store it is given. It implements the command handler's `CommandTarget` (the vehicle's commands
passed on, message requests and intervals from the telemetry scheduler, parameter storage), routes inbound
GCS/API messages and sends telemetry on the wall clock. It never reads the process.

Routing (PX4 and ArduPilot behave the same): a reply to a request (COMMAND_ACK and the messages a command
produces, PARAM_VALUE answering PARAM_REQUEST_READ, the paced PARAM_REQUEST_LIST download, mission transfers
and their re-requests, FTP and TIMESYNC answers) goes only to the link and the peer the request came from.
Broadcasts go to both GCS-facing links (every peer of each): telemetry streams and HEARTBEAT, MISSION_CURRENT
and MISSION_ITEM_REACHED, STATUSTEXT (events and refusal reasons), and the PARAM_VALUE announcing the value in
force after a PARAM_SET (accepted or refused) or a PREFLIGHT_STORAGE
load/reset, so every connected GCS stays in sync.

Who may command (docs/security.md): the sender's system id must lie in GCS_SYSID..GCS_SYSID_HI (ArduPilot's
SYSID_MYGCS/SYSID_ENFORCE, as a range) unless GCS_ENFORCE is 0. A sender outside it is refused: COMMAND_LONG/INT
get COMMAND_ACK DENIED, PARAM_SET gets the value in force, a STATUSTEXT (at most one a second) tells the
operator; everything else it sends is dropped and counted (`n_unauthorised`), and its HEARTBEAT neither arms
the GCS-loss failsafe nor makes it a peer. A source is *confirmed* when it is one of the links' configured
targets (`trusted_sources`) or has sent a HEARTBEAT from an allowed id (`admits_peer`, which the links ask
before adding a peer, so telemetry goes only to confirmed peers); from an unconfirmed source only commands and
PARAM_SETs are answered (one refusal each), so a spoofed source gets no more bytes than it sends (reflection).
A HEARTBEAT is only a claim, though: the GCS-loss failsafe listens to the configured peers alone (or to anyone
once signing is on), SETUP_SIGNING is taken only disarmed and from where GCS_SIGN_LINK says
(`gcs.operator_sources`), and the links cap what a peer they cannot vouch for receives (`links.reflection`).

GCS work off the control path: a PARAM_SET whose stability floor is not cached (a ~0.1-0.3 s workspace sweep)
waits in a bounded queue while a worker *process* computes the floor (a thread would not do: numpy's batched
eigenvalue call holds the GIL for tens of ms, measured 48 ms worst vs 13 ms idle on this host); `poll` (the main
loop, between control steps) applies it when ready, in arrival order. PARAM_SETs are rate-limited per source
(PARAM_SET_RATE); saves are written by a worker thread. The floor of the values in force (LAM_MARGIN, `stability`)
is computed on the same worker process when no PARAM_SET has computed it (at start, after a reset or a load).
Without `background_params` (in-process callers) everything runs inline.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.flight.commands import (
    Land,
    SetMode,
    Takeoff,
    VehicleCommand,
)
from navig8_fc.flight.state import VehicleCommands, VehicleState
from navig8_fc.gcs import standard_modes
from navig8_fc.gcs.calibration import Calibration
from navig8_fc.gcs.commands import CommandHandler, GlobalOrbit, ServiceHandler
from navig8_fc.gcs.failure_injection import FailureInjection
from navig8_fc.gcs.ftp import FtpServer, FtpService
from navig8_fc.gcs.ftp_pacing import ReplyPacer
from navig8_fc.gcs.log_transfer import LogSource, LogTransfer, reply_cost
from navig8_fc.gcs.metadata import build_metadata, component_metadata_message
from navig8_fc.gcs.misc import MiscProtocols
from navig8_fc.gcs.mission_protocol import MissionProtocol
from navig8_fc.gcs.operator_sources import OperatorSources
from navig8_fc.gcs.params import ParamProtocol, StoredLoad
from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.gcs.vehicle_messages import VehicleMessages
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.store import MissionStore
from navig8_fc.modes.manager import TaskStatus, Verdict
from navig8_fc.modes.px4 import mode_for_standard
from navig8_fc.params.registry import ParamRegistry, SetResult, StabilityStatus
from navig8_fc.params.store import ParamStore
from navig8_fc.shell.floor_worker import ParamSets
from navig8_fc.shell.telemetry_service import (
    MAV_AUTOPILOT_GENERIC,
    MAV_AUTOPILOT_PX4,
    Source,
    Telemetry,
)

MAV_TYPE_GCS = 6
MAV_CMD_PREFLIGHT_CALIBRATION, MAV_CMD_INJECT_FAILURE = 241, 420
MSG_AVAILABLE_MODES, MSG_CURRENT_MODE, MSG_AVAILABLE_MODES_MONITOR = 435, 436, 437
AVAILABLE_MODES_SEQ = 1  # AVAILABLE_MODES_MONITOR.seq: the set of modes never changes at run time
CURRENT_MODE_PERIOD_S = 2.0

REFUSAL_TEXT_PERIOD_S = 1.0  # at most one "not authorised" STATUSTEXT a second
_COMMANDS = frozenset({"COMMAND_LONG", "COMMAND_INT"})
_WITHOUT_SIGNING = frozenset({"HEARTBEAT", "SETUP_SIGNING", "RADIO_STATUS"})  # what GCS_SIGN_REQ lets through

_BROADCAST_TYPES = frozenset({"STATUSTEXT", "HEARTBEAT"})


def _transfers(mav: Any, sysid: int, files: Mapping[str, bytes], logs: LogSource | None, text: StatusTextEncoder,
               configured: Callable[[Source | None], bool]) -> tuple[FtpService, LogTransfer]:
    """MAVFTP (the component metadata) and the log download, each paced per source; the operator's configured
    station at a ground station's pace (ftp_pacing.OPERATOR_BUDGET); the log download in buckets of its own of the
    same sizes (docs/security.md, "MAVFTP")."""
    ftp = FtpService(mav, FtpServer(files), sysid, 1, ReplyPacer(operator=configured))
    return ftp, LogTransfer(mav, sysid, 1, logs, ReplyPacer(operator=configured, cost=reply_cost), text)


def _preflight(text: StatusTextEncoder, registry: ParamRegistry, params: ParamProtocol,
               state: Callable[[], VehicleState], command: Callable[[VehicleCommand], Verdict]
               ) -> tuple[Calibration, FailureInjection, dict[int, ServiceHandler]]:
    """PREFLIGHT_CALIBRATION (its measured values applied and saved as the FC's own parameter changes) and
    INJECT_FAILURE (SYS_FAILURE_EN; a GPS loss in the air lands), and the command handler's entries for them."""
    def flying() -> bool:
        s = state()
        return s.armed and not s.landed

    cal = Calibration(text, registry.get, params.apply_own)
    failures = FailureInjection(lambda: int(registry.get("SYS_FAILURE_EN")) == 1, flying, lambda: command(Land()))
    return cal, failures, {MAV_CMD_PREFLIGHT_CALIBRATION: lambda p: cal.command(p, state().armed),
                           MAV_CMD_INJECT_FAILURE: failures.command}


class Outbox(Protocol):
    """Where GcsService's messages go (the process implements it over its GCS-facing links)."""

    def broadcast(self, msgs: list[Any], exclude: frozenset[Source] = frozenset()) -> None:
        """To every peer of every GCS-facing link, except the sources in `exclude` (peers with their own stream
        intervals, which get their telemetry by `reply`)."""
        ...

    def reply(self, source: Source, msgs: list[Any]) -> None:
        """To the one peer `source` (as given to GcsService.handle), on its link."""
        ...


def is_broadcast_reply(request_type: str, reply_type: str) -> bool:
    """Whether a message produced in answer to a `request_type` message goes to every link (module docstring):
    STATUSTEXT always; PARAM_VALUE unless it answers a PARAM_REQUEST_READ (then it is that client's reply)."""
    if reply_type in _BROADCAST_TYPES:
        return True
    return reply_type == "PARAM_VALUE" and request_type != "PARAM_REQUEST_READ"


@dataclass(frozen=True)
class GcsSettings:
    """The GCS service's parameters, typed once per parameter change (GcsService.settings)."""

    enforce_sysid: bool  # GCS_ENFORCE: only GCS_SYSID..GCS_SYSID_HI may command
    sysid_lo: int  # GCS_SYSID
    sysid_hi: int  # GCS_SYSID_HI
    signing_required: bool  # GCS_SIGN_REQ
    param_set_rate_hz: float  # PARAM_SET_RATE: PARAM_SETs per second and source
    stream_rate_max_hz: float  # GCS_RATE_MAX: the fastest stream SET_MESSAGE_INTERVAL may ask for
    command_progress: int  # GCS_CMD_PROG: 0 as the identity's autopilot, 1 IN_PROGRESS + final ACK, 2 ACCEPTED at once
    signing_setup_from: int  # GCS_SIGN_LINK: where SETUP_SIGNING may come from (gcs.operator_sources)

    @staticmethod
    def from_params(values: Mapping[str, float]) -> GcsSettings:
        return GcsSettings(int(values["GCS_ENFORCE"]) != 0, int(values["GCS_SYSID"]), int(values["GCS_SYSID_HI"]),
                           int(values["GCS_SIGN_REQ"]) != 0, float(values["PARAM_SET_RATE"]),
                           float(values["GCS_RATE_MAX"]), int(values["GCS_CMD_PROG"]), int(values["GCS_SIGN_LINK"]))

    def flight_progress(self, autopilot: int) -> bool:
        """Whether the flight task's commands get IN_PROGRESS and a final ACK (else ACCEPTED at once, as PX4)."""
        return self.command_progress == 1 or (self.command_progress == 0 and autopilot != MAV_AUTOPILOT_PX4)


class GcsService:
    def __init__(self, mav: Any, sysid: int, state: Callable[[], VehicleState], vehicle: VehicleCommands,
                 outbox: Outbox, registry: ParamRegistry, vehicle_config: VehicleConfig,
                 store: ParamStore | None = None, mission_store: MissionStore | None = None,
                 autopilot: int = MAV_AUTOPILOT_GENERIC, trusted_sources: Iterable[Source] = (),
                 background_params: bool = False, signing: Any = None, logs: LogSource | None = None) -> None:
        """mav builds messages (srcSystem = sysid, srcComponent 1); trusted_sources: confirmed without a HEARTBEAT (the
        links' configured targets); background_params: floors and saves on a worker (the process), else inline;
        signing: links.signing.LinkSigning (None: SETUP_SIGNING refused); logs: the FC's logs for the log-download
        protocol (None: no log is written)."""
        self.mav = mav
        self.sysid = int(sysid)
        self._state = state
        self._vehicle = vehicle
        self._outbox = outbox
        self.text = StatusTextEncoder(mav)
        self._registry = registry
        self._settings_generation = -1  # the registry generation `settings` was typed from
        self._settings = GcsSettings.from_params(registry.as_dict())
        self.params = ParamProtocol(registry, mav, store, statustext=self.text, armed=lambda: self._state().armed,
                                    defer_saves=background_params)
        self._autopilot = int(autopilot)
        self.calibration, self.failures, services = _preflight(self.text, registry, self.params, state, self.command)
        self.commands = CommandHandler(mav, sysid, 1, self, statustext=self.text,
                                       flight_progress=self._settings.flight_progress(self._autopilot),
                                       takeoff_p7_amsl=(px4 := self._autopilot == MAV_AUTOPILOT_PX4), orbit_z_amsl=px4,
                                       services=services)
        self.misc = MiscProtocols(mav, statustext=self.text)
        self.mission = MissionProtocol(mav, sysid, 1, mission_store, statustext=self.text,
                                       item_check=lambda item, kind: self.vehicle_msgs.item_problem(item, kind))
        # SET_MODE, offboard targets, MANUAL_CONTROL, the global origin, the plans handed to the vehicle
        self.vehicle_msgs = VehicleMessages(mav, self.sysid, state, vehicle, self.command, registry, self.params,
                                            self.text)
        self.metadata = build_metadata(registry.definitions)  # QGC's parameter metadata, served read-only over FTP
        self.ftp, self.logs = _transfers(mav, sysid, self.metadata.files, logs, self.text,
                                         lambda source: source is not None and self.operator.configured(source))
        self.n_gcs_msgs = 0
        self._last_gcs_heartbeat: float | None = None
        self.telemetry = Telemetry(mav, sysid, state, registry, vehicle_config, autopilot)
        self._intended_custom_mode = 0  # the last mode a ground station asked for (CURRENT_MODE); 0 unknown
        self._current_mode_sent: tuple[int, int] | None = None
        self._current_mode_t = -math.inf
        self._std_modes = hasattr(mav, "current_mode_encode")  # navig8.xml includes development.xml: it has them
        self._signing = signing
        self.operator = OperatorSources(trusted_sources, lambda: signing is not None and bool(signing.active),
                                        lambda: self._state().armed)  # who speaks for the operator
        self._confirmed: set[Source] = set()  # sources that sent a HEARTBEAT from an allowed system id
        self._command_source: Source | None = None  # the sender of the command being handled
        self.n_unauthorised = 0  # messages dropped or refused: sender not allowed, or source unconfirmed
        self._refusal_text_t = -math.inf
        self._now = 0.0
        self._operator_reports: list[str] = []  # told at the first ground-station contact
        self.param_sets = ParamSets(self.params, registry, background_params, self._route, self._throttled_text,
                                    self.statustext, lambda: self._state().armed)  # PARAM_SETs off the control path

    @property
    def origin(self) -> GeoOrigin:
        """The global origin (ORIGIN_*) the plans and global targets are placed about."""
        return self.vehicle_msgs.origin

    @property
    def last_offboard_setpoint(self) -> float | None:
        """Wall time (the caller's clock) of the last accepted offboard setpoint (None: none yet)."""
        return self.vehicle_msgs.last_offboard_setpoint

    @property
    def last_gcs_heartbeat(self) -> float | None:
        """Wall time (the caller's clock, as given to `handle`) of the last HEARTBEAT from a ground station."""
        return self._last_gcs_heartbeat

    def load_stored_params(self) -> StoredLoad:
        """The persisted parameter values (startup); the caller logs the outcome. What went wrong is also told
        to the first ground station that makes contact (STATUSTEXT)."""
        loaded = self.params.load_stored()
        self._operator_reports = loaded.report()
        return loaded

    # --- authorisation ---------------------------------------------------------------------------
    @property
    def settings(self) -> GcsSettings:
        """The parameters in force, typed again only after a change."""
        reg = self._registry
        if reg.generation != self._settings_generation:
            self._settings = GcsSettings.from_params(reg.as_dict())
            self._settings_generation = reg.generation
            self.commands.flight_progress = self._settings.flight_progress(self._autopilot)
        return self._settings

    def authorised(self, sysid: int) -> bool:
        """Whether a sender with this system id may command (GCS_SYSID..GCS_SYSID_HI, unless GCS_ENFORCE 0)."""
        s = self.settings
        if not s.enforce_sysid:
            return True
        return s.sysid_lo <= int(sysid) <= max(s.sysid_lo, s.sysid_hi)

    def admits_peer(self, msg: Any, addr: Any = None) -> bool:
        """Whether a link may start sending telemetry to the sender of `msg`: a HEARTBEAT from an allowed id."""
        return msg.get_type() == "HEARTBEAT" and self.authorised(msg.get_srcSystem())

    def confirmed(self, source: Source | None) -> bool:
        return self.operator.configured(source) or source in self._confirmed

    def _refuse(self, m: Any, why: str) -> list[Any]:
        """A message from a sender that may not command: one answer for a command or PARAM_SET, else nothing."""
        self.n_unauthorised += 1
        kind = m.get_type()
        out: list[Any] = []
        if kind in _COMMANDS and m.target_system in (0, self.sysid) and m.target_component in (0, 1):
            out.append(self.mav.command_ack_encode(int(m.command), 2, 0, 0, m.get_srcSystem(),  # MAV_RESULT_DENIED
                                                   m.get_srcComponent()))
        elif kind == "PARAM_SET":
            out += [r for r in self.params.refuse_set(m, why) if r.get_type() == "PARAM_VALUE"]  # text below
        return out + (self._throttled_text(f"{kind} from system {m.get_srcSystem()} refused: {why}") if out else [])

    def _throttled_text(self, text: str) -> list[Any]:
        """A refusal STATUSTEXT, at most one a second: a flood of refused requests is not a flood of texts."""
        if self._now - self._refusal_text_t < REFUSAL_TEXT_PERIOD_S:
            return []
        self._refusal_text_t = self._now
        return self.text.warning(text)

    # --- routing ---------------------------------------------------------------------------------
    def handle(self, received: list[tuple[Any, Source | None]], now_wall: float) -> list[SetResult]:
        """Inbound messages (msg, source); replies go back to the source through the outbox (module docstring).
        Without a source (in-process callers), replies are broadcast. Returns the parameter changes (set, load,
        reset outcomes) the messages caused, for the caller's log."""
        self._now = now_wall
        for m, source in received:
            self.n_gcs_msgs += 1
            kind = m.get_type()
            src_sys = m.get_srcSystem()
            if not self.authorised(src_sys):
                self._route(kind, source, self._refuse(m, f"system {src_sys} is not an allowed ground station"))
                continue
            if kind == "HEARTBEAT":
                if source is not None:
                    self._confirmed.add(source)
                if m.type == MAV_TYPE_GCS and self.operator.is_operator(source):  # the GCS-loss failsafe's input
                    self._last_gcs_heartbeat = now_wall
            elif not self.confirmed(source):
                self._route(kind, source, self._refuse(m, "send a HEARTBEAT first"))
                continue
            if (self.settings.signing_required and not (self._signing is not None and self._signing.active)
                    and kind not in _WITHOUT_SIGNING):
                self._route(kind, source, self._refuse(m, "signing required: set a key with SETUP_SIGNING"))
                continue
            if kind == "SETUP_SIGNING":
                self._route(kind, source, self._setup_signing(m, source))
                continue
            if self._operator_reports:  # the first contact: what the operator must know (a bad parameter file)
                for line in self._operator_reports:
                    self._outbox.broadcast(self.text.encode(2, line))  # MAV_SEVERITY_CRITICAL
                self._operator_reports = []
            if kind == "PARAM_SET":
                self._route(kind, source, self.param_sets.set(m, source, now_wall, self.settings.param_set_rate_hz))
                continue
            out = self.params.handle(m, now_wall, source)
            self._command_source = source  # SET/GET_MESSAGE_INTERVAL act on this peer's stream table
            out += self.commands.handle(m, now_wall, source)
            self._command_source = None
            out += self.misc.handle(m, now_wall)
            out += self.mission.handle(m, now_wall, source)
            out += self.ftp.handle(m, source, now_wall)
            out += self.logs.handle(m, source, now_wall)
            out += self.vehicle_msgs.handle(m, now_wall)
            self._route(kind, source, out)
        return self.params.drain_changes()

    def _route(self, kind: str, source: Source | None, out: list[Any]) -> None:
        for r in out:
            if source is None or is_broadcast_reply(kind, r.get_type()):
                self._outbox.broadcast([r])
            else:
                self._outbox.reply(source, [r])

    def _setup_signing(self, m: Any, source: Source | None) -> list[Any]:
        """SETUP_SIGNING for us: the key to the links (never to a message or the log; module docstring of
        links.signing), unless the operator's sources refuse it (gcs.operator_sources; a rate-limited reason)."""
        if m.target_system not in (0, self.sysid):
            return []
        if self._signing is None:
            return self.text.warning("SETUP_SIGNING refused: signing not available on this link")
        if (why := self.operator.signing_setup_refusal(source, self.settings.signing_setup_from)) is not None:
            self.n_unauthorised += 1
            return self._throttled_text(f"SETUP_SIGNING refused: {why}")
        return self.text.info(self._signing.set_key(bytes(m.secret_key), int(m.initial_timestamp)))

    @property
    def stability(self) -> StabilityStatus | None:
        """lambda_crit, the guaranteed smallest eigenvalue and its margin in force (None: its floor is computing)."""
        return self._registry.stability_status()

    @property
    def params_busy(self) -> bool:
        """PARAM_SETs queued or a save being written (tests wait on this, bounded)."""
        return self.param_sets.busy

    def close(self) -> None:
        """Finish the queue's last save and stop the worker."""
        self.param_sets.close()

    def takeoff_amsl(self, alt_amsl_m: float) -> tuple[bool, str]:
        return self._vehicle.command(Takeoff(self.vehicle_msgs.above_home_m(alt_amsl_m)))

    def reposition_global(self, lat_deg: float, lon_deg: float, alt_m: float, relative_alt: bool,
                          yaw_rad: float) -> tuple[bool, str]:
        return self.vehicle_msgs.reposition(lat_deg, lon_deg, alt_m, relative_alt, yaw_rad)

    def orbit_global(self, orbit: GlobalOrbit) -> tuple[bool, str]:
        return self.vehicle_msgs.orbit(orbit)

    def poll(self, now_wall: float) -> list[SetResult]:
        """Wall-clock work (telemetry, paced downloads, queued PARAM_SETs); returns the parameter changes the
        queued PARAM_SETs made, for the caller's log."""
        self._now = now_wall
        self.param_sets.poll(now_wall)
        self.vehicle_msgs.poll(now_wall, self.mission)
        # one VehicleState per poll (~5 us to build): nothing below until CURRENT_MODE changes the vehicle's mode
        # (parameter, mission and command progress and the sends only read it)
        state = self._state()
        self.mission.report(state.mission)
        if cal := self.calibration.update(state.sensors, state.armed, now_wall):  # its [cal] texts, its parameters
            self._outbox.broadcast(cal)
        self.telemetry.gps_off = self.failures.gps_off
        for source, m in (self.params.poll_routed(now_wall) + self.mission.poll(now_wall) + self.commands.poll(now_wall)
                          + self.ftp.poll(now_wall) + self.logs.poll(now_wall)):
            if source is None:
                self._outbox.broadcast([m])
            else:
                self._outbox.reply(source, [m])
        tel = self.telemetry
        for peer, peer_msgs in tel.due_per_peer(now_wall):  # peers with their own SET_MESSAGE_INTERVAL rates
            self._outbox.reply(peer, peer_msgs)
        msgs = tel.due_messages(now_wall)
        custom = state.custom_mode
        key = (custom, self._intended_custom_mode)
        if self._std_modes and (key != self._current_mode_sent
                                or now_wall - self._current_mode_t >= CURRENT_MODE_PERIOD_S):
            self._current_mode_sent, self._current_mode_t = key, now_wall  # 0.5 Hz and at once on a change
            msgs.append(standard_modes.current_mode(self.mav, *key))
        if msgs:
            peers = tel.peers_with_own_rates
            if peers:
                self._outbox.broadcast(msgs, exclude=peers)
                for peer in peers:  # CURRENT_MODE is not a stream: every peer gets it
                    self._outbox.reply(peer, [m for m in msgs if m.get_type() == "CURRENT_MODE"])
            else:
                self._outbox.broadcast(msgs)
        return self.params.drain_changes()

    def statustext(self, text: str, severity: int) -> None:
        """STATUSTEXT to every GCS (chunked when longer than one message)."""
        self._outbox.broadcast(self.text.encode(severity, text))

    # --- CommandTarget: the vehicle's commands, routed ----------------------------------------------------
    def command(self, cmd: VehicleCommand) -> Verdict:
        """A command record for the vehicle (the FlightStack applies it); a mode change is also remembered as the
        intended mode (CURRENT_MODE)."""
        if isinstance(cmd, SetMode):
            self._intended_custom_mode = int(cmd.custom_mode)
        return self._vehicle.command(cmd)

    def task_status(self, channel: str) -> TaskStatus | None:
        return self._vehicle.task_status(channel)

    def set_standard_mode(self, standard_mode: int) -> tuple[bool, str]:
        mode = mode_for_standard(standard_mode)
        if mode is None:
            return False, f"Standard mode {standard_mode} not supported"
        return self.command(SetMode(1, mode.custom_mode))

    # --- CommandTarget: the GCS service's own ------------------------------------------------------
    def request_message(self, msg_id: int, params: tuple[float, ...]) -> list[Any] | None:
        if msg_id in (MSG_AVAILABLE_MODES, MSG_CURRENT_MODE, MSG_AVAILABLE_MODES_MONITOR) and not self._std_modes:
            return None  # a dialect without the standard-modes messages (pymavlink's common.xml)
        if msg_id == MSG_AVAILABLE_MODES:
            return standard_modes.available_modes(self.mav, params[0] if params else 0.0)
        if msg_id == MSG_CURRENT_MODE:
            return [standard_modes.current_mode(self.mav, self._state().custom_mode, self._intended_custom_mode)]
        if msg_id == MSG_AVAILABLE_MODES_MONITOR:
            return [self.mav.available_modes_monitor_encode(AVAILABLE_MODES_SEQ)]
        now = time.monotonic()
        meta = component_metadata_message(self.mav, msg_id, self.metadata, self.telemetry.boot_ms(now))
        return meta if meta is not None else self.telemetry.build_now(msg_id, now)

    # --- standard modes ----------------------------------------------------------------------------------
    def set_message_interval(self, msg_id: int, interval_us: int) -> bool:
        """Clamped to GCS_RATE_MAX (a floor on the interval: one request cannot ask for 500 Hz streams)."""
        if interval_us > 0:
            interval_us = max(int(interval_us), int(math.ceil(1e6 / self.settings.stream_rate_max_hz)))
        return self.telemetry.scheduler_for(self._command_source, create=True).set_interval(msg_id, interval_us)

    def message_interval_us(self, msg_id: int) -> int:
        return self.telemetry.scheduler_for(self._command_source).interval_us(msg_id)

    def set_mission_current(self, seq: int, reset: bool) -> tuple[bool, str]:
        return self.mission.set_current(seq, reset)

    def storage(self, action: int) -> tuple[int, list[Any]]:
        return self.params.storage_command(action, armed=self._state().armed)
