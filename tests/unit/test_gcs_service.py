"""GcsService at its seams: it sees the vehicle only through `VehicleState` (a callable) and `VehicleCommands`, and
sends only through an `Outbox` (broadcast / reply to the sender). Here the outbox is a recording fake (the
process implements it over its links), the vehicle is a real FlightStack fed synthetic sensors, or a replaced
VehicleState; messages cross a pymavlink encode/decode as on the wire."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from io import BytesIO
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import FcSensors
from navig8_fc.flight import FlightStack, VehicleState
from navig8_fc.modes import FlightMode
from navig8_fc.params.registry import ParamRegistry
from navig8_fc.shell.gcs_service import GcsService
from navig8_fc.shell.telemetry_service import MAV_AUTOPILOT_GENERIC, MAV_AUTOPILOT_PX4

M = mavlink2
API = ("api", ("127.0.0.1", 14540))
GCS = ("gcs", ("127.0.0.1", 14550))


class Outbox:
    def __init__(self, mav: Any) -> None:
        self.sent: list[tuple[Any, Any]] = []  # (source or "all", decoded message)
        self._mav = mav
        self._rx = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)

    def _wire(self, m: Any) -> Any:
        return self._rx.decode(bytearray(m.pack(self._mav)))

    def broadcast(self, msgs: list[Any], exclude: frozenset[Any] = frozenset()) -> None:
        self.sent += [("all" if not exclude else ("all but", exclude), self._wire(m)) for m in msgs]

    def reply(self, source: Any, msgs: list[Any]) -> None:
        self.sent += [(source, self._wire(m)) for m in msgs]

    def pop(self, kind: str) -> list[tuple[Any, Any]]:
        got = [(d, m) for d, m in self.sent if m.get_type() == kind]
        self.sent = [(d, m) for d, m in self.sent if m.get_type() != kind]
        return got


def _sensors(t_us: int, z: float, w: float, gripper_closed: bool = False) -> FcSensors:
    return FcSensors(t_s=t_us * 1e-6, gyro_frd_rad_s=(0.0, 0.0, 0.0), accel_frd_m_s2=(0.0, 0.0, -9.81),
                     pos_ned_m=(0.0, 0.0, z),
                     vel_ned_m_s=(0.0, 0.0, 0.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0), duct_tilt_rad=(0.0, 0.0),
                     prop_speed_rad_s=(w, 0.0, w), joint_pos_rad=(0.0, 0.0, 0.0), joint_rate_rad_s=(0.0, 0.0, 0.0),
                     gripper_closed=gripper_closed)


class Rig:
    def __init__(self, state_override: dict[str, Any] | None = None, signing: Any = None,
                 autopilot: int = MAV_AUTOPILOT_GENERIC) -> None:
        self.vehicle = vm.VehicleConfig.load()
        self.registry = ParamRegistry.from_defaults()
        self.stack = FlightStack(self.vehicle, self.registry)
        self.mav = M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
        self.outbox = Outbox(self.mav)

        def state() -> VehicleState:
            s = self.stack.state()
            return replace(s, **state_override) if state_override else s

        self.gcs = GcsService(self.mav, 1, state, self.stack, self.outbox, self.registry, self.vehicle,
                              trusted_sources=[API, GCS], signing=signing,  # the links' targets, as the process gives
                              autopilot=autopilot)
        self.client = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
        self.t_us = 0
        self.z, self.w = 0.0, 0.0
        self.gripper_closed = False

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            sensors = _sensors(self.t_us, self.z, self.w, self.gripper_closed)
            for notice in self.stack.step(sensors, True, self.t_us).notices:
                if notice.statustext:
                    self.gcs.statustext(notice.statustext, notice.severity)
            self.t_us += 10_000

    def send(self, msg: Any, source: Any, now: float = 0.0) -> list[Any]:
        decoded = self.mav.decode(bytearray(msg.pack(self.client)))
        return self.gcs.handle([(decoded, source)], now)

    def command(self, source: Any, command: int, *p: float) -> Any:
        params = list(p) + [0.0] * (7 - len(p))
        self.send(self.client.command_long_encode(1, 1, command, 0, *params), source)
        ((dest, ack),) = self.outbox.pop("COMMAND_ACK")
        assert ack.command == command and dest == source, (dest, source)
        return ack


def test_commands_reach_the_vehicle_and_acks_go_to_the_sender_only() -> None:
    rig = Rig()
    rig.step(60)
    assert rig.command(API, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == M.MAV_RESULT_ACCEPTED
    assert rig.stack.state().armed
    # Refused: ACK to the sender, the reason to everyone.
    assert rig.command(GCS, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, 99.0).result == M.MAV_RESULT_DENIED
    ((dest, text),) = rig.outbox.pop("STATUSTEXT")
    assert dest == "all" and text.text.startswith("Takeoff denied: altitude 99")
    # Gripper and arm joints become the stack's arm request for the bridge.
    assert rig.command(API, M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_GRAB).result == M.MAV_RESULT_ACCEPTED
    assert rig.stack.state().pending_arm_request.gripper == "grab"


def test_parameter_reads_are_replies_and_sets_are_announced_and_returned_for_the_log() -> None:
    rig = Rig()
    assert rig.send(rig.client.param_request_read_encode(1, 1, b"OL_POS_K", -1), API) == []
    ((dest, pv),) = rig.outbox.pop("PARAM_VALUE")
    assert dest == API and pv.param_id == "OL_POS_K"
    changes = rig.send(rig.client.param_set_encode(1, 1, b"OL_POS_K", 1.25, M.MAV_PARAM_TYPE_REAL32), API)
    assert [(c.name, c.accepted) for c in changes] == [("OL_POS_K", True)]
    ((dest, pv),) = rig.outbox.pop("PARAM_VALUE")
    assert dest == "all" and pv.param_value == pytest.approx(1.25)


def test_only_ground_station_heartbeats_count_for_the_gcs_link() -> None:
    rig = Rig()
    assert rig.gcs.last_gcs_heartbeat is None
    rig.send(rig.client.heartbeat_encode(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 0), API, 1.0)
    assert rig.gcs.last_gcs_heartbeat is None
    rig.send(rig.client.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0), GCS, 2.0)
    assert rig.gcs.last_gcs_heartbeat == 2.0


def test_telemetry_shows_the_published_state() -> None:
    rig = Rig({"sensors_ok": False, "armed": True, "base_mode": int(M.MAV_MODE_FLAG_SAFETY_ARMED
                                                                     | M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)})
    rig.step(60)
    rig.gcs.poll(10.0)
    (_, hb), = rig.outbox.pop("HEARTBEAT")
    assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    (_, ss), = rig.outbox.pop("SYS_STATUS")
    gyro = M.MAV_SYS_STATUS_SENSOR_3D_GYRO
    assert ss.onboard_control_sensors_present & gyro and not ss.onboard_control_sensors_health & gyro


def test_gcs_silence_lands_through_the_stack_failsafe_input() -> None:
    """The shell's loop, reduced to its decisions: GcsService records the heartbeat time, the shell passes the
    age to the stack, the stack lands a vehicle holding after a GCS takeoff."""
    rig = Rig()
    rig.step(60)
    rig.send(rig.client.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0), GCS, 0.0)
    assert rig.command(GCS, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == M.MAV_RESULT_ACCEPTED
    assert rig.command(GCS, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, 2.0).result == M.MAV_RESULT_IN_PROGRESS
    hover_w = math.sqrt(rig.vehicle.uam_mass_kg * rig.vehicle.gravity_m_s2 / (2 * rig.vehicle.k_thrust_duct))
    rig.z, rig.w = -2.0, hover_w  # the vehicle climbed (the plant is not the point here)
    rig.step(250)
    assert rig.stack.state().flight_mode is FlightMode.HOLD
    rig.gcs.poll(1.0)  # the takeoff's final ACK goes to the requester only
    assert [(d, a.result) for d, a in rig.outbox.pop("COMMAND_ACK")] == [(GCS, M.MAV_RESULT_ACCEPTED)]
    tout = float(rig.registry["FS_GCS_TOUT"])
    last = rig.gcs.last_gcs_heartbeat
    assert last is not None
    assert rig.stack.check_links(0.0, (last + tout + 0.5) - last)[0].statustext == "GCS link lost: landing"
    rig.step(1)
    assert rig.stack.state().flight_mode is FlightMode.LAND


def test_mission_transfer_is_routed_to_the_uploader_and_set_current_by_command() -> None:
    """The mission protocol inside the service: requests (and their 250 ms repeats) go to the uploading peer only,
    MISSION_CURRENT is broadcast, DO_SET_MISSION_CURRENT moves the current item (ACK) like MISSION_SET_CURRENT."""
    rig = Rig()
    wp = (M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0.0, 0.5, 0.0, 0.0, 0, 0, -2.0)
    rig.send(rig.client.mission_count_encode(1, 1, 2, 0), API, 0.0)
    assert [(d, m.seq) for d, m in rig.outbox.pop("MISSION_REQUEST_INT")] == [(API, 0)]
    rig.gcs.poll(0.3)
    assert [(d, m.seq) for d, m in rig.outbox.pop("MISSION_REQUEST_INT")] == [(API, 0)]  # repeated, to API only
    assert [(d, m.total) for d, m in rig.outbox.pop("MISSION_CURRENT")] == [("all", 65535)]  # no plan yet
    for seq in (0, 1):
        rig.send(rig.client.mission_item_int_encode(1, 1, seq, *wp, 0), API, 0.4)
    (ack,) = rig.outbox.pop("MISSION_ACK")
    assert ack == (API, ack[1]) and ack[1].type == M.MAV_MISSION_ACCEPTED
    rig.gcs.poll(0.5)
    cur = rig.outbox.pop("MISSION_CURRENT")
    assert [(d, m.seq, m.total) for d, m in cur] == [("all", 0, 2)]
    rig.send(rig.client.command_long_encode(1, 1, M.MAV_CMD_DO_SET_MISSION_CURRENT, 0, 1, 0, 0, 0, 0, 0, 0), GCS)
    (ack,) = rig.outbox.pop("COMMAND_ACK")
    assert ack[1].result == M.MAV_RESULT_ACCEPTED and rig.gcs.mission.plan().current == 1
    rig.send(rig.client.command_long_encode(1, 1, M.MAV_CMD_DO_SET_MISSION_CURRENT, 0, 5, 0, 0, 0, 0, 0, 0), GCS)
    (ack,) = rig.outbox.pop("COMMAND_ACK")
    assert ack[1].result == M.MAV_RESULT_DENIED and rig.gcs.mission.plan().current == 1


def test_manual_control_reaches_position_mode_and_stale_sticks_centre() -> None:
    rig = Rig()
    rig.step(60)
    assert rig.command(API, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196).result == M.MAV_RESULT_ACCEPTED
    rig.send(rig.client.manual_control_encode(1, 500, -250, 1000, 0, 0), GCS, 1.0)
    assert rig.stack.state().sticks == pytest.approx((0.5, -0.25, 1.0, 0.0))
    rig.gcs.poll(1.2)
    assert rig.stack.state().sticks == pytest.approx((0.5, -0.25, 1.0, 0.0))
    rig.gcs.poll(1.6)  # > 0.5 s without MANUAL_CONTROL: centred
    assert rig.stack.state().sticks == (0.0, 0.0, 0.5, 0.0)


def test_px4_identity_reads_takeoff_p7_as_amsl_and_acknowledges_flight_commands_at_once() -> None:
    """As PX4's Commander and Navigator: NAV_TAKEOFF p7 above mean sea level (QGC's PX4 plugin sends home + the
    height), COMMAND_INT in a GLOBAL frame too, ACCEPTED at once; GCS_CMD_PROG 1 brings the long-running protocol
    back. The generic identity reads p7 above home."""
    for autopilot, p7, expect_alt in ((MAV_AUTOPILOT_PX4, 1100.0 + 3.0, 3.0), (MAV_AUTOPILOT_GENERIC, 3.0, 3.0)):
        rig = Rig(autopilot=autopilot)
        rig.step(60)
        assert rig.command(API, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == M.MAV_RESULT_ACCEPTED
        ack = rig.command(API, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, p7)
        px4 = autopilot == MAV_AUTOPILOT_PX4
        assert ack.result == (M.MAV_RESULT_ACCEPTED if px4 else M.MAV_RESULT_IN_PROGRESS)
        rig.step(1)
        texts = [m.text for _, m in rig.outbox.pop("STATUSTEXT")]
        assert f"Takeoff to {expect_alt:.1f} m above home" in texts, texts
    rig = Rig(autopilot=MAV_AUTOPILOT_PX4)
    rig.step(60)
    rig.command(API, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    rig.send(rig.client.command_int_encode(1, 1, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0,
                                           math.nan, 0, 0, 1100.0 + 25.0), API)
    ((_, ack),) = rig.outbox.pop("COMMAND_ACK")
    assert ack.result == M.MAV_RESULT_DENIED  # 25 m above home: past the takeoff limit, so AMSL was read
    assert "25" in rig.outbox.pop("STATUSTEXT")[0][1].text
    rig.registry.set("GCS_CMD_PROG", 1)
    ack = rig.command(API, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 1100.0 + 2.0)
    assert ack.result == M.MAV_RESULT_IN_PROGRESS


def test_set_gps_global_origin_sets_the_origin_parameters() -> None:
    rig = Rig()
    rig.step(5)
    rig.send(rig.client.set_gps_global_origin_encode(1, 473977420, 85455940, 488000), GCS)
    (o,) = rig.outbox.pop("GPS_GLOBAL_ORIGIN")
    assert (o[1].latitude, o[1].longitude, o[1].altitude) == (473977420, 85455940, 488000)
    assert (rig.registry["ORIGIN_LAT_E7"], rig.registry["ORIGIN_LON_E7"]) == (473977420, 85455940)
    assert rig.registry["ORIGIN_ALT"] == pytest.approx(488.0)
    assert {m.param_id for _, m in rig.outbox.pop("PARAM_VALUE")} == {"ORIGIN_LAT_E7", "ORIGIN_LON_E7", "ORIGIN_ALT"}
    assert rig.gcs.origin.lat_deg == pytest.approx(47.397742)
    rig.send(rig.client.set_gps_global_origin_encode(1, 95 * 10**7, 0, 0), GCS)  # refused whole: nothing changes
    assert (rig.registry["ORIGIN_LAT_E7"], rig.registry["ORIGIN_LON_E7"]) == (473977420, 85455940)
    assert rig.registry["ORIGIN_ALT"] == pytest.approx(488.0) and rig.outbox.pop("STATUSTEXT")


def test_vfr_hud_throttle_is_the_collective_thrust_over_the_most_the_rotors_give() -> None:
    rig = Rig()
    v = rig.vehicle
    rig.w = 0.5 * v.duct_speed_max  # both ducts at half speed, tail still: T = k (w/2)^2 per duct
    rig.step(3)
    rig.gcs.poll(10.0)
    (_, hud), = rig.outbox.pop("VFR_HUD")
    # By hand: 2 kd (wmax/2)^2 / (2 kd wmax^2 + kt wtail_max^2), the tail's maximum counted with its sign.
    kd, kt = v.k_thrust_duct, v.k_thrust_tail
    expected = 100.0 * 2 * kd * (0.5 * v.duct_speed_max) ** 2 / (
        2 * kd * v.duct_speed_max ** 2 + kt * v.tail_speed_max * abs(v.tail_speed_max))
    assert 0.0 < expected < 100.0
    assert hud.throttle == round(expected)  # VFR_HUD carries an integer percentage



def test_actuator_output_status_channel_8_is_the_reported_gripper_state() -> None:
    rig = Rig()
    for k, closed in enumerate((False, True, False)):
        rig.gripper_closed = closed  # as NAVIG8_ARM_STATE reports it in the sensor bundle
        rig.step(1)
        rig.gcs.poll(10.0 + k)  # 1 s apart: every stream is due
        *_, (_, act) = rig.outbox.pop("ACTUATOR_OUTPUT_STATUS")
        assert act.actuator[8] == (1.0 if closed else 0.0)  # channel 8 (from 0): 1 closed, 0 open


class _Signing:
    """The links' signing as GcsService sees it (set_key, active); the real one is tested in test_signing.py."""

    def __init__(self) -> None:
        self.active = False
        self.keys: list[bytes] = []

    def set_key(self, key: bytes, ts: int) -> str:
        self.keys.append(key)
        self.active = True
        return "Signing key set"


