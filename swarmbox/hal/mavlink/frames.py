"""Where a MAVLink vehicle is, in the mission's frame: the one place that converts positions.

- :class:`GeoFrame` maps latitude/longitude/altitude to NED metres around a geodetic point with
  PX4's own azimuthal-equidistant projection (a sphere of 6371 km), so a vehicle's local frame and
  its GNSS agree to the millimetre;
- :class:`VehicleFrame` places one vehicle's local NED frame (PX4's EKF origin, at its spawn point)
  at its home in the mission frame (``initial_positions``) and goes through the mission's geodetic
  origin for GNSS and ground truth.
"""

from __future__ import annotations

import math

from swarmbox.api import Setpoint, SetpointKind

Vec3 = tuple[float, float, float]
EARTH_RADIUS_M = 6371000.0   # PX4's CONSTANTS_RADIUS_OF_EARTH


class GeoFrame:
    """A local NED frame anchored at a geodetic point (PX4's azimuthal-equidistant map projection)."""

    __slots__ = ("lat_deg", "lon_deg", "alt_m", "_lat0", "_lon0", "_sin0", "_cos0")

    def __init__(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        if not (abs(lat_deg) <= 90 and abs(lon_deg) <= 180 and math.isfinite(alt_m)):
            raise ValueError(f"bad geodetic origin ({lat_deg}, {lon_deg}, {alt_m})")
        self.lat_deg, self.lon_deg, self.alt_m = float(lat_deg), float(lon_deg), float(alt_m)
        self._lat0, self._lon0 = math.radians(lat_deg), math.radians(lon_deg)
        self._sin0, self._cos0 = math.sin(self._lat0), math.cos(self._lat0)

    def ned_of(self, lat_deg: float, lon_deg: float, alt_m: float) -> Vec3:
        """Geodetic position (altitude AMSL) -> NED metres in this frame."""
        lat, dlon = math.radians(lat_deg), math.radians(lon_deg) - self._lon0
        sin_lat, cos_lat, cos_dlon = math.sin(lat), math.cos(lat), math.cos(dlon)
        arg = min(1.0, max(-1.0, self._sin0 * sin_lat + self._cos0 * cos_lat * cos_dlon))
        c = math.acos(arg)
        k = c / math.sin(c) if abs(c) > 1e-12 else 1.0
        n = k * (self._cos0 * sin_lat - self._sin0 * cos_lat * cos_dlon) * EARTH_RADIUS_M
        e = k * cos_lat * math.sin(dlon) * EARTH_RADIUS_M
        return (n, e, self.alt_m - alt_m)

    def geodetic_of(self, ned: Vec3) -> tuple[float, float, float]:
        """NED metres in this frame -> (lat_deg, lon_deg, alt_m AMSL)."""
        x, y = ned[0] / EARTH_RADIUS_M, ned[1] / EARTH_RADIUS_M
        c = math.hypot(x, y)
        if c < 1e-15:
            return self.lat_deg, self.lon_deg, self.alt_m - ned[2]
        sin_c, cos_c = math.sin(c), math.cos(c)
        lat = math.asin(cos_c * self._sin0 + x * sin_c * self._cos0 / c)
        lon = self._lon0 + math.atan2(y * sin_c, c * self._cos0 * cos_c - x * self._sin0 * sin_c)
        return math.degrees(lat), math.degrees(lon), self.alt_m - ned[2]


class VehicleFrame:
    """One vehicle's local NED frame, placed at ``home_ned_m`` in the mission frame of ``origin``."""

    __slots__ = ("home_ned_m", "origin")

    def __init__(self, home_ned_m: Vec3, origin: GeoFrame) -> None:
        self.home_ned_m, self.origin = home_ned_m, origin

    def to_mission(self, local_ned_m: Vec3) -> Vec3:
        (n, e, d), (hn, he, hd) = local_ned_m, self.home_ned_m
        return (n + hn, e + he, d + hd)

    def setpoint_to_local(self, sp: Setpoint) -> Setpoint:
        """Positions move to the vehicle's frame; velocities and accelerations are the same vectors."""
        if sp.kind is not SetpointKind.POSITION:
            return sp
        (n, e, d), (hn, he, hd) = sp.ned, self.home_ned_m
        return Setpoint(sp.kind, (n - hn, e - he, d - hd), sp.yaw_rad)

    def geodetic_to_mission(self, lat_deg: float, lon_deg: float, alt_m: float) -> Vec3:
        return self.origin.ned_of(lat_deg, lon_deg, alt_m)

    @property
    def home_alt_m(self) -> float:
        """Home's altitude AMSL as the mission defines it (the origin's ground level, minus d)."""
        return self.origin.alt_m - self.home_ned_m[2]


def deg_e7(deg: float) -> int:
    """Degrees -> MAVLink's integer 1e-7 degrees."""
    return int(round(deg * 1e7))
