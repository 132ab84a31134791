"""The geofence as the flight stack checks it: the uploaded FENCE plan's inclusion circles and polygons (projected
around the global origin into NED) plus the FENCE_RADIUS / FENCE_ALT_MAX parameters around home. Pure.

A position breaches the fence when it is outside any inclusion zone (each circle and polygon must contain it, as
PX4 treats several inclusion zones when its GF_PREDICT is off: the vehicle must stay inside all of them), farther
than FENCE_RADIUS from home horizontally, or higher than FENCE_ALT_MAX above home (0 turns a limit off).
Point-in-polygon: the even-odd ray-casting rule in the N-E plane."""

from __future__ import annotations

import math
from dataclasses import dataclass

from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Cmd, Plan

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Fence:
    circles: tuple[tuple[Vec2, float], ...] = ()  # (centre N, E), radius m
    polygons: tuple[tuple[Vec2, ...], ...] = ()

    @staticmethod
    def from_plan(plan: Plan, origin: GeoOrigin) -> Fence:
        circles: list[tuple[Vec2, float]] = []
        polygons: list[tuple[Vec2, ...]] = []
        i, items = 0, plan.items
        while i < len(items):
            it = items[i]
            if it.command == Cmd.NAV_FENCE_CIRCLE_INCLUSION:
                circles.append((origin.to_ned_xy(it.x * 1e-7, it.y * 1e-7), it.param1))
                i += 1
            elif it.command == Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION:
                n = int(it.param1)
                polygons.append(tuple(origin.to_ned_xy(v.x * 1e-7, v.y * 1e-7) for v in items[i:i + n]))
                i += n
            else:
                i += 1
        return Fence(tuple(circles), tuple(polygons))

    def breach(self, pos_ned: Vec3, home_ned: Vec3, radius_m: float, alt_max_m: float) -> str | None:
        """Why pos_ned is outside the fence (None: inside)."""
        n, e, d = pos_ned
        if alt_max_m > 0.0 and home_ned[2] - d > alt_max_m:
            return f"{home_ned[2] - d:.1f} m above home (max {alt_max_m:g} m)"
        if radius_m > 0.0 and math.hypot(n - home_ned[0], e - home_ned[1]) > radius_m:
            return f"{math.hypot(n - home_ned[0], e - home_ned[1]):.1f} m from home (max {radius_m:g} m)"
        for (cn, ce), r in self.circles:
            if math.hypot(n - cn, e - ce) > r:
                return f"outside the inclusion circle of {r:g} m"
        for poly in self.polygons:
            if not _inside(poly, n, e):
                return "outside the inclusion polygon"
        return None


def _inside(poly: tuple[Vec2, ...], n: float, e: float) -> bool:
    inside = False
    j = len(poly) - 1
    for i in range(len(poly)):
        (ni, ei), (nj, ej) = poly[i], poly[j]
        if (ei > e) != (ej > e) and n < (nj - ni) * (e - ei) / (ej - ei) + ni:
            inside = not inside
        j = i
    return inside
