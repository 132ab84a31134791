"""Rally points and where Return goes (pure): PX4's RTL_TYPE 0 rule (navigator/rtl.cpp, `RTL::findRtlDestination`,
`findClosestSafePoint`, `extractValidSafePointPosition`; docs/research/mavsdk_examples.md section 3).

- The rally plan's NAV_RALLY_POINT items are positions in local NED (`rally_positions`): x/y around the global
  origin, z above home (GLOBAL_RELATIVE_ALT[_INT]) or AMSL (GLOBAL[_INT]). A point at "null island" (both
  |lat| and |lon| below 1e-12 deg, i.e. x = y = 0 in degE7) is skipped, as PX4 does.
- `return_destination`: start with home at the vehicle's horizontal distance to it; a rally point more than
  `HOME_EXCLUSION_M` (10 m, MAX_DIST_FROM_HOME_FOR_LAND_APPROACHES) from home replaces the best so far when it is
  closer to the vehicle by more than `MIN_GAIN_M` (2 m, MIN_DIST_THRESHOLD). Distances are horizontal (PX4's
  get_distance_to_next_waypoint), in the flat-earth projection the vehicle flies in (navig8_fc.mission.geo).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import GLOBAL_FRAMES, RELATIVE_ALT_FRAMES, Cmd, Plan

Vec3 = tuple[float, float, float]
HOME_EXCLUSION_M = 10.0  # PX4 MAX_DIST_FROM_HOME_FOR_LAND_APPROACHES: closer rally points are not used
MIN_GAIN_M = 2.0  # PX4 MIN_DIST_THRESHOLD: a rally point must be this much closer than the best so far


class RallyPoint(NamedTuple):
    seq: int  # the item's index in the rally plan
    pos_ned_m: Vec3


class Destination(NamedTuple):
    seq: int  # the rally point's item index; -1: home
    pos_ned_m: Vec3

    @property
    def is_home(self) -> bool:
        return self.seq < 0


def rally_positions(plan: Plan | None, origin: GeoOrigin, home_ned_m: Vec3) -> tuple[RallyPoint, ...]:
    """The plan's usable rally points in local NED (module docstring)."""
    if plan is None:
        return ()
    out = []
    for seq, it in enumerate(plan.items):
        if it.command != Cmd.NAV_RALLY_POINT or it.frame not in GLOBAL_FRAMES or (it.x == 0 and it.y == 0):
            continue
        n, e = origin.to_ned_xy(it.x * 1e-7, it.y * 1e-7)
        d = home_ned_m[2] - it.z if it.frame in RELATIVE_ALT_FRAMES else origin.alt_amsl_m - it.z
        if math.isfinite(n) and math.isfinite(e) and math.isfinite(d):
            out.append(RallyPoint(seq, (n, e, d)))
    return tuple(out)


def _horizontal(a: Vec3, b: Vec3) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


def return_destination(here: Vec3, home_ned_m: Vec3, points: tuple[RallyPoint, ...]) -> Destination:
    """Where Return goes from `here`: home or the closest usable rally point (RTL_TYPE 0, module docstring)."""
    best = Destination(-1, home_ned_m)
    best_d = _horizontal(here, home_ned_m)
    for p in points:
        if _horizontal(home_ned_m, p.pos_ned_m) <= HOME_EXCLUSION_M:
            continue
        d = _horizontal(here, p.pos_ned_m)
        if d + MIN_GAIN_M < best_d:
            best, best_d = Destination(p.seq, p.pos_ned_m), d
    return best
