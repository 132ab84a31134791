"""Telemetry: stream scheduler (rates, SET_MESSAGE_INTERVAL -1/0/>0) and builders that pack with a real MAVLink."""

from __future__ import annotations

import math
from io import BytesIO
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.core.k_xi import eig_margin_lower_bound
from navig8_fc.flight.battery import BatteryConfig, battery_initial, battery_step, open_circuit_voltage
from navig8_fc.gcs.telemetry import (
    CAPABILITIES,
    DEFAULT_RATES_HZ,
    EARTH_RADIUS_M,
    STABILITY_VALUE_NAMES,
    GeoOrigin,
    TelemetryBuilder,
    TelemetryScheduler,
    VehicleSnapshot,
    euler_from_quat,
    heading_cdeg,
    sensor_bits,
)
from navig8_fc.modes import FlightMode
from navig8_fc.modes.orbit import OrbitPlan

M = mavlink2


# --- scheduler ---------------------------------------------------------------------------------------------
def count_due(s: TelemetryScheduler, seconds: float, dt: float = 0.001, t0: float = 0.0) -> dict[int, int]:
    counts: dict[int, int] = {}
    n = int(round(seconds / dt))
    for k in range(n):
        for msg_id in s.due(t0 + k * dt):
            counts[msg_id] = counts.get(msg_id, 0) + 1
    return counts


def test_default_rates() -> None:
    s = TelemetryScheduler()
    counts = count_due(s, 10.0)
    for msg_id, hz in DEFAULT_RATES_HZ.items():
        expected = hz * 10.0
        assert abs(counts.get(msg_id, 0) - expected) <= 1, (msg_id, counts.get(msg_id), expected)
    assert counts[M.MAVLINK_MSG_ID_HEARTBEAT] == 10 and counts[M.MAVLINK_MSG_ID_ATTITUDE] == 200
    assert M.MAVLINK_MSG_ID_AUTOPILOT_VERSION not in counts  # on request only
    assert s.interval_us(M.MAVLINK_MSG_ID_ATTITUDE) == 50_000
    assert s.interval_us(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == -1


def test_set_message_interval_semantics() -> None:
    s = TelemetryScheduler()
    att = M.MAVLINK_MSG_ID_ATTITUDE
    assert s.set_interval(att, 200_000)  # 5 Hz
    assert s.interval_us(att) == 200_000
    assert count_due(s, 2.0)[att] == 10
    assert s.set_interval(att, -1)
    assert s.interval_us(att) == -1 and att not in count_due(s, 1.0, t0=3.0)
    assert s.set_interval(att, 0)  # back to the default
    assert s.interval_us(att) == 50_000 and count_due(s, 1.0, t0=5.0)[att] == 20
    assert s.set_interval(att, 1)  # clamped to the fastest allowed
    assert s.interval_us(att) == 2000
    assert not s.set_interval(9999, 100_000)  # not a stream we have
    assert s.interval_us(9999) == 0  # MESSAGE_INTERVAL: 0 = not available
    assert not s.set_interval(att, -2)
    assert not s.set_interval(M.MAVLINK_MSG_ID_HEARTBEAT, -1)  # heartbeats cannot be switched off
    assert s.set_interval(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 1_000_000)
    assert M.MAVLINK_MSG_ID_AUTOPILOT_VERSION in count_due(s, 1.5, t0=10.0)


def test_scheduler_does_not_burst_after_a_stall() -> None:
    s = TelemetryScheduler({0: 1.0, 30: 20.0})
    assert sorted(s.due(0.0)) == [0, 30]
    assert s.due(100.0) == [0, 30]  # one each after a long pause, not 100 / 2000
    assert s.due(100.01) == []
    assert s.due(100.05) == [30]


# --- builders ----------------------------------------------------------------------------------------------
@pytest.fixture
def mavs() -> tuple[Any, Any]:
    return M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1), M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)


