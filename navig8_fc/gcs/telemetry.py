"""Telemetry a GCS expects: a stream scheduler (wall time) and builders from a vehicle snapshot.

Streams (mavlink_notes §2.7; QGC does not request streams from a generic vehicle, so they run by default):

| message (id)                  | default | notes |
|-------------------------------|---------|-------|
| HEARTBEAT (0)                 | 1 Hz    | cannot be disabled (clients drop the vehicle after ~3 s without it) |
| SYS_STATUS (1)                | 1 Hz    | sensor bits incl. PREARM_CHECK, battery |
| SYSTEM_TIME (2)               | 1 Hz    | unix time from the shell, boot ms |
| ATTITUDE (30)                 | 20 Hz   | |
| ATTITUDE_QUATERNION (31)      | 10 Hz   | |
| LOCAL_POSITION_NED (32)       | 10 Hz   | |
| GLOBAL_POSITION_INT (33)      | 10 Hz   | flat earth from the configured origin |
| VFR_HUD (74)                  | 4 Hz    | |
| BATTERY_STATUS (147)          | 1 Hz    | simulated pack (navig8_fc.flight.battery) |
| AUTOPILOT_VERSION (148)       | off     | on request; may be streamed |
| NAMED_VALUE_FLOAT (251)       | 5 Hz    | stability telemetry: one message per name per tick |
| HOME_POSITION (242)           | 0.5 Hz  | also on request; nothing before a home exists |
| EXTENDED_SYS_STATE (245)      | 2 Hz    | landed state |
| ACTUATOR_OUTPUT_STATUS (375)  | 5 Hz    | tilts (rad), propeller speeds (rad/s), joints (rad), gripper |
| ORBIT_EXECUTION_STATUS (360)  | 2 Hz    | only in Orbit (PX4's rate): signed radius, centre, altitude AMSL |

SET_MESSAGE_INTERVAL semantics (`TelemetryScheduler.set_interval`): -1 disables, 0 restores the default, > 0
is the interval in us (clamped to at least `min_interval_us`, 2 ms = 500 Hz); ids not in the table are
refused (False -> the command handler answers DENIED). `interval_us` reads back in MESSAGE_INTERVAL terms:
the interval, -1 when disabled, 0 when the id is not available here.

Before the first sensor data (`VehicleSnapshot.state_valid` False) the state streams (ATTITUDE,
ATTITUDE_QUATERNION, LOCAL_POSITION_NED, GLOBAL_POSITION_INT, VFR_HUD) send nothing, as PX4 sends no
position before it has an estimate: a GCS would otherwise see the vehicle at the origin, level, until the
simulator's first bundle. A REQUEST_MESSAGE for one of them then answers TEMPORARILY_REJECTED.

Stability telemetry (NAMED_VALUE_FLOAT, names <= 10 chars, graphable in QGC's MAVLink Inspector and MAVProxy):
IXX_HAT, IYY_HAT, IZZ_HAT (kg m^2), M_HAT (kg): the constrained KF's estimate x_hat (G_hat_I, Eq. 4/21);
K1..K4: the implied weighting factors (Eq. 4); EIG_MARGIN: the *bound-based* margin the FC can compute
without ground truth, lambda_lb(q) - lambda_crit, where lambda_lb(q) is the smallest real part of
eig(K Xi(q, m)) at the current estimated arm pose q over every K in [INDI_K_MIN, INDI_K_MAX]^4 (the box the
constrained estimate is kept in, Eq. 21) and object masses 0..2 kg, and lambda_crit is the critical
eigenvalue of H(s) for the current actuator/sampling/filter parameters (Eq. 9-13). Positive = the
stability guarantee holds at this pose whatever the object; `core.k_xi.eig_margin_lower_bound` computes it (~1.4 ms).
Because the empty gripper (Xi = I, eigenvalues = K) is always a candidate, the bound is at most
K_MIN - lambda_crit and moves mostly with the parameters, a little with the pose: it is the guarantee, not a
measurement. The actual min eigenvalue of G_hat G^-1 needs the true G, which only the bridge's truth has (it
is in the logs); an "as estimated" variant (G from the estimated object) was not chosen because it would
report the estimator's own belief back as a margin.
LAM_CRIT: lambda_crit of H(s) for the configuration in force (ACT_WN, ACT_ZETA, 1/INDI_RATE_HZ, INDI_LPF_TAU;
Eq. 9-13), or, when the FC runs in real time and the sim link flies its answers later than lockstep would, of the
sampled loop with that delay (measured; docs/stability.md "Over a real-time link"). LAM_MARGIN: the stated margin
the parameter checks enforce, the smallest eigenvalue of G_hat G^-1 guaranteed over the K box and the workspace
divided by LAM_CRIT (a change that takes it below INDI_LAM_MARGIN is refused; docs/stability.md "The flown
configuration"). Both change only with those parameters and the link's delay: the registry's stability floor of the
values in force, LAM_MARGIN NaN while it is being computed (a worker, after a reset, at start, when the delay moved).
KFL_FLOWN: the floor on the rotational axes' flown K in force, INDI_KFL_MIN or, over a late link, the automatic link
floor when that is higher (INDI_KFL_LINK; docs/stability.md "Over a real-time link"): the K the margin is computed at.

Frames and units: GLOBAL_POSITION_INT converts NED to WGS-84 with PX4's flat-earth (equirectangular)
projection around `GeoOrigin`, Earth radius 6 371 000 m: lat = lat0 + n/R, lon = lon0 + e/(R cos lat0),
alt_msl = alt0 - d. Over the few metres this vehicle flies the error is far below a millimetre. Headings are
centi-degrees 0..35999 (65535 unknown). VFR_HUD airspeed = groundspeed (no wind in the simulation).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.core.rotation import quat_to_euler
from navig8_fc.flight.battery import BatteryState, battery_initial
from navig8_fc.gcs.params import PARAM_ENCODING_CAPABILITY
from navig8_fc.mission.geo import EARTH_RADIUS_M, GeoOrigin  # noqa: F401 - GeoOrigin is part of this API
from navig8_fc.modes.orbit import OrbitPlan

M = mavlink2
Vec3 = tuple[float, float, float]
Vec4 = tuple[float, float, float, float]

UINT16_MAX = 65535
INT16_MAX = 32767

MSG_HEARTBEAT = M.MAVLINK_MSG_ID_HEARTBEAT
MSG_SYS_STATUS = M.MAVLINK_MSG_ID_SYS_STATUS
MSG_SYSTEM_TIME = M.MAVLINK_MSG_ID_SYSTEM_TIME
MSG_ATTITUDE = M.MAVLINK_MSG_ID_ATTITUDE
MSG_ATTITUDE_QUATERNION = M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION
MSG_LOCAL_POSITION_NED = M.MAVLINK_MSG_ID_LOCAL_POSITION_NED
MSG_GLOBAL_POSITION_INT = M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
MSG_VFR_HUD = M.MAVLINK_MSG_ID_VFR_HUD
MSG_BATTERY_STATUS = M.MAVLINK_MSG_ID_BATTERY_STATUS
MSG_AUTOPILOT_VERSION = M.MAVLINK_MSG_ID_AUTOPILOT_VERSION
MSG_HOME_POSITION = M.MAVLINK_MSG_ID_HOME_POSITION
MSG_EXTENDED_SYS_STATE = M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE
MSG_NAMED_VALUE_FLOAT = M.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT
MSG_ACTUATOR_OUTPUT_STATUS = M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS
MSG_PROTOCOL_VERSION = 300  # not in every common.xml; built only when the dialect has it
MSG_GPS_RAW_INT = M.MAVLINK_MSG_ID_GPS_RAW_INT
MSG_GPS_GLOBAL_ORIGIN = M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN
MSG_HIGHRES_IMU = M.MAVLINK_MSG_ID_HIGHRES_IMU
MSG_ORBIT_EXECUTION_STATUS = M.MAVLINK_MSG_ID_ORBIT_EXECUTION_STATUS
# HIGHRES_IMU.fields_updated: the accelerometer (bits 0-2) and gyro (3-5) are sampled; there is no magnetometer,
# barometer or temperature sensor on the simulated vehicle, so those fields are 0 and not flagged.
HIGHRES_IMU_ACCEL_GYRO = 0x3F

DEFAULT_RATES_HZ: dict[int, float] = {
    MSG_HEARTBEAT: 1.0,
    MSG_SYS_STATUS: 1.0,
    MSG_SYSTEM_TIME: 1.0,
    MSG_ATTITUDE: 20.0,
    MSG_ATTITUDE_QUATERNION: 10.0,
    MSG_LOCAL_POSITION_NED: 10.0,
    MSG_GLOBAL_POSITION_INT: 10.0,
    MSG_VFR_HUD: 4.0,
    MSG_BATTERY_STATUS: 1.0,
    MSG_AUTOPILOT_VERSION: 0.0,
    MSG_NAMED_VALUE_FLOAT: 5.0,
    MSG_HOME_POSITION: 0.5,
    MSG_EXTENDED_SYS_STATE: 2.0,
    MSG_ACTUATOR_OUTPUT_STATUS: 5.0,
    MSG_GPS_RAW_INT: 5.0,
    MSG_GPS_GLOBAL_ORIGIN: 0.2,
    MSG_HIGHRES_IMU: 0.0,  # off until asked (SET_MESSAGE_INTERVAL; MAVSDK's set_rate_imu)
    MSG_ORBIT_EXECUTION_STATUS: 2.0,  # PX4's rate; nothing outside Orbit
}

# Capabilities this flight controller really has (AUTOPILOT_VERSION). MISSION_INT: the mission protocol is
# answered with the *_INT messages (and MAVSDK refuses mission upload without it); COMMAND_INT: handled;
# SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT: position targets fly Offboard (gcs_service); MISSION_FENCE: fence
# plans (inclusion circles and polygons) are uploaded, stored and enforced (navig8_fc.mission.fence); MISSION_RALLY:
# rally plans are uploaded, stored and flown to by Return (navig8_fc.mission.rally); MAVLINK2:
# always; PARAM_ENCODE_BYTEWISE: how INT32 parameters are encoded (navig8_fc.gcs.params).
# SET_ATTITUDE_TARGET: the attitude and thrust fly Offboard as PX4 reads them (navig8_fc.gcs.offboard).
# Not set: FTP (answered with NAK only), GRIPPER (WIP bit).
CAPABILITIES = (
    M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
    | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | PARAM_ENCODING_CAPABILITY
)

# SYS_STATUS sensor bits and what they stand for on this vehicle (docs/gcs.md).
SENSOR_GYRO = M.MAV_SYS_STATUS_SENSOR_3D_GYRO
SENSOR_ACCEL = M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
SENSOR_HEADING = M.MAV_SYS_STATUS_SENSOR_3D_MAG  # heading reference: motion capture attitude
SENSOR_POSITION = M.MAV_SYS_STATUS_SENSOR_GPS  # global position source: motion capture + configured origin
SENSOR_MOTORS = M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
SENSOR_AHRS = M.MAV_SYS_STATUS_AHRS  # attitude/position estimate usable
SENSOR_BATTERY = M.MAV_SYS_STATUS_SENSOR_BATTERY
SENSOR_PREARM = M.MAV_SYS_STATUS_PREARM_CHECK  # health bit = pre-arm checks pass (MAVSDK is_armable)


GPS_SIM_SATELLITES = 10  # GPS_RAW_INT.satellites_visible: PX4 SITL's SIM_GPS_USED default


@dataclass(frozen=True)
class SensorBits:
    present: int
    enabled: int
    health: int


def sensor_bits(
    *, imu_ok: bool, pose_ok: bool, actuators_ok: bool, estimator_ok: bool, battery_ok: bool, prearm_ok: bool,
    gps_ok: bool = True,
) -> SensorBits:
    """SYS_STATUS present/enabled/health from the FC's health flags (every sensor is always present+enabled);
    gps_ok False: the global position source failed (an injected failure) though the pose data is fresh."""
    pairs = (
        (SENSOR_GYRO | SENSOR_ACCEL, imu_ok),
        (SENSOR_HEADING, pose_ok),
        (SENSOR_POSITION, pose_ok and gps_ok),
        (SENSOR_MOTORS, actuators_ok),
        (SENSOR_AHRS, estimator_ok),
        (SENSOR_BATTERY, battery_ok),
        (SENSOR_PREARM, prearm_ok),
    )
    present = 0
    health = 0
    for bits, ok in pairs:
        present |= bits
        if ok:
            health |= bits
    return SensorBits(present, present, health)


_NAN4: Vec4 = (math.nan, math.nan, math.nan, math.nan)


@dataclass(frozen=True)
class VehicleSnapshot:
    """Everything the telemetry builders need at one instant (NED, FRD, SI, rad)."""

    armed: bool
    base_mode: int
    custom_mode: int
    system_status: int  # MAV_STATE
    landed_state: int  # MAV_LANDED_STATE
    pos_ned_m: Vec3
    vel_ned_m_s: Vec3
    quat_wxyz: Vec4
    gyro_frd_rad_s: Vec3
    accel_frd_m_s2: Vec3 = (0.0, 0.0, 0.0)  # specific force as the IMU measures it
    state_valid: bool = True  # pos/vel/attitude come from sensor data (False before the first: no state streams)
    home_ned_m: Vec3 | None = None
    home_yaw_rad: float = 0.0
    origin: GeoOrigin = field(default_factory=GeoOrigin)
    battery: BatteryState = field(default_factory=battery_initial)
    battery_cells: int = 6
    battery_low_pct: float = 20.0
    battery_critical_pct: float = 10.0
    duct_tilt_rad: tuple[float, float] = (0.0, 0.0)  # measured duct angles alpha1, alpha3
    prop_speed_rad_s: Vec3 = (0.0, 0.0, 0.0)  # measured propeller speeds w1, w2 (tail, signed), w3
    joint_pos_rad: Vec3 = (0.0, 0.0, 0.0)
    gripper_closed: bool = False
    sensors: SensorBits = SensorBits(0, 0, 0)
    load_permille: int = 0  # FC loop load 0..1000
    ckf_x_hat: Vec4 = _NAN4  # [I_xx, I_yy, I_zz, m] estimate (kg m^2, kg)
    ckf_k: Vec4 = _NAN4  # implied [K1..K4]
    eig_margin: float = math.nan  # see module docstring
    lam_crit: float = math.nan  # lambda_crit of the configuration in force (module docstring)
    lam_margin: float = math.nan  # guaranteed min eigenvalue / lambda_crit (module docstring)
    kfl_flown: float = math.nan  # the flown K's floor in force: INDI_KFL_MIN or the link floor (module docstring)
    time_unix_usec: int = 0  # given by the shell (0 = unknown)
    throttle_pct: float = 0.0
    orbit: OrbitPlan | None = None  # the orbit being flown (ORBIT_EXECUTION_STATUS)
    gps_ok: bool = True  # False: the global position source is off (an injected failure: GPS_RAW_INT has no fix)


# --- scheduler ---------------------------------------------------------------------------------------------
class TelemetryScheduler:
    """Which streams are due, on the caller's (wall) clock; rates changeable per message id."""

    def __init__(self, defaults_hz: Mapping[int, float] | None = None, min_interval_us: int = 2000) -> None:
        defaults = dict(DEFAULT_RATES_HZ if defaults_hz is None else defaults_hz)
        if any(not (hz >= 0.0 and math.isfinite(hz)) for hz in defaults.values()):
            raise ValueError("default rates must be finite and >= 0 Hz")
        self._defaults_hz = defaults
        self._min_interval_us = int(min_interval_us)
        self._default_us = {i: (max(int(round(1e6 / hz)), self._min_interval_us) if hz > 0 else -1)
                            for i, hz in defaults.items()}  # fmt: skip
        self._interval_us = dict(self._default_us)
        self._next_s: dict[int, float | None] = dict.fromkeys(defaults)

    @property
    def supported_ids(self) -> frozenset[int]:
        return frozenset(self._default_us)

    def copy(self) -> TelemetryScheduler:
        """A table with the same defaults and the same current rates, its streams due at the next call."""
        c = TelemetryScheduler(self._defaults_hz, self._min_interval_us)
        for msg_id, interval_us in self._interval_us.items():
            if interval_us != self._default_us[msg_id]:  # a rate set since: the same through set_interval
                c.set_interval(msg_id, interval_us)
        return c

    def set_interval(self, msg_id: int, interval_us: int) -> bool:
        if msg_id not in self._default_us or interval_us < -1:
            return False
        if interval_us == -1 and msg_id == MSG_HEARTBEAT:
            return False  # a vehicle without heartbeats is a lost vehicle for every client
        if interval_us == 0:
            new = self._default_us[msg_id]
        elif interval_us == -1:
            new = -1
        else:
            new = max(int(interval_us), self._min_interval_us)
        self._interval_us[msg_id] = new
        self._next_s[msg_id] = None  # due at the next call, then every interval from there
        return True

    def interval_us(self, msg_id: int) -> int:
        """MESSAGE_INTERVAL semantics: the interval in us, -1 disabled, 0 not available."""
        return self._interval_us.get(msg_id, 0)

    def due(self, now_s: float) -> list[int]:
        out: list[int] = []
        for msg_id, interval_us in self._interval_us.items():
            if interval_us <= 0:
                continue
            period_s = interval_us * 1e-6
            nxt = self._next_s[msg_id]
            if nxt is None or now_s >= nxt:
                out.append(msg_id)
                # Keep the phase when on time; after a stall start over instead of sending a burst.
                nxt = now_s + period_s if nxt is None or now_s - nxt >= period_s else nxt + period_s
                self._next_s[msg_id] = nxt
        return out


