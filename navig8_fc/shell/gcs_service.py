"""The FC's ground-station side: wires the pure protocol pieces (navig8_fc.gcs, navig8_fc.modes) to the links.

Implements `VehicleCommands` for the command handler on top of the mode manager, the bridge seam (arm
joints, gripper) and the telemetry scheduler; routes inbound GCS/API messages; sends telemetry on the wall
clock. Every outbound GCS message goes to both GCS-facing links (PARAM_VALUE and STATUSTEXT are broadcasts).
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any

from navig8_fc.gcs.commands import CommandHandler, GripperAction
from navig8_fc.gcs.misc import MiscProtocols
from navig8_fc.gcs.params import ParamProtocol
from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.mavlink import seam
from navig8_fc.params.store import ParamStore, default_state_path

if TYPE_CHECKING:
    from navig8_fc.shell.fc_process import FlightControllerProcess


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
        self.pending_arm_cmd: seam.ArmCommand | None = None
        self.telemetry: Any = None  # set by attach_telemetry when the telemetry pieces exist
        if store is not None and not o.defaults:
            loaded = self.params.load_stored()
            if loaded.ok:
                fc.log_event(f"parameters loaded from {store.path} ({loaded.applied} values)")
            for r in loaded.refused:
                fc.log_event(f"stored value refused: {r.reason}")
        elif o.defaults:
            fc.log_event("starting from default parameters (--defaults)")

    # --- routing ---------------------------------------------------------------------------------
    def handle(self, msgs: list[Any], now_wall: float) -> None:
        out: list[Any] = []
        for m in msgs:
            self.n_gcs_msgs += 1
            out += self.params.handle(m, now_wall)
            out += self.commands.handle(m, now_wall)
            out += self.misc.handle(m, now_wall)
        self.broadcast(out)
        for change in self.params.drain_changes():
            self.fc.log_param_change(change)

    def poll(self, now_wall: float) -> None:
        self.broadcast(self.params.poll(now_wall))
        if self.telemetry is not None:
            self.broadcast(self.telemetry.due_messages(now_wall))

    def broadcast(self, msgs: list[Any]) -> None:
        if not msgs:
            return
        for link in (self.fc.gcs, self.fc.api):
            for m in msgs:
                link.send(m)

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
        if self.telemetry is None:
            return None
        return self.telemetry.build_now(msg_id, time.monotonic())

    def set_message_interval(self, msg_id: int, interval_us: int) -> bool:
        return self.telemetry is not None and self.telemetry.scheduler.set_interval(msg_id, interval_us)

    def message_interval_us(self, msg_id: int) -> int:
        return self.telemetry.scheduler.interval_us(msg_id) if self.telemetry is not None else -1

    def storage(self, action: int) -> tuple[int, list[Any]]:
        return self.params.storage_command(action, armed=self.fc.modes.armed)
