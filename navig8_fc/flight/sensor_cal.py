"""The sensor calibration in force, applied to every sensor bundle before the controller sees it: the gyro offsets
(CAL_GYRO0_XOFF/YOFF/ZOFF, rad/s) and the level horizon (SENS_BOARD_X_OFF/Y_OFF, deg), as PX4 applies its
calibration to the IMU. The calibrations that measure them are navig8_fc.gcs.calibration's; docs/gcs.md,
"Calibration". With every value 0 (the defaults) nothing is applied, so a vehicle never calibrated flies the
bundles exactly as they came.

The level offset treats the measured attitude as the sensor board's: the board sits rolled and pitched by the
offsets on the vehicle, so the vehicle's attitude is q_board * conj(q_offset) and the board's vectors (gyro,
specific force) are rotated by q_offset into the vehicle's axes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

from navig8_fc.core.controller import FcSensors
from navig8_fc.core.rotation import euler_to_quat, quat_conj, quat_mul, rotate_body_to_ned

Vec3 = tuple[float, float, float]
GYRO_OFFSET_PARAMS = ("CAL_GYRO0_XOFF", "CAL_GYRO0_YOFF", "CAL_GYRO0_ZOFF")
LEVEL_PARAMS = ("SENS_BOARD_X_OFF", "SENS_BOARD_Y_OFF")


@dataclass(frozen=True)
class SensorCalibration:
    gyro_offset_rad_s: Vec3
    level_roll_rad: float
    level_pitch_rad: float

    @staticmethod
    def from_params(values: Mapping[str, float]) -> SensorCalibration | None:
        """The calibration in the parameters; None when there is nothing to apply (all 0)."""
        gx, gy, gz = (float(values[n]) for n in GYRO_OFFSET_PARAMS)
        roll, pitch = (math.radians(float(values[n])) for n in LEVEL_PARAMS)
        if gx == gy == gz == roll == pitch == 0.0:
            return None
        return SensorCalibration((gx, gy, gz), roll, pitch)

    def apply(self, s: FcSensors) -> FcSensors:
        ox, oy, oz = self.gyro_offset_rad_s
        gyro: Vec3 = (s.gyro_frd_rad_s[0] - ox, s.gyro_frd_rad_s[1] - oy, s.gyro_frd_rad_s[2] - oz)
        if self.level_roll_rad == 0.0 and self.level_pitch_rad == 0.0:
            return dataclasses.replace(s, gyro_frd_rad_s=gyro)
        q_off = euler_to_quat(self.level_roll_rad, self.level_pitch_rad, 0.0)
        q = quat_mul(s.quat_wxyz, quat_conj(q_off))
        return dataclasses.replace(s, gyro_frd_rad_s=rotate_body_to_ned(q_off, gyro),
                                   accel_frd_m_s2=rotate_body_to_ned(q_off, s.accel_frd_m_s2), quat_wxyz=q)
