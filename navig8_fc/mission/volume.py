"""The operating volume: where a ground station may send the vehicle (docs/gcs.md, "Operating volume"). Mission and
rally items on upload and offboard targets as they arrive are checked against it, whether or not a geofence is
enabled (the fence, off by default, acts in flight; this refuses the target before it is flown):

- horizontally at most VOL_DIST_MAX metres from home;
- at most VOL_ALT_MAX metres above home and at least VOL_ALT_MIN (negative: below home) - a target in the ground,
  or a kilometre up, is refused;
- an offboard velocity of at most VOL_SPEED_MAX m/s;
- a DO_ORBIT circle whole (its centre's distance plus its radius) and its altitude (the FlightStack checks it once
  the orbit is resolved).

Home is the vehicle's home when it has one, else the NED origin (where the simulated vehicle starts). PX4 has the
same idea in GF_MAX_HOR_DIST / GF_MAX_VER_DIST (0 = off there; finite by default here) and refuses a mission whose
first waypoint is further than MIS_DIST_1WP.

Pure: numbers in, a reason out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from navig8_fc.mission.executor import item_position
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import GLOBAL_FRAMES, Cmd, MissionItem, Problem, Result

Vec3 = tuple[float, float, float]

_FULL_POSITION = frozenset({Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_UNLIM, Cmd.NAV_LOITER_TIME, Cmd.NAV_RALLY_POINT})
_ALTITUDE_ONLY = frozenset({Cmd.NAV_TAKEOFF})  # climbs where the vehicle is
_HORIZONTAL_ONLY = frozenset({Cmd.NAV_LAND})  # descends to the ground at x/y


@dataclass(frozen=True)
class OperatingVolume:
    """VOL_* (module docstring)."""

    max_distance_m: float  # VOL_DIST_MAX: horizontal distance from home
    max_altitude_m: float  # VOL_ALT_MAX: height above home
    min_altitude_m: float  # VOL_ALT_MIN: height above home (negative: below)
    max_speed_m_s: float  # VOL_SPEED_MAX: an offboard velocity's magnitude

    @staticmethod
    def from_params(values: Mapping[str, float]) -> OperatingVolume:
        return OperatingVolume(float(values["VOL_DIST_MAX"]), float(values["VOL_ALT_MAX"]),
                               float(values["VOL_ALT_MIN"]), float(values["VOL_SPEED_MAX"]))

    def distance_problem(self, pos_ned_m: Vec3, home_ned_m: Vec3) -> str:
        """Why a position is too far from home horizontally ('' when it is not; NaN x or y: not given)."""
        dist = math.hypot(pos_ned_m[0] - home_ned_m[0], pos_ned_m[1] - home_ned_m[1])
        if math.isnan(dist) or dist <= self.max_distance_m:
            return ""
        return f"{_metres(dist)} from home, beyond VOL_DIST_MAX {self.max_distance_m:g} m"

    def altitude_problem(self, down_m: float, home_ned_m: Vec3) -> str:
        """Why a NED down coordinate is out of the altitude band ('' when it is not; NaN: not given)."""
        above = home_ned_m[2] - down_m
        if math.isnan(above) or self.min_altitude_m <= above <= self.max_altitude_m:
            return ""
        bound = (f"above VOL_ALT_MAX {self.max_altitude_m:g} m" if above > self.max_altitude_m
                 else f"below VOL_ALT_MIN {self.min_altitude_m:g} m")
        return f"{_metres(above)} above home, {bound}"

    def speed_problem(self, vel_ned_m_s: Vec3) -> str:
        """Why a velocity is too fast ('' when it is not; NaN components: not given)."""
        speed = math.sqrt(sum(v * v for v in vel_ned_m_s if not math.isnan(v)))
        if speed <= self.max_speed_m_s:
            return ""
        return f"speed {speed:.3g} m/s beyond VOL_SPEED_MAX {self.max_speed_m_s:g} m/s"

    def orbit_problem(self, centre_ned_m: Vec3, radius_m: float, home_ned_m: Vec3) -> str:
        """Why a circle (DO_ORBIT's) leaves the volume ('' when it does not): its farthest point from home, its
        altitude."""
        d = math.hypot(centre_ned_m[0] - home_ned_m[0], centre_ned_m[1] - home_ned_m[1])
        if d + radius_m > self.max_distance_m:
            return (f"circle reaches {_metres(d + radius_m)} from home (centre {_metres(d)}, radius {radius_m:g} m), "
                    f"beyond VOL_DIST_MAX {self.max_distance_m:g} m")
        return self.altitude_problem(centre_ned_m[2], home_ned_m)

    def target_problem(self, pos_ned_m: Vec3, vel_ned_m_s: Vec3, home_ned_m: Vec3) -> str:
        """Why an offboard target leaves the volume ('' when it does not)."""
        return (self.distance_problem(pos_ned_m, home_ned_m) or self.altitude_problem(pos_ned_m[2], home_ned_m)
                or self.speed_problem(vel_ned_m_s))

    def item_problem(self, item: MissionItem, origin: GeoOrigin, home_ned_m: Vec3) -> Problem | None:
        """Why a mission or rally item's position leaves the volume (None when it does not, or has no position):
        INVALID_PARAM5_X for the distance, INVALID_PARAM7 for the altitude."""
        cmd = item.command
        if cmd not in _FULL_POSITION | _ALTITUDE_ONLY | _HORIZONTAL_ONLY:
            return None
        pos = item_position(item, origin, home_ned_m, (math.nan, math.nan, math.nan))  # x = y = 0: here, unchecked
        name = Cmd(cmd).name
        if cmd not in _ALTITUDE_ONLY and not (item.frame in GLOBAL_FRAMES and item.x == 0 and item.y == 0):
            why = self.distance_problem(pos, home_ned_m)
            if why:
                return Problem(Result.INVALID_PARAM5_X, f"{name}: {why}")
        if cmd not in _HORIZONTAL_ONLY:
            why = self.altitude_problem(pos[2], home_ned_m)
            if why:
                return Problem(Result.INVALID_PARAM7, f"{name}: {why}")
        return None


def _metres(value_m: float) -> str:
    return f"{value_m / 1000:.4g} km" if abs(value_m) >= 10_000 else f"{value_m:.4g} m"


__all__ = ["OperatingVolume"]