# --- builders ---------------------------------------------------------------------------------------------
def _i(x: float, lo: int, hi: int, default: int) -> int:
    """Round and clamp into an integer field; non-finite -> default (a message must always pack)."""
    if not math.isfinite(x):
        return default
    return max(lo, min(hi, int(round(x))))


euler_from_quat = quat_to_euler  # (roll, pitch, yaw) ZYX from [w, x, y, z]: the core's one conversion


def heading_cdeg(yaw_rad: float) -> int:
    """0..35999 centi-degrees, 65535 when unknown."""
    if not math.isfinite(yaw_rad):
        return UINT16_MAX
    return int(round(math.degrees(yaw_rad) % 360.0 * 100.0)) % 36000


class TelemetryBuilder:
    """Builds the telemetry messages (not packed; the shell's MAVLink instance sets the header)."""

    def __init__(
        self,
        mav: Any,
        sysid: int,
        compid: int,
        *,
        sw_version: tuple[int, int, int] = (0, 1, 0),
        sw_version_type: int = M.FIRMWARE_VERSION_TYPE_DEV,
        custom_version: bytes = b"",
        approach_height_m: float = 2.5,
        autopilot: int = M.MAV_AUTOPILOT_GENERIC,
    ) -> None:
        self._mav = mav
        self.autopilot = int(autopilot)  # HEARTBEAT.autopilot: GENERIC, or PX4 as an option (docs/gcs.md)
        self._sysid = int(sysid)
        self._compid = int(compid)
        major, minor, patch = sw_version
        self.flight_sw_version = (major << 24) | (minor << 16) | (patch << 8) | int(sw_version_type)
        self._custom_version = list(custom_version[:8].ljust(8, b"\0"))
        self._approach_height_m = float(approach_height_m)
        # "N8" + sysid + compid: unique per instance (QGC keys its caches by uid).
        self.uid = (0x4E38 << 48) | (self._sysid << 8) | self._compid
        self._builders = {
            MSG_HEARTBEAT: self.heartbeat,
            MSG_SYS_STATUS: self.sys_status,
            MSG_SYSTEM_TIME: self.system_time,
            MSG_ATTITUDE: self.attitude,
            MSG_ATTITUDE_QUATERNION: self.attitude_quaternion,
            MSG_LOCAL_POSITION_NED: self.local_position_ned,
            MSG_GLOBAL_POSITION_INT: self.global_position_int,
            MSG_VFR_HUD: self.vfr_hud,
            MSG_BATTERY_STATUS: self.battery_status,
            MSG_AUTOPILOT_VERSION: lambda snap, now_boot_ms: self.autopilot_version(),
            MSG_HOME_POSITION: self.home_position,
            MSG_GPS_RAW_INT: self.gps_raw_int,
            MSG_GPS_GLOBAL_ORIGIN: self.gps_global_origin,
            MSG_EXTENDED_SYS_STATE: self.extended_sys_state,
            MSG_NAMED_VALUE_FLOAT: self.stability_values,
            MSG_ACTUATOR_OUTPUT_STATUS: self.actuator_output_status,
            MSG_HIGHRES_IMU: self.highres_imu,
            MSG_ORBIT_EXECUTION_STATUS: self.orbit_execution_status,
        }
        if hasattr(mav, "protocol_version_encode"):
            self._builders[MSG_PROTOCOL_VERSION] = lambda snap, now_boot_ms: self.protocol_version()

    @property
    def capabilities(self) -> int:
        return CAPABILITIES

    @property
    def supported_ids(self) -> frozenset[int]:
        return frozenset(self._builders)

    def build(self, msg_id: int, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        """Messages for `msg_id` ([] when unsupported or not available, e.g. HOME_POSITION without a home)."""
        builder = self._builders.get(msg_id)
        if builder is None:
            return []
        return builder(snap, int(now_boot_ms) & 0xFFFFFFFF)

    def build_many(self, msg_ids: Iterable[int], snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        return [m for i in msg_ids for m in self.build(i, snap, now_boot_ms)]

    # --- identity ---------------------------------------------------------------------------------------
    def heartbeat(self, snap: VehicleSnapshot, now_boot_ms: int = 0) -> list[Any]:
        # base_mode: CUSTOM_MODE_ENABLED always (custom_mode is PX4-encoded), SAFETY_ARMED exactly when armed.
        # HIL_ENABLED stays clear: this FC runs its real control code, only the sensors are simulated (PX4 SITL
        # does the same); a GCS would otherwise show "HIL" and some refuse commands.
        armed_bit = M.MAV_MODE_FLAG_SAFETY_ARMED if snap.armed else 0
        base = (snap.base_mode & ~M.MAV_MODE_FLAG_SAFETY_ARMED & 0xFF) | M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | armed_bit
        return [
            self._mav.heartbeat_encode(
                M.MAV_TYPE_TRICOPTER, self.autopilot, base, snap.custom_mode & 0xFFFFFFFF,
                snap.system_status, 3,
            )
        ]  # fmt: skip

    def autopilot_version(self) -> list[Any]:
        zeros8 = [0] * 8
        return [
            self._mav.autopilot_version_encode(
                CAPABILITIES, self.flight_sw_version, 0, 0, 0, self._custom_version, zeros8, zeros8, 0, 0, self.uid,
                [0] * 18,
            )
        ]  # fmt: skip

    def protocol_version(self) -> list[Any]:
        return [self._mav.protocol_version_encode(200, 100, 200, [0] * 8, [0] * 8)]

    # --- state ------------------------------------------------------------------------------------------
    def sys_status(self, snap: VehicleSnapshot, now_boot_ms: int = 0) -> list[Any]:
        b = snap.battery
        s = snap.sensors
        return [
            self._mav.sys_status_encode(
                s.present, s.enabled, s.health, _i(snap.load_permille, 0, 1000, 0),
                _i(b.voltage_v * 1000.0, 0, UINT16_MAX - 1, UINT16_MAX), _i(b.current_a * 100.0, -1, INT16_MAX, -1),
                _i(b.remaining_pct, -1, 100, -1), 0, 0, 0, 0, 0, 0,
            )
        ]  # fmt: skip

    def system_time(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        return [self._mav.system_time_encode(max(int(snap.time_unix_usec), 0), now_boot_ms)]

    def extended_sys_state(self, snap: VehicleSnapshot, now_boot_ms: int = 0) -> list[Any]:
        return [self._mav.extended_sys_state_encode(M.MAV_VTOL_STATE_UNDEFINED, snap.landed_state)]

    def attitude(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        if not snap.state_valid:
            return []
        roll, pitch, yaw = euler_from_quat(snap.quat_wxyz)
        p, q, r = snap.gyro_frd_rad_s
        return [self._mav.attitude_encode(now_boot_ms, roll, pitch, yaw, p, q, r)]

    def highres_imu(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        """The IMU's latest sample (FRD body axes, as PX4 streams it): accelerometer and gyro only."""
        if not snap.state_valid:
            return []
        ax, ay, az = snap.accel_frd_m_s2
        p, q, r = snap.gyro_frd_rad_s
        return [self._mav.highres_imu_encode(now_boot_ms * 1000, ax, ay, az, p, q, r, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                             0.0, HIGHRES_IMU_ACCEL_GYRO)]

    def attitude_quaternion(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        if not snap.state_valid:
            return []
        w, x, y, z = snap.quat_wxyz
        p, q, r = snap.gyro_frd_rad_s
        return [self._mav.attitude_quaternion_encode(now_boot_ms, w, x, y, z, p, q, r, [1.0, 0.0, 0.0, 0.0])]

    def local_position_ned(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        if not snap.state_valid:
            return []
        return [self._mav.local_position_ned_encode(now_boot_ms, *snap.pos_ned_m, *snap.vel_ned_m_s)]

    def global_position_int(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        if not snap.state_valid:
            return []
        if not snap.gps_ok:  # failure injected: a receiver without a fix (PX4 SITL's blocked GPS sends nothing)
            return [self._mav.gps_raw_int_encode(now_boot_ms * 1000, M.GPS_FIX_TYPE_NO_FIX, 0, 0, 0, 65535, 65535,
                                                 65535, 65535, 0)]
        lat, lon, alt = snap.origin.to_global(snap.pos_ned_m)
        home_d = snap.home_ned_m[2] if snap.home_ned_m is not None else 0.0
        rel_alt = home_d - snap.pos_ned_m[2]
        vn, ve, vd = snap.vel_ned_m_s
        yaw = euler_from_quat(snap.quat_wxyz)[2]
        i32 = (-(2**31), 2**31 - 1)
        return [
            self._mav.global_position_int_encode(
                now_boot_ms, _i(lat * 1e7, *i32, 0), _i(lon * 1e7, *i32, 0), _i(alt * 1000.0, *i32, 0),
                _i(rel_alt * 1000.0, *i32, 0), _i(vn * 100.0, -INT16_MAX, INT16_MAX, 0),
                _i(ve * 100.0, -INT16_MAX, INT16_MAX, 0), _i(vd * 100.0, -INT16_MAX, INT16_MAX, 0), heading_cdeg(yaw),
            )
        ]  # fmt: skip

    def gps_raw_int(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        """The global position source as a GPS: motion capture + the origin is an RTK-grade fix (3D_FIX... RTK
        would claim a receiver; 3D fix, 1 cm accuracy figures from the pose noise), so GPS widgets work. Satellites:
        GPS_SIM_SATELLITES (10), what PX4 SITL reports (its SIM_GPS_USED default), not 255 "unknown", which
        MAVSDK's telemetry example prints as is."""
        if not snap.state_valid:
            return []
        if not snap.gps_ok:  # failure injected: a receiver without a fix (PX4 SITL's blocked GPS sends nothing)
            return [self._mav.gps_raw_int_encode(now_boot_ms * 1000, M.GPS_FIX_TYPE_NO_FIX, 0, 0, 0, 65535, 65535,
                                                 65535, 65535, 0)]
        lat, lon, alt = snap.origin.to_global(snap.pos_ned_m)
        vn, ve, _ = snap.vel_ned_m_s
        i32 = (-(2**31), 2**31 - 1)
        cog = _i(math.degrees(math.atan2(ve, vn)) % 360.0 * 100.0, 0, 35999, 0) if math.hypot(vn, ve) > 0.1 else 65535
        return [self._mav.gps_raw_int_encode(
            now_boot_ms * 1000, M.GPS_FIX_TYPE_3D_FIX, _i(lat * 1e7, *i32, 0), _i(lon * 1e7, *i32, 0),
            _i(alt * 1000.0, *i32, 0), 100, 100, _i(math.hypot(vn, ve) * 100.0, 0, 65534, 0), cog,
            GPS_SIM_SATELLITES)]

    def gps_global_origin(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        o = snap.origin
        return [self._mav.gps_global_origin_encode(round(o.lat_deg * 1e7), round(o.lon_deg * 1e7),
                                                   round(o.alt_amsl_m * 1000.0))]

    def vfr_hud(self, snap: VehicleSnapshot, now_boot_ms: int = 0) -> list[Any]:
        if not snap.state_valid:
            return []
        vn, ve, vd = snap.vel_ned_m_s
        ground = math.hypot(vn, ve)
        yaw = euler_from_quat(snap.quat_wxyz)[2]
        heading_deg = _i(math.degrees(yaw) % 360.0, 0, 359, 0) if math.isfinite(yaw) else 0
        alt_msl = snap.origin.alt_amsl_m - snap.pos_ned_m[2]
        throttle = _i(snap.throttle_pct, 0, 100, 0)
        return [self._mav.vfr_hud_encode(ground, ground, heading_deg, throttle, alt_msl, -vd)]

    def home_position(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        if snap.home_ned_m is None:
            return []
        hn, he, hd = snap.home_ned_m
        lat, lon, alt = snap.origin.to_global(snap.home_ned_m)
        half = 0.5 * snap.home_yaw_rad
        q = [math.cos(half), 0.0, 0.0, math.sin(half)]  # world-to-surface: flat ground, home heading
        # Approach vector end: the vertical path a multicopter climbs and descends on, in local NED.
        approach = (hn, he, hd - self._approach_height_m)
        i32 = (-(2**31), 2**31 - 1)
        return [
            self._mav.home_position_encode(
                _i(lat * 1e7, *i32, 0), _i(lon * 1e7, *i32, 0), _i(alt * 1000.0, *i32, 0), hn, he, hd, q, *approach,
                int(now_boot_ms) * 1000,
            )
        ]  # fmt: skip

    def battery_status(self, snap: VehicleSnapshot, now_boot_ms: int = 0) -> list[Any]:
        b = snap.battery
        cells = max(int(snap.battery_cells), 1)
        voltages = [UINT16_MAX] * 10
        if cells <= 10:
            cell_mv = _i(b.voltage_v * 1000.0 / cells, 0, UINT16_MAX - 1, UINT16_MAX)
            voltages[:cells] = [cell_mv] * cells
        else:  # spec: total in cell 0 when cells are not reported individually
            voltages[0] = _i(b.voltage_v * 1000.0, 0, UINT16_MAX - 1, UINT16_MAX)
        remaining = b.remaining_pct
        if remaining < snap.battery_critical_pct:
            charge_state = M.MAV_BATTERY_CHARGE_STATE_CRITICAL
        elif remaining < snap.battery_low_pct:
            charge_state = M.MAV_BATTERY_CHARGE_STATE_LOW
        else:
            charge_state = M.MAV_BATTERY_CHARGE_STATE_OK
        i32 = (-(2**31), 2**31 - 1)
        return [
            self._mav.battery_status_encode(
                0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, INT16_MAX, voltages,
                _i(b.current_a * 100.0, -1, INT16_MAX, -1), _i(b.consumed_mah, *i32, -1),
                _i(b.energy_j / 100.0, *i32, -1), _i(remaining, -1, 100, -1), 0, charge_state, [0, 0, 0, 0], 0, 0,
            )
        ]  # fmt: skip

    def actuator_output_status(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        # Channels: 0-1 duct tilts alpha1, alpha3 (rad); 2-4 propeller speeds w1, w2 (tail), w3 (rad/s);
        # 5-7 arm joints q1..q3 (rad); 8 gripper (1 closed, 0 open).
        values = [*snap.duct_tilt_rad, *snap.prop_speed_rad_s, *snap.joint_pos_rad, 1.0 if snap.gripper_closed else 0.0]
        active = (1 << len(values)) - 1
        padded = values + [0.0] * (32 - len(values))
        return [self._mav.actuator_output_status_encode(int(now_boot_ms) * 1000, active, padded)]

    def orbit_execution_status(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        """As PX4's stream (its orbit_status): the signed radius (positive clockwise), MAV_FRAME_GLOBAL, the centre in
        degE7 and the orbit's altitude AMSL; nothing outside Orbit."""
        o = snap.orbit
        if o is None:
            return []
        lat, lon, alt = snap.origin.to_global(o.centre_ned_m)
        i32 = (-(2**31), 2**31 - 1)
        return [self._mav.orbit_execution_status_encode(int(now_boot_ms) * 1000, o.signed_radius_m, M.MAV_FRAME_GLOBAL,
                                                        _i(lat * 1e7, *i32, 0), _i(lon * 1e7, *i32, 0), alt)]

    def stability_values(self, snap: VehicleSnapshot, now_boot_ms: int) -> list[Any]:
        names_values = (
            ("IXX_HAT", snap.ckf_x_hat[0]), ("IYY_HAT", snap.ckf_x_hat[1]), ("IZZ_HAT", snap.ckf_x_hat[2]),
            ("M_HAT", snap.ckf_x_hat[3]), ("K1", snap.ckf_k[0]), ("K2", snap.ckf_k[1]), ("K3", snap.ckf_k[2]),
            ("K4", snap.ckf_k[3]), ("EIG_MARGIN", snap.eig_margin), ("LAM_CRIT", snap.lam_crit),
            ("LAM_MARGIN", snap.lam_margin), ("KFL_FLOWN", snap.kfl_flown),
        )  # fmt: skip
        return [self._mav.named_value_float_encode(now_boot_ms, n.encode("ascii"), float(v)) for n, v in names_values]


STABILITY_VALUE_NAMES = ("IXX_HAT", "IYY_HAT", "IZZ_HAT", "M_HAT", "K1", "K2", "K3", "K4", "EIG_MARGIN", "LAM_CRIT",
                         "LAM_MARGIN", "KFL_FLOWN")
