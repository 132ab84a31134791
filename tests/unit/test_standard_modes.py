"""Standard modes (AVAILABLE_MODES, CURRENT_MODE, AVAILABLE_MODES_MONITOR, MAV_CMD_DO_SET_STANDARD_MODE) and the
autopilot identity option, through GcsService with the navig8 dialect (it includes development.xml) and a
pymavlink client of the `development` dialect decoding what it sends."""

from __future__ import annotations

from io import BytesIO
from typing import Any

from pymavlink.dialects.v20 import development as dev

from navig8_fc.core import vehicle as vm
from navig8_fc.flight import FlightStack
from navig8_fc.mavlink import dialect
from navig8_fc.modes.px4 import AVAILABLE_MODES, FlightMode
from navig8_fc.params.registry import ParamRegistry
from navig8_fc.shell.gcs_service import GcsService
from navig8_fc.shell.telemetry_service import MAV_AUTOPILOT_PX4

GCS = ("gcs", ("127.0.0.1", 14550))


class Outbox:
    def __init__(self, mav: Any) -> None:
        self.sent: list[Any] = []
        self._mav = mav
        self._rx = dev.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)

    def broadcast(self, msgs: list[Any], exclude: frozenset[Any] = frozenset()) -> None:
        self.sent += [self._rx.decode(bytearray(m.pack(self._mav))) for m in msgs]

    def reply(self, source: Any, msgs: list[Any]) -> None:
        self.broadcast(msgs)

    def pop(self, kind: str) -> list[Any]:
        got = [m for m in self.sent if m.get_type() == kind]
        self.sent = [m for m in self.sent if m.get_type() != kind]
        return got


def _rig(autopilot: int = 0) -> tuple[GcsService, Outbox, Any, FlightStack]:
    vehicle = vm.VehicleConfig.load()
    reg = ParamRegistry.from_defaults()
    stack = FlightStack(vehicle, reg)
    mav = dialect.load().MAVLink(None, srcSystem=1, srcComponent=1)
    out = Outbox(mav)
    svc = GcsService(mav, 1, stack.state, stack, out, reg, vehicle, autopilot=autopilot, trusted_sources=[GCS])
    client = dev.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
    return svc, out, client, stack


def _send(svc: GcsService, client: Any, msg: Any) -> None:
    svc.handle([(svc.mav.decode(bytearray(msg.pack(client))), GCS)], 0.0)


def test_available_modes_all_at_once_and_one_by_one() -> None:
    svc, out, client, _ = _rig()
    n = len(AVAILABLE_MODES)
    _send(svc, client, client.command_long_encode(1, 1, 512, 0, 435, 0, 0, 0, 0, 0, 0))  # QGC >= 5.1: all
    assert out.pop("COMMAND_ACK")[0].result == dev.MAV_RESULT_ACCEPTED
    modes = out.pop("AVAILABLE_MODES")
    assert [m.mode_index for m in modes] == list(range(1, n + 1)) and all(m.number_modes == n for m in modes)
    by_custom = {m.custom_mode: m for m in modes}
    assert len(by_custom) == n  # custom_mode is QGC's key: unique
    assert by_custom[0x04040000].standard_mode == dev.MAV_STANDARD_MODE_MISSION
    assert by_custom[0x05040000].standard_mode == dev.MAV_STANDARD_MODE_SAFE_RECOVERY
    assert by_custom[0x00030000].standard_mode == dev.MAV_STANDARD_MODE_POSITION_HOLD
    assert by_custom[0x03040000].mode_name == "Hold" and by_custom[0x03040000].standard_mode == 0
    assert by_custom[FlightMode.READY.custom_mode].properties & dev.MAV_MODE_PROPERTY_NOT_USER_SELECTABLE
    for i in (1, n):  # QGC 5.0: one by one, 1-based
        _send(svc, client, client.command_long_encode(1, 1, 512, 0, 435, i, 0, 0, 0, 0, 0))
        assert out.pop("COMMAND_ACK")[0].result == dev.MAV_RESULT_ACCEPTED
        assert [m.mode_index for m in out.pop("AVAILABLE_MODES")] == [i]
    _send(svc, client, client.command_long_encode(1, 1, 512, 0, 435, n + 1, 0, 0, 0, 0, 0))
    assert out.pop("COMMAND_ACK")[0].result == dev.MAV_RESULT_DENIED and not out.pop("AVAILABLE_MODES")
    _send(svc, client, client.command_long_encode(1, 1, 512, 0, 437, 0, 0, 0, 0, 0, 0))
    assert [m.seq for m in out.pop("AVAILABLE_MODES_MONITOR")] == [1]


def test_current_mode_streams_and_set_standard_mode_changes_it() -> None:
    svc, out, client, stack = _rig()
    svc.poll(0.0)
    (cur,) = out.pop("CURRENT_MODE")
    assert cur.custom_mode == stack.state().custom_mode and cur.intended_custom_mode == 0
    svc.poll(1.0)
    assert not out.pop("CURRENT_MODE")  # 0.5 Hz
    _send(svc, client, client.command_long_encode(1, 1, 262, 0, dev.MAV_STANDARD_MODE_MISSION, 0, 0, 0, 0, 0, 0))
    (ack,) = out.pop("COMMAND_ACK")
    assert ack.command == 262 and ack.result == dev.MAV_RESULT_DENIED  # no plan: refused like DO_SET_MODE
    svc.poll(1.1)
    (cur,) = out.pop("CURRENT_MODE")  # the intention changed: at once
    assert cur.intended_custom_mode == 0x04040000
    _send(svc, client, client.command_long_encode(1, 1, 262, 0, dev.MAV_STANDARD_MODE_ORBIT, 0, 0, 0, 0, 0, 0))
    assert out.pop("COMMAND_ACK")[0].result == dev.MAV_RESULT_DENIED


def test_autopilot_identity_option() -> None:
    for autopilot, version in ((0, (0, 1, 0)), (MAV_AUTOPILOT_PX4, (1, 15, 0))):
        svc, out, client, _ = _rig(autopilot)
        for _ in range(3):
            svc.poll(10.0)
        hb = [m for m in out.pop("HEARTBEAT")]
        assert hb and all(m.autopilot == autopilot for m in hb)
        _send(svc, client, client.command_long_encode(1, 1, 512, 0, 148, 0, 0, 0, 0, 0, 0))
        (av,) = out.pop("AUTOPILOT_VERSION")
        major, minor, patch = version
        assert av.flight_sw_version >> 8 == (major << 16) | (minor << 8) | patch
        assert av.flight_sw_version & 0xFF == dev.FIRMWARE_VERSION_TYPE_DEV  # never OFFICIAL: no "update" dialog
