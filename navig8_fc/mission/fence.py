"""The geofence as the flight stack checks it: the uploaded FENCE plan's inclusion and exclusion circles and polygons
(projected around the global origin into NED) plus the FENCE_RADIUS / FENCE_ALT_MAX parameters around home. Pure.

A position breaches the fence when it is outside any inclusion zone (each circle and polygon must contain it, as
PX4 treats several inclusion zones when its GF_PREDICT is off: the vehicle must stay inside all of them), inside an
exclusion zone, farther than FENCE_RADIUS from home horizontally, or higher than FENCE_ALT_MAX above home (0 turns
a limit off). As PX4's `Geofence::_updateFence` (it drops them with "Geofence invalid, doesn't contain Home
position"), a zone on the wrong side of home is not enforced: an inclusion zone that does not contain home, an
exclusion zone that does (MAVSDK's geofence example always adds an empty circle at 0, 0). Point-in-polygon: the
even-odd ray-casting rule in the N-E plane."""

from __future__ import annotations

import math
from dataclasses import dataclass

from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import FENCE_CIRCLE_COMMANDS, FENCE_POLYGON_COMMANDS, Cmd, Plan

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]


_EXCLUSION = frozenset({Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION})


@dataclass(frozen=True)
class Fence:
    circles: tuple[tuple[Vec2, float], ...] = ()  # inclusion: (centre N, E), radius m
    polygons: tuple[tuple[Vec2, ...], ...] = ()  # inclusion
    exclusion_circles: tuple[tuple[Vec2, float], ...] = ()
    exclusion_polygons: tuple[tuple[Vec2, ...], ...] = ()

    @staticmethod
    def from_plan(plan: Plan, origin: GeoOrigin) -> Fence:
        zones: dict[tuple[bool, bool], list] = {(c, x): [] for c in (True, False) for x in (True, False)}
        i, items = 0, plan.items
        while i < len(items):
            it = items[i]
            excl = it.command in _EXCLUSION
            if it.command in FENCE_CIRCLE_COMMANDS:
                zones[True, excl].append((origin.to_ned_xy(it.x * 1e-7, it.y * 1e-7), it.param1))
                i += 1
            elif it.command in FENCE_POLYGON_COMMANDS:
                n = int(it.param1)
                zones[False, excl].append(tuple(origin.to_ned_xy(v.x * 1e-7, v.y * 1e-7) for v in items[i:i + n]))
                i += n
            else:  # NAV_FENCE_RETURN_POINT: stored, not used
                i += 1
        return Fence(tuple(zones[True, False]), tuple(zones[False, False]), tuple(zones[True, True]),
                     tuple(zones[False, True]))

    @property
    def has_zones(self) -> bool:
        return bool(self.circles or self.polygons or self.exclusion_circles or self.exclusion_polygons)

    def breach(self, pos_ned_m: Vec3, home_ned_m: Vec3, radius_m: float, alt_max_m: float) -> str | None:
        """Why pos_ned_m is outside the fence (None: inside). Zones on the wrong side of home are not enforced."""
        n, e, d = pos_ned_m
        hn, he = home_ned_m[0], home_ned_m[1]
        if alt_max_m > 0.0 and home_ned_m[2] - d > alt_max_m:
            return f"{home_ned_m[2] - d:.1f} m above home (max {alt_max_m:g} m)"
        if radius_m > 0.0 and math.hypot(n - hn, e - he) > radius_m:
            return f"{math.hypot(n - hn, e - he):.1f} m from home (max {radius_m:g} m)"
        for (cn, ce), r in self.circles:
            if math.hypot(n - cn, e - ce) > r and math.hypot(hn - cn, he - ce) <= r:
                return f"outside the inclusion circle of {r:g} m"
        for poly in self.polygons:
            if not _inside(poly, n, e) and _inside(poly, hn, he):
                return "outside the inclusion polygon"
        for (cn, ce), r in self.exclusion_circles:
            if math.hypot(n - cn, e - ce) < r and math.hypot(hn - cn, he - ce) >= r:
                return f"inside the exclusion circle of {r:g} m"
        for poly in self.exclusion_polygons:
            if _inside(poly, n, e) and not _inside(poly, hn, he):
                return "inside the exclusion polygon"
        return None

    def zones_not_enforced(self, home_ned_m: Vec3) -> int:
        """How many zones are on the wrong side of home (for the operator's notice)."""
        hn, he = home_ned_m[0], home_ned_m[1]
        return (sum(math.hypot(hn - cn, he - ce) > r for (cn, ce), r in self.circles)
                + sum(not _inside(p, hn, he) for p in self.polygons)
                + sum(math.hypot(hn - cn, he - ce) < r for (cn, ce), r in self.exclusion_circles)
                + sum(_inside(p, hn, he) for p in self.exclusion_polygons))


def _inside(poly: tuple[Vec2, ...], n: float, e: float) -> bool:
    inside = False
    j = len(poly) - 1
    for i in range(len(poly)):
        (ni, ei), (nj, ej) = poly[i], poly[j]
        if (ei > e) != (ej > e) and n < (nj - ni) * (e - ei) / (ej - ei) + ni:
            inside = not inside
        j = i
    return inside
