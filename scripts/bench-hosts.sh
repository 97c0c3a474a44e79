#!/bin/sh
# One team over two "hosts" against one host, in the same session (docs/src/benchmarks/hosts.md).
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
# On the wire: both directions of host A's veth end, framing, TLS records and zenoh's own
# traffic included (the payload column counts our frames only).
wire_bytes() { ip netns exec "$a" cat /sys/class/net/veth0/statistics/rx_bytes \
  /sys/class/net/veth0/statistics/tx_bytes | awk '{ s += $1 } END { print s }'; }
echo "| N | hosts (link) | ticks | ticks/s | start-up s | crossing edges | payload bytes per tick | link bytes per tick |"
echo "|---|---|---|---|---|---|---|---|"
for n in $ns; do
  for how in ${HOW:-1 tcp tls}; do
    label=1; [ "$how" = 1 ] || label="2 ($how)"
    run=$((${run:-0} + 1)); team=bench$$$how$run
    w0=$(wire_bytes)
    fly_hosts "$how" "$out/log" "$out/daemon" "$team" --n "$n" --max-ticks "$ticks" \
      --out "$out/$team-$n" --no-figures
    rate=$(sed -n 's/.*ticking: [0-9.]* s (\([0-9]*\) ticks\/s), start-up \([0-9.]*\) s.*/\1 \2/p' "$out/log")
    wire=$(sed -n 's/.*hosts: \([0-9]*\) crossing edges, \([0-9]*\) bytes per tick.*/\1 \2/p' "$out/log")
    w1=$(wire_bytes)
    set -- ${rate:-- -} ${wire:-0 0}
    echo "| $n | $label | $((ticks + 1)) | $1 | $2 | $3 | $4 | $(( (w1 - w0) / (ticks + 1) )) |"
  done
done
