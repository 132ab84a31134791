"""The GCS pieces together, without sockets: a pymavlink "GCS" connects, downloads parameters, sets one,
arms, takes off to 2 m, holds, lands and sees the vehicle disarm, through CommandHandler + ModeManager +
ParamProtocol + TelemetryScheduler/Builder and a point-mass stand-in for the plant. Run with pymavlink's
common dialect and with the generated navig8 dialect (the code takes a `mav` object, either works)."""

from __future__ import annotations

import math
from io import BytesIO
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from test_modes import modes_command

from navig8_fc.flight.commands import (
    ArmJoints,
    Gripper,
)
from navig8_fc.gcs.commands import CommandHandler
from navig8_fc.gcs.misc import MiscProtocols
from navig8_fc.gcs.params import ParamProtocol
from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.gcs.telemetry import TelemetryBuilder, TelemetryScheduler, VehicleSnapshot, sensor_bits
from navig8_fc.modes import ModeInputs, ModeManager, ModeOutput
from navig8_fc.modes.records import Verdict
from navig8_fc.params.registry import ParamRegistry, StabilityFloor
from navig8_fc.params.store import ParamStore

DT = 0.01


def _dialects() -> list[Any]:
    out: list[Any] = [pytest.param(mavlink2, id="common")]
    try:
        from navig8_fc.mavlink import dialect

        out.append(pytest.param(dialect.load(), id="navig8"))
    except Exception as exc:  # noqa: BLE001 - the dialect is optional for this test
        out.append(pytest.param(None, id="navig8", marks=pytest.mark.skip(reason=f"no navig8 dialect: {exc}")))
    return out


class SimVehicle:
    """A minimal shell: owns the pure pieces, a point mass, and implements VehicleCommands."""

    def __init__(self, mod: Any, store: ParamStore) -> None:
        self.mav = mod.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
        text = StatusTextEncoder(self.mav)
        self.text = text
        self.events_out: list[Any] = []
        self.registry = ParamRegistry.from_defaults(
            stability_check=lambda v: StabilityFloor(0.2, float(v["INDI_K_MIN"]))
        )
        self.params = ParamProtocol(self.registry, self.mav, store, statustext=text)
        self.modes = ModeManager()
        self.sched = TelemetryScheduler()
        self.builder = TelemetryBuilder(self.mav, 1, 1)
        self.commands = CommandHandler(self.mav, 1, 1, self, statustext=text)
        self.misc = MiscProtocols(self.mav, statustext=text)
        self.pos = [0.0, 0.0, 0.0]
        self.vel = [0.0, 0.0, 0.0]
        self.thrust = 0.0
        self.t = 0.0
        self.out: ModeOutput | None = None
        self.gripper_closed = False

    # VehicleCommands: the flight commands go to a real ModeManager
    def command(self, cmd: Any) -> Verdict:
        verdict = modes_command(self.modes, cmd)
        if verdict is not None:
            return verdict
        match cmd:
            case Gripper(action=action):
                self.gripper_closed = action == "grab"
                return Verdict(True)
            case ArmJoints():
                return Verdict(True)
        return Verdict(False, f"{type(cmd).__name__} not simulated here")

    def task_status(self, channel: str):
        return self.modes.task if channel == "flight" else None

    def request_message(self, msg_id: int, params):
        if msg_id not in self.builder.supported_ids:
            return None
        return self.builder.build(msg_id, self.snapshot(), int(self.t * 1000))

    def set_message_interval(self, msg_id: int, interval_us: int) -> bool:
        return self.sched.set_interval(msg_id, interval_us)

    def message_interval_us(self, msg_id: int) -> int:
        return self.sched.interval_us(msg_id)

    def storage(self, action: int):
        return self.params.storage_command(action, armed=self.modes.armed)

    # shell duties
    def snapshot(self) -> VehicleSnapshot:
        m = self.modes
        return VehicleSnapshot(
            armed=m.armed, base_mode=m.base_mode, custom_mode=m.custom_mode,
            system_status=self.out.system_status if self.out else 1,
            landed_state=self.out.landed_state if self.out else 0,
            pos_ned_m=tuple(self.pos), vel_ned_m_s=tuple(self.vel), quat_wxyz=(1.0, 0.0, 0.0, 0.0),
            gyro_frd_rad_s=(0.0, 0.0, 0.0), home_ned_m=m.home_ned_m, home_yaw_rad=m.home_yaw_rad,
            sensors=sensor_bits(imu_ok=True, pose_ok=True, actuators_ok=True, estimator_ok=True, battery_ok=True,
                                prearm_ok=m.prearm_check().ok),
        )  # fmt: skip

    def control_step(self) -> None:
        self.out = self.modes.step(ModeInputs(self.t, tuple(self.pos), tuple(self.vel), 0.0, self.thrust))
        for event in self.out.events:  # the shell turns mode events into STATUSTEXT(INFO)
            self.events_out += self.text.info(event)
        if self.out.engaged:
            err = [self.out.setpoint.pos_ned_m[i] - self.pos[i] for i in range(3)]
            self.vel = [max(-1.5, min(1.5, 2.0 * e)) for e in err]
            self.thrust = 1.0
        else:
            self.vel = [0.0, 0.0, 0.0]
            self.thrust = 0.0
        self.pos = [self.pos[i] + self.vel[i] * DT for i in range(3)]
        if self.pos[2] >= 0.0:
            self.pos[2] = 0.0
            if self.vel[2] > 0.0:
                self.vel[2] = 0.0
                self.thrust = 0.1
        self.t += DT

    def receive(self, msg: Any) -> list[Any]:
        now = self.t
        return (self.params.handle(msg, now) + self.commands.handle(msg, now) + self.misc.handle(msg, now))

    def outbound(self) -> list[Any]:
        snap = self.snapshot()
        due = self.sched.due(self.t)
        events, self.events_out = self.events_out, []
        return (events + self.builder.build_many(due, snap, int(self.t * 1000)) + self.params.poll(self.t)
                + [m for _, m in self.commands.poll(self.t)])


