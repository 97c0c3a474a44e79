"""Check an `orchestrator export skybrush` show: the .skyc ZIP holds show.json in Skybrush's show
specification, the light program is Skybrush bytecode, and the Bézier segments evaluated
(de Casteljau, numpy) at 1,000 instants are the plan's r_HT from `simulate`'s telemetry within
1e-6 m.

A mission's show is checked over its whole duration (the certificate file's `duration_s`); with
GROUND_Z, every drone must start and end on the ground at that height.

usage: check_skyc.py SHOW.skyc TELEMETRY_CSV CERTIFICATE_JSON [GROUND_Z]
"""
import base64
import json
import sys
import zipfile

import numpy as np

from export_common import fail, pick_instants, reference

MAX_SEGMENT_S = 65.5  # skybrush-server refuses longer segments


def de_casteljau(points, v):
    p = np.array(points, dtype=np.float64)
    while len(p) > 1:
        p = (1.0 - v) * p[:-1] + v * p[1:]
    return p[0]


def segments(trajectory):
    """(t0, t1, control points incl. both ends) as skybrush-server reads them."""
    if trajectory.get("version") != 1:
        fail(f"trajectory version {trajectory.get('version')}")
    pts = trajectory["points"]
    if pts[0][2]:
        fail("the first keyframe has control points")
    out = []
    for (t0, p0, _), (t1, p1, ctrl) in zip(pts, pts[1:]):
        if not 0 < t1 - t0 <= MAX_SEGMENT_S:
            fail(f"segment {t0}..{t1} s")
        if len(ctrl) != 4:
            fail(f"segment {t0}..{t1}: {len(ctrl)} inner control points, a quintic has 4")
        out.append((t0, t1, [p0, *ctrl, p1]))
    return out


def evaluate(segs, t):
    for t0, t1, cp in segs:
        if t <= t1 + 1e-12:
            return de_casteljau(cp, (t - t0) / (t1 - t0))
    return np.array(segs[-1][2][-1], dtype=np.float64)


def main(skyc, telemetry, certificate, ground_z=None):
    with zipfile.ZipFile(skyc) as z:
        if z.testzip() is not None:
            fail("corrupt ZIP member")
        show = json.loads(z.read("show.json"))
    record = json.loads(open(certificate).read())
    cert = record["certificate"]
    if show.get("version") != 1:
        fail(f"show version {show.get('version')}")
    v = show["settings"]["validation"]
    for key in ("minDistance", "maxVelocityXY", "maxVelocityZ", "maxAltitude"):
        if not isinstance(v.get(key), (int, float)):
            fail(f"settings.validation.{key} = {v.get(key)}")
    if abs(v["minDistance"] - 2 * cert["eps_m"]) > 1e-12:
        fail(f"minDistance {v['minDistance']} is not 2 eps = {2 * cert['eps_m']}")
    ref = reference(telemetry)
    drones = show["swarm"]["drones"]
    if len(drones) != len(ref):
        fail(f"{len(drones)} drones, telemetry has {len(ref)} agents")
    worst = 0.0
    top_z = top_vxy = 0.0
    t_total = record.get("duration_s", cert["t_total_s"])
    for drone, (ident, (t_all, r_all)) in zip(drones, sorted(ref.items())):
        if drone["type"] != "generic":
            fail(f"drone type {drone['type']}")
        s = drone["settings"]
        lights = s["lights"]
        code = base64.b64decode(lights["data"])
        if lights["version"] != 1 or code[0] != 0x04 or code[-1] != 0x00 or len(code) < 6:
            fail(f"light program {code!r} is not SET_COLOR .. END")
        segs = segments(s["trajectory"])
        if abs(segs[-1][1] - t_total) > 1e-9:
            fail(f"drone {ident}: show ends at {segs[-1][1]} s, plan at {t_total} s")
        if ground_z is not None:
            first, last = evaluate(segs, 0.0), evaluate(segs, t_total)
            if abs(first[2] - float(ground_z)) > 1e-9 or abs(last[2] - float(ground_z)) > 1e-9:
                fail(f"drone {ident}: z {first[2]} at 0 s and {last[2]} at {t_total} s, ground {ground_z}")
            if abs(s["home"][2] - float(ground_z)) > 1e-9:
                fail(f"drone {ident}: home {s['home']} is not on the ground")
        idx = pick_instants(t_all, t_total)
        got = np.array([evaluate(segs, t) for t in t_all[idx]])
        worst = max(worst, np.abs(got - r_all[idx]).max())
        top_z = max(top_z, r_all[:, 2].max())
        dt = np.diff(t_all)
        vel = np.diff(r_all, axis=0) / dt[:, None]
        top_vxy = max(top_vxy, np.hypot(vel[:, 0], vel[:, 1]).max())
    if worst > 1e-6:
        fail(f"Bézier curves are {worst} m from r_HT (limit 1e-6 m)")
    if top_z > v["maxAltitude"] + 1e-9 or top_vxy > v["maxVelocityXY"] + 1e-6:
        fail(f"the plan exceeds its own validation: z {top_z}, v_xy {top_vxy}, {v}")
    where = "" if ground_z is None else f", from and to the ground at z = {ground_z}"
    print(
        f"skyc ok: {len(drones)} drones, {len(segs)} segments each, max error {worst:.3e} m, "
        f"{segs[-1][1]} s{where}"
    )


if __name__ == "__main__":
    main(*sys.argv[1:5])