def snapshot(**kw: Any) -> VehicleSnapshot:
    yaw = kw.pop("yaw", math.radians(90.0))
    base = dict(
        armed=True,
        base_mode=M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED,
        custom_mode=FlightMode.HOLD.custom_mode,
        system_status=M.MAV_STATE_ACTIVE,
        landed_state=M.MAV_LANDED_STATE_IN_AIR,
        pos_ned_m=(10.0, -5.0, -2.0),
        vel_ned_m_s=(1.0, 2.0, -0.5),
        quat_wxyz=(math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)),
        gyro_frd_rad_s=(0.01, -0.02, 0.03),
        home_ned_m=(0.0, 0.0, 0.0),
        home_yaw_rad=math.radians(90.0),
        duct_tilt_rad=(0.1, -0.1),
        prop_speed_rad_s=(600.0, -50.0, 610.0),
        joint_pos_rad=(0.3, 0.2, 0.1),
        gripper_closed=True,
        sensors=sensor_bits(imu_ok=True, pose_ok=True, actuators_ok=True, estimator_ok=True, battery_ok=True,
                            prearm_ok=False),
        ckf_x_hat=(0.1, 0.2, 0.3, 7.5),
        ckf_k=(0.9, 0.8, 0.95, 1.0),
        eig_margin=0.31,
        time_unix_usec=1_700_000_000_000_000,
        throttle_pct=55.0,
        orbit=OrbitPlan((20.0, -3.0, -4.0), 10.0, 1.5, False, 0, 0.0, 0.0),  # ORBIT_EXECUTION_STATUS: in Orbit
    )
    base.update(kw)
    return VehicleSnapshot(**base)


def roundtrip(msgs: list[Any], mavs) -> list[Any]:
    veh, gcs = mavs
    return [gcs.decode(bytearray(m.pack(veh))) for m in msgs]


def test_every_supported_message_packs(mavs) -> None:
    tb = TelemetryBuilder(mavs[0], 1, 1)
    snap = snapshot()
    for msg_id in sorted(tb.supported_ids):
        out = roundtrip(tb.build(msg_id, snap, 123_456), mavs)
        assert out and all(m.get_msgId() == msg_id for m in out), msg_id
    assert tb.build(9999, snap, 0) == []


def test_no_state_streams_before_the_first_sensor_data(mavs) -> None:
    tb = TelemetryBuilder(mavs[0], 1, 1)
    state_ids = {M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                 M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_VFR_HUD, M.MAVLINK_MSG_ID_GPS_RAW_INT,
                 M.MAVLINK_MSG_ID_HIGHRES_IMU}
    snap = snapshot(state_valid=False)
    for msg_id in sorted(tb.supported_ids):
        got = tb.build(msg_id, snap, 0)
        assert (got == []) == (msg_id in state_ids), msg_id


def test_messages_pack_with_hostile_values(mavs) -> None:
    tb = TelemetryBuilder(mavs[0], 1, 1)
    nan = math.nan
    snap = snapshot(pos_ned_m=(nan, 1e12, -1e12), vel_ned_m_s=(1e9, nan, -1e9), quat_wxyz=(nan, 0.0, 0.0, 0.0),
                    throttle_pct=nan, load_permille=5000, battery=battery_initial(soc=0.0))
    for msg_id in sorted(tb.supported_ids):
        roundtrip(tb.build(msg_id, snap, 2**40), mavs)


def test_heartbeat(mavs) -> None:
    tb = TelemetryBuilder(mavs[0], 1, 1)
    (hb,) = roundtrip(tb.heartbeat(snapshot()), mavs)
    assert hb.type == M.MAV_TYPE_TRICOPTER and hb.autopilot == M.MAV_AUTOPILOT_GENERIC
    assert hb.base_mode == M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.custom_mode == 0x03040000 and hb.system_status == M.MAV_STATE_ACTIVE and hb.mavlink_version == 3
    # SAFETY_ARMED exactly when armed, whatever base_mode says.
    (hb,) = roundtrip(tb.heartbeat(snapshot(armed=False)), mavs)
    assert hb.base_mode == M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    (hb,) = roundtrip(tb.heartbeat(snapshot(armed=True, base_mode=0)), mavs)
    assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED and not hb.base_mode & M.MAV_MODE_FLAG_HIL_ENABLED


