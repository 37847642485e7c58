"""Global (WGS-84 latitude, longitude, altitude AMSL) ↔ local NED positions.

The local frame is PX4's: its origin is the estimator's reference point (in SITL, where the
vehicle boots), north-east-down in metres. The mapping is the azimuthal equidistant projection
PX4 uses (``MapProjection``), on a sphere of PX4's Earth radius, so that a waypoint given in
latitude and longitude lands on the same local position as it would on PX4 (to millimetres over
the few kilometres a quadrotor flies).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: PX4's CONSTANTS_RADIUS_OF_EARTH (metres).
EARTH_RADIUS_M = 6_371_000.0

#: PX4 SITL's default location (Zurich, Irchel park): its home unless configured otherwise.
PX4_SITL_ORIGIN = (47.397742, 8.545594, 488.0)


@dataclass(frozen=True, slots=True)
class GlobalOrigin:
    """The global position of the local frame's origin (``alt_amsl_m`` is the origin's
    altitude above mean sea level: local down = ``alt_amsl_m`` − altitude)."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float

    def to_ned(self, lat_deg: float, lon_deg: float, alt_amsl_m: float
               ) -> tuple[float, float, float]:
        """Local NED of a global position."""
        lat0, lon0 = math.radians(self.lat_deg), math.radians(self.lon_deg)
        lat, lon = math.radians(lat_deg), math.radians(lon_deg)
        sin_lat0, cos_lat0 = math.sin(lat0), math.cos(lat0)
        sin_lat, cos_lat = math.sin(lat), math.cos(lat)
        cos_dlon = math.cos(lon - lon0)
        arg = min(max(sin_lat0 * sin_lat + cos_lat0 * cos_lat * cos_dlon, -1.0), 1.0)
        c = math.acos(arg)
        k = 1.0 if abs(c) < 1e-12 else c / math.sin(c)
        north = k * (cos_lat0 * sin_lat - sin_lat0 * cos_lat * cos_dlon) * EARTH_RADIUS_M
        east = k * cos_lat * math.sin(lon - lon0) * EARTH_RADIUS_M
        return north, east, self.alt_amsl_m - alt_amsl_m

    def to_global(self, north_m: float, east_m: float, down_m: float
                  ) -> tuple[float, float, float]:
        """(latitude°, longitude°, altitude AMSL m) of a local NED position."""
        lat0, lon0 = math.radians(self.lat_deg), math.radians(self.lon_deg)
        x, y = north_m / EARTH_RADIUS_M, east_m / EARTH_RADIUS_M
        c = math.hypot(x, y)
        if c < 1e-15:
            return self.lat_deg, self.lon_deg, self.alt_amsl_m - down_m
        sin_c, cos_c = math.sin(c), math.cos(c)
        sin_lat0, cos_lat0 = math.sin(lat0), math.cos(lat0)
        lat = math.asin(cos_c * sin_lat0 + x * sin_c * cos_lat0 / c)
        lon = lon0 + math.atan2(y * sin_c, c * cos_lat0 * cos_c - x * sin_lat0 * sin_c)
        return math.degrees(lat), math.degrees(lon), self.alt_amsl_m - down_m
