"""MAV_CMD_INJECT_FAILURE as PX4 SITL answers it: DENIED unless SYS_FAILURE_EN is 1 (PX4's MavlinkReceiver), then
the failures the simulation can make. docs/gcs.md, "Failure injection".

- FAILURE_UNIT_SENSOR_GPS (p1 4), instance (p3) 0 (all) or 1: type OFF (p2 1) takes the global position source
  away, type OK (p2 0) gives it back; ACCEPTED, as PX4's simulator answers for its GPS. This vehicle's "GPS" is the
  global position source (motion capture + the origin; docs/gcs.md "SYS_STATUS sensor bits"): while off,
  GPS_RAW_INT reports no fix and no satellites and SYS_STATUS's GPS bit is unhealthy (MAVSDK's
  is_global_position_ok is false), and a vehicle in the air lands where it is, as PX4 descends when GPS loss
  leaves it without a position ("GPS lost (failure injected): landing"). The controller keeps flying on the
  motion-capture position meanwhile: the simulator has no GPS-free estimator to fall back on.
- Other types of the GPS, other instances, every other unit (the gyro, accelerometer, magnetometer, barometer,
  motors, ...): UNSUPPORTED with the reason, as PX4's simulator answers a failure it does not simulate. The duct
  fault of the simulator (docs/plant.md) is a world setting chosen at start, not a command.
Pure: the caller gives the parameter, the vehicle's state and a way to land.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

MAV_RESULT_ACCEPTED, MAV_RESULT_DENIED, MAV_RESULT_UNSUPPORTED = 0, 2, 3
FAILURE_UNIT_SENSOR_GPS = 4
FAILURE_TYPE_OK, FAILURE_TYPE_OFF = 0, 1


class FailureInjection:
    """The failures injected so far (module docstring)."""

    def __init__(self, enabled: Callable[[], bool], flying: Callable[[], bool],
                 land: Callable[[], tuple[bool, str]]) -> None:
        """enabled(): SYS_FAILURE_EN is 1; flying(): armed and in the air; land(): the Land command's verdict."""
        self._enabled, self._flying, self._land = enabled, flying, land
        self.gps_off = False

    def command(self, params: Sequence[float]) -> tuple[int, str | None, str | None]:
        """(MAV_RESULT, reason (WARNING), event (INFO)) for INJECT_FAILURE p1 unit, p2 type, p3 instance."""
        if not self._enabled():
            return MAV_RESULT_DENIED, "INJECT_FAILURE denied: set SYS_FAILURE_EN to 1", None
        unit, kind, instance = (int(round(v)) if math.isfinite(v) else -1 for v in params[:3])
        if unit != FAILURE_UNIT_SENSOR_GPS:
            return MAV_RESULT_UNSUPPORTED, f"INJECT_FAILURE: failure unit {unit} is not simulated (GPS only)", None
        if instance not in (0, 1) or kind not in (FAILURE_TYPE_OK, FAILURE_TYPE_OFF):
            return MAV_RESULT_UNSUPPORTED, (f"INJECT_FAILURE: GPS {instance} type {kind} is not simulated "
                                            "(instance 0 or 1, OK or OFF)"), None
        if kind == FAILURE_TYPE_OK:
            self.gps_off = False
            return MAV_RESULT_ACCEPTED, None, "GPS restored (failure injection)"
        self.gps_off = True
        if not self._flying():
            return MAV_RESULT_ACCEPTED, None, "GPS off (failure injected)"
        ok, why = self._land()
        return MAV_RESULT_ACCEPTED, None, ("GPS lost (failure injected): landing" if ok else
                                           f"GPS lost (failure injected): landing refused: {why}")


__all__ = ["FailureInjection"]
