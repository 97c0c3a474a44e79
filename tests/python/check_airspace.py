"""Check that the exports carry the scenario's airspace in the target frame: the
Crazyswarm2 export's airspace.yaml (read with PyYAML) and the Skybrush show's `geofence` (read
as skybrush-server reads `show["geofence"]`: version 1, inclusion polygons of [x, y], minAltitude
and maxAltitude) both equal the original scenario's [geofence] and [[obstacle]] tables mapped by
p -> scale p + origin, and equal the scaled scenario.toml the export wrote (read with tomllib).

usage: check_airspace.py ORIGINAL_TOML CRAZYSWARM2_DIR SHOW_SKYC SCALE OX OY OZ
"""
import json
import sys
import tomllib
import zipfile

import yaml

from export_common import fail

TOL = 1e-9


def close(a, b, what):
    a, b = list(a), list(b)
    if len(a) != len(b) or any(abs(x - y) > TOL * max(1.0, abs(y)) for x, y in zip(a, b)):
        fail(f"{what}: {a} != {b}")


def mapped(table, s, o):
    """The original tables in the target frame, in airspace.yaml's shape."""
    fence = table.get("geofence")
    out = {"obstacles": []}
    if fence:
        out["geofence"] = {
            "polygon": [[s * x + o[0], s * y + o[1]] for x, y in fence["polygon"]],
            "min_z_m": s * fence["min_z_m"] + o[2],
            "max_z_m": s * fence["max_z_m"] + o[2],
        }
    for ob in table.get("obstacle", []):
        if "min" in ob:
            shape = {"box": {k: [s * v + o[i] for i, v in enumerate(ob[k])] for k in ("min", "max")}}
        else:
            shape = {"cylinder": {
                "center": [s * ob["center"][0] + o[0], s * ob["center"][1] + o[1]],
                "radius_m": s * ob["radius_m"],
                "min_z_m": s * ob["min_z_m"] + o[2],
                "max_z_m": s * ob["max_z_m"] + o[2],
            }}
        out["obstacles"].append({"name": ob["name"], **shape})
    return out


def same(got, want, where):
    if ("geofence" in got) != ("geofence" in want):
        fail(f"{where}: geofence present {('geofence' in got)}, expected {('geofence' in want)}")
    if "geofence" in want:
        g, w = got["geofence"], want["geofence"]
        if len(g["polygon"]) != len(w["polygon"]):
            fail(f"{where}: {len(g['polygon'])} fence vertices, expected {len(w['polygon'])}")
        for k, (a, b) in enumerate(zip(g["polygon"], w["polygon"])):
            close(a, b, f"{where}: fence vertex {k}")
        close([g["min_z_m"], g["max_z_m"]], [w["min_z_m"], w["max_z_m"]], f"{where}: fence z")
    if [o["name"] for o in got["obstacles"]] != [o["name"] for o in want["obstacles"]]:
        fail(f"{where}: obstacles {got['obstacles']} != {want['obstacles']}")
    for g, w in zip(got["obstacles"], want["obstacles"]):
        kind = "box" if "box" in w else "cylinder"
        if kind not in g:
            fail(f"{where}: obstacle {w['name']!r} is not a {kind}")
        for key, value in w[kind].items():
            close(g[kind][key] if isinstance(value, list) else [g[kind][key]],
                  value if isinstance(value, list) else [value], f"{where}: {w['name']}.{key}")


def main(original, cf_dir, skyc, scale, ox, oy, oz):
    s, o = float(scale), (float(ox), float(oy), float(oz))
    with open(original, "rb") as f:
        want = mapped(tomllib.load(f), s, o)
    with open(f"{cf_dir}/scenario.toml", "rb") as f:
        same(mapped(tomllib.load(f), 1.0, (0.0, 0.0, 0.0)), want, "scenario.toml")
    with open(f"{cf_dir}/airspace.yaml") as f:
        same(yaml.safe_load(f), want, "airspace.yaml")
    with zipfile.ZipFile(skyc) as z:
        fence = json.loads(z.read("show.json")).get("geofence")
    if not fence or fence.get("version") != 1 or not fence.get("enabled", True):
        fail(f"show.json geofence {fence}")
    inclusion = [p for p in fence.get("polygons", []) if p.get("isInclusion")]
    if len(inclusion) != 1:
        fail(f"show.json: {len(inclusion)} inclusion polygons")
    sky = {
        "geofence": {
            "polygon": inclusion[0]["points"],
            "min_z_m": fence["minAltitude"],
            "max_z_m": fence["maxAltitude"],
        },
        "obstacles": [],
    }
    same(sky, {**want, "obstacles": []}, "show.json")
    print(f"airspace ok: {len(want['obstacles'])} obstacles, fence of "
          f"{len(want['geofence']['polygon'])} vertices")


if __name__ == "__main__":
    if len(sys.argv) != 8:
        fail(__doc__)
    main(*sys.argv[1:])
