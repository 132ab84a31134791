"""MAVLink command protocol (COMMAND_LONG, COMMAND_INT): exactly one final COMMAND_ACK per command.

`CommandHandler.handle(msg, now_s)` decodes a command addressed to us (target_system 0 or ours,
target_component 0 or ours), runs it against the vehicle (a `CommandTarget`: the FlightStack's
`VehicleCommands` plus the GCS service's message and storage requests) and
returns [COMMAND_ACK, then any STATUSTEXT reason, then any requested messages]. Commands that act on the
simulated hardware (DO_GRIPPER, the arm-joint target) add a STATUSTEXT(INFO) event when accepted
("Gripper: grab", "Arm joints: target 20.0 20.0 20.0 deg"), like the mode manager's arm/mode events.
The ACK goes back to the sender (ACK.target_system/component = the sender's ids). Results:
- ACCEPTED: done (or, for takeoff/land/mode changes, started: the mode manager carries them out);
- DENIED + STATUSTEXT(WARNING) with the reason when a check refuses it (pre-arm, not landed, bad params);
- UNSUPPORTED for command ids we do not implement (no STATUSTEXT: QGC probes several on connect);
- TEMPORARILY_REJECTED when a requested message cannot be produced yet (HOME_POSITION before a home);
- FAILED + STATUSTEXT when the vehicle raised (never a crash: the link keeps working).

Long-running commands (the MAVLink command protocol's IN_PROGRESS; docs/gcs.md "Long-running commands"):
NAV_TAKEOFF, NAV_LAND, NAV_RETURN_TO_LAUNCH, DO_REPOSITION (the vehicle's flight task) and the arm-joint target
(its arm task) answer COMMAND_ACK IN_PROGRESS (progress 0) when accepted, then IN_PROGRESS with `progress`
(0..100) every PROGRESS_PERIOD_S from `poll`, then one final ACK to the requester: ACCEPTED when it got there,
CANCELLED after COMMAND_CANCEL (the vehicle holds where it is) or when a newer command replaced it, FAILED when a
failsafe took over or it could not complete (with a STATUSTEXT). A command that is already complete when accepted
(landing on the ground) is ACCEPTED at once. The same command with the same parameters from the same sender while
it runs is a retry (MAVSDK re-sends when no ACK came for 1.5 s): it gets IN_PROGRESS again, not a second start.
MAVSDK's Action waits for the final ACK (takeoff() returns at the takeoff altitude); a client that reads only the
first ACK sees IN_PROGRESS, "accepted and running". With `flight_progress` off (PX4's way, the default of the PX4
identity: PX4's Commander answers take-off, land, return and reposition ACCEPTED at once and the client watches
telemetry), the flight task's commands are ACCEPTED when started and nothing follows; the arm-joint target keeps
the protocol (no PX4 command does it).

Duplicates: a COMMAND_LONG with confirmation > 0 that repeats the same command with the same parameters from
the same sender within `duplicate_window_s` (default 2 s, on the caller's clock: wall time) is the client
retrying because it missed our ACK (MAVSDK retries 3x at 0.5 s, QGC 3x): it gets the same result again
without executing twice. Read-only commands (REQUEST_MESSAGE, GET_MESSAGE_INTERVAL, the legacy requests) are
executed again instead, since the client most likely missed the message, not the ACK. COMMAND_INT has no
confirmation field, so every COMMAND_INT executes; all commands here are idempotent anyway.

Parameters (docs/gcs.md has the table): COMPONENT_ARM_DISARM p1 1/0, p2 21196 = force; NAV_TAKEOFF altitude
from p7 (COMMAND_LONG: above home, or AMSL with `takeoff_p7_amsl` as PX4 reads it) or z (COMMAND_INT: frame
GLOBAL_RELATIVE_ALT[_INT] above home, GLOBAL[_INT] AMSL), NaN = default;
NAV_LAND here; DO_SET_MODE p1 base_mode with CUSTOM_MODE_ENABLED, p2 PX4 main mode, p3 sub mode;
DO_SET_STANDARD_MODE p1 MAV_STANDARD_MODE; REQUEST_MESSAGE p1 message id; SET/GET_MESSAGE_INTERVAL; DO_GRIPPER
p1 instance (0 or 1), p2 0 release / 1 grab; MAV_CMD_USER_1 (31010, MAV_CMD_NAVIG8_ARM_JOINTS in navig8.xml)
p1..p3 joint targets in degrees, p4 must be 1; PREFLIGHT_STORAGE p1 0 read / 1 write / 2 reset; DO_REPOSITION
p4 yaw rad, p5/p6 (x/y) latitude/longitude (COMMAND_LONG degrees, COMMAND_INT degE7; NaN, 0 or INT32_MAX =
keep), p7 altitude AMSL (frames GLOBAL[_INT]) or above home (GLOBAL_RELATIVE_ALT[_INT]), NaN keep: Hold there;
DO_SET_MISSION_CURRENT p1 item (-1 = keep), p2 1 = reset the mission's progress; DO_ORBIT p1 radius (sign: direction),
p2 speed, p3 yaw behaviour, p4 angle, x/y/z the centre (`orbit_from_request`; flown by navig8_fc.modes.orbit),
ACCEPTED at once whatever the identity: an orbit is a mode, not a task with an end.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.flight.commands import (
    Arm,
    ArmJoints,
    CancelTask,
    Disarm,
    Gripper,
    Land,
    ReturnToLaunch,
    SetMode,
    Takeoff,
)
from navig8_fc.flight.state import VehicleCommands
from navig8_fc.gcs.params import is_for_us
from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.modes.manager import TASK_CANCELLED, TASK_DONE, TASK_FAILED
from navig8_fc.modes.px4 import px4_custom_mode

MAV_CMD_NAVIG8_ARM_JOINTS = 31010  # = MAV_CMD_USER_1 in common.xml; named in navig8.xml
ARM_FORCE_MAGIC = 21196  # COMPONENT_ARM_DISARM p2: arm despite checks / disarm in flight
MSG_ID_AUTOPILOT_VERSION = 148
MSG_ID_HOME_POSITION = 242
MSG_ID_MESSAGE_INTERVAL = 244
MSG_ID_PROTOCOL_VERSION = 300
MAV_CMD_DO_SET_STANDARD_MODE = 262
PROGRESS_PERIOD_S = 0.5  # IN_PROGRESS updates, wall clock (MAVSDK re-sends a command after 1.5 s without one)
MAV_RESULT_CANCELLED = 6  # common.xml upstream; pymavlink's copy lacks it, navig8.xml adds it (with COMMAND_CANCEL)
INT32_NAN_BITS = 0x7FF80000  # a float NaN's bits sent as a COMMAND_INT x/y (PX4 refuses it)
ORBIT_YAW_UNCHANGED = 5  # ORBIT_YAW_BEHAVIOUR_UNCHANGED: keep the orbit's heading behaviour

CMD = mavlink2  # MAV_CMD_* / MAV_RESULT_* values are the same in every dialect that includes common.xml
_READ_ONLY = frozenset({
    CMD.MAV_CMD_REQUEST_MESSAGE, CMD.MAV_CMD_GET_MESSAGE_INTERVAL, CMD.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    CMD.MAV_CMD_GET_HOME_POSITION, CMD.MAV_CMD_REQUEST_PROTOCOL_VERSION,
})  # fmt: skip
_RELATIVE_ALT_FRAMES = frozenset({CMD.MAV_FRAME_GLOBAL_RELATIVE_ALT, CMD.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})
_REPOSITION_FRAMES = _RELATIVE_ALT_FRAMES | {CMD.MAV_FRAME_GLOBAL, CMD.MAV_FRAME_GLOBAL_INT}
# Long-running commands and the vehicle task channel that carries them (FlightStack.task_status).
LONG_COMMANDS = {
    CMD.MAV_CMD_NAV_TAKEOFF: "flight", CMD.MAV_CMD_NAV_LAND: "flight", CMD.MAV_CMD_NAV_RETURN_TO_LAUNCH: "flight",
    CMD.MAV_CMD_DO_REPOSITION: "flight", MAV_CMD_NAVIG8_ARM_JOINTS: "arm",
}
_TASK_RESULT = {TASK_DONE: CMD.MAV_RESULT_ACCEPTED, TASK_FAILED: CMD.MAV_RESULT_FAILED,
                TASK_CANCELLED: MAV_RESULT_CANCELLED}


class CommandTarget(VehicleCommands, Protocol):
    """What the command handler needs: the vehicle's commands as records (`VehicleCommands.command`, routed to the
    FlightStack) and the GCS service's own (message requests and intervals, parameter storage); the shell's GCS service
    implements it."""

    def request_message(self, msg_id: int, params: tuple[float, ...]) -> list[Any] | None:
        """The requested message(s); None when msg_id is not supported, [] when not available yet.

        params = (p2, ..., p7) of MAV_CMD_REQUEST_MESSAGE (message-specific).
        """
        ...

    def set_message_interval(self, msg_id: int, interval_us: int) -> bool:
        """-1 disable, 0 default rate, > 0 interval; False when msg_id cannot be streamed."""
        ...

    def message_interval_us(self, msg_id: int) -> int:
        """Current interval (MESSAGE_INTERVAL semantics: -1 disabled, 0 not available)."""
        ...

    def set_standard_mode(self, standard_mode: int) -> tuple[bool, str]:
        """MAV_CMD_DO_SET_STANDARD_MODE: the mode that implements a MAV_STANDARD_MODE."""
        ...

    def reposition_global(self, lat_deg: float, lon_deg: float, alt_m: float, relative_alt: bool,
                          yaw_rad: float) -> tuple[bool, str]:
        """MAV_CMD_DO_REPOSITION: hold at a WGS-84 point (NaN: keep that coordinate); alt AMSL, or above home
        when relative_alt."""
        ...

    def takeoff_amsl(self, alt_amsl_m: float) -> tuple[bool, str]:
        """MAV_CMD_NAV_TAKEOFF to an altitude above mean sea level (PX4's p7; GLOBAL frames)."""
        ...

    def orbit_global(self, orbit: GlobalOrbit) -> tuple[bool, str]:
        """MAV_CMD_DO_ORBIT about a WGS-84 centre (NaN parts: not given)."""
        ...

    def set_mission_current(self, seq: int, reset: bool) -> tuple[bool, str]:
        """MAV_CMD_DO_SET_MISSION_CURRENT: fly item `seq` next (-1: keep it; reset: forget what was reached)."""
        ...

    def storage(self, action: int) -> tuple[int, list[Any]]:
        """MAV_CMD_PREFLIGHT_STORAGE param1 -> (MAV_RESULT, messages); see ParamProtocol.storage_command."""
        ...


@dataclass(frozen=True)
class CommandRequest:
    """A COMMAND_LONG or COMMAND_INT in one shape: p5/p6 are x/y (int) and p7 is z for COMMAND_INT."""

    command: int
    params: tuple[float, float, float, float, float, float, float]
    is_int: bool
    frame: int  # COMMAND_INT frame (0 for COMMAND_LONG)
    confirmation: int  # COMMAND_LONG only
    src_system: int
    src_component: int


@dataclass(frozen=True)
class GlobalOrbit:
    """MAV_CMD_DO_ORBIT as sent (NaN: not given; navig8_fc.modes.orbit says what each default is)."""

    radius_m: float  # p1, signed: positive clockwise
    speed_m_s: float  # p2, tangential
    yaw_behaviour: int  # p3, ORBIT_YAW_BEHAVIOUR; NaN -> 5 (unchanged)
    sweep_rad: float  # p4, the angle to fly (0: forever)
    lat_deg: float  # the centre
    lon_deg: float
    alt_m: float  # AMSL, or above home when relative_alt
    relative_alt: bool


@dataclass(frozen=True)
class _Outcome:
    result: int
    reason: str | None = None  # STATUSTEXT(WARNING) when set
    info: str | None = None  # STATUSTEXT(INFO) when set: the event an accepted command caused
    extra: list[Any] = field(default_factory=list)  # messages after the ACK


class _BadParam(ValueError):
    pass


@dataclass
class _Running:
    """A long-running command being reported: the task it started, who asked (ids for the ACK, `source` for the
    routing) and when the last IN_PROGRESS went out."""

    req: CommandRequest
    pkey: tuple[float | None, ...]
    task_id: int
    source: Hashable | None
    last_sent_s: float


def _int_param(p: float, name: str, lo: int = -(2**31), hi: int = 2**31 - 1) -> int:
    """An integer parameter sent as float; refused when not a number or outside [lo, hi]."""
    if not math.isfinite(p):
        raise _BadParam(f"{name} must be a number, got {p}")
    v = int(round(p))
    if not lo <= v <= hi:
        raise _BadParam(f"{name} = {p:g} outside [{lo}, {hi}]")
    return v


def _msg_id_param(p: float, name: str) -> int:
    # MAVLink 2 message ids are 24-bit; MESSAGE_INTERVAL.message_id is uint16, so intervals stop at 65535.
    return _int_param(p, name, 0, 65535)


def orbit_from_request(req: CommandRequest, z_amsl: bool) -> GlobalOrbit:
    """DO_ORBIT's parameters (COMMAND_INT: x/y degE7, INT32_MAX for either = the current centre or position; both
    0x7ff80000, a NaN sent as an integer, refused as PX4 does; z AMSL in frames GLOBAL[_INT], above home in
    GLOBAL_RELATIVE_ALT[_INT] unless `z_amsl`: PX4 reads z as AMSL whatever the frame, and MAVSDK sends its AMSL
    altitude in GLOBAL_RELATIVE_ALT. COMMAND_LONG: p5/p6 degrees, p7 AMSL)."""
    p = req.params
    if req.is_int:
        if req.frame not in _REPOSITION_FRAMES:
            raise _BadParam(f"frame {req.frame} unsupported (GLOBAL[_INT], GLOBAL_RELATIVE_ALT[_INT])")
        if p[4] == p[5] == INT32_NAN_BITS:
            raise _BadParam("x/y invalid (a NaN sent as an integer; INT32_MAX = the current position)")
        unset = float(2**31 - 1) in (p[4], p[5])
        lat, lon = (math.nan, math.nan) if unset else (p[4] * 1e-7, p[5] * 1e-7)
        relative = req.frame in _RELATIVE_ALT_FRAMES and not z_amsl
    else:
        lat, lon, relative = p[4], p[5], False
    for v, what in ((p[0], "radius"), (p[1], "velocity"), (p[3], "param4 (angle)"), (lat, "latitude"),
                    (lon, "longitude"), (p[6], "altitude")):
        if math.isinf(v):
            raise _BadParam(f"{what} must be a number or NaN (default)")
    if (math.isfinite(lat) and abs(lat) > 90) or (math.isfinite(lon) and abs(lon) > 180):
        raise _BadParam(f"centre {lat:g}, {lon:g} is not on Earth")
    yaw = ORBIT_YAW_UNCHANGED if math.isnan(p[2]) else _int_param(p[2], "param3 (yaw behaviour)", 0,
                                                                   ORBIT_YAW_UNCHANGED)
    return GlobalOrbit(p[0], p[1], yaw, p[3], lat, lon, p[6], relative)


def decode_command(msg: Any, sysid: int, compid: int) -> CommandRequest | None:
    """The command in `msg` if it is a COMMAND_LONG/COMMAND_INT addressed to (sysid, compid), else None."""
    kind = msg.get_type()
    if kind not in ("COMMAND_LONG", "COMMAND_INT") or not is_for_us(msg, sysid, compid):
        return None
    src = (int(msg.get_srcSystem()), int(msg.get_srcComponent()))
    if kind == "COMMAND_LONG":
        p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        return CommandRequest(int(msg.command), tuple(float(v) for v in p), False, 0,  # type: ignore[arg-type]
                              int(msg.confirmation), *src)
    p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z)
    return CommandRequest(int(msg.command), tuple(float(v) for v in p), True, int(msg.frame),  # type: ignore[arg-type]
                          0, *src)


