"""Check `orchestrator export geojson` and `export qgc-plan` against readers nobody here wrote:
the GeoJSON is loaded by the `geojson` package (its own validation of RFC 7946 objects) and
its polygons by `shapely` (validity and winding); every vertex and path point is taken back to
scenario metres with `pymap3d` (WGS-84 -> east, north, up about the [origin], then the
heading) and compared with the scenario file. The QGroundControl plan is checked against the
structure of QGroundControl's "Plan File Format" page (keys, versions, [lat, lon] order,
clockwise polygons) and its points the same way.

usage: check_map_exports.py geojson MAP.geojson SCENARIO.toml
       check_map_exports.py qgc-plan PLAN.plan SCENARIO.toml
       check_map_exports.py skyc SHOW.skyc SCENARIO.toml
"""
import json
import math
import sys
import tomllib
import zipfile

import geojson
import pymap3d
from shapely.geometry import LinearRing, shape

from export_common import fail

TOL_M = 1e-6


class Frame:
    """The scenario's [origin]: geodetic <-> scenario metres, through pymap3d."""

    def __init__(self, origin):
        self.o = origin
        h = math.radians(origin["heading_deg"])
        self.s, self.c = math.sin(h), math.cos(h)

    def local(self, lat, lon, alt=None):
        """Scenario metres of a point; without an altitude, of the point of that latitude and
        longitude on the plane z = 0 (a fence vertex is a column: the plane's height there is
        below the origin's by the Earth's curvature, and measuring at the wrong height would
        tilt the answer by the angle between the two verticals)."""
        if alt is None:
            alt = self.o["alt_m"]
            for _ in range(3):
                alt -= self.local(lat, lon, alt)[2]
        e, n, u = pymap3d.geodetic2enu(lat, lon, alt, self.o["lat_deg"], self.o["lon_deg"], self.o["alt_m"])
        return (e * self.s + n * self.c, -e * self.c + n * self.s, u)


def near(a, b, what, tol=TOL_M):
    d = math.dist(a, b)
    if d > tol:
        fail(f"{what}: {a} is {d} m from {b}")
    return d


def scenario(path):
    with open(path, "rb") as f:
        s = tomllib.load(f)
    if "origin" not in s:
        fail(f"{path} has no [origin]")
    return s, Frame(s["origin"])


def same_ring(got_xy, want_xy, what):
    """The same vertices, in either direction, from any start."""
    n = len(want_xy)
    if len(got_xy) != n:
        fail(f"{what}: {len(got_xy)} vertices, the scenario has {n}")
    best = math.inf
    for order in (got_xy, got_xy[::-1]):
        k = min(range(n), key=lambda i: math.dist(order[i], want_xy[0]))
        best = min(best, max(math.dist(order[(k + i) % n], want_xy[i]) for i in range(n)))
    if best > TOL_M:
        fail(f"{what}: vertices differ from the scenario's by {best} m")
    return best


def box_corners(o):
    (x0, y0, _), (x1, y1, _) = o["min"], o["max"]
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