def test_autopilot_version(mavs) -> None:
    tb = TelemetryBuilder(mavs[0], 3, 1, sw_version=(1, 2, 3), custom_version=b"abcdef12")
    (av,) = roundtrip(tb.autopilot_version(), mavs)
    caps = av.capabilities
    for bit in (M.MAV_PROTOCOL_CAPABILITY_MISSION_INT, M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                M.MAV_PROTOCOL_CAPABILITY_MAVLINK2, M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
                M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED,
                M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT, M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE,
                M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET, M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY):
        assert caps & bit
    for bit in (M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST, M.MAV_PROTOCOL_CAPABILITY_FTP):
        assert not caps & bit
    assert caps == CAPABILITIES
    assert av.flight_sw_version == (1 << 24) | (2 << 16) | (3 << 8) | M.FIRMWARE_VERSION_TYPE_DEV
    assert bytes(av.flight_custom_version) == b"abcdef12"
    other = TelemetryBuilder(mavs[0], 4, 1)
    assert av.uid != 0 and av.uid != other.uid  # unique per instance


def test_global_position_flat_earth(mavs) -> None:
    origin = GeoOrigin(51.0789, -114.1339, 1100.0)
    tb = TelemetryBuilder(mavs[0], 1, 1)
    (gp,) = roundtrip(tb.global_position_int(snapshot(origin=origin, home_ned_m=(0.0, 0.0, -0.5)), 1000), mavs)
    lat = 51.0789 + math.degrees(10.0 / EARTH_RADIUS_M)
    lon = -114.1339 + math.degrees(-5.0 / (EARTH_RADIUS_M * math.cos(math.radians(51.0789))))
    assert gp.lat == round(lat * 1e7) and gp.lon == round(lon * 1e7)
    assert gp.alt == 1_102_000 and gp.relative_alt == 1500  # 2 m up from origin, 1.5 m above home
    assert (gp.vx, gp.vy, gp.vz) == (100, 200, -50)
    assert gp.hdg == 9000 and gp.time_boot_ms == 1000
    # 10 m north moves ~ 10 m on the sphere.
    assert (gp.lat * 1e-7 - 51.0789) * math.pi / 180 * EARTH_RADIUS_M == pytest.approx(10.0, abs=0.01)


def test_heading_and_euler() -> None:
    assert heading_cdeg(0.0) == 0 and heading_cdeg(math.radians(-90.0)) == 27000
    assert heading_cdeg(math.radians(359.999)) == 0 and heading_cdeg(math.nan) == 65535
    assert 0 <= heading_cdeg(-1e-9) <= 35999
    r, p, y = euler_from_quat((math.cos(0.25), 0.0, math.sin(0.25), 0.0))
    assert (r, p, y) == pytest.approx((0.0, 0.5, 0.0))


def test_home_position(mavs) -> None:
    tb = TelemetryBuilder(mavs[0], 1, 1, approach_height_m=2.5)
    (hp,) = roundtrip(tb.home_position(snapshot(home_ned_m=(1.0, 2.0, 0.0)), 5000), mavs)
    assert (hp.x, hp.y, hp.z) == (1.0, 2.0, 0.0)
    assert hp.altitude == 1_100_000
    assert hp.q == pytest.approx([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])
    assert (hp.approach_x, hp.approach_y, hp.approach_z) == (1.0, 2.0, -2.5)
    assert hp.time_usec == 5_000_000
    assert tb.home_position(snapshot(home_ned_m=None), 0) == []


