"""The FC's ground-station side: wires the pure protocol pieces (navig8_fc.gcs) to the vehicle and the links.

Depends on three seams only: the vehicle's published `VehicleState` (a callable returning the latest
snapshot), its `VehicleCommands` (the FlightStack answers arm, takeoff, land, modes, gripper, arm joints) and
an `Outbox` (broadcast / reply to the sender; the process implements it over its links), plus the parameter
registry and store it is given. It implements the command handler's `CommandTarget` (the vehicle's commands
passed on, message requests and intervals from the telemetry scheduler, parameter storage), routes inbound
GCS/API messages and sends telemetry on the wall clock. It never reads the process.

Routing (PX4 and ArduPilot behave the same): a reply to a request (COMMAND_ACK and the messages a command
produces, PARAM_VALUE answering PARAM_REQUEST_READ, the paced PARAM_REQUEST_LIST download, mission, FTP and
TIMESYNC answers) goes only to the link and the peer the request came from. Broadcasts go to both GCS-facing
links (every peer of each): telemetry streams and HEARTBEAT, STATUSTEXT (events and refusal reasons), and the
PARAM_VALUE announcing the value in force after a PARAM_SET (accepted or refused) or a PREFLIGHT_STORAGE
load/reset, so every connected GCS stays in sync.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Hashable
from typing import Any, Protocol

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.flight.state import GripperAction, VehicleCommands, VehicleState
from navig8_fc.gcs.commands import CommandHandler
from navig8_fc.gcs.ftp import FtpServer, FtpService
from navig8_fc.gcs.metadata import build_metadata, component_metadata_message
from navig8_fc.gcs.misc import MiscProtocols
from navig8_fc.gcs.params import ParamProtocol, StoredLoad
from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.gcs.telemetry import (
    TelemetryBuilder,
    TelemetryScheduler,
    VehicleSnapshot,
    eig_margin_lower_bound,
    sensor_bits,
)
from navig8_fc.params.registry import ParamRegistry, SetResult
from navig8_fc.params.store import ParamStore

MAV_TYPE_GCS = 6

Source = Hashable  # who sent a message, as the Outbox knows how to answer it (the process: (link name, address))
_BROADCAST_TYPES = frozenset({"STATUSTEXT", "HEARTBEAT"})


class Outbox(Protocol):
    """Where GcsService's messages go (the process implements it over its GCS-facing links)."""

    def broadcast(self, msgs: list[Any]) -> None:
        """To every peer of every GCS-facing link."""
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


class GcsService:
    def __init__(self, mav: Any, sysid: int, state: Callable[[], VehicleState], vehicle: VehicleCommands,
                 outbox: Outbox, registry: ParamRegistry, vehicle_config: VehicleConfig,
                 store: ParamStore | None = None) -> None:
        """mav: a MAVLink object that builds messages (srcSystem = sysid, srcComponent 1; links pack them)."""
        self.mav = mav
        self.sysid = int(sysid)
        self._state = state
        self._vehicle = vehicle
        self._outbox = outbox
        self.text = StatusTextEncoder(mav)
        self.params = ParamProtocol(registry, mav, store, statustext=self.text)
        self.commands = CommandHandler(mav, sysid, 1, self, statustext=self.text)
        self.misc = MiscProtocols(mav, statustext=self.text)
        self.metadata = build_metadata(registry.definitions)  # QGC's parameter metadata, served read-only over FTP
        self.ftp = FtpService(mav, FtpServer(self.metadata.files), sysid, 1)
        self.n_gcs_msgs = 0
        self._last_gcs_heartbeat: float | None = None
        self.telemetry = Telemetry(mav, sysid, state, registry, vehicle_config)

    @property
    def last_gcs_heartbeat(self) -> float | None:
        """Wall time (the caller's clock, as given to `handle`) of the last HEARTBEAT from a ground station."""
        return self._last_gcs_heartbeat

    def load_stored_params(self) -> StoredLoad:
        """The persisted parameter values (startup); the caller logs the outcome."""
        return self.params.load_stored()

    # --- routing ---------------------------------------------------------------------------------
    def handle(self, received: list[tuple[Any, Source | None]], now_wall: float) -> list[SetResult]:
        """Inbound messages (msg, source); replies go back to the source through the outbox (module docstring).
        Without a source (in-process callers), replies are broadcast. Returns the parameter changes (set, load,
        reset outcomes) the messages caused, for the caller's log."""
        for m, source in received:
            self.n_gcs_msgs += 1
            kind = m.get_type()
            if kind == "HEARTBEAT" and m.type == MAV_TYPE_GCS:
                self._last_gcs_heartbeat = now_wall
            out = self.params.handle(m, now_wall, source)
            out += self.commands.handle(m, now_wall)
            out += self.misc.handle(m, now_wall)
            out += self.ftp.handle(m)
            out += self._set_mode_message(m)
            for r in out:
                if source is None or is_broadcast_reply(kind, r.get_type()):
                    self._outbox.broadcast([r])
                else:
                    self._outbox.reply(source, [r])
        return self.params.drain_changes()

    def _set_mode_message(self, m: Any) -> list[Any]:
        """The legacy SET_MODE message (what `mode X` in MAVProxy sends), read in PX4's custom_mode encoding
        as PX4 does; there is no ACK in that protocol, so a refusal is reported by STATUSTEXT."""
        if m.get_type() != "SET_MODE" or m.target_system not in (0, self.sysid):
            return []
        ok, reason = self.set_mode(int(m.base_mode), int(m.custom_mode))
        return [] if ok else self.text.warning(reason or f"SET_MODE {int(m.custom_mode):#x} refused")

    def poll(self, now_wall: float) -> None:
        for source, m in self.params.poll_routed(now_wall):
            if source is None:
                self._outbox.broadcast([m])
            else:
                self._outbox.reply(source, [m])
        msgs = self.telemetry.due_messages(now_wall)
        if msgs:
            self._outbox.broadcast(msgs)

    def statustext(self, text: str, severity: int) -> None:
        """STATUSTEXT to every GCS (chunked when longer than one message)."""
        self._outbox.broadcast(self.text.encode(severity, text))

    # --- CommandTarget: the vehicle's commands, passed on ------------------------------------------
    def arm(self, force: bool) -> tuple[bool, str]:
        return self._vehicle.arm(force)

    def disarm(self, force: bool) -> tuple[bool, str]:
        return self._vehicle.disarm(force)

    def takeoff(self, alt_m: float) -> tuple[bool, str]:
        return self._vehicle.takeoff(alt_m)

    def land(self) -> tuple[bool, str]:
        return self._vehicle.land()

    def set_mode(self, base_mode: int, custom_mode: int) -> tuple[bool, str]:
        return self._vehicle.set_mode(base_mode, custom_mode)

    def gripper(self, action: GripperAction) -> tuple[bool, str]:
        return self._vehicle.gripper(action)

    def arm_joints(self, q_rad: tuple[float, float, float]) -> tuple[bool, str]:
        return self._vehicle.arm_joints(q_rad)

    # --- CommandTarget: the GCS service's own ------------------------------------------------------
    def request_message(self, msg_id: int, params: tuple[float, ...]) -> list[Any] | None:
        now = time.monotonic()
        meta = component_metadata_message(self.mav, msg_id, self.metadata, self.telemetry._boot_ms(now))
        return meta if meta is not None else self.telemetry.build_now(msg_id, now)

    def set_message_interval(self, msg_id: int, interval_us: int) -> bool:
        return self.telemetry.scheduler.set_interval(msg_id, interval_us)

    def message_interval_us(self, msg_id: int) -> int:
        return self.telemetry.scheduler.interval_us(msg_id)

    def storage(self, action: int) -> tuple[int, list[Any]]:
        return self.params.storage_command(action, armed=self._state().armed)


