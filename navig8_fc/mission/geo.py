"""WGS-84 <-> local NED around the configured global origin: PX4's flat-earth (equirectangular) projection with
Earth radius 6 371 000 m (CONSTANTS_RADIUS_OF_EARTH): lat = lat0 + n/R, lon = lon0 + e/(R cos lat0),
alt_amsl = alt0 - d. Over the few metres this vehicle flies the error is far below a millimetre. Telemetry
(GLOBAL_POSITION_INT, HOME_POSITION) projects one way, mission items in global frames the other."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

EARTH_RADIUS_M = 6_371_000.0  # PX4 CONSTANTS_RADIUS_OF_EARTH


@dataclass(frozen=True)
class GeoOrigin:
    """WGS-84 position of the NED origin (default: Calgary, 1100 m AMSL)."""

    lat_deg: float = 51.0789
    lon_deg: float = -114.1339
    alt_amsl_m: float = 1100.0

    def to_global(self, pos_ned_m: Sequence[float]) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt AMSL m) of a NED point, flat earth (module docstring)."""
        n, e, d = pos_ned_m
        lat = self.lat_deg + math.degrees(n / EARTH_RADIUS_M)
        lon = self.lon_deg + math.degrees(e / (EARTH_RADIUS_M * math.cos(math.radians(self.lat_deg))))
        return lat, lon, self.alt_amsl_m - d

    def to_ned_xy(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        """North, east (m) of a WGS-84 point: the inverse of `to_global`'s horizontal part."""
        n = math.radians(lat_deg - self.lat_deg) * EARTH_RADIUS_M
        e = math.radians(lon_deg - self.lon_deg) * EARTH_RADIUS_M * math.cos(math.radians(self.lat_deg))
        return n, e


def origin_from_params(values: Mapping[str, float]) -> GeoOrigin:
    """The global origin from ORIGIN_LAT_E7 / ORIGIN_LON_E7 / ORIGIN_ALT (a parameter registry or a snapshot)."""
    return GeoOrigin(int(values["ORIGIN_LAT_E7"]) * 1e-7, int(values["ORIGIN_LON_E7"]) * 1e-7,
                     float(values["ORIGIN_ALT"]))
