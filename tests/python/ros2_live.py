"""The live ROS 2 topics of `orchestrator launch --ros2`, received by code nobody here
wrote, then compared with the run's telemetry.

Usage:
  ros2_live.py dds OUT COUNT DEADLINE
      A real ROS 2 node: rclpy (PyPI ros-rclpy, kilted, over rmw_fastrtps_cpp) subscribes to
      /cdm/agent_1/pose in domain ROS_DOMAIN_ID until COUNT PoseStamped arrived, and reads the
      ROS graph: the node /cdm_orchestrator publishes the bag's topics and subscribes to nothing.
  ros2_live.py zenoh OUT COUNT DEADLINE LISTEN
      eclipse-zenoh, standing where rmw_zenoh's router (rmw_zenohd) stands: listens on LISTEN,
      subscribes to rmw_zenoh's key expression for /cdm/agent_1/pose (built here from rmw_zenoh's
      docs/design.md, the type hash from `rosbags`) and to the liveliness tokens of domain
      ROS_DOMAIN_ID, until COUNT samples arrived; checks each attachment (sequence number,
      source timestamp, the GID = XXH3-128 of the publisher's token) and the node's and the
      publisher's tokens, and decodes each payload with `rosbags`' CDR deserializer.
  ros2_live.py check OUT RUN_DIR
      Every pose received equals a telemetry.csv row of agent 1: the same time stamp, the
      position within 1e-6 m, frame `world`.

Prints "subscribed" once listening, then one line per result; exits 1 naming the first failure.
"""

import csv
import json
import os
import struct
import sys
import threading
import time

TOPIC = "/cdm/agent_1/pose"
POSE = "geometry_msgs/msg/PoseStamped"
NODE = "cdm_orchestrator"


def fail(msg):
    print(f"FAIL: {msg}", flush=True)
    sys.exit(1)


def pose_of(msg):
    """A PoseStamped (rclpy's or rosbags') as plain values."""
    p, q, st = msg.pose.position, msg.pose.orientation, msg.header.stamp
    return {
        "t_ns": st.sec * 10**9 + st.nanosec,
        "frame": msg.header.frame_id,
        "p": [p.x, p.y, p.z],
        "q": [q.x, q.y, q.z, q.w],
    }


def write(out, poses, extra):
    with open(out, "w") as f:
        json.dump({"poses": poses, **extra}, f)
    print(f"received {len(poses)} poses", flush=True)


def graph_of_our_node(node, deadline):
    """The topics /cdm_orchestrator publishes and subscribes to, as the ROS graph shows them."""
    while True:
        try:
            pubs = node.get_publisher_names_and_types_by_node(NODE, "/")
            subs = node.get_subscriber_names_and_types_by_node(NODE, "/")
            if pubs or time.monotonic() > deadline:
                return pubs, subs
        except Exception:  # noqa: BLE001 - the node is not in the graph yet
            if time.monotonic() > deadline:
                raise
        time.sleep(0.05)


def dds(out, count, deadline):
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.node import Node

    rclpy.init()
    node = Node("cdm_live_check")
    got = []
    node.create_subscription(PoseStamped, TOPIC, lambda m: got.append(pose_of(m)), 100)
    print("subscribed", flush=True)
    until = time.monotonic() + deadline
    while len(got) < count:
        if time.monotonic() > until:
            fail(f"dds: {len(got)} of {count} PoseStamped on {TOPIC} within {deadline} s")
        rclpy.spin_once(node, timeout_sec=0.05)
    pubs, subs = graph_of_our_node(node, time.monotonic() + 10)
    types = {name: t for name, t in pubs}
    # /cdm/commands exists from the start: a launched team may be commanded in flight.
    want = {"/tf": "tf2_msgs/msg/TFMessage", "/cdm/formation": "visualization_msgs/msg/MarkerArray",
            "/cdm/audit": "std_msgs/msg/String", "/cdm/commands": "std_msgs/msg/String"}
    want.update({t: POSE for t in types if t.startswith("/cdm/agent_") and t.endswith("/pose")})
    # ros2-client's node also announces /parameter_events, as rclcpp's and rclpy's nodes do.
    extra = set(types) - set(want) - {"/parameter_events"}
    if TOPIC not in want or extra or any(types.get(t) != [w] for t, w in want.items()):
        fail(f"dds: /{NODE} publishes {pubs}")
    if subs:
        fail(f"dds: /{NODE} subscribes to {subs}: it must be output only")
    print(f"dds: /{NODE} publishes {len(pubs)} topics and subscribes to none", flush=True)
    write(out, got, {"topics": sorted(types)})
    node.destroy_node()
    rclpy.try_shutdown()


def zenoh_keys(domain):
    from rosbags.typesys import Stores, get_typestore

    h = get_typestore(Stores.ROS2_HUMBLE).hash_rihs01(POSE)
    dds_type = "geometry_msgs::msg::dds_::PoseStamped_"
    # design.md: <domain_id>/<fully qualified name>/<type name>/<type hash>; tokens mangle / to %.
    key = f"{domain}{TOPIC}/{dds_type}/{h}"
    return key, f"/MP/%/%/{NODE}/{TOPIC.replace('/', '%')}/{dds_type}/{h}/", h