def check_geojson(path, toml):
    s, frame = scenario(toml)
    with open(path, encoding="utf-8") as f:
        text = f.read()
    parsed = geojson.loads(text)
    if not isinstance(parsed, geojson.FeatureCollection) or not parsed.is_valid:
        fail(f"not a valid FeatureCollection: {getattr(parsed, 'errors', lambda: None)()}")
    # The geojson package rounds coordinates to 6 decimals (about 0.1 m) as it builds its
    # objects: it judges the structure, the numbers are read as written.
    doc = json.loads(text)
    kinds = {}
    worst = 0.0
    obstacles = {o["name"]: o for o in s.get("obstacle", [])}
    for feat in doc["features"]:
        props = feat["properties"]
        kind = props["kind"]
        kinds[kind] = kinds.get(kind, 0) + 1
        geom = shape(feat["geometry"])
        if feat["geometry"]["type"] == "Polygon":
            ring = feat["geometry"]["coordinates"][0]
            if ring[0] != ring[-1]:
                fail(f"{kind}: ring not closed")
            if not geom.is_valid or not LinearRing(ring).is_ccw:
                fail(f"{kind} {props.get('name')}: invalid or not counter-clockwise (RFC 7946 3.1.6)")
            xy = [frame.local(lat, lon)[:2] for lon, lat in ring[:-1]]
            if kind == "geofence":
                worst = max(worst, same_ring(xy, [tuple(v) for v in s["geofence"]["polygon"]], "geofence"))
                if abs(props["max_alt_m"] - (s["origin"]["alt_m"] + s["geofence"]["max_z_m"])) > 1e-9:
                    fail(f"geofence ceiling {props['max_alt_m']}")
            elif props["shape"] == "box":
                worst = max(worst, same_ring(xy, box_corners(obstacles[props["name"]]), props["name"]))
            else:
                o = obstacles[props["name"]]
                cx, cy, _ = frame.local(props["center"][1], props["center"][0])
                worst = max(worst, near((cx, cy), tuple(o["center"]), f"{props['name']} centre"))
                # The polygon contains the circle: every side is at least the radius away.
                d = min(math.dist((cx, cy), v) for v in xy)
                if d < o["radius_m"] or not geom.buffer(0).contains(shape({"type": "Point", "coordinates": props["center"]})):
                    fail(f"{props['name']}: the polygon does not contain the circle")
        elif kind == "leader_path":
            pts = feat["geometry"]["coordinates"]
            agent = next(a for a in s["agents"] if a["id"] == props["agent"])
            x, y, z = agent["position"]
            ground = s["takeoff"]["ground_z_m"] if "takeoff" in s else z
            lon, lat, alt = pts[0]
            worst = max(worst, near(frame.local(lat, lon, alt), (x, y, ground), f"leader {props['agent']} start"))
        elif kind == "ground_spot":
            lon, lat, alt = feat["geometry"]["coordinates"]
            _, _, u = frame.local(lat, lon, alt)
            if abs(u - props["z_m"]) > TOL_M:
                fail(f"ground spot of {props['agent']} at {u} m, not {props['z_m']}")
    leaders = sum(1 for a in s["agents"] if a["role"] != "follower")
    want = {
        "geofence": 1 if "geofence" in s else 0,
        "obstacle": len(obstacles),
        "leader_path": leaders,
        "ground_spot": len(s["agents"]) * (("takeoff" in s) + ("landing" in s)),
    }
    got = {k: kinds.get(k, 0) for k in want}
    if got != want:
        fail(f"features {got}, the scenario has {want}")
    print(f"geojson ok: {sum(got.values())} features {got}, worst vertex {worst:.2e} m")


PLAN_KEYS = {"fileType", "geoFence", "groundStation", "mission", "rallyPoints", "version"}
MISSION_KEYS = {"cruiseSpeed", "firmwareType", "globalPlanAltitudeMode", "hoverSpeed", "items",
                "plannedHomePosition", "vehicleType", "version"}


