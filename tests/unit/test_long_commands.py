"""Long-running commands (COMMAND_ACK IN_PROGRESS with progress, then one final ACK) and COMMAND_CANCEL: the command
handler over a real ModeManager flying a point-mass vehicle, and the FlightStack's arm-joint move."""

from __future__ import annotations

import math
from io import BytesIO
from typing import Any

import pytest
from test_gcs_commands import FakeVehicle
from test_modes import DT, PointMass

from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import FcSensors
from navig8_fc.flight import FlightStack
from navig8_fc.flight.arm_task import ARM_JOINT_TIMEOUT_S
from navig8_fc.flight.commands import ArmJoints, CancelTask
from navig8_fc.flight.stack import TASK_ARM
from navig8_fc.gcs.commands import MAV_CMD_NAVIG8_ARM_JOINTS, MAV_RESULT_CANCELLED, PROGRESS_PERIOD_S, CommandHandler
from navig8_fc.mavlink import dialect
from navig8_fc.modes import FlightMode
from navig8_fc.modes.tasks import TASK_CANCELLED, TASK_DONE, TASK_FAILED, TASK_RUNNING
from navig8_fc.params.registry import ParamRegistry

D = dialect.load()  # has COMMAND_CANCEL and MAV_RESULT_CANCELLED (navig8.xml)
NAN = math.nan
API, GCS = "api", "gcs"


class Bench:
    """The handler, a vehicle whose commands go to a real ModeManager, the point mass it flies, two clients."""

    def __init__(self, flight_progress: bool = True) -> None:
        self.vehicle = FakeVehicle()
        self.body = PointMass()
        self.mav = D.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
        self.clients = {API: D.MAVLink(BytesIO(), 245, 190), GCS: D.MAVLink(BytesIO(), 255, 190)}
        self.handler = CommandHandler(self.mav, 1, 1, self.vehicle, flight_progress=flight_progress)
        self.t = 0.0
        self.sent: list[tuple[Any, Any]] = []  # (source, message) from poll
        self.fly(DT)

    def fly(self, seconds: float) -> None:
        """Step the vehicle; poll the handler every step (sim time stands for the wall clock here)."""
        for _ in range(int(round(seconds / DT))):
            out = self.vehicle.modes.step(self.body.inputs(self.t))
            self.body.move(out.engaged, out.setpoint)
            self.t += DT
            self.sent += [(s, self._wire(m)) for s, m in self.handler.poll(self.t)]

    def _wire(self, m: Any) -> Any:
        return self.mav.decode(bytearray(m.pack(self.mav)))

    def send(self, who: str, msg: Any) -> list[Any]:
        inbound = self.mav.decode(bytearray(msg.pack(self.clients[who])))
        return [self._wire(m) for m in self.handler.handle(inbound, self.t, who)]

    def command(self, who: str, command: int, *p: float) -> Any:
        params = list(p) + [0.0] * (7 - len(p))
        out = self.send(who, self.clients[who].command_long_encode(1, 1, command, 0, *params))
        return next(m for m in out if m.get_type() == "COMMAND_ACK")

    def acks(self) -> list[tuple[Any, int, int, int]]:
        got = [(s, m.command, m.result, m.progress) for s, m in self.sent if m.get_type() == "COMMAND_ACK"]
        self.sent = [(s, m) for s, m in self.sent if m.get_type() != "COMMAND_ACK"]
        return got


