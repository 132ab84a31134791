"""PX4's simulator interface as the FC's sensor source (docs/hil.md, "PX4 simulator messages"). Pure: no I/O.

PX4's `simulator_mavlink` takes HIL_SENSOR (the IMU; the sample with id 0 steps lockstep), HIL_GPS and
HIL_STATE_QUATERNION (which PX4 itself only logs as ground truth) and answers HIL_ACTUATOR_CONTROLS. Navig8's FC
has no GNSS/INS estimator: it flies on the IMU plus a pose, which here is HIL_STATE_QUATERNION read as motion
capture, projected to local NED around the FC's global origin (ORIGIN_*; PX4's flat-earth projection,
navig8_fc.mission.geo). What is required and what is optional:

- required: HIL_SENSOR (id 0: the step's trigger and time stamp; gyro, accel) and HIL_STATE_QUATERNION (attitude,
  position lat/lon/alt, velocity; the newest one at or before the HIL_SENSOR's stamp);
- optional: HIL_GPS (accepted and counted; not used for control: it carries no attitude, and the state message
  has the same position at a higher rate), NAVIG8_ACTUATOR_STATE (measured tilts and rotor speeds) and
  NAVIG8_ARM_STATE (joints, gripper) with the HIL_SENSOR's stamp. Without actuator measurements the FC feeds
  its own commands through the actuator model the stability analysis uses (second order, ACT_WN, ACT_ZETA;
  Eq. 10), exactly discretised for the control period; without arm measurements the joints are taken at their
  commanded targets, at rest.

Resolution on the wire: lat/lon in 1e-7 deg (~1.1 cm north), alt in mm, velocity in cm/s, against float32 in
the private bundle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from navig8_fc.core.actuator_model import ActuatorModel  # the FC's model (core), re-exported here
from navig8_fc.mavlink.codec import SEAM_MESSAGES, Message
from navig8_fc.mavlink.seam import StepBundle
from navig8_fc.mission.geo import GeoOrigin

# What the sim link decodes in PX4 mode: the seam's messages plus PX4's two (HIL_SENSOR is in both)
PX4_SIM_MESSAGES = (*SEAM_MESSAGES, "HIL_STATE_QUATERNION", "HIL_GPS")
IMU_FIELDS = 0b111  # HIL_SENSOR.fields_updated: x/y/z accel
GYRO_FIELDS = 0b111000  # x/y/z gyro


def ned_from_global(origin: GeoOrigin, lat_e7: int, lon_e7: int, alt_mm: int) -> tuple[float, float, float]:
    """Local NED (m) of a MAVLink position (degE7, degE7, mm AMSL): the inverse of GeoOrigin.to_global."""
    n, e = origin.to_ned_xy(lat_e7 * 1e-7, lon_e7 * 1e-7)
    return n, e, origin.alt_amsl_m - alt_mm * 1e-3


@dataclass
class Px4SimCounters:
    bundles: int = 0  # HIL_SENSOR id 0 turned into a step
    no_pose: int = 0  # HIL_SENSOR dropped: no HIL_STATE_QUATERNION (or HIL_GPS) yet
    other_imu: int = 0  # HIL_SENSOR with id != 0 (a second IMU: ignored, as PX4 steps on id 0)
    gps: int = 0
    states: int = 0
    modelled_actuators: int = 0  # steps whose actuator states came from the model
    measured_actuators: int = 0


@dataclass
class Px4SimAssembler:
    """Messages in, StepBundle out on every HIL_SENSOR id 0 (see the module docstring). `commanded` is what the
    FC sent last (tilts, speeds, joint targets): the model's input and the joints' stand-in."""

    origin: GeoOrigin
    model: ActuatorModel
    joint_target_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    counters: Px4SimCounters = field(default_factory=Px4SimCounters)
    _state: Message | None = None
    _act: Message | None = None
    _arm: Message | None = None
    _command: tuple[float, ...] | None = None
    completed: dict = field(default_factory=dict)

    def command(self, tilt_rad: Sequence[float], speed_rad_s: Sequence[float]) -> None:
        """The command the FC answered with (held by the simulator until the next step: the model's input)."""
        self._command = (*tilt_rad, *speed_rad_s)

    def add(self, m: Message) -> StepBundle | None:
        name = m.name
        if name == "HIL_STATE_QUATERNION":
            self._state = m
            self.counters.states += 1
        elif name == "HIL_GPS":
            self.counters.gps += 1
        elif name == "NAVIG8_ACTUATOR_STATE":
            self._act = m
        elif name == "NAVIG8_ARM_STATE":
            self._arm = m
        elif name == "HIL_SENSOR":
            return self._bundle(m)
        return None

    def _bundle(self, imu_msg: Message) -> StepBundle | None:
        c = self.counters
        imu = imu_msg.fields
        if imu["id"] != 0:
            c.other_imu += 1
            return None
        t_us = int(imu["time_usec"])
        if self._state is None:
            c.no_pose += 1
            return None
        st = self._state.fields
        pos = ned_from_global(self.origin, st["lat"], st["lon"], st["alt"])
        vel = (st["vx"] * 0.01, st["vy"] * 0.01, st["vz"] * 0.01)
        quat = tuple(float(q) for q in st["attitude_quaternion"])
        if self._command is not None:
            modelled = self.model.step(self._command)
        else:
            modelled = self.model.positions
        act = self._act.fields if self._act is not None and self._act.fields["time_usec"] == t_us else None
        if act is not None:
            tilt, speed = tuple(act["duct_tilt"]), tuple(act["prop_speed"])
            c.measured_actuators += 1
        else:
            tilt, speed = modelled[:2], modelled[2:]
            c.modelled_actuators += 1
        arm = self._arm.fields if self._arm is not None and self._arm.fields["time_usec"] == t_us else None
        if arm is not None:
            jp, jr, grip = tuple(arm["joint_pos"]), tuple(arm["joint_rate"]), bool(arm["gripper_closed"])
        else:
            jp, jr, grip = self.joint_target_rad, (0.0, 0.0, 0.0), False
        fresh = (imu["fields_updated"] & (IMU_FIELDS | GYRO_FIELDS)) == (IMU_FIELDS | GYRO_FIELDS)
        c.bundles += 1
        self.completed = {"HIL_SENSOR": imu_msg, "HIL_STATE_QUATERNION": self._state}
        return StepBundle(c.bundles - 1, t_us, (imu["xgyro"], imu["ygyro"], imu["zgyro"]),
                          (imu["xacc"], imu["yacc"], imu["zacc"]), fresh, pos, vel, quat,  # type: ignore[arg-type]
                          tilt, speed, jp, jr, grip, None)  # type: ignore[arg-type]

    @property
    def incomplete(self) -> int:
        """HIL_SENSOR samples that made no step (no pose yet), as BundleAssembler.incomplete counts."""
        return self.counters.no_pose


__all__ = ["PX4_SIM_MESSAGES", "ActuatorModel", "Px4SimAssembler", "Px4SimCounters", "ned_from_global"]
