"""Command protocol: one final ACK per command, UNSUPPORTED for unknown ids, DENIED + reason, duplicates."""

from __future__ import annotations

import math
from io import BytesIO
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from test_modes import modes_command

from navig8_fc.flight.commands import (
    ArmJoints,
    Disarm,
    Gripper,
    SetMode,
    Takeoff,
)
from navig8_fc.gcs.commands import ARM_FORCE_MAGIC, MAV_CMD_NAVIG8_ARM_JOINTS, CommandHandler, CommandTarget
from navig8_fc.modes import FlightMode, ModeInputs, ModeManager
from navig8_fc.modes.records import Verdict

M = mavlink2
NAN = math.nan


class FakeVehicle:
    """Records the command records it gets; the flight commands go to a real ModeManager so the checks are the real
    ones."""

    def __init__(self) -> None:
        self.modes = ModeManager()
        self.calls: list[tuple[Any, ...]] = []
        self.intervals: dict[int, int] = {0: 1_000_000, 30: 50_000}
        self.home_ready = True
        self.mav = M.MAVLink(BytesIO(), 1, 1)

    def command(self, cmd: Any) -> Verdict:
        self.calls.append(cmd)
        verdict = modes_command(self.modes, cmd)
        if verdict is not None:
            return verdict
        match cmd:
            case Gripper():
                return Verdict(True)
            case ArmJoints(q_rad=q_rad):
                if any(abs(q) > 1.75 for q in q_rad):
                    return Verdict(False, "joint target outside +-100 deg")
                return Verdict(True)
        return Verdict(False, f"{type(cmd).__name__} not simulated here")

    def task_status(self, channel: str):
        return self.modes.task if channel == "flight" else None  # arm moves are not tracked here

    def takeoff_amsl(self, alt_amsl_m: float) -> Verdict:
        self.calls.append(("takeoff_amsl", alt_amsl_m))
        return self.command(Takeoff(alt_amsl_m - 1100.0))  # home at 1100 m AMSL here

    def request_message(self, msg_id: int, params):
        self.calls.append(("request_message", msg_id, params))
        if msg_id == 148:
            return [self.mav.autopilot_version_encode(8196, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 1)]
        if msg_id == 242:
            if not self.home_ready:
                return []
            return [self.mav.home_position_encode(0, 0, 0, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0)]
        return None

    def set_message_interval(self, msg_id: int, interval_us: int) -> bool:
        self.calls.append(("set_interval", msg_id, interval_us))
        if msg_id not in self.intervals:
            return False
        self.intervals[msg_id] = interval_us
        return True

    def message_interval_us(self, msg_id: int) -> int:
        return self.intervals.get(msg_id, 0)

    def storage(self, action: int):
        self.calls.append(("storage", action))
        if action == 1:
            return M.MAV_RESULT_ACCEPTED, []
        return M.MAV_RESULT_DENIED, [self.mav.statustext_encode(4, b"nope")]


@pytest.fixture
def rig():
    veh_mav = M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
    gcs = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
    vehicle = FakeVehicle()
    vehicle.modes.step(ModeInputs(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0))
    handler = CommandHandler(veh_mav, 1, 1, vehicle)
    return handler, vehicle, veh_mav, gcs


def cmd_long(rig, command: int, *p: float, confirmation: int = 0, target=(1, 1), now_s: float = 0.0) -> list[Any]:
    handler, _, veh, gcs = rig
    params = list(p) + [0.0] * (7 - len(p))
    msg = gcs.command_long_encode(target[0], target[1], command, confirmation, *params)
    inbound = veh.decode(bytearray(msg.pack(gcs)))
    return [gcs.decode(bytearray(m.pack(veh))) for m in handler.handle(inbound, now_s)]


def cmd_int(rig, command: int, frame: int, p1=0.0, p2=0.0, p3=0.0, p4=0.0, x=0, y=0, z=0.0) -> list[Any]:
    handler, _, veh, gcs = rig
    msg = gcs.command_int_encode(1, 1, frame, command, 0, 0, p1, p2, p3, p4, x, y, z)
    inbound = veh.decode(bytearray(msg.pack(gcs)))
    return [gcs.decode(bytearray(m.pack(veh))) for m in handler.handle(inbound, 0.0)]