def _airborne() -> Bench:
    b = Bench()
    assert b.command(API, D.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == D.MAV_RESULT_ACCEPTED
    assert b.command(API, D.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, NAN, NAN, NAN, 1.5).result == D.MAV_RESULT_IN_PROGRESS
    b.fly(5.0)
    b.acks()
    return b


def test_takeoff_reports_progress_then_accepted_and_a_retry_does_not_restart_it() -> None:
    b = Bench()
    b.command(API, D.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    ack = b.command(API, D.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, NAN, NAN, NAN, 2.0)
    assert (ack.result, ack.progress, ack.target_system) == (D.MAV_RESULT_IN_PROGRESS, 0, 245)
    b.fly(1.0)
    calls = len(b.vehicle.calls)
    retry = b.command(API, D.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, NAN, NAN, NAN, 2.0)  # MAVSDK re-sends after 1.5 s
    assert retry.result == D.MAV_RESULT_IN_PROGRESS and retry.progress > 0 and len(b.vehicle.calls) == calls
    b.fly(4.0)
    acks = b.acks()
    updates = [a for a in acks if a[2] == D.MAV_RESULT_IN_PROGRESS]
    assert all(s == API and c == D.MAV_CMD_NAV_TAKEOFF for s, c, _, _ in acks)
    assert len(updates) >= 3 * PROGRESS_PERIOD_S * 2  # every PROGRESS_PERIOD_S while climbing (~3 s)
    assert [p for *_, p in updates] == sorted(p for *_, p in updates)
    assert acks[-1][2:] == (D.MAV_RESULT_ACCEPTED, 100) and len(acks) - len(updates) == 1
    assert b.body.pos[2] == pytest.approx(-2.0, abs=0.2) and b.vehicle.modes.flight_mode is FlightMode.HOLD


def test_without_flight_progress_flight_commands_are_accepted_at_once_as_px4_does() -> None:
    """PX4's Commander: take-off, reposition, land and return ACCEPTED when started, nothing after; the vehicle does
    them all the same (seen in telemetry); a retry gets the same answer without a second start."""
    b = Bench(flight_progress=False)
    b.command(API, D.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    ack = b.command(API, D.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, NAN, NAN, NAN, 2.0)
    assert (ack.result, ack.target_system) == (D.MAV_RESULT_ACCEPTED, 245)
    b.fly(5.0)
    assert b.acks() == [] and b.body.pos[2] == pytest.approx(-2.0, abs=0.2)
    assert b.vehicle.modes.flight_mode is FlightMode.HOLD
    for cmd in (D.MAV_CMD_NAV_RETURN_TO_LAUNCH, D.MAV_CMD_NAV_LAND):
        first = b.command(API, cmd)
        calls = len(b.vehicle.calls)
        again = b.send(API, b.clients[API].command_long_encode(1, 1, cmd, 1, 0, 0, 0, 0, 0, 0, 0))[0]
        assert first.result == again.result == D.MAV_RESULT_ACCEPTED and len(b.vehicle.calls) == calls
        b.fly(0.5)
    b.fly(8.0)
    assert b.acks() == [] and b.vehicle.modes.landed


def test_cancel_stops_a_landing_holds_where_the_vehicle_is_and_acks_the_requester() -> None:
    b = _airborne()
    assert b.command(API, D.MAV_CMD_NAV_LAND).result == D.MAV_RESULT_IN_PROGRESS
    b.fly(1.0)
    z_cancel = b.body.pos[2]
    assert z_cancel > -1.4  # descending
    assert b.send(GCS, b.clients[GCS].command_cancel_encode(1, 1, D.MAV_CMD_NAV_LAND)) == []
    b.fly(2.0)
    acks = b.acks()
    assert acks[-1][:3] == (API, D.MAV_CMD_NAV_LAND, MAV_RESULT_CANCELLED)  # to the requester, not the canceller
    assert b.vehicle.modes.flight_mode is FlightMode.HOLD and b.body.pos[2] == pytest.approx(z_cancel, abs=0.05)
    assert b.vehicle.modes.task.state == TASK_CANCELLED
    # Nothing runs now: a cancel is ignored.
    assert b.send(GCS, b.clients[GCS].command_cancel_encode(1, 1, D.MAV_CMD_NAV_LAND)) == []
    b.fly(0.5)
    assert b.acks() == [] and b.vehicle.modes.flight_mode is FlightMode.HOLD


def test_reposition_task_progress_and_done_within_the_acceptance_radius() -> None:
    b = _airborne()
    mm = b.vehicle.modes
    assert mm.reposition((3.0, 0.0, -1.5)).ok
    b.fly(1.0)
    mid = mm.task
    assert mid.kind == "reposition" and mid.state == TASK_RUNNING and 20.0 < mid.progress_pct < 80.0
    b.fly(4.0)
    assert mm.task.state == TASK_DONE and math.dist(b.body.pos, (3.0, 0.0, -1.5)) < mm.config.reposition_reached_tol_m


def test_a_newer_command_replaces_the_running_one_and_a_failsafe_fails_it() -> None:
    b = _airborne()
    assert b.command(API, D.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == D.MAV_RESULT_IN_PROGRESS
    b.fly(0.5)
    assert b.command(GCS, D.MAV_CMD_NAV_LAND).result == D.MAV_RESULT_IN_PROGRESS  # Land replaces Return
    b.fly(0.1)
    acks = b.acks()
    assert (API, D.MAV_CMD_NAV_RETURN_TO_LAUNCH, MAV_RESULT_CANCELLED, 0) in [(s, c, r, 0) for s, c, r, _ in acks]
    b.vehicle.modes.fail_task("failsafe: Battery critical")  # what FlightStack._failsafe does before acting
    b.fly(0.1)
    (last,) = [a for a in b.acks() if a[2] != D.MAV_RESULT_IN_PROGRESS]
    assert last[:3] == (GCS, D.MAV_CMD_NAV_LAND, D.MAV_RESULT_FAILED)
    texts = [m.text for _, m in b.sent if m.get_type() == "STATUSTEXT"]
    assert any("failsafe: Battery critical" in t for t in texts), texts


def test_return_to_launch_command_is_done_at_touchdown_at_home() -> None:
    b = _airborne()
    b.vehicle.modes.reposition((2.0, 1.0, -1.5))
    b.fly(3.0)
    assert b.command(API, D.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == D.MAV_RESULT_IN_PROGRESS
    b.fly(15.0)
    acks = b.acks()
    assert acks[-1][1:] == (D.MAV_CMD_NAV_RETURN_TO_LAUNCH, D.MAV_RESULT_ACCEPTED, 100)
    assert math.hypot(b.body.pos[0], b.body.pos[1]) < 0.25 and b.body.pos[2] == 0.0


# --- the arm-joint move (FlightStack) ------------------------------------------------------------------------
def _sensors(t_s: float, q: tuple[float, float, float]) -> FcSensors:
    return FcSensors(t_s=t_s, gyro_frd_rad_s=(0.0, 0.0, 0.0), accel_frd_m_s2=(0.0, 0.0, -9.81), pos_ned_m=(0.0, 0.0,
                                                                                                           0.0),
                     vel_ned_m_s=(0.0, 0.0, 0.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0), duct_tilt_rad=(0.0, 0.0),
                     prop_speed_rad_s=(0.0, 0.0, 0.0), joint_pos_rad=q, joint_rate_rad_s=(0.0, 0.0, 0.0))


def test_arm_joint_move_progress_done_cancel_and_timeout() -> None:
    stack = FlightStack(vm.VehicleConfig.load(), ParamRegistry.from_defaults())
    stack.step(_sensors(0.0, (0.0, 0.0, 0.0)))
    target = (math.radians(40), 0.0, math.radians(-20))
    assert stack.command(ArmJoints(target)).ok
    ts = stack.task_status(TASK_ARM)
    assert ts.state == TASK_RUNNING and ts.kind == "arm_joints"
    stack.step(_sensors(0.01, (math.radians(20), 0.0, math.radians(-10))))  # half way (largest error 40 -> 20)
    assert stack.task_status(TASK_ARM).progress_pct == pytest.approx(50.0)
    stack.step(_sensors(0.02, (math.radians(39.5), 0.0, math.radians(-19.5))))  # within 2 deg
    assert stack.task_status(TASK_ARM).state == TASK_DONE
    # Cancel: the joints are told to stay where they are.
    assert stack.command(ArmJoints((0.0, 0.0, 0.0))).ok
    stack.step(_sensors(0.03, (0.5, 0.0, -0.3)))
    assert stack.command(CancelTask(TASK_ARM)).ok
    assert stack.state().pending_arm_request.joint_target_rad == (0.5, 0.0, -0.3)
    assert stack.task_status(TASK_ARM).state == TASK_CANCELLED and not stack.command(CancelTask(TASK_ARM)).ok
    # A move that never gets there fails after ARM_JOINT_TIMEOUT_S.
    assert stack.command(ArmJoints((1.0, 0.0, 0.0))).ok
    stack.step(_sensors(0.04 + ARM_JOINT_TIMEOUT_S + 0.01, (0.5, 0.0, -0.3)))
    ts = stack.task_status(TASK_ARM)
    assert ts.state == TASK_FAILED and "off after" in ts.reason


@pytest.mark.parametrize("flight_progress", [True, False])  # the arm-joint target keeps the protocol either way
def test_arm_joint_command_is_long_through_the_handler(flight_progress: bool) -> None:
    stack = FlightStack(vm.VehicleConfig.load(), ParamRegistry.from_defaults())
    stack.step(_sensors(0.0, (0.0, 0.0, 0.0)))
    mav = D.MAVLink(BytesIO(), 1, 1)
    client = D.MAVLink(BytesIO(), 255, 190)

    class Target:  # the stack's commands, nothing else needed here
        def __getattr__(self, name: str) -> Any:
            return getattr(stack, name)

    handler = CommandHandler(mav, 1, 1, Target(), flight_progress=flight_progress)  # type: ignore[arg-type]
    msg = mav.decode(bytearray(client.command_long_encode(1, 1, MAV_CMD_NAVIG8_ARM_JOINTS, 0, 30, 0, 0, 1, 0, 0, 0)
                               .pack(client)))
    (ack, *_) = handler.handle(msg, 0.0, GCS)
    assert ack.result == D.MAV_RESULT_IN_PROGRESS
    stack.step(_sensors(0.01, (math.radians(30), 0.0, 0.0)))
    ((dest, final),) = handler.poll(0.1)
    assert dest == GCS and final.result == D.MAV_RESULT_ACCEPTED and final.command == MAV_CMD_NAVIG8_ARM_JOINTS
