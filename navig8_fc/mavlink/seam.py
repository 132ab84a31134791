"""The bridge <-> flight-controller lockstep seam: the contracts of what crosses it (docs/bridge.md).

Both processes import this module, so the meaning of the wire lives in one place; the bytes are the codec's
(`navig8_fc.mavlink.codec`). Messages go out as records `(name, values in field order)` and come back as
`codec.Message` records (name, field names and values; `.fields` the dict):

- bridge -> FC, once per step k: ONE UDP datagram holding, in this order, ODOMETRY, NAVIG8_ACTUATOR_STATE,
  NAVIG8_ARM_STATE, NAVIG8_TRUTH and HIL_SENSOR (last: the FC's trigger). `bundle_records` maps the plant's
  SensorBundle and Truth to them, `encode_bundle` packs the datagram; `BundleAssembler` / `decode_bundle`
  turn received messages back into a `StepBundle`.
- FC -> bridge, exactly one per bundle: HIL_ACTUATOR_CONTROLS whose time_usec echoes the bundle's
  (`actuator_controls_record` / `pack_actuator_controls`, `decode_actuator_controls`: the five channels
  normalised by `ControlsScale`).
- FC -> bridge, any time: NAVIG8_ARM_CMD (`encode_arm_cmd` / `decode_arm_cmd`, `arm_command_from_mav_cmd`
  for the GCS's MAV_CMD_NAVIG8_ARM_JOINTS in degrees); HEARTBEAT at start (the FC announces itself, so a
  bridge that does not know the FC's port learns it from the datagram's source).
- bridge -> FC, >= 1 Hz wall and at the end: NAVIG8_SIM_STATUS (`encode_sim_status` / `decode_sim_status`).

Time: time_usec = t_sim_us + 1 (`time_usec_from_sim_us`), so step 0 is never stamped 0 (a zero stamp
means "unset" to many MAVLink consumers and desynchronised PX4's lockstep, PR #13390); the FC recovers
the exact simulation time with `sim_us_from_time_usec` (StepBundle.t_s).

No sockets or clocks here. Floats cross the wire as float32 (MAVLink has no float64 fields for these), which
is the only numerical difference between a SITL run and the in-process runner.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from operator import itemgetter
from typing import Any, NamedTuple, Protocol

from navig8_fc.mavlink import dialect
from navig8_fc.mavlink.codec import Encoder, Message, seam_codec

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
Record = tuple[str, Sequence[Any]]  # (message name, field values in the message's field order)

_NAN = float("nan")
# ODOMETRY covariances: "If unknown, assign NaN value to first element in the array" (common.xml).
_COV_UNKNOWN = (_NAN,) + (0.0,) * 20


def time_usec_from_sim_us(t_sim_us: int) -> int:
    """Wire stamp of plant time t_sim_us (never 0)."""
    return int(t_sim_us) + 1


def sim_us_from_time_usec(time_usec: int) -> int:
    """Plant time (us) of a wire stamp."""
    return int(time_usec) - 1


# ---- actuator answer ------------------------------------------------------------------------------
@dataclass(frozen=True)
class ControlsScale:
    """Normalisation of HIL_ACTUATOR_CONTROLS: controls = value / limit (so |controls| <= 1 in range)."""

    tilt_max_abs_rad: float  # max(|tilt_min|, |tilt_max|): controls[0], controls[1]
    duct_speed_max_rad_s: float  # controls[2], controls[4] (0..1)
    tail_speed_max_rad_s: float  # controls[3] (signed, -1..1)

    def __post_init__(self) -> None:
        for name in ("tilt_max_abs_rad", "duct_speed_max_rad_s", "tail_speed_max_rad_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"ControlsScale.{name} must be finite and > 0, got {v}")

    @staticmethod
    def from_vehicle(vehicle: Any) -> ControlsScale:
        """From a navig8_fc.core.vehicle.VehicleConfig (duck-typed: tilt_min/max_rad, *_speed_max)."""
        return _limits_from(float(vehicle.tilt_min_rad), float(vehicle.tilt_max_rad), float(vehicle.duct_speed_max),
                            float(vehicle.tail_speed_min), float(vehicle.tail_speed_max))


@functools.lru_cache(maxsize=16)
def _limits_from(tilt_min: float, tilt_max: float, duct_max: float, tail_min: float, tail_max: float
                 ) -> ControlsScale:
    # memoised: the FC passes its VehicleConfig with every answer (validation would cost ~1 us of each step)
    return ControlsScale(tilt_max_abs_rad=max(abs(tilt_min), abs(tilt_max)), duct_speed_max_rad_s=duct_max,
                          tail_speed_max_rad_s=max(abs(tail_max), abs(tail_min)))


def _limits(limits_or_vehicle: Any) -> ControlsScale:
    if isinstance(limits_or_vehicle, ControlsScale):
        return limits_or_vehicle
    return ControlsScale.from_vehicle(limits_or_vehicle)


class HasActuators(Protocol):
    """Any actuator command: navig8_fc.core.controller.ActuatorCommand, sim_bridge.ActuatorCommand."""

    @property
    def tilt_rad(self) -> Sequence[float]: ...

    @property
    def speed_rad_s(self) -> Sequence[float]: ...


class ActuatorControls(NamedTuple):
    """A decoded HIL_ACTUATOR_CONTROLS in SI units.

    Immutable like the seam's frozen dataclasses, but a NamedTuple: the bridge makes one every lockstep step, and
    a frozen dataclass's __init__ (one object.__setattr__ per field) costs ~1 us of the ~170 us step."""

    time_usec: int  # echo of the bundle's stamp
    tilt_rad: Vec2  # alpha1 (right), alpha3 (left)
    speed_rad_s: Vec3  # w1 (right duct), w2 (tail, signed), w3 (left duct)
    armed: bool


