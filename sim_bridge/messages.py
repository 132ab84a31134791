"""Immutable messages at the plant's seams: the actuator command in, the sensor bundle and the truth out.

NamedTuples (not frozen dataclasses: a frozen dataclass's __init__ pays one object.__setattr__ per field,
~3.5 us for a Truth and ~1.3 us for a SensorBundle, a few percent of a closed-loop step; a NamedTuple is
built in ~1 us and is as immutable). Array fields are read-only numpy views (one fresh buffer per message), so
a message cannot change after it was made. Units and frames are in the field names: body FRD, earth NED, SI,
radians.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import numpy as np


class ActuatorCommand(NamedTuple):
    """Commanded actuator positions (what HIL_ACTUATOR_CONTROLS will carry, in SI units).

    tilt_rad: duct angles (alpha1 right, alpha3 left); speed_rad_s: propeller speeds (w1 right duct,
    w2 tail (signed, reversible), w3 left duct); joint_targets_rad: arm joint targets, or None to follow
    the scenario's arm commands. The plant clamps out-of-range values and holds the last valid value
    for non-finite ones, and counts both (Truth.cmd_clamped_count, Truth.cmd_nonfinite_count).
    """

    tilt_rad: tuple[float, float]
    speed_rad_s: tuple[float, float, float]
    joint_targets_rad: tuple[float, float, float] | None = None

    @staticmethod
    def off() -> ActuatorCommand:
        return ActuatorCommand((0.0, 0.0), (0.0, 0.0, 0.0))


class SensorField(enum.IntFlag):
    """Bits of SensorBundle.updated: which groups were sampled fresh at this time."""

    IMU = 1  # gyro_frd_rad_s, accel_frd_m_s2
    MOCAP = 2  # pos_ned_m, vel_ned_m_s, quat_wxyz
    ACTUATORS = 4  # duct_tilt_rad, prop_speed_rad_s
    JOINTS = 8  # joint_pos_rad, joint_rate_rad_s
    ALL = 15


class SensorBundle(NamedTuple):
    """One sensor sample at time_us (plant time). Groups not in `updated` repeat their last sample."""

    time_us: int
    gyro_frd_rad_s: np.ndarray  # (3,)
    accel_frd_m_s2: np.ndarray  # (3,) specific force a_O - g at O ([0, 0, -g] at rest, level)
    pos_ned_m: np.ndarray  # (3,) motion capture
    vel_ned_m_s: np.ndarray  # (3,) motion capture
    quat_wxyz: np.ndarray  # (4,) body FRD -> NED, motion capture
    duct_tilt_rad: np.ndarray  # (2,) alpha1, alpha3
    prop_speed_rad_s: np.ndarray  # (3,) w1, w2 (tail, signed), w3
    joint_pos_rad: np.ndarray  # (3,)
    joint_rate_rad_s: np.ndarray  # (3,)
    gripper_closed: bool
    updated: int  # SensorField bits

    def is_updated(self, field: SensorField) -> bool:
        return bool(self.updated & field)


class Truth(NamedTuple):
    """Ground truth at time_us for logs and analysis.

    The arm's reaction wrench on the UAV is given about the mount (joint 1) and about O (the UAV's
    own CoM), each with and without gravity (notes §3.4 step 5: F_r = -sum m_k (a_k - g),
    M_r = -sum [(r_k - r_mount) x m_k (a_k - g) + I_k W'_k + W_k x I_k W_k]; "no gravity" drops the g).
    The headline (what docs/plant.md compares with the paper's Fig. 10) is reaction_force_frd_n and
    reaction_moment_mount_frd_nm: the physical joint-1 load, gravity included.
    """

    time_us: int
    # rigid-body state of the UAV (origin O = UAV CoM)
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    quat_wxyz: np.ndarray
    euler_rad: np.ndarray  # roll, pitch, yaw (ZYX)
    rate_frd_rad_s: np.ndarray
    accel_frd_m_s2: np.ndarray  # absolute acceleration of O, body axes
    ang_accel_frd_rad_s2: np.ndarray
    specific_force_frd_m_s2: np.ndarray  # noise-free accelerometer at O
    # actuators (alpha1, alpha3, w1, w2, w3)
    actuator_pos: np.ndarray
    actuator_rate: np.ndarray
    actuator_cmd: np.ndarray  # the command in force, after validation and clamping
    # arm and object
    joint_pos_rad: np.ndarray
    joint_rate_rad_s: np.ndarray
    joint_accel_rad_s2: np.ndarray  # over the current servo period (piecewise constant)
    joint_target_rad: np.ndarray
    object_mass_kg: float
    gripper_closed: bool
    # composite mass properties, UAV + arm + object
    mass_kg: float
    com_frd_m: np.ndarray  # relative to O
    inertia_com_kgm2: np.ndarray  # (3,3) about the composite CoM
    inertia_o_kgm2: np.ndarray  # (3,3) about O
    # reaction wrench of the arm on the UAV (body axes)
    reaction_force_frd_n: np.ndarray  # headline: gravity included
    reaction_moment_mount_frd_nm: np.ndarray  # headline: about the mount, gravity included
    reaction_moment_o_frd_nm: np.ndarray
    reaction_force_nog_frd_n: np.ndarray
    reaction_moment_mount_nog_frd_nm: np.ndarray
    reaction_moment_o_nog_frd_nm: np.ndarray
    # external wrenches (about O, body axes)
    prop_force_frd_n: np.ndarray
    prop_moment_frd_nm: np.ndarray
    contact_force_frd_n: np.ndarray
    contact_moment_frd_nm: np.ndarray
    contact_points_active: int
    # bad-input counters
    cmd_nonfinite_count: int
    cmd_clamped_count: int


class WireSensors:
    """Plant.sense_wire(): a SensorBundle's values as plain Python floats (lists), for the bridge's encoder.

    Same attribute names and numbers as SensorBundle (what navig8_fc.mavlink.seam.encode_bundle reads), without
    the numpy views seam would convert back to floats at once. Not frozen; made fresh for every step.
    """

    time_us: int
    gyro_frd_rad_s: list[float]
    accel_frd_m_s2: list[float]
    pos_ned_m: list[float]
    vel_ned_m_s: list[float]
    quat_wxyz: list[float]
    duct_tilt_rad: list[float]
    prop_speed_rad_s: list[float]
    joint_pos_rad: list[float]
    joint_rate_rad_s: list[float]
    gripper_closed: bool
    updated: int
