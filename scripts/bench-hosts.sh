#!/bin/sh
# One team over two "hosts" against one host, in the same session (issue 12; BENCHMARKS.md).
# Two network namespaces joined by a veth pair (10.77.0.1/24, 10.77.0.2/24); host B gets its own
# /dev/shm. Needs root and release binaries (cargo build --release). Usage:
#   [BIN_DIR=DIR] scripts/bench-hosts.sh [N ...]   (default: 40 250; BIN_DIR: other binaries)
set -eu
. "$(dirname "$0")/two-hosts.sh"
bin=${BIN_DIR:-$(cd "$(dirname "$0")/.." && pwd)/target/release}/orchestrator
ticks=${TICKS:-5000}
ns=${*:-40 250}
a=cdmbench$$a b=cdmbench$$b
out=$(mktemp -d)
cleanup() { two_hosts_down; rm -rf "$out"; }
trap cleanup EXIT
two_hosts_up
echo "| N | hosts | ticks | ticks/s | start-up s | crossing edges | bytes per tick |"
echo "|---|---|---|---|---|---|---|"
for n in $ns; do
  for hosts in 1 2; do
    team=bench$$h$hosts
    fly_hosts "$hosts" "$out/log" "$out/daemon" "$team" --n "$n" --max-ticks "$ticks" \
      --out "$out/$team-$n" --no-figures
    rate=$(sed -n 's/.*ticking: [0-9.]* s (\([0-9]*\) ticks\/s), start-up \([0-9.]*\) s.*/\1 \2/p' "$out/log")
    wire=$(sed -n 's/.*hosts: \([0-9]*\) crossing edges, \([0-9]*\) bytes per tick.*/\1 \2/p' "$out/log")
    set -- $rate ${wire:-0 0}
    echo "| $n | $hosts | $((ticks + 1)) | $1 | $2 | $3 | $4 |"
  done
done
