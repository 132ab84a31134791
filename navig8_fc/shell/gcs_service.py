"""The FC's ground-station side: wires the pure protocol pieces (navig8_fc.gcs, navig8_fc.modes) to the links.

Implements `VehicleCommands` for the command handler on top of the mode manager, the bridge seam (arm
joints, gripper) and the telemetry scheduler; routes inbound GCS/API messages; sends telemetry on the wall
clock.

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
from typing import TYPE_CHECKING, Any

from navig8_fc.gcs.battery import battery_initial, battery_step
from navig8_fc.gcs.commands import CommandHandler, GripperAction
from navig8_fc.gcs.misc import MiscProtocols
from navig8_fc.gcs.params import ParamProtocol
from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.gcs.telemetry import (
    TelemetryBuilder,
    TelemetryScheduler,
    VehicleSnapshot,
    eig_margin_lower_bound,
    sensor_bits,
)
from navig8_fc.mavlink import seam
from navig8_fc.params.store import ParamStore, default_state_path

MAV_TYPE_GCS = 6

if TYPE_CHECKING:
    from navig8_fc.shell.fc_process import FlightControllerProcess
    from navig8_fc.shell.mavlink_link import UdpLink

Addr = tuple[str, int]
_BROADCAST_TYPES = frozenset({"STATUSTEXT", "HEARTBEAT"})


def is_broadcast_reply(request_type: str, reply_type: str) -> bool:
    """Whether a message produced in answer to a `request_type` message goes to every link (module docstring):
    STATUSTEXT always; PARAM_VALUE unless it answers a PARAM_REQUEST_READ (then it is that client's reply)."""
    if reply_type in _BROADCAST_TYPES:
        return True
    return reply_type == "PARAM_VALUE" and request_type != "PARAM_REQUEST_READ"


class GcsService:
    def __init__(self, fc: FlightControllerProcess) -> None:
        self.fc = fc
        o = fc.opts
        self.mav = fc.d.MAVLink(None, srcSystem=o.sysid, srcComponent=1)  # builds messages (links pack them)
        self.text = StatusTextEncoder(self.mav)
        store = ParamStore(default_state_path(o.state_dir, o.instance)) if o.state_dir else None
        self.params = ParamProtocol(fc.registry, self.mav, store, statustext=self.text)
        self.commands = CommandHandler(self.mav, o.sysid, 1, self, statustext=self.text)
        self.misc = MiscProtocols(self.mav, statustext=self.text)
        self.n_gcs_msgs = 0
        self.last_gcs_heartbeat: float | None = None  # wall time of the last HEARTBEAT from a ground station
        self.gcs_lost = False
        self.pending_arm_cmd: seam.ArmCommand | None = None
        self.telemetry = Telemetry(fc, self.mav)
        if store is not None and not o.defaults:
            loaded = self.params.load_stored()
            if loaded.ok:
                fc.log_event(f"parameters loaded from {store.path} ({loaded.applied} values)")
            for r in loaded.refused:
                fc.log_event(f"stored value refused: {r.reason}")
        elif o.defaults:
            fc.log_event("starting from default parameters (--defaults)")

    # --- routing ---------------------------------------------------------------------------------
    def handle(self, received: list[tuple[Any, Addr | None]], now_wall: float, link: UdpLink | None = None) -> None:
        """Inbound messages (msg, sender address) from `link`; replies go back there (module docstring).
        With no link or address (in-process callers), replies are broadcast."""
        for m, addr in received:
            self.n_gcs_msgs += 1
            kind = m.get_type()
            if kind == "HEARTBEAT" and m.type == MAV_TYPE_GCS:
                self.last_gcs_heartbeat = now_wall
                if self.gcs_lost:
                    self.gcs_lost = False
                    self.fc.log_event("GCS link regained")
            source = (link.name, addr) if link is not None and addr is not None else None  # hashable
            out = self.params.handle(m, now_wall, source)
            out += self.commands.handle(m, now_wall)
            out += self.misc.handle(m, now_wall)
            out += self._set_mode_message(m)
            for r in out:
                if source is None or is_broadcast_reply(kind, r.get_type()):
                    self.broadcast([r])
                else:
                    self.reply(source, [r])
        for change in self.params.drain_changes():
            self.fc.log_param_change(change)

    def _set_mode_message(self, m: Any) -> list[Any]:
        """The legacy SET_MODE message (what `mode X` in MAVProxy sends), read in PX4's custom_mode encoding
        as PX4 does; there is no ACK in that protocol, so a refusal is reported by STATUSTEXT."""
        if m.get_type() != "SET_MODE" or m.target_system not in (0, self.fc.opts.sysid):
            return []
        ok, reason = self.set_mode(int(m.base_mode), int(m.custom_mode))
        return [] if ok else self.text.warning(reason or f"SET_MODE {int(m.custom_mode):#x} refused")

    def poll(self, now_wall: float) -> None:
        for source, m in self.params.poll_routed(now_wall):
            if source is None:
                self.broadcast([m])
            else:
                self.reply(source, [m])
        self.broadcast(self.telemetry.due_messages(now_wall))

    def broadcast(self, msgs: list[Any]) -> None:
        """To every peer of both GCS-facing links (telemetry, HEARTBEAT, STATUSTEXT, PARAM_VALUE announcements)."""
        if not msgs:
            return
        for link in (self.fc.gcs, self.fc.api):
            for m in msgs:
                link.send(m)

    def reply(self, source: tuple[str, Addr], msgs: list[Any]) -> None:
        """To the one peer a request came from, on its link: source = (link name, sender address)."""
        name, addr = source
        link = self.fc.api if name == self.fc.api.name else self.fc.gcs
        dest = [addr]
        for m in msgs:
            link.send(m, dest)

    def statustext(self, text: str, severity: int) -> None:
        self.broadcast(self.text.encode(severity, text))

    # --- VehicleCommands ---------------------------------------------------------------------------
    def arm(self, force: bool) -> tuple[bool, str]:
        v = self.fc.modes.arm(force)
        return v.ok, v.reason

    def disarm(self, force: bool) -> tuple[bool, str]:
        v = self.fc.modes.disarm(force)
        return v.ok, v.reason

    def takeoff(self, alt_m: float) -> tuple[bool, str]:
        v = self.fc.modes.takeoff(alt_m)
        return v.ok, v.reason

    def land(self) -> tuple[bool, str]:
        v = self.fc.modes.land()
        return v.ok, v.reason

    def set_mode(self, base_mode: int, custom_mode: int) -> tuple[bool, str]:
        v = self.fc.modes.set_custom_mode(int(custom_mode))
        return v.ok, v.reason

    def gripper(self, action: GripperAction) -> tuple[bool, str]:
        grab = action == "grab"
        self._queue_arm_cmd(seam.ArmCommand(0, None, seam.GRIPPER_GRAB if grab else seam.GRIPPER_RELEASE))
        return True, ""

    def arm_joints(self, q_rad: tuple[float, float, float]) -> tuple[bool, str]:
        if not all(math.isfinite(q) for q in q_rad):
            return False, "arm joints: targets must be finite"
        lim = self.fc.vehicle.joint_limit_rad
        if any(abs(q) > lim for q in q_rad):
            return False, f"arm joints: targets beyond +-{math.degrees(lim):.0f} deg"
        self._queue_arm_cmd(seam.ArmCommand(0, tuple(float(q) for q in q_rad), seam.GRIPPER_NONE))
        return True, ""

    def _queue_arm_cmd(self, cmd: seam.ArmCommand) -> None:
        p = self.pending_arm_cmd
        if p is not None:  # merge: keep both a joint target and a gripper action queued before the next step
            cmd = seam.ArmCommand(0, cmd.joint_target_rad or p.joint_target_rad,
                                  cmd.gripper if cmd.gripper != seam.GRIPPER_NONE else p.gripper)
        self.pending_arm_cmd = cmd

    def request_message(self, msg_id: int, params: tuple[float, ...]) -> list[Any] | None:
        return self.telemetry.build_now(msg_id, time.monotonic())

    def set_message_interval(self, msg_id: int, interval_us: int) -> bool:
        return self.telemetry.scheduler.set_interval(msg_id, interval_us)

    def message_interval_us(self, msg_id: int) -> int:
        return self.telemetry.scheduler.interval_us(msg_id)

    def storage(self, action: int) -> tuple[int, list[Any]]:
        return self.params.storage_command(action, armed=self.fc.modes.armed)


class Telemetry:
    """Streams on the wall clock from a snapshot of the FC's latest state (built only when something is due)."""

    EIG_MARGIN_PERIOD_S = 0.5  # the bound-based margin costs ~1.4 ms: refresh it at 2 Hz

    def __init__(self, fc: FlightControllerProcess, mav: Any) -> None:
        self.fc = fc
        self.scheduler = TelemetryScheduler()
        self.builder = TelemetryBuilder(mav, fc.opts.sysid, 1)
        self.boot_wall = time.monotonic()
        self.battery = battery_initial()
        self._last_batt_t: float | None = None
        self._eig_margin = math.nan
        self._eig_t = -1e9

    def on_tick(self, t_s: float, speed_rad_s: tuple[float, float, float]) -> None:
        """Battery discharge on sim time from the propeller speeds (hover ~ 0.6 kW at 8 kg, docs/gcs.md)."""
        if self._last_batt_t is not None and t_s > self._last_batt_t:
            v = self.fc.vehicle
            w1, w2, w3 = speed_rad_s
            # Ideal induced power P = T^1.5 / sqrt(2 rho A) per rotor with a figure of merit: a simple model.
            thrusts = (v.k_thrust_duct * w1 * w1, v.k_thrust_tail * w2 * w2, v.k_thrust_duct * w3 * w3)
            power = sum(max(t, 0.0) ** 1.5 for t in thrusts) / (math.sqrt(2 * 1.225 * 0.07) * 0.6)
            self.battery = battery_step(self.battery, power, t_s - self._last_batt_t)
        self._last_batt_t = t_s

    def snapshot(self, now_wall: float) -> VehicleSnapshot:
        fc = self.fc
        mo = fc.mode_out
        s = fc.last_sensors
        st = fc.last_status
        modes = getattr(fc, "modes", None)
        armed = bool(modes.armed) if modes is not None else False
        sensors_ok = s is not None and now_wall - fc.last_bundle_wall < fc.sensor_timeout_s
        prearm_ok = bool(modes.prearm_check().ok) if modes is not None else False
        if st is not None and now_wall - self._eig_t > self.EIG_MARGIN_PERIOD_S:
            self._eig_t = now_wall
            self._eig_margin = eig_margin_lower_bound(fc.vehicle, st.q_est_rad, float(fc.registry["INDI_K_MIN"]),
                                                      float(fc.registry["INDI_K_MAX"]), fc.lambda_crit)
        zero3 = (0.0, 0.0, 0.0)
        return VehicleSnapshot(
            armed=armed,
            base_mode=mo.base_mode if mo else (modes.base_mode if modes else 1),
            custom_mode=mo.custom_mode if mo else (modes.custom_mode if modes else 0),
            system_status=modes.system_status if modes is not None else 3,  # now, with faults since the step
            landed_state=mo.landed_state if mo else 0,
            pos_ned=s.pos_ned if s else zero3,
            vel_ned=s.vel_ned if s else zero3,
            quat_wxyz=s.quat_wxyz if s else (1.0, 0.0, 0.0, 0.0),
            rates_frd=s.gyro_frd if s else zero3,
            home_ned=mo.home_ned if mo else None,
            home_yaw_rad=mo.home_yaw_rad if mo else 0.0,
            battery=self.battery,
            tilt_rad=s.tilt_rad if s else (0.0, 0.0),
            speed_rad_s=s.speed_rad_s if s else zero3,
            joint_pos_rad=s.joint_pos_rad if s else zero3,
            sensors=sensor_bits(imu_ok=sensors_ok, pose_ok=sensors_ok, actuators_ok=sensors_ok,
                                estimator_ok=st is not None, battery_ok=self.battery.remaining_pct > 10,
                                prearm_ok=prearm_ok),
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