def test_sys_status_battery_and_hud(mavs) -> None:
    tb = TelemetryBuilder(mavs[0], 1, 1)
    batt = battery_step(battery_initial(), 1500.0, 60.0)
    snap = snapshot(battery=batt)
    (ss,) = roundtrip(tb.sys_status(snap), mavs)
    assert ss.onboard_control_sensors_present & M.MAV_SYS_STATUS_PREARM_CHECK
    assert not ss.onboard_control_sensors_health & M.MAV_SYS_STATUS_PREARM_CHECK  # pre-arm checks failing
    assert ss.onboard_control_sensors_health & M.MAV_SYS_STATUS_SENSOR_GPS
    assert ss.voltage_battery == round(batt.voltage_v * 1000) and ss.battery_remaining == batt.remaining_pct
    (bs,) = roundtrip(tb.battery_status(snap), mavs)
    assert bs.voltages[:6] == [round(batt.voltage_v * 1000 / 6)] * 6 and bs.voltages[6:] == [65535] * 4
    assert bs.current_battery == round(batt.current_a * 100) and bs.charge_state == M.MAV_BATTERY_CHARGE_STATE_OK
    (hud,) = roundtrip(tb.vfr_hud(snap), mavs)
    assert hud.groundspeed == pytest.approx(math.hypot(1.0, 2.0)) and hud.heading == 90 and hud.throttle == 55
    assert hud.alt == pytest.approx(1102.0) and hud.climb == pytest.approx(0.5)
    (es,) = roundtrip(tb.extended_sys_state(snap), mavs)
    assert es.landed_state == M.MAV_LANDED_STATE_IN_AIR and es.vtol_state == M.MAV_VTOL_STATE_UNDEFINED


def test_actuators_and_stability_values(mavs) -> None:
    tb = TelemetryBuilder(mavs[0], 1, 1)
    (act,) = roundtrip(tb.actuator_output_status(snapshot(), 7), mavs)
    assert act.active == 0x1FF
    assert act.actuator[:9] == pytest.approx([0.1, -0.1, 600.0, -50.0, 610.0, 0.3, 0.2, 0.1, 1.0])
    named = roundtrip(tb.stability_values(snapshot(), 7), mavs)
    assert [m.name for m in named] == list(STABILITY_VALUE_NAMES)
    assert all(len(n) <= 10 for n in STABILITY_VALUE_NAMES)
    values = {m.name: m.value for m in named}
    assert values["M_HAT"] == pytest.approx(7.5) and values["EIG_MARGIN"] == pytest.approx(0.31)
    assert values["K3"] == pytest.approx(0.95)


def test_eig_margin_lower_bound() -> None:
    from navig8_fc.core import stability
    from navig8_fc.core.vehicle import VehicleConfig

    cfg = VehicleConfig.load()
    lam_crit = stability.lambda_crit(120.0, 1.0, 0.01, 0.1)
    m = eig_margin_lower_bound(cfg, (0.0, 0.0, 0.0), 0.5, 1.0, lam_crit)
    # At object mass 0, Xi = I: the bound can never exceed k_min - lambda_crit.
    assert m <= 0.5 - lam_crit + 1e-9
    assert m > 0.0  # the default K bounds are safe at the hover pose
    # A K_MIN below lambda_crit gives a negative margin.
    assert eig_margin_lower_bound(cfg, (0.0, 0.0, 0.0), 0.05, 1.0, lam_crit) < 0.0


# --- battery -----------------------------------------------------------------------------------------------
def test_battery_discharges_and_sags() -> None:
    cfg = BatteryConfig()
    b0 = battery_initial(cfg)
    assert b0.voltage_v == pytest.approx(25.2) and b0.remaining_pct == 100
    b = b0
    for _ in range(60):
        b = battery_step(b, 1500.0, 1.0, cfg)
    assert b.soc < 1.0 and b.consumed_mah > 0 and b.energy_j == pytest.approx(1500.0 * 60, rel=1e-6)
    assert b.voltage_v < open_circuit_voltage(b.soc, cfg)  # sag under load
    assert b.current_a == pytest.approx(1500.0 / b.voltage_v, rel=1e-6)
    assert b.consumed_mah == pytest.approx((1.0 - b.soc) * 10_000.0, rel=1e-6)
    idle = battery_step(b, 0.0, 1.0, cfg)
    assert idle.current_a == 0.0 and idle.voltage_v == pytest.approx(open_circuit_voltage(b.soc, cfg))
    assert battery_step(b, math.nan, 1.0, cfg).current_a == 0.0
    empty = battery_step(battery_initial(cfg, soc=0.0), 1000.0, 1.0, cfg)
    assert empty.soc == 0.0 and empty.remaining_pct == 0
    overload = battery_step(b0, 1e9, 0.001, cfg)  # beyond maximum power: bounded, finite
    assert math.isfinite(overload.current_a) and overload.voltage_v == pytest.approx(25.2 / 2, rel=1e-3)