def the_ack(out: list[Any], command: int) -> Any:
    acks = [m for m in out if m.get_type() == "COMMAND_ACK"]
    assert len(acks) == 1, out  # exactly one final ACK
    assert out[0] is acks[0]  # and it comes first
    ack = acks[0]
    assert ack.command == command and ack.target_system == 255 and ack.target_component == 190
    return ack


def texts(out: list[Any]) -> str:
    return "".join(m.text for m in out if m.get_type() == "STATUSTEXT")  # chunks join without separator


def test_fake_vehicle_satisfies_protocol() -> None:
    v: CommandTarget = FakeVehicle()  # type-checks structurally
    assert callable(v.command)


def test_unknown_command_unsupported_without_statustext(rig) -> None:
    out = cmd_long(rig, 12345, 1.0)
    assert the_ack(out, 12345).result == M.MAV_RESULT_UNSUPPORTED and len(out) == 1
    out = cmd_long(rig, M.MAV_CMD_DO_SET_SERVO, 1.0)
    assert the_ack(out, M.MAV_CMD_DO_SET_SERVO).result == M.MAV_RESULT_UNSUPPORTED


def test_commands_for_others_are_ignored(rig) -> None:
    assert cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target=(2, 1)) == []
    assert cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target=(1, 100)) == []
    assert rig[1].calls == []
    out = cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target=(0, 0))  # broadcast
    assert the_ack(out, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED


def test_arm_disarm_and_force(rig) -> None:
    _, vehicle, _, _ = rig
    out = cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    assert the_ack(out, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED and vehicle.modes.armed
    out = cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, ARM_FORCE_MAGIC)
    assert the_ack(out, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
    assert vehicle.calls[-1] == Disarm(True) and not vehicle.modes.armed
    out = cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 3.0)
    assert the_ack(out, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_DENIED and "param1" in texts(out)


def test_prearm_failure_denied_with_statustext(rig) -> None:
    _, vehicle, _, _ = rig
    vehicle.modes.step(ModeInputs(0.01, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, sensors_ok=False))
    out = cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    assert the_ack(out, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_DENIED
    assert "Arming denied" in texts(out) and "sensors" in texts(out)
    assert all(m.severity == M.MAV_SEVERITY_WARNING for m in out if m.get_type() == "STATUSTEXT")
    assert not vehicle.modes.armed


def test_takeoff_long_p7_and_int_z(rig) -> None:
    _, vehicle, _, _ = rig
    out = cmd_long(rig, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, NAN, NAN, NAN, 2.0)
    assert the_ack(out, M.MAV_CMD_NAV_TAKEOFF).result == M.MAV_RESULT_DENIED and "not armed" in texts(out)
    cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    out = cmd_long(rig, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, NAN, NAN, NAN, 2.0)
    assert the_ack(out, M.MAV_CMD_NAV_TAKEOFF).result == M.MAV_RESULT_IN_PROGRESS  # long-running (docs/gcs.md)
    assert vehicle.calls[-1] == Takeoff(2.0) and vehicle.modes.flight_mode is FlightMode.TAKEOFF
    out = cmd_int(rig, M.MAV_CMD_NAV_TAKEOFF, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, p4=NAN, z=3.0)
    assert the_ack(out, M.MAV_CMD_NAV_TAKEOFF).result == M.MAV_RESULT_IN_PROGRESS
    assert vehicle.calls[-1] == Takeoff(3.0)
    out = cmd_int(rig, M.MAV_CMD_NAV_TAKEOFF, M.MAV_FRAME_GLOBAL_INT, z=1104.0)  # a GLOBAL frame: z AMSL
    assert the_ack(out, M.MAV_CMD_NAV_TAKEOFF).result == M.MAV_RESULT_IN_PROGRESS
    assert vehicle.calls[-2:] == [("takeoff_amsl", 1104.0), Takeoff(4.0)]
    out = cmd_int(rig, M.MAV_CMD_NAV_TAKEOFF, M.MAV_FRAME_LOCAL_NED, z=-3.0)
    assert the_ack(out, M.MAV_CMD_NAV_TAKEOFF).result == M.MAV_RESULT_DENIED and "frame" in texts(out)


def test_land_and_set_mode_px4(rig) -> None:
    _, vehicle, _, _ = rig
    cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED
    out = cmd_long(rig, M.MAV_CMD_DO_SET_MODE, base, 4, 3)  # AUTO.LOITER = Hold
    assert the_ack(out, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_ACCEPTED
    assert vehicle.calls[-1] == SetMode(base, 0x03040000)
    out = cmd_long(rig, M.MAV_CMD_DO_SET_MODE, 0, 4, 3)
    assert the_ack(out, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_DENIED and "CUSTOM_MODE_ENABLED" in texts(out)
    out = cmd_long(rig, M.MAV_CMD_DO_SET_MODE, 1, 2, 0)  # ALTCTL
    assert the_ack(out, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_DENIED and "ALTCTL" in texts(out)
    out = cmd_long(rig, M.MAV_CMD_DO_SET_MODE, 1, 4, 4)  # Mission without a script
    assert the_ack(out, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_DENIED and "mission" in texts(out)
    out = cmd_long(rig, M.MAV_CMD_NAV_LAND, 0, 0, 0, NAN, 0, 0, 0)
    assert the_ack(out, M.MAV_CMD_NAV_LAND).result == M.MAV_RESULT_ACCEPTED
    assert vehicle.modes.flight_mode is FlightMode.LAND


def test_request_message_autopilot_version_and_unknown(rig) -> None:
    out = cmd_long(rig, M.MAV_CMD_REQUEST_MESSAGE, 148)
    assert the_ack(out, M.MAV_CMD_REQUEST_MESSAGE).result == M.MAV_RESULT_ACCEPTED
    assert [m.get_type() for m in out] == ["COMMAND_ACK", "AUTOPILOT_VERSION"]
    out = cmd_long(rig, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1)
    assert [m.get_type() for m in out] == ["COMMAND_ACK", "AUTOPILOT_VERSION"]
    for msg_id in (395, 397, 435):  # what QGC asks for on connect: a fast answer, no STATUSTEXT spam
        out = cmd_long(rig, M.MAV_CMD_REQUEST_MESSAGE, msg_id)
        assert the_ack(out, M.MAV_CMD_REQUEST_MESSAGE).result == M.MAV_RESULT_DENIED and len(out) == 1
    out = cmd_long(rig, M.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1)
    assert the_ack(out, M.MAV_CMD_REQUEST_PROTOCOL_VERSION).result == M.MAV_RESULT_UNSUPPORTED


def test_home_position_request_and_not_ready(rig) -> None:
    _, vehicle, _, _ = rig
    out = cmd_long(rig, M.MAV_CMD_REQUEST_MESSAGE, 242)
    assert [m.get_type() for m in out] == ["COMMAND_ACK", "HOME_POSITION"]
    vehicle.home_ready = False
    out = cmd_long(rig, M.MAV_CMD_GET_HOME_POSITION)
    assert the_ack(out, M.MAV_CMD_GET_HOME_POSITION).result == M.MAV_RESULT_TEMPORARILY_REJECTED


def test_message_intervals(rig) -> None:
    _, vehicle, _, _ = rig
    out = cmd_long(rig, M.MAV_CMD_SET_MESSAGE_INTERVAL, 30, 100_000)
    assert the_ack(out, M.MAV_CMD_SET_MESSAGE_INTERVAL).result == M.MAV_RESULT_ACCEPTED
    assert vehicle.intervals[30] == 100_000
    out = cmd_long(rig, M.MAV_CMD_SET_MESSAGE_INTERVAL, 30, -1)
    assert the_ack(out, M.MAV_CMD_SET_MESSAGE_INTERVAL).result == M.MAV_RESULT_ACCEPTED and vehicle.intervals[30] == -1
    out = cmd_long(rig, M.MAV_CMD_SET_MESSAGE_INTERVAL, 9999, 100_000)
    assert the_ack(out, M.MAV_CMD_SET_MESSAGE_INTERVAL).result == M.MAV_RESULT_DENIED
    out = cmd_long(rig, M.MAV_CMD_SET_MESSAGE_INTERVAL, 30, -5)
    assert the_ack(out, M.MAV_CMD_SET_MESSAGE_INTERVAL).result == M.MAV_RESULT_DENIED
    out = cmd_long(rig, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0)
    assert [m.get_type() for m in out] == ["COMMAND_ACK", "MESSAGE_INTERVAL"]
    assert out[1].message_id == 0 and out[1].interval_us == 1_000_000
    out = cmd_long(rig, M.MAV_CMD_REQUEST_MESSAGE, 244, 30)  # MESSAGE_INTERVAL via REQUEST_MESSAGE
    assert out[1].get_type() == "MESSAGE_INTERVAL" and out[1].message_id == 30 and out[1].interval_us == -1


def test_gripper(rig) -> None:
    _, vehicle, _, _ = rig
    out = cmd_long(rig, M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_GRAB)
    assert the_ack(out, M.MAV_CMD_DO_GRIPPER).result == M.MAV_RESULT_ACCEPTED
    assert vehicle.calls[-1] == Gripper("grab")
    out = cmd_long(rig, M.MAV_CMD_DO_GRIPPER, 0, M.GRIPPER_ACTION_RELEASE)
    assert the_ack(out, M.MAV_CMD_DO_GRIPPER).result == M.MAV_RESULT_ACCEPTED
    assert vehicle.calls[-1] == Gripper("release")
    out = cmd_long(rig, M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_HOLD)
    assert the_ack(out, M.MAV_CMD_DO_GRIPPER).result == M.MAV_RESULT_DENIED
    out = cmd_long(rig, M.MAV_CMD_DO_GRIPPER, 3, 1)
    assert the_ack(out, M.MAV_CMD_DO_GRIPPER).result == M.MAV_RESULT_DENIED


def test_arm_joints_user_1(rig) -> None:
    _, vehicle, _, _ = rig
    assert MAV_CMD_NAVIG8_ARM_JOINTS == M.MAV_CMD_USER_1 == 31010
    out = cmd_long(rig, 31010, 20.0, -20.0, 10.0, 1.0)
    assert the_ack(out, 31010).result == M.MAV_RESULT_ACCEPTED
    assert vehicle.calls[-1].q_rad == pytest.approx((math.radians(20), math.radians(-20), math.radians(10)))
    out = cmd_long(rig, 31010, 20.0, -20.0, 10.0, 0.0)  # p4 must be 1
    assert the_ack(out, 31010).result == M.MAV_RESULT_DENIED and "param4" in texts(out)
    out = cmd_long(rig, 31010, 200.0, 0.0, 0.0, 1.0)  # refused by the vehicle
    assert the_ack(out, 31010).result == M.MAV_RESULT_DENIED and "outside" in texts(out)
    out = cmd_long(rig, 31010, NAN, 0.0, 0.0, 1.0)
    assert the_ack(out, 31010).result == M.MAV_RESULT_DENIED


def test_gripper_and_arm_joints_accepted_send_an_info_statustext(rig) -> None:
    out = cmd_long(rig, M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_GRAB)
    assert [m.get_type() for m in out] == ["COMMAND_ACK", "STATUSTEXT"]
    assert out[1].severity == M.MAV_SEVERITY_INFO and out[1].text == "Gripper: grab"
    out = cmd_long(rig, M.MAV_CMD_DO_GRIPPER, 0, M.GRIPPER_ACTION_RELEASE)
    assert out[1].severity == M.MAV_SEVERITY_INFO and out[1].text == "Gripper: release"
    out = cmd_long(rig, 31010, 20.0, -20.0, 10.0, 1.0)
    assert [m.get_type() for m in out] == ["COMMAND_ACK", "STATUSTEXT"]
    assert out[1].severity == M.MAV_SEVERITY_INFO and out[1].text == "Arm joints: target 20.0 -20.0 10.0 deg"
    # Denied ones keep their reason (WARNING) and report no event.
    for out in (cmd_long(rig, M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_HOLD), cmd_long(rig, 31010, 200.0, 0, 0, 1)):
        assert out[0].result == M.MAV_RESULT_DENIED
        assert [m.severity for m in out[1:]] == [M.MAV_SEVERITY_WARNING] * (len(out) - 1) and len(out) > 1
        assert "Gripper:" not in texts(out) and "Arm joints: target" not in texts(out)


def test_storage_passes_result_and_messages(rig) -> None:
    out = cmd_long(rig, M.MAV_CMD_PREFLIGHT_STORAGE, 1)
    assert the_ack(out, M.MAV_CMD_PREFLIGHT_STORAGE).result == M.MAV_RESULT_ACCEPTED
    out = cmd_long(rig, M.MAV_CMD_PREFLIGHT_STORAGE, 5)
    assert the_ack(out, M.MAV_CMD_PREFLIGHT_STORAGE).result == M.MAV_RESULT_DENIED and texts(out) == "nope"


def test_duplicate_confirmation_gets_same_result_without_reexecuting(rig) -> None:
    _, vehicle, _, _ = rig
    out1 = cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, now_s=10.0)
    n_calls = len(vehicle.calls)
    out2 = cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, confirmation=1, now_s=10.5)
    assert the_ack(out2, M.MAV_CMD_COMPONENT_ARM_DISARM).result == the_ack(out1, 400).result
    assert len(vehicle.calls) == n_calls and len(out2) == 1
    # Outside the window, or with other parameters, it executes again.
    cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, confirmation=2, now_s=13.0)
    assert len(vehicle.calls) == n_calls + 1
    cmd_long(rig, M.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, confirmation=1, now_s=13.1)
    assert len(vehicle.calls) == n_calls + 2
    # Read-only requests are answered again (the client probably lost the message).
    cmd_long(rig, M.MAV_CMD_REQUEST_MESSAGE, 148, now_s=14.0)
    out = cmd_long(rig, M.MAV_CMD_REQUEST_MESSAGE, 148, confirmation=1, now_s=14.1)
    assert [m.get_type() for m in out] == ["COMMAND_ACK", "AUTOPILOT_VERSION"]


def test_denied_duplicate_keeps_denied(rig) -> None:
    _, vehicle, _, _ = rig
    vehicle.modes.step(ModeInputs(0.01, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, sensors_ok=False))
    out1 = cmd_long(rig, 400, 1.0, now_s=1.0)
    out2 = cmd_long(rig, 400, 1.0, confirmation=1, now_s=1.2)
    assert the_ack(out1, 400).result == the_ack(out2, 400).result == M.MAV_RESULT_DENIED


def test_vehicle_exception_becomes_failed(rig) -> None:
    handler, vehicle, _, _ = rig

    def boom(cmd: Any):
        raise RuntimeError("kaboom")

    vehicle.command = boom  # type: ignore[method-assign]
    out = cmd_long(rig, 400, 1.0)
    assert the_ack(out, 400).result == M.MAV_RESULT_FAILED and "kaboom" in texts(out)


def test_every_supported_command_gets_exactly_one_ack_even_with_garbage_params(rig) -> None:
    handler = rig[0]
    for command in sorted(handler.supported_commands):
        for params in ((NAN,) * 7, (1e30,) * 7, (-1.0,) * 7, (0.0,) * 7):
            the_ack(cmd_long(rig, command, *params), command)
            frame = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
            the_ack(cmd_int(rig, command, frame, *params[:4], x=-(2**31), y=2**31 - 1, z=params[0]), command)
