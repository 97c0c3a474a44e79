"""An outsider on the team's network: an independent zenoh client (PyPI eclipse-zenoh, the same
zenoh version as ours) that connects to the orchestrator's endpoint, subscribes to every key,
watches every liveliness token and queries every key, until a stop file appears.

It does what a stranger on the Wi-Fi can do with zenoh's own tools: with --insecure teams it
receives their frames (the control), against mutual TLS it must receive nothing.

With --put KEY it also publishes bytes that are no frame of ours on KEY (a forged frame).

Prints one JSON line: {"samples": n, "keys": [...], "tokens": [...], "replies": n, "puts": n,
"error": str}.
"""

import argparse
import json
import os
import sys
import threading
import time

import zenoh


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--endpoint", required=True, help="tcp/ADDR or tls/ADDR")
    p.add_argument("--ca", help="a root certificate to trust (tls/)")
    p.add_argument("--cert", help="a client certificate (tls/)")
    p.add_argument("--key", help="its private key (tls/)")
    p.add_argument("--until", required=True, help="stop once this file exists")
    p.add_argument("--deadline", type=float, default=120.0, help="stop after this many seconds")
    p.add_argument("--put", help="also publish a frame that does not decode on this key, each round")
    a = p.parse_args()

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([a.endpoint]))
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    tls = "transport/link/tls"
    if a.ca:
        conf.insert_json5(f"{tls}/root_ca_certificate", json.dumps(a.ca))
    if a.cert and a.key:
        for side in ("connect", "listen"):
            conf.insert_json5(f"{tls}/{side}_certificate", json.dumps(a.cert))
            conf.insert_json5(f"{tls}/{side}_private_key", json.dumps(a.key))
        conf.insert_json5(f"{tls}/enable_mtls", "true")
    conf.insert_json5(f"{tls}/verify_name_on_connect", "false")

    lock = threading.Lock()
    seen = {"samples": 0, "keys": set(), "tokens": set(), "replies": 0, "puts": 0, "error": ""}

    def on_sample(sample):
        with lock:
            seen["samples"] += 1
            seen["keys"].add(str(sample.key_expr))

    def on_token(sample):
        with lock:
            seen["tokens"].add(str(sample.key_expr))

    until = time.monotonic() + a.deadline
    try:
        session = zenoh.open(conf)
        # Only what comes from the network counts (not this client's own puts).
        sub = session.declare_subscriber("**", on_sample, allowed_origin=zenoh.Locality.REMOTE)
        tok = session.liveliness().declare_subscriber("**", on_token, history=True)
        while not os.path.exists(a.until) and time.monotonic() < until:
            for reply in session.get("**", timeout=0.5):
                if reply.ok is not None:
                    with lock:
                        seen["replies"] += 1
            if a.put:
                session.put(a.put, b"\xff" * 64, allowed_destination=zenoh.Locality.REMOTE)
                seen["puts"] += 1
            time.sleep(0.2)
        sub.undeclare()
        tok.undeclare()
        session.close()
    except Exception as e:  # noqa: BLE001 - reported, the test decides
        seen["error"] = f"{type(e).__name__}: {e}"
    with lock:
        out = {
            "samples": seen["samples"],
            "keys": sorted(seen["keys"])[:20],
            "tokens": sorted(seen["tokens"])[:20],
            "replies": seen["replies"],
            "puts": seen["puts"],
            "error": seen["error"],
        }
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