def test_gps_raw_int_and_origin_follow_the_origin(mavs) -> None:
    origin = GeoOrigin(47.0, 8.0, 500.0)
    tb = TelemetryBuilder(mavs[0], 1, 1)
    snap = snapshot(pos_ned_m=(10.0, -5.0, -2.0), vel_ned_m_s=(0.0, 1.0, 0.0), origin=origin)
    (gps,) = roundtrip(tb.build(M.MAVLINK_MSG_ID_GPS_RAW_INT, snap, 1000), mavs)
    lat, lon, alt = origin.to_global((10.0, -5.0, -2.0))
    assert (gps.lat, gps.lon, gps.alt) == (round(lat * 1e7), round(lon * 1e7), round(alt * 1000))
    assert gps.fix_type == M.GPS_FIX_TYPE_3D_FIX and gps.vel == 100 and gps.cog == 9000
    assert gps.satellites_visible == 10  # as PX4 SITL (MAVSDK's telemetry example prints it)
    (o,) = roundtrip(tb.build(M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, snap, 0), mavs)
    assert (o.latitude, o.longitude, o.altitude) == (470000000, 80000000, 500000)


def test_highres_imu_is_off_until_asked_and_carries_the_imu_sample(mavs) -> None:
    """MAVSDK's set_rate_imu asks for HIGHRES_IMU by SET_MESSAGE_INTERVAL (its highres_imu example); the message has
    the IMU's accelerometer and gyro in FRD and flags only those as updated (no magnetometer or barometer here)."""
    sched = TelemetryScheduler()
    assert sched.interval_us(M.MAVLINK_MSG_ID_HIGHRES_IMU) == -1
    assert sched.set_interval(M.MAVLINK_MSG_ID_HIGHRES_IMU, 20_000)
    tb = TelemetryBuilder(mavs[0], 1, 1)
    snap = snapshot(accel_frd_m_s2=(0.5, -0.25, -9.75))
    (imu,) = roundtrip(tb.build(M.MAVLINK_MSG_ID_HIGHRES_IMU, snap, 1234), mavs)
    assert (imu.xacc, imu.yacc, imu.zacc) == (0.5, -0.25, -9.75)
    assert (imu.xgyro, imu.ygyro, imu.zgyro) == pytest.approx((0.01, -0.02, 0.03))
    assert imu.time_usec == 1_234_000 and imu.fields_updated == 0b111111 and imu.xmag == 0.0


def test_eig_margin_is_bounded_over_the_box_of_the_k_flown() -> None:
    """EIG_MARGIN sweeps the K the INDI flies: at the defaults' flown gain (lambda* 0.4, floor 0.4) the box is
    [0.4, 1], wider than the estimate's [0.5, 1]; flying K_hat (INDI_LAM_REF 1, INDI_KFL_MIN 0) it is the Eq. 20 box."""
    from navig8_fc.params.registry import ParamRegistry
    from navig8_fc.shell.telemetry_service import TelemetrySettings

    values = ParamRegistry.from_defaults(check_stability=False).as_dict()
    s = TelemetrySettings.from_params(values)
    assert (s.k_min, s.k_max) == pytest.approx((0.4, 1.0))
    s = TelemetrySettings.from_params({**values, "INDI_LAM_REF": 1.0, "INDI_KFL_MIN": 0.0})
    assert (s.k_min, s.k_max) == pytest.approx((values["INDI_K_MIN"], values["INDI_K_MAX"]))