class Telemetry:
    """Streams on the wall clock from a snapshot of the vehicle's latest state (built only when something is due)."""

    EIG_MARGIN_PERIOD_S = 0.5  # the bound-based margin costs ~1.4 ms: refresh it at 2 Hz

    def __init__(self, mav: Any, sysid: int, state: Callable[[], VehicleState], registry: ParamRegistry,
                 vehicle_config: VehicleConfig) -> None:
        self._state = state
        self._registry = registry
        self._vehicle = vehicle_config
        self.scheduler = TelemetryScheduler()
        self.builder = TelemetryBuilder(mav, sysid, 1)
        self.boot_wall = time.monotonic()
        self._eig_margin = math.nan
        self._eig_t = -1e9

    def snapshot(self, now_wall: float) -> VehicleSnapshot:
        v = self._state()
        s = v.sensors
        st = v.status
        if st is not None and now_wall - self._eig_t > self.EIG_MARGIN_PERIOD_S:
            self._eig_t = now_wall
            reg = self._registry
            self._eig_margin = eig_margin_lower_bound(self._vehicle, st.q_est_rad, float(reg["INDI_K_MIN"]),
                                                      float(reg["INDI_K_MAX"]), v.lambda_crit)
        zero3 = (0.0, 0.0, 0.0)
        ok = v.sensors_ok
        return VehicleSnapshot(
            armed=v.armed,
            base_mode=v.base_mode,
            custom_mode=v.custom_mode,
            system_status=v.system_status,
            landed_state=v.landed_state,
            pos_ned=s.pos_ned if s else zero3,
            vel_ned=s.vel_ned if s else zero3,
            quat_wxyz=s.quat_wxyz if s else (1.0, 0.0, 0.0, 0.0),
            rates_frd=s.gyro_frd if s else zero3,
            state_valid=s is not None,  # no made-up pose before the first sensor data
            home_ned=v.home_ned,
            home_yaw_rad=v.home_yaw_rad,
            battery=v.battery,
            tilt_rad=s.tilt_rad if s else (0.0, 0.0),
            speed_rad_s=s.speed_rad_s if s else zero3,
            joint_pos_rad=s.joint_pos_rad if s else zero3,
            sensors=sensor_bits(imu_ok=ok, pose_ok=ok, actuators_ok=ok, estimator_ok=st is not None,
                                battery_ok=v.battery.remaining_pct > 10, prearm_ok=bool(v.prearm.ok)),
            ckf_x_hat=st.adapt.x_hat if st else (math.nan,) * 4,  # type: ignore[arg-type]
            ckf_k=st.adapt.k if st else (math.nan,) * 4,  # type: ignore[arg-type]
            eig_margin=self._eig_margin,
            time_unix_usec=time.time_ns() // 1000,
            throttle_pct=0.0,
        )

    def _boot_ms(self, now_wall: float) -> int:
        return int((now_wall - self.boot_wall) * 1000)

    def due_messages(self, now_wall: float) -> list[Any]:
        due = self.scheduler.due(now_wall)
        if not due:
            return []
        return self.builder.build_many(due, self.snapshot(now_wall), self._boot_ms(now_wall))

    def build_now(self, msg_id: int, now_wall: float) -> list[Any] | None:
        if msg_id not in self.builder.supported_ids:
            return None
        return self.builder.build(msg_id, self.snapshot(now_wall), self._boot_ms(now_wall))
