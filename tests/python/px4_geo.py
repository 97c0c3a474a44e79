"""PX4's map projection (src/lib/geo/geo.cpp, class MapProjection): how PX4 turns a latitude and
longitude into its local north and east about the local position's reference and back. An
azimuthal equidistant projection on a sphere of radius CONSTANTS_RADIUS_OF_EARTH (6371 km);
PX4's local down is the reference altitude minus the altitude. The MAVLink test vehicle uses it
for SET_POSITION_TARGET_GLOBAL_INT (mavlink_receiver.cpp projects the target into the local
frame) and GLOBAL_POSITION_INT (the local position reprojected)."""
import math

RADIUS_OF_EARTH_M = 6371000.0


class MapProjection:
    def __init__(self, lat_deg, lon_deg):
        self.lat = math.radians(lat_deg)
        self.lon = math.radians(lon_deg)
        self.sin_lat = math.sin(self.lat)
        self.cos_lat = math.cos(self.lat)

    def project(self, lat_deg, lon_deg):
        """(north, east) metres of a latitude and longitude."""
        lat, lon = math.radians(lat_deg), math.radians(lon_deg)
        sin_lat, cos_lat = math.sin(lat), math.cos(lat)
        cos_d_lon = math.cos(lon - self.lon)
        arg = max(-1.0, min(1.0, self.sin_lat * sin_lat + self.cos_lat * cos_lat * cos_d_lon))
        c = math.acos(arg)
        k = c / math.sin(c) if abs(c) > 0.0 else 1.0
        north = k * (self.cos_lat * sin_lat - self.sin_lat * cos_lat * cos_d_lon) * RADIUS_OF_EARTH_M
        east = k * cos_lat * math.sin(lon - self.lon) * RADIUS_OF_EARTH_M
        return north, east

    def reproject(self, north, east):
        """(latitude, longitude) degrees of a local (north, east)."""
        x, y = north / RADIUS_OF_EARTH_M, east / RADIUS_OF_EARTH_M
        c = math.hypot(x, y)
        if c == 0.0:
            return math.degrees(self.lat), math.degrees(self.lon)
        sin_c, cos_c = math.sin(c), math.cos(c)
        lat = math.asin(cos_c * self.sin_lat + x * sin_c * self.cos_lat / c)
        lon = self.lon + math.atan2(y * sin_c, c * self.cos_lat * cos_c - x * self.sin_lat * sin_c)
        return math.degrees(lat), math.degrees(lon)
