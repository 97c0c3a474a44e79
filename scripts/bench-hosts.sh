#!/bin/sh
# One team over two "hosts" against one host, in the same session (issue 12; BENCHMARKS.md).
# Two network namespaces joined by a veth pair (10.77.0.1/24, 10.77.0.2/24); host B gets its own
# /dev/shm. Needs root and release binaries (cargo build --release). Usage:
#   [BIN_DIR=DIR] scripts/bench-hosts.sh [N ...]   (default: 40 250; BIN_DIR: other binaries)
set -eu
bin=${BIN_DIR:-$(cd "$(dirname "$0")/.." && pwd)/target/release}/orchestrator
ticks=${TICKS:-5000}
ns=${*:-40 250}
a=cdmbench$$a b=cdmbench$$b
out=$(mktemp -d)
cleanup() { ip netns del "$a" 2>/dev/null || true; ip netns del "$b" 2>/dev/null || true; rm -rf "$out"; }
trap cleanup EXIT
ip netns add "$a"; ip netns add "$b"
ip -n "$a" link add veth0 type veth peer name veth1 netns "$b"
ip -n "$a" addr add 10.77.0.1/24 dev veth0; ip -n "$b" addr add 10.77.0.2/24 dev veth1
for x in "$a veth0" "$b veth1" "$a lo" "$b lo"; do set -- $x; ip -n "$1" link set "$2" up; done
echo "| N | hosts | ticks | ticks/s | start-up s | crossing edges | bytes per tick |"
echo "|---|---|---|---|---|---|---|"
for n in $ns; do
  for hosts in 1 2; do
    team=bench$$h$hosts
    if [ "$hosts" = 1 ]; then
      ip netns exec "$a" "$bin" launch --n "$n" --max-ticks "$ticks" --team "$team" \
        --out "$out/$team-$n" --no-figures > "$out/log" 2>&1
    else
      ip netns exec "$b" unshare --mount sh -c 'mount -t tmpfs tmpfs /dev/shm && exec "$0" "$@"' \
        "$bin" host --connect tcp/10.77.0.1:7447 --team "$team" --quiet > "$out/daemon" 2>&1 &
      ip netns exec "$a" "$bin" launch --n "$n" --max-ticks "$ticks" --team "$team" \
        --out "$out/$team-$n" --no-figures --hosts 2 --listen tcp/10.77.0.1:7447 > "$out/log" 2>&1
      wait
    fi
    rate=$(sed -n 's/.*ticking: [0-9.]* s (\([0-9]*\) ticks\/s), start-up \([0-9.]*\) s.*/\1 \2/p' "$out/log")
    wire=$(sed -n 's/.*hosts: \([0-9]*\) crossing edges, \([0-9]*\) bytes per tick.*/\1 \2/p' "$out/log")
    set -- $rate ${wire:-0 0}
    echo "| $n | $hosts | $((ticks + 1)) | $1 | $2 | $3 | $4 |"
  done
done