def actuator_controls_record(time_usec: int, cmd: HasActuators, limits: Any, *, armed: bool) -> Record:
    """HIL_ACTUATOR_CONTROLS answering the bundle stamped time_usec (limits: ControlsScale or VehicleConfig).

    Values are divided by the limits but not clipped: the plant clamps and counts out-of-range commands,
    which would be hidden if the encoder clipped them. Non-finite values pass through (the plant holds).
    """
    lim = _limits(limits)
    t, s = cmd.tilt_rad, cmd.speed_rad_s
    controls = (float(t[0]) / lim.tilt_max_abs_rad, float(t[1]) / lim.tilt_max_abs_rad,
                float(s[0]) / lim.duct_speed_max_rad_s, float(s[1]) / lim.tail_speed_max_rad_s,
                float(s[2]) / lim.duct_speed_max_rad_s) + (0.0,) * 11
    # fields: time_usec, controls[16], mode, flags
    return "HIL_ACTUATOR_CONTROLS", (int(time_usec), controls, MODE_FLAG_SAFETY_ARMED if armed else 0, 0)


def pack_actuator_controls(enc: Encoder, time_usec: int, cmd: HasActuators, limits: Any, *, armed: bool) -> bytes:
    """The frame of actuator_controls_record(...) from `enc` (the FC's answer on every lockstep step)."""
    return enc.frame(*actuator_controls_record(time_usec, cmd, limits, armed=armed))


def decode_actuator_controls(fields: Mapping[str, Any], limits: Any) -> ActuatorControls:
    """SI command from HIL_ACTUATOR_CONTROLS fields (limits: ControlsScale or VehicleConfig)."""
    lim = _limits(limits)
    c = fields["controls"]
    return ActuatorControls(
        time_usec=int(fields["time_usec"]),
        tilt_rad=(c[0] * lim.tilt_max_abs_rad, c[1] * lim.tilt_max_abs_rad),
        speed_rad_s=(c[2] * lim.duct_speed_max_rad_s, c[3] * lim.tail_speed_max_rad_s, c[4] * lim.duct_speed_max_rad_s),
        armed=bool(fields["mode"] & MODE_FLAG_SAFETY_ARMED),
    )