def check_qgc_plan(path, toml):
    s, frame = scenario(toml)
    with open(path, encoding="utf-8") as f:
        plan = json.load(f)
    if set(plan) != PLAN_KEYS or plan["fileType"] != "Plan" or plan["version"] != 1:
        fail(f"top level {sorted(plan)}, fileType {plan.get('fileType')}, version {plan.get('version')}")
    fence, rally, mission = plan["geoFence"], plan["rallyPoints"], plan["mission"]
    if fence["version"] != 2 or rally["version"] != 2 or mission["version"] != 2:
        fail("geoFence, rallyPoints and mission are version 2")
    if not MISSION_KEYS <= set(mission) or len(mission["items"]) < 1:
        fail(f"mission keys {sorted(mission)}, {len(mission['items'])} items (at least one)")
    item = mission["items"][0]
    if item["type"] != "SimpleItem" or len(item["params"]) != 7:
        fail(f"mission item {item}")
    o = s["origin"]
    if mission["plannedHomePosition"] != [o["lat_deg"], o["lon_deg"], o["alt_m"]]:
        fail(f"plannedHomePosition {mission['plannedHomePosition']}")
    worst = 0.0
    boxes = [box_corners(ob) for ob in s.get("obstacle", []) if "min" in ob]
    cylinders = [ob for ob in s.get("obstacle", []) if "center" in ob]
    inclusions = [p for p in fence["polygons"] if p["inclusion"]]
    exclusions = [p for p in fence["polygons"] if not p["inclusion"]]
    if len(inclusions) != ("geofence" in s) or len(exclusions) != len(boxes):
        fail(f"{len(inclusions)} inclusion and {len(exclusions)} exclusion polygons")
    for p in fence["polygons"]:
        if p["version"] != 1:
            fail("polygon version 1")
        # [lat, lon] pairs, clockwise (seen as x = lon, y = lat).
        if LinearRing([(lon, lat) for lat, lon in p["polygon"]]).is_ccw:
            fail("a fence polygon is not clockwise")
    for p, want in zip(inclusions, [s.get("geofence", {}).get("polygon")]):
        xy = [frame.local(lat, lon)[:2] for lat, lon in p["polygon"]]
        worst = max(worst, same_ring(xy, [tuple(v) for v in want], "inclusion polygon"))
    for p, want in zip(exclusions, boxes):
        xy = [frame.local(lat, lon)[:2] for lat, lon in p["polygon"]]
        worst = max(worst, same_ring(xy, want, "exclusion polygon"))
    if len(fence["circles"]) != len(cylinders):
        fail(f"{len(fence['circles'])} circles, {len(cylinders)} cylinders")
    for c, ob in zip(fence["circles"], cylinders):
        if c["inclusion"] or c["version"] != 1 or c["circle"]["radius"] != ob["radius_m"]:
            fail(f"circle {c}")
        lat, lon = c["circle"]["center"]
        worst = max(worst, near(frame.local(lat, lon)[:2], tuple(ob["center"]), ob["name"]))
    spots = len(s["agents"]) if ("landing" in s or "takeoff" in s) else 0
    if len(rally["points"]) != spots:
        fail(f"{len(rally['points'])} rally points, {spots} ground spots")
    print(
        f"qgc-plan ok: {len(inclusions)} inclusion, {len(exclusions)} exclusion polygon(s), "
        f"{len(fence['circles'])} circle(s), {len(rally['points'])} rally point(s), worst vertex {worst:.2e} m"
    )


def check_skyc(path, toml):
    """The show's environment and validation as Skybrush reads them (skybrush.js types.ts;
    Skybrush Live's toLonLatFromScaledJSON: origin = [lat 1e-7, lon 1e-7, AMSL mm])."""
    with open(toml, "rb") as f:
        s = tomllib.load(f)
    with zipfile.ZipFile(path) as z:
        show = json.loads(z.read("show.json"))
    env = show["environment"]
    o = s["origin"]
    lat, lon, amsl = env["location"]["origin"]
    if env["type"] != "outdoor" or not all(isinstance(v, int) for v in (lat, lon, amsl)):
        fail(f"environment {env}")
    if abs(lat / 1e7 - o["lat_deg"]) > 0.5e-7 or abs(lon / 1e7 - o["lon_deg"]) > 0.5e-7:
        fail(f"origin {lat}, {lon} is not [origin] {o}")
    if abs(amsl / 1e3 - o["alt_m"]) > 0.5e-3 or env["location"]["orientation"] != o["heading_deg"]:
        fail(f"altitude {amsl} mm, orientation {env['location']['orientation']}")
    v, lim = show["settings"]["validation"], s["vehicle"]
    want = {
        "maxVelocityXY": lim["max_speed_xy_m_s"],
        "maxVelocityZUp": lim["max_speed_up_m_s"],
        "maxVelocityZ": lim["max_speed_down_m_s"],
        "maxAccelerationXY": lim["max_accel_xy_m_s2"],
        "maxAccelerationZ": lim["max_accel_z_m_s2"],
    }
    for key, value in want.items():
        if v.get(key) != value:
            fail(f"settings.validation.{key} = {v.get(key)}, [vehicle] says {value}")
    print(f"skyc frame ok: origin {lat} {lon} {amsl}, orientation {env['location']['orientation']}, validation {v}")


if __name__ == "__main__":
    {"geojson": check_geojson, "qgc-plan": check_qgc_plan, "skyc": check_skyc}[sys.argv[1]](*sys.argv[2:4])
