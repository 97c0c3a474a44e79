#!/usr/bin/env python3
"""A hostile or broken process on a member's MAVLink port, for the tests of the member's link.

From its own UDP socket (so from another address than the member's vehicle), for --seconds, it
sends round after round of four datagrams to the member's port:
- LOCAL_POSITION_NED with the vehicle's own system id (--sysid, component 1), at --spoof-ned: a
  spoofed position, far from the team;
- HEARTBEAT with that system id, as PX4 would send it (a spoofed vehicle);
- --big-bytes of random bytes (default 65,000: about the largest UDP datagram);
- 64 random bytes.
At most --rounds-hz rounds a second. pymavlink encodes the MAVLink frames (MAVLink 2, the common
dialect), so they are valid frames with correct checksums, only not from the vehicle. It also
counts every datagram that comes back to its socket (the member must send it nothing) and prints
one JSON summary on stdout at the end.

Every loop is bounded by --seconds.
"""

import argparse
import json
import os
import random
import socket
import time

os.environ["MAVLINK20"] = "1"
os.environ["MAVLINK_DIALECT"] = "common"
from pymavlink import mavutil  # noqa: E402

mavutil.set_dialect("common")
mavlink = mavutil.mavlink

PX4_OFFBOARD_MODE = 6 << 16


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, required=True, help="the member's port")
    p.add_argument("--sysid", type=int, required=True, help="the member's vehicle's system id")
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--rounds-hz", type=float, default=1000.0)
    p.add_argument("--big-bytes", type=int, default=65000)
    p.add_argument("--spoof-ned", default="1000,1000,-50", help="the spoofed position (m, NED)")
    p.add_argument("--seed", type=int, default=7)
    a = p.parse_args()

    rng = random.Random(a.seed)
    north, east, down = (float(v) for v in a.spoof_ned.split(","))
    mav = mavlink.MAVLink(None, srcSystem=a.sysid, srcComponent=1)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
    sock.setblocking(False)
    to = (a.host, a.port)
    big = rng.randbytes(a.big_bytes)
    sent = {"positions": 0, "heartbeats": 0, "big": 0, "small": 0, "send_errors": 0}
    received = 0
    start = time.monotonic()
    period = 1.0 / a.rounds_hz
    next_round = start
    while time.monotonic() - start < a.seconds:
        boot_ms = int((time.monotonic() - start) * 1e3)
        frames = [
            ("positions", mav.local_position_ned_encode(boot_ms, north, east, down, 0, 0, 0).pack(mav)),
            ("heartbeats", mav.heartbeat_encode(
                mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4,
                mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED,
                PX4_OFFBOARD_MODE, mavlink.MAV_STATE_ACTIVE).pack(mav)),
            ("big", big),
            ("small", rng.randbytes(64)),
        ]
        for kind, data in frames:
            try:
                sock.sendto(data, to)
                sent[kind] += 1
            except (BlockingIOError, ConnectionRefusedError):
                sent["send_errors"] += 1
        while True:
            try:
                sock.recvfrom(65536)
                received += 1
            except (BlockingIOError, ConnectionRefusedError):
                break
        # At most --rounds-hz over any stretch: after a stall (this process not scheduled), the
        # schedule restarts from now instead of sending the missed rounds in one burst.
        next_round = max(next_round + period, time.monotonic())
        wait = next_round - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    print(json.dumps({"sent": sent, "received": received,
                      "seconds": round(time.monotonic() - start, 3)}), flush=True)


if __name__ == "__main__":
    main()