# ---- the step bundle ------------------------------------------------------------------------------
class StepBundle(NamedTuple):
    """One lockstep step as the FC sees it (float32 precision), sensors measured and noisy.

    Immutable like the seam's frozen dataclasses, but a NamedTuple: the FC makes one every lockstep step, and a
    frozen dataclass's __init__ (one object.__setattr__ per field) costs ~2 us of the ~170 us step."""

    step: int
    time_usec: int
    gyro_frd_rad_s: Vec3  # HIL_SENSOR x/y/zgyro
    accel_frd_m_s2: Vec3  # specific force at O (HIL_SENSOR x/y/zacc)
    imu_fresh: bool  # HIL_SENSOR.fields_updated has the accel+gyro bits
    pos_ned_m: Vec3  # motion capture (ODOMETRY x, y, z)
    vel_ned_m_s: Vec3  # ODOMETRY vx, vy, vz
    quat_wxyz: Vec4  # body FRD -> NED (ODOMETRY q)
    duct_tilt_rad: Vec2  # alpha1, alpha3
    prop_speed_rad_s: Vec3  # w1, w2 (signed), w3
    joint_pos_rad: Vec3
    joint_rate_rad_s: Vec3
    gripper_closed: bool
    # NAVIG8_TRUTH (for logs only; never for control), None if absent
    truth: TruthFloats | None = None
    # NAVIG8_ACTUATOR_STATE.cmd_time_usec: the stamp whose answer drove the actuators up to this sample (0: unknown)
    cmd_time_usec: int = 0

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
            gyro_frd_rad_s=self.gyro_frd_rad_s,
            accel_frd_m_s2=self.accel_frd_m_s2,
            pos_ned_m=self.pos_ned_m,
            vel_ned_m_s=self.vel_ned_m_s,
            quat_wxyz=self.quat_wxyz,
            duct_tilt_rad=self.duct_tilt_rad,
            prop_speed_rad_s=self.prop_speed_rad_s,
            joint_pos_rad=self.joint_pos_rad,
            joint_rate_rad_s=self.joint_rate_rad_s,
            gripper_closed=self.gripper_closed,
            # a stamp older than this sample's: the command's age on the link; else unknown (the last one flown)
            cmd_applied_t_s=(sim_us_from_time_usec(self.cmd_time_usec) * 1e-6
                             if 0 < self.cmd_time_usec < self.time_usec else None),
        )


class TruthFloats:
    """The plant's ground truth (sim_bridge.messages.Truth: the same names, units and numbers) as plain Python floats
    in lists, the inertia about the CoM as three rows: what NAVIG8_TRUTH carries (the bridge encodes it from
    Plant.truth_floats) and what /truth logs in both processes (navig8_fc.logrecords.log_truth_record). Decoded
    from NAVIG8_TRUTH (truth_floats_of_message, the FC's side) the quantities the wire does not carry are None.
    Not frozen; made fresh for every step (attributes, no __init__: the plant fills it from its state)."""

    time_us: int
    pos_ned_m: Sequence[float]
    vel_ned_m_s: Sequence[float]
    quat_wxyz: Sequence[float]
    rate_frd_rad_s: Sequence[float]
    accel_frd_m_s2: Sequence[float]  # absolute acceleration of O, body axes
    ang_accel_frd_rad_s2: Sequence[float] | None
    actuator_pos: Sequence[float]  # alpha1, alpha3 (rad), w1, w2, w3 (rad/s)
    joint_pos_rad: Sequence[float]
    joint_rate_rad_s: Sequence[float]
    joint_accel_rad_s2: Sequence[float]
    object_mass_kg: float
    mass_kg: float
    com_frd_m: Sequence[float]
    inertia_com_kgm2: tuple[Sequence[float], Sequence[float], Sequence[float]]
    reaction_force_frd_n: Sequence[float]  # the headline: at the mount, gravity included
    reaction_moment_mount_frd_nm: Sequence[float]
    reaction_moment_o_frd_nm: Sequence[float] | None
    reaction_force_nog_frd_n: Sequence[float] | None
    reaction_moment_mount_nog_frd_nm: Sequence[float] | None
    cmd_nonfinite_count: int
    cmd_clamped_count: int


