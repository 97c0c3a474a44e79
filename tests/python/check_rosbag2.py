"""Check a ROS 2 bag written by `orchestrator export rosbag2` or `--telemetry mcap` with readers
nobody here wrote: `rosbags` (its rosbag2 Reader and the ROS 2 Humble typestore's CDR decoder)
and Foxglove's `mcap` reader.

Usage:
  check_rosbag2.py check BAG RUN_DIR   the bag against the run's telemetry (csv or parquet)
  check_rosbag2.py equal BAG_A BAG_B   the same messages, topic by topic, decoded from both

Prints one line per check; exits 1 naming the first failure.
"""

import csv
import json
import math
import os
import sys
import tomllib
from collections import defaultdict

from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_HUMBLE)
TYPES = {
    "pose": "geometry_msgs/msg/PoseStamped",
    "tf": "tf2_msgs/msg/TFMessage",
    "markers": "visualization_msgs/msg/MarkerArray",
    "string": "std_msgs/msg/String",
}


def fail(msg):
    print(f"FAIL: {msg}")
    sys.exit(1)


def telemetry(run_dir):
    """Rows of the run as dicts with floats, from telemetry.parquet or telemetry.csv."""
    pq_path = os.path.join(run_dir, "telemetry.parquet")
    if os.path.exists(pq_path):
        import pyarrow.parquet as pq

        return pq.read_table(pq_path).to_pylist()
    with open(os.path.join(run_dir, "telemetry.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k in r:
            if k in ("tick", "id"):
                r[k] = int(r[k])
            elif k != "role":
                r[k] = float(r[k])
    return rows


def decode(bag):
    """{topic: [(timestamp, msgtype, rawdata, message)]} in bag order, and the reader's info."""
    out = defaultdict(list)
    with Reader(bag) as reader:
        info = {
            "count": reader.message_count,
            "types": {c.topic: c.msgtype for c in reader.connections},
            "counts": {c.topic: c.msgcount for c in reader.connections},
        }
        for conn, stamp, raw in reader.messages():
            msg = TS.deserialize_cdr(raw, conn.msgtype)
            out[conn.topic].append((stamp, conn.msgtype, bytes(raw), msg))
    return out, info


def plain(x):
    """A decoded message as plain Python values (numpy arrays to lists)."""
    if hasattr(x, "__dataclass_fields__"):
        return {k: plain(getattr(x, k)) for k in x.__dataclass_fields__}
    if hasattr(x, "tolist"):
        return x.tolist()
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    return x


def check_poses(msgs, info, rows):
    by_id = defaultdict(list)
    for r in rows:
        by_id[r["id"]].append(r)
    for aid, rs in sorted(by_id.items()):
        topic = f"/cdm/agent_{aid}/pose"
        if info["types"].get(topic) != TYPES["pose"]:
            fail(f"{topic}: missing or not PoseStamped ({info['types'].get(topic)})")
        got = msgs[topic]
        if len(got) != len(rs) or info["counts"][topic] != len(rs):
            fail(f"{topic}: {len(got)} messages, {len(rs)} telemetry rows")
        stamp, _, _, last = got[-1]
        p, r = last.pose.position, rs[-1]
        err = max(abs(p.x - r["x"]), abs(p.y - r["y"]), abs(p.z - r["z"]))
        if err > 1e-6 or last.header.frame_id != "world":
            fail(f"{topic}: last pose {p} frame {last.header.frame_id}, telemetry {r}")
        t_ns = last.header.stamp.sec * 10**9 + last.header.stamp.nanosec
        if abs(t_ns - r["t"] * 1e9) > 1 or stamp != t_ns:
            fail(f"{topic}: stamp {t_ns} / log time {stamp}, telemetry t = {r['t']}")
    print(f"poses: {len(by_id)} topics, one message per telemetry row, last pose = telemetry")
    return by_id


def expected_airspace(run_dir):
    """(type, ns, position, scale or points) of the markers the run's scenario.toml (tomllib)
    asks for: its geofence as a LINE_LIST (each edge at floor and ceiling, a post per vertex),
    boxes as CUBEs and cylinders as CYLINDERs, centred, scale the full size."""
    with open(os.path.join(run_dir, "scenario.toml"), "rb") as f:
        sc = tomllib.load(f)
    out = []
    fence = sc.get("geofence")
    if fence:
        poly, lo, hi = fence["polygon"], fence["min_z_m"], fence["max_z_m"]
        pts = []
        for k, (x, y) in enumerate(poly):
            nx, ny = poly[(k + 1) % len(poly)]
            pts += [(x, y, lo), (nx, ny, lo), (x, y, hi), (nx, ny, hi), (x, y, lo), (x, y, hi)]
        out.append((5, "geofence", None, pts))
    for o in sc.get("obstacle", []):
        if "min" in o:
            lo, hi = o["min"], o["max"]
            kind = 1
        else:
            (cx, cy), r = o["center"], o["radius_m"]
            lo, hi = (cx - r, cy - r, o["min_z_m"]), (cx + r, cy + r, o["max_z_m"])
            kind = 3
        centre = tuple((a + b) / 2 for a, b in zip(lo, hi))
        out.append((kind, "obstacles", centre, tuple(b - a for a, b in zip(lo, hi))))
    return out


def check_airspace(arr, airspace):
    got = [m for m in arr.markers if m.ns in ("geofence", "obstacles")]
    if len(got) != len(airspace):
        fail(f"/cdm/formation: {len(got)} airspace markers, the scenario has {len(airspace)}")
    for m, (kind, ns, centre, extent) in zip(got, airspace):
        if (m.type, m.ns) != (kind, ns):
            fail(f"/cdm/formation: marker {m.ns}/{m.id} type {m.type}, expected {ns} type {kind}")
        if centre is None:
            pts = [(p.x, p.y, p.z) for p in m.points]
            if len(pts) != len(extent) or any(
                    math.dist(a, b) > 1e-9 for a, b in zip(pts, extent)):
                fail(f"/cdm/formation: geofence points {pts[:6]}..., expected {extent[:6]}...")
        else:
            pos = (m.pose.position.x, m.pose.position.y, m.pose.position.z)
            size = (m.scale.x, m.scale.y, m.scale.z)
            if math.dist(pos, centre) > 1e-9 or math.dist(size, extent) > 1e-9:
                fail(f"/cdm/formation: obstacle {m.id} at {pos} size {size}, "
                     f"expected {centre} size {extent}")
    if airspace:
        fences = sum(1 for a in airspace if a[1] == "geofence")
        print(f"/cdm/formation: {fences} geofence and {len(airspace) - fences} obstacles as markers")


def check_tf_markers_audit(msgs, rows, by_id, run_dir):
    ticks = sorted({r["tick"] for r in rows})
    last_tick = [r for r in rows if r["tick"] == ticks[-1]]
    for topic in ("/tf", "/cdm/formation", "/cdm/audit"):
        if len(msgs[topic]) != len(ticks):
            fail(f"{topic}: {len(msgs[topic])} messages, {len(ticks)} ticks")
    tf = msgs["/tf"][-1][3]
    kids = sorted(t.child_frame_id for t in tf.transforms)
    want = sorted(f"agent_{r['id']}" for r in last_tick)
    if kids != want or {t.header.frame_id for t in tf.transforms} != {"world"}:
        fail(f"/tf: last frames {kids}, want {want} in world")
    airspace = expected_airspace(run_dir)
    for stamp, _, _, arr in msgs["/cdm/formation"][:: max(1, len(ticks) // 7)]:
        kinds = sorted(m.type for m in arr.markers)
        if kinds != sorted([2] * len(by_id) + [4] + [k for k, _, _, _ in airspace]):
            fail(f"/cdm/formation at {stamp}: marker types {kinds}")
    arr = msgs["/cdm/formation"][-1][3]
    roles = {r["id"]: r["role"] for r in rows}
    colors = defaultdict(set)
    for m in arr.markers:
        if m.type == 2:
            colors[roles[m.id]].add((round(m.color.r, 3), round(m.color.g, 3), round(m.color.b, 3)))
    if any(len(c) != 1 for c in colors.values()) or len(set().union(*colors.values())) != len(colors):
        fail(f"/cdm/formation: colours by role {dict(colors)}")
    strip = [m for m in arr.markers if m.type == 4][0]
    if len(strip.points) < 4 or plain(strip.points[0]) != plain(strip.points[-1]):
        fail(f"/cdm/formation: the polygon is not a closed LINE_STRIP: {len(strip.points)} points")
    check_airspace(arr, airspace)
    margins = [json.loads(m[3].data) for m in msgs["/cdm/audit"]]
    if [m["tick"] for m in margins] != ticks:
        fail("/cdm/audit: ticks differ from telemetry")
    keys = {"separation_m", "separation_margin_m", "deviation_m", "deviation_margin_m",
            "boundary_margin_m", "lambda1", "lambda1_margin"}
    if not keys <= set(margins[-1]):
        fail(f"/cdm/audit: keys {sorted(margins[-1])}")
    print(f"/tf, /cdm/formation (MarkerArray, {len(arr.markers)} markers), /cdm/audit: one per tick")


def check_commands(msgs, info, run_dir):
    """/cdm/commands: one std_msgs/String per command of the run's commands.json, in order, each
    stamped at or after its switch tick; no such topic in a run without commands."""
    path = os.path.join(run_dir, "commands.json")
    if not os.path.exists(path):
        if "/cdm/commands" in info["types"]:
            fail("/cdm/commands in a run without commands.json")
        return
    with open(path) as f:
        want = json.load(f)
    if info["types"].get("/cdm/commands") != TYPES["string"]:
        fail(f"/cdm/commands: missing or not String ({info['types'].get('/cdm/commands')})")
    got = [(stamp, json.loads(m.data)) for stamp, _, _, m in msgs["/cdm/commands"]]
    if len(got) != len(want):
        fail(f"/cdm/commands: {len(got)} messages, commands.json has {len(want)}")
    for (stamp, g), w in zip(got, want):
        if (g["tick"], g["command"], g["accepted"]) != (w["switch_tick"], w["command"], w["accepted"]):
            fail(f"/cdm/commands: {g} differs from {w}")
        if g["verdict"] != w["verdict"] or g["why"] != w.get("why"):
            fail(f"/cdm/commands: verdict or why {g} differs from {w}")
        if stamp < round(g["t_s"] * 1e9):
            fail(f"/cdm/commands: {g} stamped {stamp}, before its switch")
    print(f"/cdm/commands: {len(got)} commands as in commands.json "
          f"({sum(g['accepted'] for _, g in got)} accepted)")


def check_mcap(bag, info):
    files = [f for f in os.listdir(bag) if f.endswith(".mcap")]
    if len(files) != 1:
        fail(f"{bag}: {files}, expected one .mcap")
    with open(os.path.join(bag, files[0]), "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
    if header.profile != "ros2" or summary is None:
        fail(f"mcap: profile {header.profile!r}, summary {summary}")
    for s in summary.schemas.values():
        want, _ = TS.generate_msgdef(s.name, ros_version=2)
        if s.encoding != "ros2msg" or s.data.decode() != want.rstrip("\n"):
            fail(f"mcap: schema {s.name} ({s.encoding}) differs from the ROS 2 definition")
    for c in summary.channels.values():
        if c.message_encoding != "cdr" or "offered_qos_profiles" not in c.metadata:
            fail(f"mcap: channel {c.topic}: {c.message_encoding}, {c.metadata}")
        if c.metadata.get("topic_type_hash") != TS.hash_rihs01(info["types"][c.topic]):
            fail(f"mcap: channel {c.topic}: type hash {c.metadata.get('topic_type_hash')}")
    if summary.statistics.message_count != info["count"]:
        fail(f"mcap: {summary.statistics.message_count} messages, metadata.yaml {info['count']}")
    names = sorted(s.name for s in summary.schemas.values())
    print(f"mcap: profile ros2, {len(summary.channels)} channels, schemas {names}")


def equal(a, b):
    ma, ia = decode(a)
    mb, ib = decode(b)
    if ia != ib:
        fail(f"metadata differ: {ia} vs {ib}")
    for topic in ma:
        xa = [(s, t, plain(m)) for s, t, _, m in ma[topic]]
        xb = [(s, t, plain(m)) for s, t, _, m in mb[topic]]
        if xa != xb:
            k = next(i for i, (p, q) in enumerate(zip(xa, xb)) if p != q) if len(xa) == len(xb) else -1
            fail(f"{topic}: decoded messages differ (first at {k}; {len(xa)} vs {len(xb)})")
        if [r for _, _, r, _ in ma[topic]] != [r for _, _, r, _ in mb[topic]]:
            fail(f"{topic}: same decoded messages, different bytes")
    print(f"equal: {ia['count']} messages on {len(ma)} topics, decoded and compared one by one")


def main():
    if len(sys.argv) != 4 or sys.argv[1] not in ("check", "equal"):
        fail(__doc__)
    if sys.argv[1] == "equal":
        equal(sys.argv[2], sys.argv[3])
        return
    bag, run_dir = sys.argv[2], sys.argv[3]
    msgs, info = decode(bag)
    rows = telemetry(run_dir)
    by_id = check_poses(msgs, info, rows)
    check_tf_markers_audit(msgs, rows, by_id, run_dir)
    check_commands(msgs, info, run_dir)
    if info["count"] != sum(len(v) for v in msgs.values()):
        fail("metadata.yaml message_count differs from the messages read")
    check_mcap(bag, info)


if __name__ == "__main__":
    main()