class CommandHandler:
    """Command microservice of one component (module docstring)."""

    def __init__(
        self,
        mav: Any,
        sysid: int,
        compid: int,
        vehicle: CommandTarget,
        *,
        statustext: StatusTextEncoder | None = None,
        duplicate_window_s: float = 2.0,
        flight_progress: bool = True,
        takeoff_p7_amsl: bool = False,
        orbit_z_amsl: bool = False,
        services: Mapping[int, ServiceHandler] | None = None,
    ) -> None:
        """services: commands another GCS service answers (calibration, failure injection): command id -> a handler
        of p1..p7 returning (MAV_RESULT, reason for a WARNING, event for an INFO)."""
        self._mav = mav
        self._sysid = int(sysid)
        self._compid = int(compid)
        self._vehicle = vehicle
        self._text = statustext or StatusTextEncoder(mav)
        self._window_s = float(duplicate_window_s)
        self.flight_progress = bool(flight_progress)  # the flight task's commands: IN_PROGRESS + final ACK (or at once)
        self._takeoff_p7_amsl = bool(takeoff_p7_amsl)  # PX4: COMMAND_LONG NAV_TAKEOFF p7 is AMSL
        self._orbit_z_amsl = bool(orbit_z_amsl)  # PX4: DO_ORBIT z is AMSL in every frame
        # (src_system, src_component, command) -> (params key, time, result) of the last execution.
        self._recent: dict[tuple[int, int, int], tuple[tuple[float | None, ...], float, int]] = {}
        self._running: dict[str, _Running] = {}  # task channel -> the long command being reported
        self._pending: list[tuple[Hashable | None, Any]] = []  # (source, message) for the next poll
        self._handlers = {
            CMD.MAV_CMD_COMPONENT_ARM_DISARM: self._arm_disarm,
            CMD.MAV_CMD_NAV_TAKEOFF: self._takeoff,
            CMD.MAV_CMD_NAV_LAND: lambda r: self._verdict(self._vehicle.command(Land())),
            CMD.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda r: self._verdict(self._vehicle.command(ReturnToLaunch())),
            CMD.MAV_CMD_DO_SET_MODE: self._set_mode,
            CMD.MAV_CMD_REQUEST_MESSAGE: self._request_message,
            CMD.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: lambda r: self._produce(MSG_ID_AUTOPILOT_VERSION, ()),
            CMD.MAV_CMD_GET_HOME_POSITION: lambda r: self._produce(MSG_ID_HOME_POSITION, ()),
            CMD.MAV_CMD_REQUEST_PROTOCOL_VERSION: self._protocol_version,
            CMD.MAV_CMD_SET_MESSAGE_INTERVAL: self._set_interval,
            CMD.MAV_CMD_GET_MESSAGE_INTERVAL: self._get_interval,
            CMD.MAV_CMD_DO_GRIPPER: self._gripper,
            MAV_CMD_NAVIG8_ARM_JOINTS: self._arm_joints,
            CMD.MAV_CMD_PREFLIGHT_STORAGE: self._storage,
            CMD.MAV_CMD_DO_SET_MISSION_CURRENT: self._set_mission_current,
            CMD.MAV_CMD_DO_REPOSITION: self._reposition,
            CMD.MAV_CMD_DO_ORBIT: lambda r: self._verdict(
                self._vehicle.orbit_global(orbit_from_request(r, self._orbit_z_amsl))),
            MAV_CMD_DO_SET_STANDARD_MODE: lambda r: self._verdict(
                self._vehicle.set_standard_mode(_int_param(r.params[0], "param1 (standard mode)", 0, 255))),
        }

        for command, service in (services or {}).items():
            self._handlers[command] = _service_handler(service)

    @property
    def supported_commands(self) -> frozenset[int]:
        return frozenset(self._handlers)

    def handle(self, msg: Any, now_s: float, source: Hashable | None = None) -> list[Any]:
        """Replies to `msg` (for its sender); `source` is kept with a long-running command so that `poll` can route
        its later ACKs (as (source, message) pairs) to the same peer."""
        if msg.get_type() == "COMMAND_CANCEL":
            self._cancel(msg)
            return []
        req = decode_command(msg, self._sysid, self._compid)
        if req is None:
            return []
        key = (req.src_system, req.src_component, req.command)
        pkey = tuple(None if math.isnan(p) else p for p in req.params) + (req.frame,)
        channel = LONG_COMMANDS.get(req.command)
        if channel == "flight" and not self.flight_progress:
            channel = None  # ACCEPTED at once (PX4); a retry within the window gets the same answer below
        if channel is not None:
            self._report(channel, now_s)  # the running one may have ended: its final ACK before a new start
            run = self._running.get(channel)
            if run is not None and run.req.command == req.command and run.pkey == pkey and (
                    run.req.src_system, run.req.src_component) == key[:2]:
                ts = self._vehicle.task_status(channel)  # a retry of the running command
                return [self._ack(req, CMD.MAV_RESULT_IN_PROGRESS, int(ts.progress_pct) if ts else 0)]
        elif req.confirmation > 0 and req.command not in _READ_ONLY:
            seen = self._recent.get(key)
            if seen is not None and seen[0] == pkey and now_s - seen[1] <= self._window_s:
                return [self._ack(req, seen[2])]
        outcome = self._execute(req)
        if channel is not None and outcome.result == CMD.MAV_RESULT_ACCEPTED:
            outcome = self._start_long(channel, req, pkey, source, now_s, outcome)
        elif req.command not in _READ_ONLY:
            self._remember(key, pkey, now_s, outcome.result)
        out = [self._ack(req, outcome.result)]
        if outcome.reason:
            out += self._text.warning(outcome.reason)
        if outcome.info and outcome.result == CMD.MAV_RESULT_ACCEPTED:
            out += self._text.info(outcome.info)
        return out + outcome.extra

    # --- execution -----------------------------------------------------------------------------------
    def _execute(self, req: CommandRequest) -> _Outcome:
        handler = self._handlers.get(req.command)
        if handler is None:
            return _Outcome(CMD.MAV_RESULT_UNSUPPORTED)
        try:
            return handler(req)
        except _BadParam as exc:
            return _Outcome(CMD.MAV_RESULT_DENIED, f"{_cmd_name(req.command)}: {exc}")
        except Exception as exc:  # noqa: BLE001 - a vehicle bug must not take the GCS link down
            return _Outcome(CMD.MAV_RESULT_FAILED, f"{_cmd_name(req.command)} failed: {type(exc).__name__}: {exc}")

    def _ack(self, req: CommandRequest, result: int, progress: int = 0) -> Any:
        return self._mav.command_ack_encode(req.command, int(result), progress, 0, req.src_system, req.src_component)

    # --- long-running commands -------------------------------------------------------------------------
    def _start_long(self, channel: str, req: CommandRequest, pkey: tuple[float | None, ...],
                    source: Hashable | None, now_s: float, outcome: _Outcome) -> _Outcome:
        """An accepted long command: IN_PROGRESS while the task it started runs (ACCEPTED when it started none,
        e.g. Land on the ground, or joined a running one, e.g. Land during a Return's descent)."""
        ts = self._vehicle.task_status(channel)
        old = self._running.get(channel)
        if ts is None or not ts.running or (old is not None and old.task_id == ts.task_id):
            return outcome
        if old is not None:  # replaced by this one
            self._finish(channel, MAV_RESULT_CANCELLED)
        self._running[channel] = _Running(req, pkey, ts.task_id, source, now_s)
        return _Outcome(CMD.MAV_RESULT_IN_PROGRESS, outcome.reason, outcome.info, outcome.extra)

    def _finish(self, channel: str, result: int, reason: str = "") -> None:
        run = self._running.pop(channel)
        progress = 100 if result == CMD.MAV_RESULT_ACCEPTED else 0
        self._pending.append((run.source, self._ack(run.req, result, progress)))
        if reason:
            self._pending += [(None, m) for m in self._text.warning(f"{_cmd_name(run.req.command)}: {reason}")]

    def _report(self, channel: str, now_s: float) -> None:
        run = self._running.get(channel)
        if run is None:
            return
        ts = self._vehicle.task_status(channel)
        if ts is None or ts.task_id != run.task_id:
            self._finish(channel, MAV_RESULT_CANCELLED)
        elif not ts.running:
            result = _TASK_RESULT[ts.state]
            self._finish(channel, result, ts.reason if result == CMD.MAV_RESULT_FAILED else "")
        elif now_s - run.last_sent_s >= PROGRESS_PERIOD_S:
            run.last_sent_s = now_s
            self._pending.append((run.source, self._ack(run.req, CMD.MAV_RESULT_IN_PROGRESS, int(ts.progress_pct))))

    def poll(self, now_s: float) -> list[tuple[Hashable | None, Any]]:
        """Progress of the long-running commands: IN_PROGRESS updates and final ACKs as (source, message), source
        None for a STATUSTEXT to everyone."""
        for channel in list(self._running):
            self._report(channel, now_s)
        out, self._pending = self._pending, []
        return out

    def _cancel(self, msg: Any) -> None:
        """COMMAND_CANCEL: the running long command with that id stops (its final ACK, CANCELLED, goes to whoever
        sent it, at the next poll); nothing runs with that id: ignored, as the protocol says."""
        if msg.target_system != self._sysid or msg.target_component not in (0, self._compid):
            return
        for channel, run in self._running.items():
            if run.req.command == int(msg.command):
                self._vehicle.command(CancelTask(channel))
                return

    def _remember(self, key: tuple[int, int, int], pkey: tuple[float | None, ...], now_s: float, result: int) -> None:
        if len(self._recent) >= 256:  # a flood of distinct senders must not grow this without bound
            self._recent = {k: v for k, v in self._recent.items() if now_s - v[1] <= self._window_s}
            if len(self._recent) >= 256:
                self._recent.clear()
        self._recent[key] = (pkey, now_s, int(result))

    @staticmethod
    def _verdict(v: tuple[bool, str], info: str | None = None) -> _Outcome:
        """ACCEPTED (with `info` as STATUSTEXT INFO) or DENIED with the reason as STATUSTEXT WARNING."""
        ok, reason = v
        return _Outcome(CMD.MAV_RESULT_ACCEPTED, info=info) if ok else _Outcome(CMD.MAV_RESULT_DENIED,
                                                                                 reason or "denied")

    def _arm_disarm(self, req: CommandRequest) -> _Outcome:
        p1, p2 = req.params[0], req.params[1]
        force = math.isfinite(p2) and int(round(p2)) == ARM_FORCE_MAGIC
        arm = _int_param(p1, "param1")
        if arm == 1:
            return self._verdict(self._vehicle.command(Arm(force)))
        if arm == 0:
            return self._verdict(self._vehicle.command(Disarm(force)))
        raise _BadParam(f"param1 must be 1 (arm) or 0 (disarm), got {p1:g}")

    def _takeoff(self, req: CommandRequest) -> _Outcome:
        alt = req.params[6]
        if req.is_int and req.frame not in _REPOSITION_FRAMES:
            raise _BadParam(f"frame {req.frame} unsupported; use GLOBAL_RELATIVE_ALT(_INT) (z above home) or "
                            "GLOBAL(_INT) (z AMSL)")
        amsl = req.frame not in _RELATIVE_ALT_FRAMES if req.is_int else self._takeoff_p7_amsl
        if amsl and not math.isnan(alt):  # NaN: the default height (PX4: MIS_TAKEOFF_ALT)
            return self._verdict(self._vehicle.takeoff_amsl(alt))
        return self._verdict(self._vehicle.command(Takeoff(alt)))

    def _set_mode(self, req: CommandRequest) -> _Outcome:
        base = _int_param(req.params[0], "param1 (base_mode)")
        if not base & CMD.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            raise _BadParam("base_mode must include CUSTOM_MODE_ENABLED (PX4 custom modes in p2/p3)")
        main = _int_param(req.params[1], "param2 (main mode)")
        sub = 0 if math.isnan(req.params[2]) else _int_param(req.params[2], "param3 (sub mode)")
        try:
            custom = px4_custom_mode(main, sub)
        except ValueError as exc:
            raise _BadParam(str(exc)) from None
        return self._verdict(self._vehicle.command(SetMode(base, custom)))

    def _produce(self, msg_id: int, params: tuple[float, ...], unknown_result: int = CMD.MAV_RESULT_DENIED) -> _Outcome:
        msgs = self._vehicle.request_message(msg_id, params)
        if msgs is None:
            # PX4 answers DENIED for message ids it cannot send; no STATUSTEXT (QGC asks for several on connect).
            return _Outcome(unknown_result)
        if not msgs:
            return _Outcome(CMD.MAV_RESULT_TEMPORARILY_REJECTED)
        return _Outcome(CMD.MAV_RESULT_ACCEPTED, extra=list(msgs))

    def _request_message(self, req: CommandRequest) -> _Outcome:
        msg_id = _int_param(req.params[0], "param1 (message id)", 0, 2**24 - 1)
        if msg_id == MSG_ID_MESSAGE_INTERVAL:
            return self._interval_reply(_msg_id_param(req.params[1], "param2 (message id)"))
        return self._produce(msg_id, req.params[1:])

    def _protocol_version(self, req: CommandRequest) -> _Outcome:
        return self._produce(MSG_ID_PROTOCOL_VERSION, (), unknown_result=CMD.MAV_RESULT_UNSUPPORTED)

    def _interval_reply(self, msg_id: int) -> _Outcome:
        interval = max(-1, min(int(self._vehicle.message_interval_us(msg_id)), 2**31 - 1))  # int32 field
        return _Outcome(CMD.MAV_RESULT_ACCEPTED, extra=[self._mav.message_interval_encode(msg_id, interval)])

    def _get_interval(self, req: CommandRequest) -> _Outcome:
        return self._interval_reply(_msg_id_param(req.params[0], "param1 (message id)"))

    def _set_interval(self, req: CommandRequest) -> _Outcome:
        msg_id = _msg_id_param(req.params[0], "param1 (message id)")
        interval = _int_param(req.params[1], "param2 (interval us, -1 disable, 0 default)", -1)
        if not self._vehicle.set_message_interval(msg_id, interval):
            return _Outcome(CMD.MAV_RESULT_DENIED, f"SET_MESSAGE_INTERVAL: message {msg_id} cannot be streamed")
        return _Outcome(CMD.MAV_RESULT_ACCEPTED)

    def _gripper(self, req: CommandRequest) -> _Outcome:
        instance = _int_param(req.params[0], "param1 (gripper instance)")
        if instance not in (0, 1):
            raise _BadParam(f"no gripper {instance} (0 = all, 1 = the arm's gripper)")
        action = _int_param(req.params[1], "param2 (action)")
        if action == CMD.GRIPPER_ACTION_GRAB:
            return self._verdict(self._vehicle.command(Gripper("grab")), "Gripper: grab")
        if action == CMD.GRIPPER_ACTION_RELEASE:
            return self._verdict(self._vehicle.command(Gripper("release")), "Gripper: release")
        raise _BadParam(f"action {action} unsupported (0 release, 1 grab)")

    def _arm_joints(self, req: CommandRequest) -> _Outcome:
        if not (math.isfinite(req.params[3]) and int(round(req.params[3])) == 1):
            raise _BadParam("param4 must be 1 to apply the joint targets")
        q_deg = req.params[:3]
        if not all(math.isfinite(v) for v in q_deg):
            raise _BadParam("joint targets p1..p3 must be numbers (degrees)")
        q_rad = (math.radians(q_deg[0]), math.radians(q_deg[1]), math.radians(q_deg[2]))
        info = "Arm joints: target " + " ".join(f"{q:.1f}" for q in q_deg[:3]) + " deg"
        return self._verdict(self._vehicle.command(ArmJoints(q_rad)), info)

    def _reposition(self, req: CommandRequest) -> _Outcome:
        p = req.params
        if req.is_int:
            if req.frame not in _REPOSITION_FRAMES:
                raise _BadParam(f"frame {req.frame} unsupported (GLOBAL[_INT], GLOBAL_RELATIVE_ALT[_INT])")
            unset = (0.0, float(2**31 - 1))  # x/y 0 or INT32_MAX: not given
            lat = math.nan if p[4] in unset else p[4] * 1e-7
            lon = math.nan if p[5] in unset else p[5] * 1e-7
            relative = req.frame in _RELATIVE_ALT_FRAMES
        else:
            lat, lon, relative = p[4], p[5], False
        for v, what in ((lat, "latitude"), (lon, "longitude"), (p[6], "altitude"), (p[3], "yaw")):
            if math.isinf(v):
                raise _BadParam(f"{what} must be a number or NaN (keep)")
        if (math.isfinite(lat) and abs(lat) > 90) or (math.isfinite(lon) and abs(lon) > 180):
            raise _BadParam(f"position {lat:g}, {lon:g} is not on Earth")
        return self._verdict(self._vehicle.reposition_global(lat, lon, p[6], relative, p[3]))

    def _set_mission_current(self, req: CommandRequest) -> _Outcome:
        seq = _int_param(req.params[0], "param1 (item)", -1, 65535)
        reset = math.isfinite(req.params[1]) and int(round(req.params[1])) == 1
        return self._verdict(self._vehicle.set_mission_current(seq, reset))

    def _storage(self, req: CommandRequest) -> _Outcome:
        action = _int_param(req.params[0], "param1 (storage action)")
        result, msgs = self._vehicle.storage(action)
        return _Outcome(int(result), extra=list(msgs))


ServiceHandler = Callable[[tuple[float, ...]], tuple[int, str | None, str | None]]


def _service_handler(service: ServiceHandler) -> Callable[[CommandRequest], _Outcome]:
    """A service's answer as the command handler's outcome."""
    def handle(req: CommandRequest) -> _Outcome:
        result, reason, info = service(req.params)
        return _Outcome(int(result), reason, info)
    return handle


def _cmd_name(command: int) -> str:
    if command == MAV_CMD_NAVIG8_ARM_JOINTS:
        return "ARM_JOINTS"
    entry = mavlink2.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry is not None else f"command {command}"