def truth_floats_of_message(f: Mapping[str, Any]) -> TruthFloats:
    """A decoded NAVIG8_TRUTH's fields (codec.Message.fields) as TruthFloats."""
    xx, yy, zz, xy, xz, yz = f["inertia"]  # tensor entries about the composite CoM
    t = TruthFloats()
    t.time_us = sim_us_from_time_usec(f["time_usec"])
    t.pos_ned_m, t.vel_ned_m_s, t.quat_wxyz = f["pos_ned"], f["vel_ned"], f["quat"]
    t.rate_frd_rad_s, t.accel_frd_m_s2, t.ang_accel_frd_rad_s2 = f["rate_frd"], f["accel_frd"], None
    t.actuator_pos = f["actuators"]
    t.joint_pos_rad, t.joint_rate_rad_s, t.joint_accel_rad_s2 = f["joint_pos"], f["joint_rate"], f["joint_accel"]
    t.object_mass_kg, t.mass_kg, t.com_frd_m = f["object_mass"], f["mass"], f["com_frd"]
    t.inertia_com_kgm2 = ((xx, xy, xz), (xy, yy, yz), (xz, yz, zz))
    t.reaction_force_frd_n, t.reaction_moment_mount_frd_nm = f["reaction_force"], f["reaction_moment_mount"]
    t.reaction_moment_o_frd_nm = t.reaction_force_nog_frd_n = t.reaction_moment_mount_nog_frd_nm = None
    t.cmd_nonfinite_count, t.cmd_clamped_count = f["cmd_nonfinite"], f["cmd_clamped"]
    return t


def _f(v: Any) -> Sequence[float]:
    # a list passes as it is (Plant.sense_wire / truth_floats already give Python floats); numpy's tolist() yields
    # Python floats ~5x faster than a comprehension over the array
    if type(v) is list:
        return v
    return v.tolist() if hasattr(v, "tolist") else [float(x) for x in v]


@functools.cache
def _odometry_consts() -> tuple[int, int]:
    """MAV_FRAME_LOCAL_NED, MAV_ESTIMATOR_TYPE_MOCAP of the dialect."""
    d = dialect.load()
    return int(d.MAV_FRAME_LOCAL_NED), int(d.MAV_ESTIMATOR_TYPE_MOCAP)


