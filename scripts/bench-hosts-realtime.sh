#!/bin/sh
# Real time over two "hosts" against one host, in the same session (issue 12; BENCHMARKS.md):
# `launch --realtime` with the members paced on one wall-clock start instant, host B's half
# behind a daemon with its own /dev/shm, crossing states over zenoh on a veth pair. Prints the
# pacing figures of the summary line (audit.json's `realtime`). Both "hosts" share this
# machine's clock, so this measures the transport, not clock synchronisation. Needs root and
# release binaries (cargo build --release). Usage:
#   [BIN_DIR=DIR] [TICKS=1000] scripts/bench-hosts-realtime.sh [N ...]   (default: 10 40)
set -eu
bin=${BIN_DIR:-$(cd "$(dirname "$0")/.." && pwd)/target/release}/orchestrator
ticks=${TICKS:-1000}
ns=${*:-10 40}
a=cdmbrt$$a b=cdmbrt$$b
out=$(mktemp -d)
cleanup() { ip netns del "$a" 2>/dev/null || true; ip netns del "$b" 2>/dev/null || true; rm -rf "$out"; }
trap cleanup EXIT
ip netns add "$a"; ip netns add "$b"
ip -n "$a" link add veth0 type veth peer name veth1 netns "$b"
ip -n "$a" addr add 10.77.0.1/24 dev veth0; ip -n "$b" addr add 10.77.0.2/24 dev veth1
for x in "$a veth0" "$b veth1" "$a lo" "$b lo"; do ip -n "${x% *}" link set "${x#* }" up; done
echo "| N | hosts | verdict | member ticks | late ticks | late % | neighbour age p50 ms | p99 ms | max ms | members reported |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for n in $ns; do
  for hosts in 1 2; do
    team=brt$$h$hosts
    common="--n $n --t-total 600 --max-ticks $ticks --realtime --team $team --out $out/$team-$n --no-figures"
    if [ "$hosts" = 1 ]; then
      ip netns exec "$a" "$bin" launch $common > "$out/log" 2>&1 || true
    else
      ip netns exec "$b" unshare --mount sh -c 'mount -t tmpfs tmpfs /dev/shm && exec "$0" "$@"' \
        "$bin" host --connect tcp/10.77.0.1:7447 --team "$team" --quiet > "$out/daemon" 2>&1 &
      ip netns exec "$a" "$bin" launch $common --hosts 2 --listen tcp/10.77.0.1:7447 \
        > "$out/log" 2>&1 || true
      wait
    fi
    verdict=$(sed -n 's/.*verdict \([A-Z]*\).*/\1/p' "$out/log" | head -1)
    rt=$(sed -n 's/.*real time: \([0-9]*\) ticks, \([0-9]*\) late (\([0-9.]*\) %), neighbour age p50 \([0-9.]*\) ms, p99 \([0-9.]*\) ms, max \([0-9.]*\) ms (\([0-9]*\) of.*/\1 \2 \3 \4 \5 \6 \7/p' "$out/log")
    set -- ${rt:-- - - - - - -}
    echo "| $n | $hosts | ${verdict:-?} | $1 | $2 | $3 | $4 | $5 | $6 | $7 of $n |"
  done
done