def test_signing_required_refuses_commands_until_a_key_is_set_and_the_key_never_leaves() -> None:
    signing = _Signing()
    rig = Rig(signing=signing)
    rig.registry.set("GCS_SIGN_REQ", 1)
    rig.step(60)
    assert rig.command(GCS, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == M.MAV_RESULT_DENIED
    key = bytes(range(7, 39))
    rig.send(rig.client.setup_signing_encode(1, 1, list(key), 1), GCS)
    assert signing.keys == [key]
    texts = [m.text for _, m in rig.outbox.pop("STATUSTEXT")]
    assert "Signing key set" in texts and not any(key.hex() in t or key.decode("latin-1") in t for t in texts)
    assert rig.command(GCS, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == M.MAV_RESULT_ACCEPTED


def test_foreign_system_ids_are_refused_and_do_not_arm_the_gcs_loss_failsafe() -> None:
    rig = Rig()
    rig.step(60)
    stranger = M.MAVLink(BytesIO(), srcSystem=200, srcComponent=190)
    src = ("gcs", ("127.0.0.1", 40000))
    hb = rig.mav.decode(bytearray(stranger.heartbeat_encode(M.MAV_TYPE_GCS, 8, 0, 0, 0).pack(stranger)))
    rig.gcs.handle([(hb, src)], 1.0)
    assert rig.gcs.last_gcs_heartbeat is None and not rig.gcs.admits_peer(hb)
    cmd = stranger.command_long_encode(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    rig.gcs.handle([(rig.mav.decode(bytearray(cmd.pack(stranger))), src)], 1.0)
    ((dest, ack),) = rig.outbox.pop("COMMAND_ACK")
    assert dest == src and ack.result == M.MAV_RESULT_DENIED and not rig.stack.state().armed
    # An allowed id from an address that sent no HEARTBEAT: a command is refused, a HEARTBEAT confirms it.
    own = ("gcs", ("127.0.0.1", 40001))
    rig.send(rig.client.param_request_list_encode(1, 1), own)
    assert rig.gcs.params.list_remaining == 0
    rig.send(rig.client.heartbeat_encode(M.MAV_TYPE_GCS, 8, 0, 0, 0), own, now=2.0)
    # confirmed for its requests, but a HEARTBEAT from an address nobody configured is only a claim: the GCS-loss
    # failsafe listens to the configured peers (docs/security.md)
    assert rig.gcs.confirmed(own) and rig.gcs.last_gcs_heartbeat is None
    rig.send(rig.client.param_request_list_encode(1, 1), own)
    assert rig.gcs.params.list_remaining > 0


def test_message_intervals_are_per_peer() -> None:
    """A SET_MESSAGE_INTERVAL changes the rate only for the peer that sent it (the other ground station keeps the
    defaults); the shared broadcast then leaves that peer out, and GET_MESSAGE_INTERVAL answers each its own."""
    rig = Rig()
    rig.step(5)
    rig.command(API, M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
    ((_, mi),) = rig.outbox.pop("MESSAGE_INTERVAL")
    default_us = mi.interval_us
    assert default_us > 0
    assert rig.command(GCS, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 200_000).result == \
        M.MAV_RESULT_ACCEPTED
    for source, want in ((GCS, 200_000), (API, default_us)):
        rig.command(source, M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
        ((dest, mi),) = rig.outbox.pop("MESSAGE_INTERVAL")
        assert dest == source and mi.interval_us == want
    rig.outbox.sent.clear()
    for i in range(201):  # 2 s of wall time in 10 ms polls
        rig.gcs.poll(10.0 + 0.01 * i)
    att = rig.outbox.pop("ATTITUDE")
    to_gcs = [d for d, _ in att if d == GCS]
    shared = [d for d, _ in att if d != GCS]
    assert len(to_gcs) in (10, 11)  # 5 Hz for 2 s
    assert len(shared) == pytest.approx(2e6 / default_us, abs=1) and all(d == ("all but", {GCS}) for d in shared)
    # only the mission protocol's own MISSION_CURRENT report goes to every peer; every telemetry stream of the
    # shared table leaves GCS out
    assert {m.get_type() for d, m in rig.outbox.sent if d == "all"} <= {"MISSION_CURRENT"}
    hb = [d for d, _ in rig.outbox.pop("HEARTBEAT")]
    assert GCS in hb  # its own table keeps the heartbeat


def test_message_interval_has_a_floor() -> None:
    rig = Rig()
    rig.command(GCS, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 2000)
    floor_us = 1e6 / float(rig.registry["GCS_RATE_MAX"])
    assert rig.gcs.message_interval_us(M.MAVLINK_MSG_ID_ATTITUDE) >= floor_us


def test_param_sets_needing_a_stability_sweep_wait_on_the_worker_and_every_one_is_answered(tmp_path) -> None:
    """The process's mode: floors on a worker thread, applied by poll in arrival order; the queue is bounded and
    PARAM_SET rate-limited, and every PARAM_SET gets a PARAM_VALUE (accepted, refused, or busy/rate refusals)."""
    from navig8_fc.params.store import ParamStore

    rig = Rig()
    store = ParamStore(tmp_path / "p.json")
    svc = GcsService(rig.mav, 1, rig.stack.state, rig.stack, rig.outbox, rig.registry, rig.vehicle, store,
                     trusted_sources=[GCS], background_params=True)
    try:
        n = 120
        # five distinct floors (~1.5 s of CPU each on the worker): the queue's order and bounds are under test, not
        # the analysis' speed on a busy machine
        values = [0.5 + 0.002 * (i % 5) for i in range(n)]
        for i, v in enumerate(values):
            msg = rig.client.param_set_encode(1, 1, b"INDI_K_MIN", v, M.MAV_PARAM_TYPE_REAL32)
            svc.handle([(rig.mav.decode(bytearray(msg.pack(rig.client))), GCS)], 1.0 + i * 1e-4)
        t = 2.0
        deadline = time.monotonic() + 120.0
        while svc.params_busy and time.monotonic() < deadline:
            t += 0.01
            svc.poll(t)
            time.sleep(0.005)
        assert not svc.params_busy, "queued PARAM_SETs never finished"
        answers = [m for _, m in rig.outbox.pop("PARAM_VALUE") if m.param_id == "INDI_K_MIN"]
        assert len(answers) == n
        final = float(rig.registry["INDI_K_MIN"])
        assert abs(answers[-1].param_value - final) < 1e-6  # the last answer is the value in force
        assert final in {float(np.float32(v)) for v in values}
        svc.close()
        assert store.load().values["INDI_K_MIN"] == final  # saved by the worker
    finally:
        svc.close()


def test_a_heartbeat_from_an_unconfigured_address_never_feeds_the_gcs_loss_failsafe_until_signing_is_on() -> None:
    """One spoofed HEARTBEAT with an allowed id (250, MAVLink 1 or 2) from a new address neither arms the GCS-loss
    failsafe nor (by going silent) triggers it; the configured peers' HEARTBEATs do; with a key in force every
    frame that gets in carries it, so then any source counts."""
    signing = _Signing()
    rig = Rig(signing=signing)
    spoof = ("gcs", ("127.0.0.1", 40002))
    for version in (1, 2):
        mav = M.MAVLink(BytesIO(), srcSystem=250, srcComponent=190)
        if version == 1:
            mav.WIRE_PROTOCOL_VERSION = "1.0"
        hb = rig.mav.decode(bytearray(mav.heartbeat_encode(M.MAV_TYPE_GCS, 8, 0, 0, 0).pack(mav, force_mavlink1=
                                                                                              version == 1)))
        rig.gcs.handle([(hb, spoof)], 1.0)
    assert rig.gcs.last_gcs_heartbeat is None
    rig.send(rig.client.heartbeat_encode(M.MAV_TYPE_GCS, 8, 0, 0, 0), GCS, now=2.0)
    assert rig.gcs.last_gcs_heartbeat == 2.0
    signing.active = True
    rig.send(rig.client.heartbeat_encode(M.MAV_TYPE_GCS, 8, 0, 0, 0), spoof, now=3.0)
    assert rig.gcs.last_gcs_heartbeat == 3.0


def test_setup_signing_only_disarmed_and_only_from_the_configured_ground_station() -> None:
    """SETUP_SIGNING from an allowed id at another address is refused (GCS_SIGN_LINK 0: the GCS link's configured
    peer only; 1 adds the API link's; 2 anyone allowed), and from anywhere while armed, with the reason."""
    signing = _Signing()
    rig = Rig(signing=signing)
    rig.step(60)
    key = bytes(range(7, 39))
    setup = lambda: rig.client.setup_signing_encode(1, 1, list(key), 1)
    impostor = ("gcs", ("127.0.0.1", 40003))
    rig.send(rig.client.heartbeat_encode(M.MAV_TYPE_GCS, 8, 0, 0, 0), impostor, now=1.0)
    rig.send(setup(), impostor, now=1.0)
    rig.send(setup(), API, now=3.0)
    assert signing.keys == []
    texts = [m.text for _, m in rig.outbox.pop("STATUSTEXT")]
    assert texts == ["SETUP_SIGNING refused: configured GCS link only"] * 2, texts
    rig.registry.set("GCS_SIGN_LINK", 1)
    rig.send(setup(), API, now=5.0)
    assert signing.keys == [key]
    rig.registry.set("GCS_SIGN_LINK", 2)
    rig.send(setup(), impostor, now=6.0)
    assert len(signing.keys) == 2
    rig.registry.set("GCS_SIGN_LINK", 0)
    assert rig.command(GCS, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == M.MAV_RESULT_ACCEPTED
    rig.outbox.sent.clear()
    rig.send(setup(), GCS, now=8.0)  # the operator's own station, armed
    assert len(signing.keys) == 2
    assert [m.text for _, m in rig.outbox.pop("STATUSTEXT")] == ["SETUP_SIGNING refused: not while armed"]
