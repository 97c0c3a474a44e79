"""Check `orchestrator plan`'s geographic lines against pymap3d (pinned in
python/requirements-test.txt), an independent implementation of the WGS-84 tangent plane.

Reads the plan's stdout on stdin: the `geographic origin:` line (latitude, longitude, altitude
AMSL and the heading of +x) and one line per leader's start or goal, each with its scenario point
(metres) and the latitude, longitude and altitude printed for it. For each, pymap3d converts the
printed latitude, longitude and altitude to east, north, up about the origin; turned into the
scenario's axes by the heading, that must be the scenario point. Prints one JSON line: the
number of points, the largest distance of a point from the origin and the largest error (m).

usage: orchestrator plan --scenario S.toml | check_geodetic.py
"""
import json
import math
import re
import sys

import pymap3d

NUM = r"(-?\d+(?:\.\d+)?)"
ORIGIN = re.compile(
    rf"geographic origin: lat {NUM} deg, lon {NUM} deg, alt {NUM} m AMSL, \+x heading {NUM} deg")
POINT = re.compile(
    rf"leader\s+(\d+)\s+(.+?)\s+local \({NUM}, {NUM}, {NUM}\) m -> lat {NUM} lon {NUM} alt {NUM} m")


def main():
    text = sys.stdin.read()
    origin = ORIGIN.search(text)
    if origin is None:
        print("FAIL: no `geographic origin:` line", file=sys.stderr)
        return 1
    lat0, lon0, alt0, heading = (float(v) for v in origin.groups())
    s, c = math.sin(math.radians(heading)), math.cos(math.radians(heading))
    points = POINT.findall(text)
    if not points:
        print("FAIL: no leader lines", file=sys.stderr)
        return 1
    worst, farthest = 0.0, 0.0
    for _ident, _what, x, y, z, lat, lon, alt in points:
        x, y, z = float(x), float(y), float(z)
        e, n, u = pymap3d.geodetic2enu(float(lat), float(lon), float(alt), lat0, lon0, alt0)
        # East, north, up in the scenario's axes: +x on bearing `heading`, +y to its left.
        local = (e * s + n * c, -e * c + n * s, u)
        worst = max(worst, math.dist(local, (x, y, z)))
        farthest = max(farthest, math.hypot(x, y, z))
    print(json.dumps({"points": len(points), "farthest_m": farthest, "max_error_m": worst}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