def check_tokens(tokens, token_part, zid_of_pub):
    """The publisher's token (the one whose GID the samples carry) and its node's token."""
    mine = [t for t in tokens if token_part in t]
    if len(mine) != 1:
        fail(f"zenoh: {len(mine)} publisher tokens for {TOPIC} among {sorted(tokens)}")
    token = mine[0]
    parts = token.split("/")
    # @ros2_lv/<domain>/<zid>/<node id>/<entity id>/MP/<enclave>/<ns>/<node>/<topic>/<type>/<hash>/<qos>
    if len(parts) != 13 or len(parts[12].split(":")) != 6:
        fail(f"zenoh: token {token} is not of rmw_zenoh's form")
    zid, nid = parts[2], parts[3]
    node_token = f"@ros2_lv/{parts[1]}/{zid}/{nid}/{nid}/NN/%/%/{NODE}"
    if node_token not in tokens:
        fail(f"zenoh: no node token {node_token} among {sorted(tokens)}")
    ours = [t for t in tokens if t.split("/")[2] == zid]
    kinds = {t.split("/")[5] for t in ours}
    if kinds != {"NN", "MP"}:
        fail(f"zenoh: our session declares {sorted(kinds)}: only a node and publishers expected")
    zid_of_pub.append(zid)
    return token


def zenoh_session(listen, domain, key, on_sample, on_token):
    import zenoh

    conf = zenoh.Config()
    # Where rmw_zenohd stands: a router the node connects to.
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([listen]))
    conf.insert_json5("connect/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    subs = [
        session.declare_subscriber(key, on_sample),
        session.liveliness().declare_subscriber(f"@ros2_lv/{domain}/**", on_token, history=True),
    ]
    return session, subs


def zenoh_check(samples, token, started_ns):
    """Each sample's attachment, and its payload decoded by rosbags."""
    import xxhash
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    gid = xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little")
    poses, last_seq = [], 0
    for key, payload, att in samples:
        if key != samples[0][0]:
            fail(f"zenoh: samples on {key} and {samples[0][0]}")
        if len(att) != 33:
            fail(f"zenoh: attachment of {len(att)} bytes, rmw_zenoh's has 33")
        seq, stamp_ns, n = struct.unpack_from("<qqB", att)
        if seq <= last_seq or n != 16 or att[17:] != gid:
            fail(f"zenoh: attachment seq {seq} after {last_seq}, gid length {n}, gid {att[17:].hex()} (want {gid.hex()})")
        if not started_ns - 10**9 <= stamp_ns <= time.time_ns() + 10**9:
            fail(f"zenoh: source timestamp {stamp_ns} is not the wall clock of the run")
        last_seq = seq
        poses.append(pose_of(ts.deserialize_cdr(payload, POSE)))
    return poses


def zenoh_live(out, count, deadline, listen):
    domain = int(os.environ.get("ROS_DOMAIN_ID", "0"))
    key, token_part, _ = zenoh_keys(domain)
    lock, samples, tokens = threading.Lock(), [], set()

    def on_sample(s):
        with lock:
            att = s.attachment.to_bytes() if s.attachment is not None else b""
            samples.append((str(s.key_expr), s.payload.to_bytes(), att))

    def on_token(s):
        with lock:
            tokens.add(str(s.key_expr))

    started_ns = time.time_ns()
    session, subs = zenoh_session(listen, domain, key, on_sample, on_token)
    print("subscribed", flush=True)
    until = time.monotonic() + deadline
    while True:
        with lock:
            n = len(samples)
        if n >= count:
            break
        if time.monotonic() > until:
            fail(f"zenoh: {n} of {count} samples on {key} within {deadline} s; tokens {sorted(tokens)}")
        time.sleep(0.02)
    with lock:
        got, seen = list(samples), set(tokens)
    for s in subs:
        s.undeclare()
    session.close()
    token = check_tokens(seen, token_part, [])
    poses = zenoh_check(got, token, started_ns)
    print(f"zenoh: {len(poses)} samples on {key}, attachments and tokens of rmw_zenoh's form", flush=True)
    write(out, poses, {"key": key, "token": token})


def telemetry_of(run_dir, agent):
    with open(os.path.join(run_dir, "telemetry.csv"), newline="") as f:
        rows = [r for r in csv.DictReader(f) if int(r["id"]) == agent]
    return {round(float(r["t"]) * 1e9): r for r in rows}


def check(out, run_dir):
    with open(out) as f:
        poses = json.load(f)["poses"]
    rows = telemetry_of(run_dir, 1)
    if not poses or not rows:
        fail(f"check: {len(poses)} poses received, {len(rows)} telemetry rows of agent 1")
    stamps = [p["t_ns"] for p in poses]
    if stamps != sorted(set(stamps)):
        fail("check: time stamps not strictly increasing")
    for p in poses:
        r = rows.get(p["t_ns"])
        if r is None:
            fail(f"check: stamp {p['t_ns']} ns is no telemetry row's time")
        err = max(abs(a - float(r[k])) for a, k in zip(p["p"], ("x", "y", "z")))
        if err > 1e-6 or p["frame"] != "world" or p["q"] != [0.0, 0.0, 0.0, 1.0]:
            fail(f"check: pose {p} differs from telemetry {r} (by {err} m)")
    print(f"check: {len(poses)} poses equal telemetry rows (t {stamps[0]}..{stamps[-1]} ns)", flush=True)


def main():
    a = sys.argv[1:]
    if a[:1] == ["dds"] and len(a) == 4:
        dds(a[1], int(a[2]), float(a[3]))
    elif a[:1] == ["zenoh"] and len(a) == 5:
        zenoh_live(a[1], int(a[2]), float(a[3]), a[4])
    elif a[:1] == ["check"] and len(a) == 3:
        check(a[1], a[2])
    else:
        fail(__doc__)


if __name__ == "__main__":
    main()