class Gcs:
    def __init__(self, mod: Any, vehicle: SimVehicle) -> None:
        self.mav = mod.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
        self.vehicle = vehicle
        self.inbox: list[Any] = []

    def send(self, msg: Any) -> None:
        decoded = self.vehicle.mav.decode(bytearray(msg.pack(self.mav)))
        self._take(self.vehicle.receive(decoded))

    def _take(self, msgs: list[Any]) -> None:
        self.inbox += [self.mav.decode(bytearray(m.pack(self.vehicle.mav))) for m in msgs]

    def run(self, seconds: float) -> None:
        for _ in range(int(round(seconds / DT))):
            self.vehicle.control_step()
            self._take(self.vehicle.outbound())

    def pop(self, kind: str) -> list[Any]:
        got = [m for m in self.inbox if m.get_type() == kind]
        self.inbox = [m for m in self.inbox if m.get_type() != kind]
        return got

    def command(self, command: int, *p: float) -> Any:
        params = list(p) + [0.0] * (7 - len(p))
        self.send(self.mav.command_long_encode(1, 1, command, 0, *params))
        (ack,) = self.pop("COMMAND_ACK")
        assert ack.command == command
        return ack


@pytest.mark.parametrize("mod", _dialects())
def test_connect_params_arm_takeoff_hold_land_disarm(mod: Any, tmp_path: Path) -> None:
    M = mavlink2
    vehicle = SimVehicle(mod, ParamStore(tmp_path / "p.json"))
    gcs = Gcs(mod, vehicle)
    gcs.run(1.0)
    hbs = gcs.pop("HEARTBEAT")
    assert len(hbs) == 1 and hbs[0].type == M.MAV_TYPE_TRICOPTER and hbs[0].get_srcComponent() == 1
    assert gcs.pop("HOME_POSITION")  # a home before arming (MAVSDK's is_home_position_ok)

    ack = gcs.command(M.MAV_CMD_REQUEST_MESSAGE, 148)
    assert ack.result == M.MAV_RESULT_ACCEPTED and gcs.pop("AUTOPILOT_VERSION")

    # Full parameter download, then a refused and an accepted set.
    gcs.send(gcs.mav.param_request_list_encode(1, 1))
    gcs.run(1.0)
    values = gcs.pop("PARAM_VALUE")
    n = len(vehicle.registry)
    assert sorted(v.param_index for v in values) == list(range(n)) and {v.param_count for v in values} == {n}
    gcs.send(gcs.mav.param_set_encode(1, 1, b"INDI_K_MIN", 0.1, M.MAV_PARAM_TYPE_REAL32))
    (pv,) = gcs.pop("PARAM_VALUE")
    assert pv.param_value == pytest.approx(0.5) and gcs.pop("STATUSTEXT")
    gcs.send(gcs.mav.param_set_encode(1, 1, b"OL_POS_K", 1.25, M.MAV_PARAM_TYPE_REAL32))
    (pv,) = gcs.pop("PARAM_VALUE")
    assert pv.param_value == pytest.approx(1.25)

    assert gcs.command(31337).result == M.MAV_RESULT_UNSUPPORTED

    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == M.MAV_RESULT_ACCEPTED
    # A long-running command: IN_PROGRESS at once, progress updates, the final ACCEPTED at the takeoff altitude.
    ack = gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 2.0)
    assert ack.result == M.MAV_RESULT_IN_PROGRESS and ack.progress == 0
    gcs.run(6.0)
    acks = gcs.pop("COMMAND_ACK")
    assert [a.result for a in acks[:-1]] == [M.MAV_RESULT_IN_PROGRESS] * (len(acks) - 1) and len(acks) >= 4
    progress = [a.progress for a in acks[:-1]]
    assert progress == sorted(progress) and progress[-1] > 50
    assert acks[-1].result == M.MAV_RESULT_ACCEPTED and acks[-1].progress == 100
    hb = gcs.pop("HEARTBEAT")[-1]
    assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED and hb.custom_mode == 0x03040000  # Hold
    assert abs(vehicle.pos[2] + 2.0) < 0.05
    assert gcs.pop("EXTENDED_SYS_STATE")[-1].landed_state == M.MAV_LANDED_STATE_IN_AIR
    gp = gcs.pop("GLOBAL_POSITION_INT")[-1]
    assert gp.relative_alt == pytest.approx(2000, abs=50)

    assert gcs.command(M.MAV_CMD_NAV_LAND).result == M.MAV_RESULT_IN_PROGRESS
    gcs.run(8.0)
    assert gcs.pop("COMMAND_ACK")[-1].result == M.MAV_RESULT_ACCEPTED  # at touchdown
    hbs = gcs.pop("HEARTBEAT")
    assert not hbs[-1].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    assert any(h.custom_mode == 0x06040000 for h in hbs)  # was in Land
    texts = [t.text for t in gcs.pop("STATUSTEXT")]
    assert "Landing" in texts and "Landed" in texts and "Disarmed after landing" in texts
    assert vehicle.pos[2] == 0.0
    assert ParamStore(tmp_path / "p.json").load().values == {"OL_POS_K": pytest.approx(1.25)}
