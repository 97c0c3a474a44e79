"""A packet capture on one interface (a raw AF_PACKET socket; needs root, as tcpdump does):
every frame's bytes appended to OUT until a stop file appears. Prints one JSON line
{"packets": n, "bytes": n} at the end. The test searches OUT for what must not be in clear."""

import argparse
import json
import os
import select
import socket
import sys
import time

ETH_P_ALL = 0x0003


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--iface", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--until", required=True, help="stop once this file exists")
    p.add_argument("--ready", required=True, help="created once the socket is bound")
    p.add_argument("--deadline", type=float, default=300.0)
    a = p.parse_args()
    s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
    s.bind((a.iface, 0))
    open(a.ready, "w").close()
    packets = total = 0
    until = time.monotonic() + a.deadline
    with open(a.out, "wb") as out:
        while not os.path.exists(a.until) and time.monotonic() < until:
            r, _, _ = select.select([s], [], [], 0.2)
            if not r:
                continue
            frame = s.recv(65536)
            packets += 1
            total += len(frame)
            out.write(frame)
    print(json.dumps({"packets": packets, "bytes": total}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