def bundle_records(step: int, sensors: Any, truth: Any, cmd_time_usec: int = 0) -> list[Record]:
    """The messages of step `step` in datagram order, from the plant's SensorBundle and Truth (or anything with
    their attributes: Plant.sense_wire / truth_floats give them as plain float lists, the bridge's fast path);
    truth None: no NAVIG8_TRUTH. cmd_time_usec: the stamp the answer that drove the actuators over the step just
    ended echoed (NAVIG8_ACTUATOR_STATE.cmd_time_usec; 0: none)."""
    frame_ned, mocap = _odometry_consts()
    tu = int(sensors.time_us) + 1  # time_usec_from_sim_us
    g = _f(sensors.gyro_frd_rad_s)
    a = _f(sensors.accel_frd_m_s2)
    p = _f(sensors.pos_ned_m)
    v = _f(sensors.vel_ned_m_s)
    out: list[Record] = [
        ("ODOMETRY", (
            tu, frame_ned, frame_ned, p[0], p[1], p[2], _f(sensors.quat_wxyz),
            v[0], v[1], v[2],
            # ODOMETRY's body rates: the gyro (motion capture has no rate of its own); the same numbers as HIL_SENSOR
            g[0], g[1], g[2],
            _COV_UNKNOWN, _COV_UNKNOWN, 0, mocap, 0,
        )),
        ("NAVIG8_ACTUATOR_STATE", (tu, step, _f(sensors.duct_tilt_rad), _f(sensors.prop_speed_rad_s),
                                   int(cmd_time_usec))),
        ("NAVIG8_ARM_STATE", (
            tu, step, _f(sensors.joint_pos_rad), _f(sensors.joint_rate_rad_s), 1 if sensors.gripper_closed else 0,
        )),
    ]
    if truth is not None:
        out.append(truth_message_record(step, truth))
    imu_fresh = bool(int(getattr(sensors, "updated", 1)) & 1)  # SensorField.IMU = 1
    out.append(("HIL_SENSOR", (
        tu, a[0], a[1], a[2], g[0], g[1], g[2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        HIL_SENSOR_ACCEL_GYRO if imu_fresh else 0, 0,
    )))
    return out


def truth_message_record(step: int, truth: Any) -> Record:
    """NAVIG8_TRUTH from a plant Truth or TruthFloats (the same names)."""
    j = truth.inertia_com_kgm2
    j0, j1, j2 = j[0], j[1], j[2]
    inertia = (float(j0[0]), float(j1[1]), float(j2[2]), float(j0[1]), float(j0[2]), float(j1[2]))
    return "NAVIG8_TRUTH", (
        int(truth.time_us) + 1, step,  # time_usec_from_sim_us
        _f(truth.pos_ned_m), _f(truth.vel_ned_m_s), _f(truth.quat_wxyz), _f(truth.rate_frd_rad_s),
        _f(truth.accel_frd_m_s2), _f(truth.actuator_pos), _f(truth.joint_pos_rad), _f(truth.joint_rate_rad_s),
        _f(truth.joint_accel_rad_s2), float(truth.object_mass_kg), float(truth.mass_kg), _f(truth.com_frd_m),
        inertia, _f(truth.reaction_force_frd_n), _f(truth.reaction_moment_mount_frd_nm),
        int(truth.cmd_clamped_count) & 0xFFFFFFFF, int(truth.cmd_nonfinite_count) & 0xFFFFFFFF,
    )


def encode_bundle(enc: Encoder, step: int, sensors: Any, truth: Any, cmd_time_usec: int = 0) -> bytes:
    """The step datagram for `step`: the frames of bundle_records(...) back to back, one sequence number each."""
    return enc.frames(bundle_records(step, sensors, truth, cmd_time_usec))


_BUNDLE_PARTS = frozenset(("ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "NAVIG8_TRUTH"))


class BundleAssembler:
    """Collects the parts of a step bundle; HIL_SENSOR completes it.

    Parts are keyed by time_usec, so a stray part of another step never mixes into a bundle. A HIL_SENSOR
    whose ODOMETRY / ACTUATOR_STATE / ARM_STATE with the same stamp did not arrive yields nothing and
    counts in `incomplete` (NAVIG8_TRUTH is optional). `completed` holds the messages of the last bundle
    returned, by name (the FC logs them decoded). Values are read by position (codec.MessageSpec.index): the
    FC assembles on every lockstep step, before its answer; the field dicts are left to the log.
    """

    def __init__(self) -> None:
        self._parts: dict[str, Message] = {}
        self.completed: dict[str, Message] = {}
        self.incomplete = 0
        specs = seam_codec().specs

        def at(name: str, *fields: str) -> Any:
            ix = specs[name].index
            return itemgetter(*(ix[f] for f in fields))

        self._time = {n: specs[n].index["time_usec"] for n in (*_BUNDLE_PARTS, "HIL_SENSOR")}
        self._sensor = at("HIL_SENSOR", "id", "fields_updated")
        self._gyro = at("HIL_SENSOR", "xgyro", "ygyro", "zgyro")
        self._accel = at("HIL_SENSOR", "xacc", "yacc", "zacc")
        self._pos = at("ODOMETRY", "x", "y", "z")
        self._vel = at("ODOMETRY", "vx", "vy", "vz")
        self._quat = specs["ODOMETRY"].index["q"]
        self._act = at("NAVIG8_ACTUATOR_STATE", "step", "duct_tilt", "prop_speed", "cmd_time_usec")
        self._arm = at("NAVIG8_ARM_STATE", "joint_pos", "joint_rate", "gripper_closed")

    def clear(self) -> None:
        """Forget collected parts."""
        self._parts.clear()

    def add(self, msg: Message) -> StepBundle | None:
        name = msg.name
        if name in _BUNDLE_PARTS:
            self._parts[name] = msg
            return None
        if name != "HIL_SENSOR":
            return None
        h = msg.values
        sensor_id, updated = self._sensor(h)
        if sensor_id != 0:
            return None
        t = self._time
        tu = h[t["HIL_SENSOR"]]
        parts, self._parts = self._parts, {}
        odom = parts.get("ODOMETRY")
        act = parts.get("NAVIG8_ACTUATOR_STATE")
        arm = parts.get("NAVIG8_ARM_STATE")
        if (odom is None or act is None or arm is None or odom.values[t["ODOMETRY"]] != tu
                or act.values[t["NAVIG8_ACTUATOR_STATE"]] != tu or arm.values[t["NAVIG8_ARM_STATE"]] != tu):
            self.incomplete += 1
            return None
        truth = parts.get("NAVIG8_TRUTH")
        if truth is not None and truth.values[t["NAVIG8_TRUTH"]] != tu:
            del parts["NAVIG8_TRUTH"]  # a stray truth of another step: not this bundle's (it is optional)
            truth = None
        parts["HIL_SENSOR"] = msg
        self.completed = parts
        o = odom.values
        step, tilt, speed, cmd_tu = self._act(act.values)
        jp, jr, grip = self._arm(arm.values)
        return StepBundle(int(step), int(tu), self._gyro(h), self._accel(h),
                          (updated & HIL_SENSOR_ACCEL_GYRO) == HIL_SENSOR_ACCEL_GYRO, self._pos(o), self._vel(o),
                          o[self._quat], tilt, speed, jp, jr, bool(grip),
                          truth_floats_of_message(truth.fields) if truth is not None else None, int(cmd_tu))


def decode_bundle(msgs: Iterable[Message]) -> StepBundle | None:
    """The last StepBundle completed in a sequence of messages (None if there is none)."""
    asm = BundleAssembler()
    out = None
    for m in msgs:
        b = asm.add(m)
        if b is not None:
            out = b
    return out


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


def encode_arm_cmd(cmd: ArmCommand) -> Record:
    """NAVIG8_ARM_CMD (fields: time_usec, joint_target[3], joint_target_valid, gripper)."""
    valid = cmd.joint_target_rad is not None
    q = tuple(float(v) for v in cmd.joint_target_rad) if cmd.joint_target_rad is not None else (0.0, 0.0, 0.0)
    return "NAVIG8_ARM_CMD", (int(cmd.time_usec), q, 1 if valid else 0, int(cmd.gripper))


def decode_arm_cmd(fields: Mapping[str, Any]) -> ArmCommand:
    """ArmCommand from NAVIG8_ARM_CMD fields; raises ValueError on an unknown gripper action."""
    q = tuple(float(v) for v in fields["joint_target"]) if fields["joint_target_valid"] else None
    return ArmCommand(int(fields["time_usec"]), q, int(fields["gripper"]))  # type: ignore[arg-type]


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


def encode_sim_status(st: SimStatus) -> Record:
    """NAVIG8_SIM_STATUS (fields: time_usec, step, state, speed, rtf, stall_count)."""
    return "NAVIG8_SIM_STATUS", (int(st.time_usec), int(st.step) & 0xFFFFFFFF, int(st.state), float(st.speed),
                                 float(st.rtf), int(st.stall_count) & 0xFFFFFFFF)


def decode_sim_status(fields: Mapping[str, Any]) -> SimStatus:
    return SimStatus(int(fields["time_usec"]), int(fields["step"]), int(fields["state"]), float(fields["speed"]),
                     float(fields["rtf"]), int(fields["stall_count"]))


# ---- announcement ---------------------------------------------------------------------------------
def announce_record() -> Record:
    """The HEARTBEAT the FC sends on the sim link at start: the bridge learns the FC's address from it."""
    d = dialect.load()
    return "HEARTBEAT", (int(d.MAV_TYPE_GENERIC), int(d.MAV_AUTOPILOT_GENERIC), 0, 0, int(d.MAV_STATE_BOOT), 3)




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
    "ControlsScale",
    "ArmCommand",
    "BundleAssembler",
    "Record",
    "SimStatus",
    "StepBundle",
    "actuator_controls_record",
    "announce_record",
    "arm_command_from_mav_cmd",
    "bundle_records",
    "decode_actuator_controls",
    "decode_arm_cmd",
    "decode_bundle",
    "decode_sim_status",
    "encode_arm_cmd",
    "encode_bundle",
    "encode_sim_status",
    "pack_actuator_controls",
    "sim_us_from_time_usec",
    "time_usec_from_sim_us",
    "truth_message_record",
    "TruthFloats",
    "truth_floats_of_message",
]
