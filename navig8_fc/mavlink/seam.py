"""The bridge <-> flight-controller lockstep seam: pure encode/decode of what crosses it (docs/bridge.md).

Both processes import this module, so the wire format lives in one place:

- bridge -> FC, once per step k: ONE UDP datagram holding, in this order, ODOMETRY, NAVIG8_ACTUATOR_STATE,
  NAVIG8_ARM_STATE, NAVIG8_TRUTH and HIL_SENSOR (last: the FC's trigger). `encode_bundle` builds it from
  the plant's SensorBundle and Truth; `decode_bundle` / `BundleAssembler` turn received messages back
  into a `StepBundle`.
- FC -> bridge, exactly one per bundle: HIL_ACTUATOR_CONTROLS whose time_usec echoes the bundle's.
  `encode_actuator_controls` / `decode_actuator_controls` normalise / denormalise the five channels.
- FC -> bridge, any time: NAVIG8_ARM_CMD (`encode_arm_cmd` / `decode_arm_cmd`,
  `arm_command_from_mav_cmd` for the GCS's MAV_CMD_NAVIG8_ARM_JOINTS in degrees).
- bridge -> FC, >= 1 Hz wall and at the end: NAVIG8_SIM_STATUS (`encode_sim_status` / `decode_sim_status`).

Time: time_usec = t_sim_us + 1 (`time_usec_from_sim_us`), so step 0 is never stamped 0 (a zero stamp
means "unset" to many MAVLink consumers and desynchronised PX4's lockstep, PR #13390); the FC recovers
the exact simulation time with `sim_us_from_time_usec` (StepBundle.t_s).

No sockets or clocks here: message objects and bytes in, frozen dataclasses and bytes out. Floats cross
the wire as float32 (MAVLink has no float64 fields for these), which is the only numerical difference
between a SITL run and the in-process runner.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from navig8_fc.core.rotation import quat_to_euler
from navig8_fc.mavlink import dialect

# HIL_SENSOR.fields_updated bits for accel (0x7) and gyro (0x38), PX4's grouping.
HIL_SENSOR_ACCEL_GYRO = 0b111111
# MAV_MODE_FLAG_SAFETY_ARMED: HIL_ACTUATOR_CONTROLS.mode bit set while armed.
MODE_FLAG_SAFETY_ARMED = 128
# Channels of HIL_ACTUATOR_CONTROLS.controls used: alpha1, alpha3, w1, w2, w3.
N_ACTUATOR_CHANNELS = 5

GRIPPER_NONE = 0
GRIPPER_GRAB = 1
GRIPPER_RELEASE = 2

SIM_STATE_WAITING_FOR_FC = 0
SIM_STATE_RUNNING = 1
SIM_STATE_DONE = 2
SIM_STATE_STALLED = 3

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
Vec4 = tuple[float, float, float, float]

_NAN = float("nan")
# ODOMETRY covariances: "If unknown, assign NaN value to first element in the array" (common.xml).
_COV_UNKNOWN = [_NAN] + [0.0] * 20


def time_usec_from_sim_us(t_sim_us: int) -> int:
    """Wire stamp of plant time t_sim_us (never 0)."""
    return int(t_sim_us) + 1


def sim_us_from_time_usec(time_usec: int) -> int:
    """Plant time (us) of a wire stamp."""
    return int(time_usec) - 1


# ---- actuator answer ------------------------------------------------------------------------------
@dataclass(frozen=True)
class ActuatorLimits:
    """Normalisation of HIL_ACTUATOR_CONTROLS: controls = value / limit (so |controls| <= 1 in range)."""

    tilt_max_abs_rad: float  # max(|tilt_min|, |tilt_max|): controls[0], controls[1]
    duct_speed_max_rad_s: float  # controls[2], controls[4] (0..1)
    tail_speed_max_rad_s: float  # controls[3] (signed, -1..1)

    def __post_init__(self) -> None:
        for name in ("tilt_max_abs_rad", "duct_speed_max_rad_s", "tail_speed_max_rad_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"ActuatorLimits.{name} must be finite and > 0, got {v}")

    @staticmethod
    def from_vehicle(vehicle: Any) -> ActuatorLimits:
        """From a navig8_fc.core.vehicle.VehicleConfig (duck-typed: tilt_min/max_rad, *_speed_max)."""
        return ActuatorLimits(
            tilt_max_abs_rad=max(abs(float(vehicle.tilt_min_rad)), abs(float(vehicle.tilt_max_rad))),
            duct_speed_max_rad_s=float(vehicle.duct_speed_max),
            tail_speed_max_rad_s=max(abs(float(vehicle.tail_speed_max)), abs(float(vehicle.tail_speed_min))),
        )


def _limits(limits_or_vehicle: Any) -> ActuatorLimits:
    if isinstance(limits_or_vehicle, ActuatorLimits):
        return limits_or_vehicle
    return ActuatorLimits.from_vehicle(limits_or_vehicle)


class HasActuators(Protocol):
    """Any actuator command: navig8_fc.core.controller.ActuatorCommand, sim_bridge.ActuatorCommand."""

    @property
    def tilt_rad(self) -> Sequence[float]: ...

    @property
    def speed_rad_s(self) -> Sequence[float]: ...


@dataclass(frozen=True)
class ActuatorControls:
    """A decoded HIL_ACTUATOR_CONTROLS in SI units."""

    time_usec: int  # echo of the bundle's stamp
    tilt_rad: Vec2  # alpha1 (right), alpha3 (left)
    speed_rad_s: Vec3  # w1 (right duct), w2 (tail, signed), w3 (left duct)
    armed: bool


def _actuator_controls_args(time_usec: int, cmd: HasActuators, limits: Any, armed: bool) -> tuple[Any, ...]:
    lim = _limits(limits)
    controls = [0.0] * 16
    controls[0] = float(cmd.tilt_rad[0]) / lim.tilt_max_abs_rad
    controls[1] = float(cmd.tilt_rad[1]) / lim.tilt_max_abs_rad
    controls[2] = float(cmd.speed_rad_s[0]) / lim.duct_speed_max_rad_s
    controls[3] = float(cmd.speed_rad_s[1]) / lim.tail_speed_max_rad_s
    controls[4] = float(cmd.speed_rad_s[2]) / lim.duct_speed_max_rad_s
    return (int(time_usec), controls, MODE_FLAG_SAFETY_ARMED if armed else 0, 0)


def encode_actuator_controls(time_usec: int, cmd: HasActuators, limits: Any, *, armed: bool) -> Any:
    """HIL_ACTUATOR_CONTROLS answering the bundle stamped time_usec (limits: ActuatorLimits or VehicleConfig).

    Values are divided by the limits but not clipped: the plant clamps and counts out-of-range commands,
    which would be hidden if the encoder clipped them. Non-finite values pass through (the plant holds).
    """
    return dialect.load().MAVLink_hil_actuator_controls_message(*_actuator_controls_args(time_usec, cmd, limits,
                                                                                          armed))


def pack_actuator_controls(mav: Any, time_usec: int, cmd: HasActuators, limits: Any, *, armed: bool) -> bytes:
    """The frame of encode_actuator_controls(...) packed with `mav`, byte-identical, without building the
    pymavlink message (the FC's answer on every lockstep step; see fast_pack)."""
    return fast_pack(mav, "HIL_ACTUATOR_CONTROLS", _actuator_controls_args(time_usec, cmd, limits, armed))


def decode_actuator_controls(msg: Any, limits: Any) -> ActuatorControls:
    """SI command from a HIL_ACTUATOR_CONTROLS (limits: ActuatorLimits or VehicleConfig)."""
    lim = _limits(limits)
    c = msg.controls
    return ActuatorControls(
        time_usec=int(msg.time_usec),
        tilt_rad=(c[0] * lim.tilt_max_abs_rad, c[1] * lim.tilt_max_abs_rad),
        speed_rad_s=(c[2] * lim.duct_speed_max_rad_s, c[3] * lim.tail_speed_max_rad_s, c[4] * lim.duct_speed_max_rad_s),
        armed=bool(msg.mode & MODE_FLAG_SAFETY_ARMED),
    )


# ---- the step bundle ------------------------------------------------------------------------------
@dataclass(frozen=True)
class StepBundle:
    """One lockstep step as the FC sees it (float32 precision), sensors measured and noisy."""

    step: int
    time_usec: int
    gyro_frd: Vec3  # rad/s (HIL_SENSOR x/y/zgyro)
    accel_frd: Vec3  # m/s^2 specific force at O (HIL_SENSOR x/y/zacc)
    imu_fresh: bool  # HIL_SENSOR.fields_updated has the accel+gyro bits
    pos_ned: Vec3  # m, motion capture (ODOMETRY x, y, z)
    vel_ned: Vec3  # m/s (ODOMETRY vx, vy, vz)
    quat_wxyz: Vec4  # body FRD -> NED (ODOMETRY q)
    duct_tilt_rad: Vec2  # alpha1, alpha3
    prop_speed_rad_s: Vec3  # w1, w2 (signed), w3
    joint_pos_rad: Vec3
    joint_rate_rad_s: Vec3
    gripper_closed: bool
    truth: Any | None  # the NAVIG8_TRUTH message (for logs only; never for control), None if absent

    @property
    def t_us(self) -> int:
        """Exact simulation time in microseconds."""
        return sim_us_from_time_usec(self.time_usec)

    @property
    def t_s(self) -> float:
        """Simulation time in seconds, as the in-process runner computes it (t_us * 1e-6)."""
        return self.t_us * 1e-6

    def fc_sensors(self) -> Any:
        """The controller core's input (navig8_fc.core.controller.FcSensors)."""
        from navig8_fc.core.controller import FcSensors  # lazy: the bridge never needs the controller

        return FcSensors(
            t_s=self.t_s,
            gyro_frd=self.gyro_frd,
            accel_frd=self.accel_frd,
            pos_ned=self.pos_ned,
            vel_ned=self.vel_ned,
            quat_wxyz=self.quat_wxyz,
            tilt_rad=self.duct_tilt_rad,
            speed_rad_s=self.prop_speed_rad_s,
            joint_pos_rad=self.joint_pos_rad,
            joint_rate_rad_s=self.joint_rate_rad_s,
        )


def _f(v: Any) -> list[float]:
    # a list passes as it is (Plant.sense_wire / truth_wire already give Python floats); numpy's tolist() yields
    # Python floats ~5x faster than a comprehension over the array
    if type(v) is list:
        return v
    return v.tolist() if hasattr(v, "tolist") else [float(x) for x in v]


def _bundle_args(step: int, sensors: Any, truth: Any) -> list[tuple[str, tuple[Any, ...]]]:
    """(message name, constructor arguments) of the five messages of step `step`, in datagram order."""
    consts = _BUNDLE_CONSTS or _bundle_consts()
    tu = int(sensors.time_us) + 1  # time_usec_from_sim_us
    g = _f(sensors.gyro_frd)
    a = _f(sensors.accel_frd)
    p = _f(sensors.pos_ned)
    v = _f(sensors.vel_ned)
    out: list[tuple[str, tuple[Any, ...]]] = [
        ("ODOMETRY", (
            tu, consts[0], consts[0], p[0], p[1], p[2], _f(sensors.quat_wxyz),
            v[0], v[1], v[2],
            # ODOMETRY's body rates: the gyro (motion capture has no rate of its own); the same numbers as HIL_SENSOR
            g[0], g[1], g[2],
            _COV_UNKNOWN, _COV_UNKNOWN, 0, consts[1], 0,
        )),
        ("NAVIG8_ACTUATOR_STATE", (tu, step, _f(sensors.duct_tilt_rad), _f(sensors.prop_speed_rad_s))),
        ("NAVIG8_ARM_STATE", (
            tu, step, _f(sensors.joint_pos_rad), _f(sensors.joint_rate_rad_s), 1 if sensors.gripper_closed else 0,
        )),
    ]
    if truth is not None:
        out.append(("NAVIG8_TRUTH", _truth_args(step, truth)))
    imu_fresh = bool(int(getattr(sensors, "updated", 1)) & 1)  # SensorField.IMU = 1
    out.append(("HIL_SENSOR", (
        tu, a[0], a[1], a[2], g[0], g[1], g[2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        HIL_SENSOR_ACCEL_GYRO if imu_fresh else 0, 0,
    )))
    return out


_BUNDLE_CONSTS: tuple[int, int] | None = None  # MAV_FRAME_LOCAL_NED, MAV_ESTIMATOR_TYPE_MOCAP


def _bundle_consts() -> tuple[int, int]:
    global _BUNDLE_CONSTS
    d = dialect.load()
    _BUNDLE_CONSTS = (d.MAV_FRAME_LOCAL_NED, d.MAV_ESTIMATOR_TYPE_MOCAP)
    return _BUNDLE_CONSTS


def bundle_messages(step: int, sensors: Any, truth: Any) -> list[Any]:
    """The five messages of step `step` in datagram order, from a plant SensorBundle and Truth (duck-typed)."""
    d = dialect.load()
    return [d.mavlink_map[getattr(d, f"MAVLINK_MSG_ID_{name}")](*args)
            for name, args in _bundle_args(step, sensors, truth)]


def _truth_args(step: int, truth: Any) -> tuple[Any, ...]:
    j = truth.inertia_com_kgm2
    j0, j1, j2 = j[0], j[1], j[2]
    inertia = [float(j0[0]), float(j1[1]), float(j2[2]), float(j0[1]), float(j0[2]), float(j1[2])]
    return (
        int(truth.time_us) + 1, step,  # time_usec_from_sim_us
        _f(truth.pos_ned_m), _f(truth.vel_ned_m_s), _f(truth.quat_wxyz), _f(truth.rate_frd_rad_s),
        _f(truth.accel_frd_m_s2), _f(truth.actuator_pos), _f(truth.joint_pos_rad), _f(truth.joint_rate_rad_s),
        _f(truth.joint_accel_rad_s2), float(truth.object_mass_kg), float(truth.mass_kg), _f(truth.com_frd_m),
        inertia, _f(truth.reaction_force_frd_n), _f(truth.reaction_moment_mount_frd_nm),
        int(truth.cmd_clamped_count) & 0xFFFFFFFF, int(truth.cmd_nonfinite_count) & 0xFFFFFFFF,
    )


def truth_message(step: int, truth: Any) -> Any:
    """NAVIG8_TRUTH from a plant Truth (duck-typed)."""
    return dialect.load().MAVLink_navig8_truth_message(*_truth_args(step, truth))


def pack(mav: Any, msgs: Iterable[Any]) -> bytes:
    """Frames of msgs back to back, one sequence number each (msg.pack alone does not advance mav.seq)."""
    out = bytearray()
    for m in msgs:
        out += m.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        mav.total_packets_sent += 1
    mav.total_bytes_sent += len(out)
    return bytes(out)


def encode_bundle(mav: Any, step: int, sensors: Any, truth: Any) -> bytes:
    """The step datagram (bytes) for `step` from the plant's SensorBundle and Truth (or anything with their
    attributes: Plant.sense_wire / truth_wire give them as plain float lists, the bridge's fast path).

    Byte-identical to `pack(mav, bundle_messages(...))` (tests/unit/test_seam_fast.py), without building
    pymavlink message objects (see `fast_pack`); mav's sequence number and counters advance as there.
    """
    if _codecs is None:
        _codec_table()
    codecs = _codecs_by_name
    seq, sysid, compid = mav.seq, mav.srcSystem, mav.srcComponent
    hdr = _V2_HEADER_NO_MAGIC.pack
    parts = []
    for name, args in _bundle_args(step, sensors, truth):
        c = codecs[name]
        payload = c.pack_args(args).rstrip(b"\0") or b"\0"
        body = hdr(len(payload), 0, 0, seq, sysid, compid, c.msg_id_lo, c.msg_id_hi) + payload
        parts += (b"\xfd", body, _crc16(body + c.crc_extra_byte).to_bytes(2, "little"))
        seq = (seq + 1) % 256
    out = b"".join(parts)
    mav.seq = seq
    mav.total_packets_sent += len(parts) // 3
    mav.total_bytes_sent += len(out)
    return out


class BundleAssembler:
    """Collects the parts of a step bundle; HIL_SENSOR completes it.

    Parts are keyed by time_usec, so a stray part of another step never mixes into a bundle. A HIL_SENSOR
    whose ODOMETRY / ACTUATOR_STATE / ARM_STATE with the same stamp did not arrive yields nothing and
    counts in `incomplete` (NAVIG8_TRUTH is optional).
    """

    _PARTS = ("ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "NAVIG8_TRUTH")

    def __init__(self) -> None:
        self._parts: dict[str, Any] = {}
        self.incomplete = 0

    def clear(self) -> None:
        """Forget collected parts (a whole bundle arrived by another path)."""
        self._parts.clear()

    def add(self, msg: Any) -> StepBundle | None:
        name = msg.get_type()
        if name in self._PARTS:
            self._parts[name] = msg
            return None
        if name != "HIL_SENSOR" or getattr(msg, "id", 0) != 0:
            return None
        tu = msg.time_usec
        parts = {k: m for k, m in self._parts.items() if m.time_usec == tu}
        self._parts.clear()
        odom = parts.get("ODOMETRY")
        act = parts.get("NAVIG8_ACTUATOR_STATE")
        arm = parts.get("NAVIG8_ARM_STATE")
        if odom is None or act is None or arm is None:
            self.incomplete += 1
            return None
        return StepBundle(
            step=int(act.step),
            time_usec=int(tu),
            gyro_frd=(msg.xgyro, msg.ygyro, msg.zgyro),
            accel_frd=(msg.xacc, msg.yacc, msg.zacc),
            imu_fresh=(msg.fields_updated & HIL_SENSOR_ACCEL_GYRO) == HIL_SENSOR_ACCEL_GYRO,
            pos_ned=(odom.x, odom.y, odom.z),
            vel_ned=(odom.vx, odom.vy, odom.vz),
            quat_wxyz=tuple(odom.q),  # type: ignore[arg-type]
            duct_tilt_rad=tuple(act.duct_tilt),  # type: ignore[arg-type]
            prop_speed_rad_s=tuple(act.prop_speed),  # type: ignore[arg-type]
            joint_pos_rad=tuple(arm.joint_pos),  # type: ignore[arg-type]
            joint_rate_rad_s=tuple(arm.joint_rate),  # type: ignore[arg-type]
            gripper_closed=bool(arm.gripper_closed),
            truth=parts.get("NAVIG8_TRUTH"),
        )


def decode_bundle(msgs: Iterable[Any]) -> StepBundle | None:
    """The StepBundle in one datagram's messages (None if it holds no complete bundle)."""
    asm = BundleAssembler()
    out = None
    for m in msgs:
        b = asm.add(m)
        if b is not None:
            out = b
    return out


def decode_sensors(msgs: Mapping[str, Any] | Iterable[Any]) -> Any:
    """navig8_fc.core.controller.FcSensors from one bundle's messages (a name -> message mapping or any iterable).

    t_s is the exact simulation time (StepBundle.t_s). Raises ValueError when HIL_SENSOR, ODOMETRY,
    NAVIG8_ACTUATOR_STATE or NAVIG8_ARM_STATE with the bundle's stamp is missing.
    """
    ms = list(msgs.values()) if isinstance(msgs, Mapping) else list(msgs)
    # parts first, the trigger last, whatever order the caller kept them in
    ms.sort(key=lambda m: m.get_type() == "HIL_SENSOR")
    b = decode_bundle(ms)
    if b is None:
        raise ValueError("incomplete step bundle (HIL_SENSOR, ODOMETRY, NAVIG8_ACTUATOR_STATE, NAVIG8_ARM_STATE)")
    return b.fc_sensors()


def truth_record(msg: Any) -> dict[str, Any]:
    """A NAVIG8_TRUTH message as the /truth record of tools/sim.py (the keys navig8-plot and the summary read).

    Not on the wire, so absent here: ang_accel, the reaction moment about O and the no-gravity variants.
    """
    q = [float(v) for v in msg.quat]
    roll, pitch, yaw = quat_to_euler(q)
    act = [float(v) for v in msg.actuators]
    return {
        "pos_ned_m": list(msg.pos_ned),
        "vel_ned_m_s": list(msg.vel_ned),
        "quat_wxyz": q,
        "euler_rad": [roll, pitch, yaw],
        "rate_frd_rad_s": list(msg.rate_frd),
        "accel_frd_m_s2": list(msg.accel_frd),
        "tilt_rad": act[:2],
        "speed_rad_s": act[2:],
        "joint_pos_rad": list(msg.joint_pos),
        "joint_rate_rad_s": list(msg.joint_rate),
        "joint_accel_rad_s2": list(msg.joint_accel),
        "object_mass_kg": float(msg.object_mass),
        "mass_kg": float(msg.mass),
        "com_frd_m": list(msg.com_frd),
        "inertia_diag_kgm2": list(msg.inertia[:3]),
        # Headline reaction wrench (Fig. 10): about the mount, gravity included.
        "reaction_force_mount_n": list(msg.reaction_force),
        "reaction_torque_mount_nm": list(msg.reaction_moment_mount),
        "cmd_nonfinite_count": int(msg.cmd_nonfinite),
        "cmd_clamped_count": int(msg.cmd_clamped),
    }


# ---- fast frame codec -----------------------------------------------------------------------------
# pymavlink builds a message object per frame and packs / parses it field by field (~35 us per bundle to
# pack, ~40 us to decode). The seam's own messages take a shorter path with the same bytes: the generated
# classes' precompiled Structs (`unpacker`), their field order (`orders`, `lengths`) and CRC_EXTRA, the
# MAVLink 2 header and trailing-zero truncation exactly as MAVLink_message._pack does, and the CRC with
# fastcrc's mcrf4xx as pymavlink uses it. Anything else falls back to pymavlink.
_V2_HEADER = struct.Struct("<BBBBBBBHB")
_V2_HEADER_NO_MAGIC = struct.Struct("<BBBBBBHB")  # the header after the magic byte (what the CRC covers)
_CRC = struct.Struct("<H")
_FAST_MESSAGES = ("ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "NAVIG8_TRUTH", "HIL_SENSOR",
                  "HIL_ACTUATOR_CONTROLS", "NAVIG8_ARM_CMD", "NAVIG8_SIM_STATUS")


def _crc16(data: bytes) -> int:
    return _mcrf4xx(data, 0xFFFF)


try:  # the same CRC pymavlink uses when fastcrc is installed
    from fastcrc.crc16 import mcrf4xx as _mcrf4xx
except ImportError:  # pragma: no cover - pymavlink's own (slower) CRC
    def _crc16(data: bytes) -> int:  # type: ignore[no-redef]
        return dialect.load().x25crc(data).crc


class _MsgCodec:
    """Wire layout of one message class, from the generated class's metadata (fieldnames, ordered_fieldnames,
    array_lengths, lengths, crc_extra, unpacker): `pack_args` packs constructor-order arguments into the
    untruncated payload exactly as the class's pack() does; `from_wire` turns the unpacked tuple back into
    field name -> value dict (arrays as lists) as MAVLink.decode sets the fields."""

    __slots__ = ("cls", "msg_id", "name", "crc_extra", "struct", "size", "pack_args", "from_wire", "fieldnames",
                 "crc_extra_byte", "msg_id_lo", "msg_id_hi")

    def __init__(self, cls: Any) -> None:
        self.cls = cls
        self.msg_id = int(cls.id)
        self.name = str(cls.msgname)
        self.crc_extra = int(cls.crc_extra)
        self.crc_extra_byte = bytes((self.crc_extra,))
        self.msg_id_lo, self.msg_id_hi = self.msg_id & 0xFFFF, self.msg_id >> 16
        self.struct = cls.unpacker
        self.size = cls.unpacker.size
        if "s" in cls.unpacker.format or "c" in cls.unpacker.format:
            raise ValueError(f"{self.name}: char fields are not supported by the fast codec")
        fieldnames = list(cls.fieldnames)
        self.fieldnames = fieldnames
        pack_terms: list[str] = []
        start: dict[str, tuple[int, int]] = {}
        pos = 0
        for j, fname in enumerate(cls.ordered_fieldnames):
            i = fieldnames.index(fname)
            n = int(cls.array_lengths[j])  # lengths and array_lengths are in wire order, like ordered_fieldnames
            if int(cls.lengths[j]) != max(n, 1):
                raise ValueError(f"{self.name}.{fname}: lengths and array_lengths disagree")
            # an array's first n elements, unpacked (as pymavlink's pack indexes them; faster than n subscripts)
            pack_terms.append(f"*a[{i}][:{n}]" if n else f"a[{i}]")
            start[fname] = (pos, n)
            pos += max(n, 1)
        wire_terms = []
        for fname in fieldnames:
            p, n = start[fname]
            wire_terms.append(f"{fname!r}: list(t[{p}:{p + n}])" if n else f"{fname!r}: t[{p}]")
        self.pack_args = eval(f"lambda a, _p=_p: _p({', '.join(pack_terms)})", {"_p": cls.unpacker.pack})
        self.from_wire = eval(f"lambda t: {{{', '.join(wire_terms)}}}", {})


def frame_v2(payload: bytes, msg_id: int, crc_extra: int, seq: int, sysid: int, compid: int) -> bytes:
    """A MAVLink 2 frame (unsigned) as MAVLink_message._pack writes it: trailing zeros stripped (>= 1 byte)."""
    payload = payload.rstrip(b"\0") or payload[:1]
    body = _V2_HEADER_NO_MAGIC.pack(len(payload), 0, 0, seq, sysid, compid, msg_id & 0xFFFF, msg_id >> 16) + payload
    return b"\xfd" + body + _CRC.pack(_crc16(body + bytes((crc_extra,))))


_codecs: dict[int, _MsgCodec] | None = None
_codecs_by_name: dict[str, _MsgCodec] = {}


_header_class: Any = None
_header_new = object.__new__


def _codec_table() -> dict[int, _MsgCodec]:
    global _codecs, _header_class
    if _codecs is None:
        d = dialect.load()
        _header_class = d.MAVLink_header
        table = {}
        for name in _FAST_MESSAGES:
            cls = d.mavlink_map[getattr(d, f"MAVLINK_MSG_ID_{name}")]
            c = _MsgCodec(cls)
            table[c.msg_id] = c
            _codecs_by_name[c.name] = c
        _codecs = table
    return _codecs


def _codec(name: str) -> _MsgCodec:
    _codec_table()
    return _codecs_by_name[name]


def fast_pack(mav: Any, name: str, args: Sequence[Any]) -> bytes:
    """One frame of message `name` from its constructor arguments (all of them, in the class's fieldnames order),
    byte-identical to `cls(*args).pack(mav)`; advances mav.seq and its counters as `pack` does."""
    c = _codecs_by_name.get(name) or _codec(name)
    fr = frame_v2(c.pack_args(args), c.msg_id, c.crc_extra, mav.seq, mav.srcSystem, mav.srcComponent)
    mav.seq = (mav.seq + 1) % 256
    mav.total_packets_sent += 1
    mav.total_bytes_sent += len(fr)
    return fr


def _frame_at(data: bytes, i: int) -> tuple[_MsgCodec, dict[str, Any], int] | None:
    """(codec, fields as MAVLink.decode sets them, end offset) of the unsigned MAVLink 2 frame of a seam message
    that starts at data[i] and lies wholly in data with a valid CRC; None otherwise. The one frame check of
    fast_decode, frame_fields and decode_step_datagram."""
    n = len(data)
    if i + 12 > n or data[i] != 253 or data[i + 2] != 0:
        return None
    end = i + 12 + data[i + 1]
    if end > n:
        return None
    c = (_codecs or _codec_table()).get(data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16))
    if c is None or _crc16(data[i + 1 : end - 2] + c.crc_extra_byte) != (data[end - 2] | (data[end - 1] << 8)):
        return None
    payload = data[i + 10 : end - 2]
    if len(payload) < c.size:
        payload += bytes(c.size - len(payload))
    return c, c.from_wire(c.struct.unpack(payload[: c.size])), end


def fast_decode(frame: bytes | bytearray) -> Any | None:
    """The pymavlink message object of one MAVLink 2 frame of a seam message, or None when the fast path does not
    apply (another message id, MAVLink 1, signed, a length that disagrees with the header, a bad CRC): the caller
    then decodes with pymavlink, which counts and reports the frame as before.

    The object is an instance of the generated class with the same fields, header, CRC and buffers as
    MAVLink.decode would give it, built without running the class constructor.
    """
    frame = bytes(frame)
    got = _frame_at(frame, 0)
    if got is None or got[2] != len(frame):
        return None
    c, state, _ = got
    cls = c.cls
    m = cls.__new__(cls)
    buf = bytearray(frame)
    crc = frame[-2] | (frame[-1] << 8)
    header = _header_new(_header_class)
    header.__dict__ = {"mlen": frame[1], "seq": frame[4], "srcSystem": frame[5], "srcComponent": frame[6],
                       "msgId": c.msg_id, "incompat_flags": 0, "compat_flags": frame[3]}
    state.update(
        _header=header, _payload=buf[6:-2], _msgbuf=buf, _crc=crc, _fieldnames=cls.fieldnames, _type=c.name,
        _signed=False, _link_id=None, _instances=None, _instance_field=cls.instance_field,
        _instance_offset=cls.instance_offset,
    )
    m.__dict__ = state
    return m


# ---- datagram parsing -----------------------------------------------------------------------------
@dataclass(frozen=True)
class ParsedDatagram:
    messages: list[Any]  # decoded messages of ids this dialect knows, in order
    bad: int  # malformed frames, bad CRCs, unknown ids and trailing partial bytes (0 for a clean datagram)


def _parse_fast(data: bytes) -> list[Any] | None:
    """The messages of a datagram made only of whole, valid seam frames; None for anything else."""
    msgs = []
    i, n = 0, len(data)
    while i < n:
        if data[i] != 253 or i + 2 > n:
            return None
        end = i + 12 + data[i + 1]
        if end > n:
            return None
        m = fast_decode(data[i:end])
        if m is None:
            return None
        msgs.append(m)
        i = end
    return msgs


def parse_datagram(mav: Any, data: bytes) -> ParsedDatagram:
    """Decode one UDP datagram; never raises.

    A datagram of whole, valid seam frames (the usual case) takes the fast path (`fast_decode`); anything else
    goes through pymavlink, which counts its bad frames. The parser state is reset first: UDP preserves
    datagram boundaries, so a truncated frame at the end of one datagram must not swallow the start of the
    next (pymavlink's parser is a byte stream parser).
    """
    if mav.signing.secret_key is None:
        fast = _parse_fast(data)
        if fast is not None:
            mav.total_packets_received += len(fast)
            mav.total_bytes_received += len(data)
            return ParsedDatagram(fast, 0)
    d = dialect.load()
    mav.buf = bytearray()
    mav.buf_index = 0
    mav.expected_length = d.HEADER_LEN_V1 + 2
    mav.have_prefix_error = False
    msgs: list[Any] = []
    bad = 0
    try:
        got = mav.parse_buffer(data) or []
    except Exception:  # robust_parsing should prevent this; a parser bug must not kill a process
        return ParsedDatagram([], 1)
    for m in got:
        t = m.get_type()
        if t == "BAD_DATA" or t.startswith("UNKNOWN"):
            bad += 1
        else:
            msgs.append(m)
    if mav.buf_len() > 0:
        bad += 1
    return ParsedDatagram(msgs, bad)


# ---- arm command ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class ArmCommand:
    """NAVIG8_ARM_CMD in SI: joint targets (None: unchanged) and a gripper action (GRIPPER_*)."""

    time_usec: int
    joint_target_rad: Vec3 | None
    gripper: int = GRIPPER_NONE

    def __post_init__(self) -> None:
        if self.gripper not in (GRIPPER_NONE, GRIPPER_GRAB, GRIPPER_RELEASE):
            raise ValueError(f"gripper must be 0 (none), 1 (grab) or 2 (release), got {self.gripper}")


def encode_arm_cmd(cmd: ArmCommand) -> Any:
    d = dialect.load()
    valid = cmd.joint_target_rad is not None
    q = [float(v) for v in cmd.joint_target_rad] if cmd.joint_target_rad is not None else [0.0, 0.0, 0.0]
    return d.MAVLink_navig8_arm_cmd_message(int(cmd.time_usec), q, 1 if valid else 0, int(cmd.gripper))


def decode_arm_cmd(msg: Any) -> ArmCommand:
    """ArmCommand from NAVIG8_ARM_CMD; raises ValueError on an unknown gripper action."""
    q = tuple(float(v) for v in msg.joint_target) if msg.joint_target_valid else None
    return ArmCommand(int(msg.time_usec), q, int(msg.gripper))  # type: ignore[arg-type]


def arm_command_from_mav_cmd(time_usec: int, params: Sequence[float]) -> ArmCommand | None:
    """ArmCommand from MAV_CMD_NAVIG8_ARM_JOINTS (= MAV_CMD_USER_1) params 1-4: q1-q3 in degrees, apply flag.

    None when param4 is 0 (ignore). ValueError (the FC answers DENIED with the reason) when param4 is
    neither 0 nor 1 or a target is not finite. Joint limits are the plant's to enforce (clamped, counted).
    """
    p = [float(v) for v in params[:4]]
    if len(p) < 4:
        raise ValueError("MAV_CMD_NAVIG8_ARM_JOINTS needs params 1-4")
    if p[3] == 0.0:
        return None
    if p[3] != 1.0:
        raise ValueError(f"param4 must be 0 (ignore) or 1 (apply), got {p[3]}")
    if not all(math.isfinite(v) for v in p[:3]):
        raise ValueError("joint targets must be finite")
    return ArmCommand(int(time_usec), (math.radians(p[0]), math.radians(p[1]), math.radians(p[2])))


# ---- simulation status ----------------------------------------------------------------------------
@dataclass(frozen=True)
class SimStatus:
    time_usec: int
    step: int
    state: int  # SIM_STATE_*
    speed: float  # requested: 1 real time, N x, 0 as fast as possible
    rtf: float  # measured real-time factor since stepping began
    stall_count: int


def encode_sim_status(st: SimStatus) -> Any:
    d = dialect.load()
    return d.MAVLink_navig8_sim_status_message(
        int(st.time_usec), int(st.step) & 0xFFFFFFFF, int(st.state), float(st.speed), float(st.rtf),
        int(st.stall_count) & 0xFFFFFFFF,
    )


def decode_sim_status(msg: Any) -> SimStatus:
    return SimStatus(int(msg.time_usec), int(msg.step), int(msg.state), float(msg.speed), float(msg.rtf),
                     int(msg.stall_count))


__all__ = [
    "GRIPPER_GRAB",
    "GRIPPER_NONE",
    "GRIPPER_RELEASE",
    "HIL_SENSOR_ACCEL_GYRO",
    "MODE_FLAG_SAFETY_ARMED",
    "SIM_STATE_DONE",
    "SIM_STATE_RUNNING",
    "SIM_STATE_STALLED",
    "SIM_STATE_WAITING_FOR_FC",
    "ActuatorControls",
    "ActuatorLimits",
    "ArmCommand",
    "BundleAssembler",
    "ParsedDatagram",
    "SimStatus",
    "StepBundle",
    "arm_command_from_mav_cmd",
    "bundle_messages",
    "decode_actuator_controls",
    "decode_arm_cmd",
    "decode_bundle",
    "decode_sensors",
    "decode_sim_status",
    "encode_actuator_controls",
    "encode_arm_cmd",
    "encode_bundle",
    "encode_sim_status",
    "fast_decode",
    "fast_pack",
    "frame_v2",
    "pack",
    "parse_datagram",
    "sim_us_from_time_usec",
    "time_usec_from_sim_us",
    "truth_message",
]


# ---- the FC's direct path for a whole step datagram -------------------------------------------------------------
class TruthFields:
    """The fields of a NAVIG8_TRUTH frame as attributes (what truth_record and the log read), without the
    pymavlink message object decode_step_datagram skips building."""

    def __init__(self, fields: dict[str, Any]) -> None:
        self.__dict__.update(fields)

    def get_type(self) -> str:
        return "NAVIG8_TRUTH"


_BUNDLE_ORDER = ("ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "NAVIG8_TRUTH", "HIL_SENSOR")


def decode_step_datagram(data: bytes) -> tuple[StepBundle, int, dict[str, dict[str, Any]]] | None:
    """(StepBundle, number of frames, {message name: fields}) of a clean step datagram as encode_bundle writes
    it, or None. The fields are each message's as MAVLink.decode sets them (arrays as lists): the log's
    decoded /mavlink/sim/in/<NAME> channels.

    Clean: only whole, unsigned MAVLink 2 frames with valid CRCs, in the bridge's order (ODOMETRY,
    NAVIG8_ACTUATOR_STATE, NAVIG8_ARM_STATE, NAVIG8_TRUTH optional, HIL_SENSOR), all with the same time_usec.
    Anything else (a status message, a stray part, garbage) gives None and the caller decodes frame by frame,
    counting what is wrong as before. The result equals BundleAssembler's for the same frames (the truth as
    TruthFields instead of a message object; tests/unit/test_seam_fast.py). ~3x cheaper than fast_decode per
    frame plus the assembler: this runs for every lockstep step."""
    fields: dict[str, dict[str, Any]] = {}
    i, n, k = 0, len(data), 0
    while i < n:
        got = _frame_at(data, i)
        if got is None:
            return None
        c, f, i = got
        name = c.name
        while k < 5 and _BUNDLE_ORDER[k] != name:
            if k != 3:  # only the truth may be missing
                return None
            k += 1
        if k == 5:
            return None
        k += 1
        fields[name] = f
    if k != 5:
        return None
    odom, act, arm, sens = (fields["ODOMETRY"], fields["NAVIG8_ACTUATOR_STATE"], fields["NAVIG8_ARM_STATE"],
                            fields["HIL_SENSOR"])
    tu = sens["time_usec"]
    truth = fields.get("NAVIG8_TRUTH")
    if (sens["id"] != 0 or odom["time_usec"] != tu or act["time_usec"] != tu or arm["time_usec"] != tu
            or (truth is not None and truth["time_usec"] != tu)):
        return None
    bundle = StepBundle(
        step=int(act["step"]),
        time_usec=int(tu),
        gyro_frd=(sens["xgyro"], sens["ygyro"], sens["zgyro"]),
        accel_frd=(sens["xacc"], sens["yacc"], sens["zacc"]),
        imu_fresh=(sens["fields_updated"] & HIL_SENSOR_ACCEL_GYRO) == HIL_SENSOR_ACCEL_GYRO,
        pos_ned=(odom["x"], odom["y"], odom["z"]),
        vel_ned=(odom["vx"], odom["vy"], odom["vz"]),
        quat_wxyz=tuple(odom["q"]),  # type: ignore[arg-type]
        duct_tilt_rad=tuple(act["duct_tilt"]),  # type: ignore[arg-type]
        prop_speed_rad_s=tuple(act["prop_speed"]),  # type: ignore[arg-type]
        joint_pos_rad=tuple(arm["joint_pos"]),  # type: ignore[arg-type]
        joint_rate_rad_s=tuple(arm["joint_rate"]),  # type: ignore[arg-type]
        gripper_closed=bool(arm["gripper_closed"]),
        truth=TruthFields(truth) if truth is not None else None,
    )
    return bundle, len(fields), fields


def frame_fields(frame: bytes) -> tuple[str, dict[str, Any]] | None:
    """(message name, fields as MAVLink.decode sets them) of one clean MAVLink 2 frame of a seam message, or
    None (another id, signed, bad length or CRC). The log's decoded form of the FC's answer, without building
    the pymavlink object."""
    got = _frame_at(frame, 0)
    return None if got is None or got[2] != len(frame) else (got[0].name, got[1])


def wire_class(name: str) -> Any:
    """The generated pymavlink class of a seam message (for its JSON schema in the log)."""
    return (_codecs_by_name.get(name) or _codec(name)).cls
