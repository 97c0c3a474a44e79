#!/bin/sh
# Real time over two "hosts" against one host, in the same session (docs/src/benchmarks/hosts.md):
# `launch --realtime` with the members paced on one wall-clock start instant, host B's half
# behind a daemon with its own /dev/shm, crossing states over zenoh on a veth pair. Prints the
# pacing figures of the summary line (audit.json's `realtime`). Both "hosts" share this
# machine's clock, so this measures the transport, not clock synchronisation. Needs root and
# release binaries (cargo build --release). Usage:
#   [BIN_DIR=DIR] [TICKS=1000] scripts/bench-hosts-realtime.sh [N ...]   (default: 10 40)
set -eu
. "$(dirname "$0")/two-hosts.sh"
bin=${BIN_DIR:-$(cd "$(dirname "$0")/.." && pwd)/target/release}/orchestrator
ticks=${TICKS:-1000}
ns=${*:-10 40}
a=cdmbrt$$a b=cdmbrt$$b
out=$(mktemp -d)
cleanup() { two_hosts_down; rm -rf "$out"; }
trap cleanup EXIT
two_hosts_up
echo "| N | hosts (link) | verdict | member ticks | late ticks | late % | neighbour age p50 ms | p99 ms | max ms | members reported |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for n in $ns; do
  for how in ${HOW:-1 tcp tls}; do
    label=1; [ "$how" = 1 ] || label="2 ($how)"
    run=$((${run:-0} + 1)); team=brt$$$how$run
    fly_hosts "$how" "$out/log" "$out/daemon" "$team" --n "$n" --t-total 600 \
      --max-ticks "$ticks" --realtime --out "$out/$team-$n" --no-figures
    verdict=$(sed -n 's/.*verdict \([A-Z]*\).*/\1/p' "$out/log" | head -1)
    rt=$(sed -n 's/.*real time: \([0-9]*\) ticks, \([0-9]*\) late (\([0-9.]*\) %), neighbour age p50 \([0-9.]*\) ms, p99 \([0-9.]*\) ms, max \([0-9.]*\) ms (\([0-9]*\) of.*/\1 \2 \3 \4 \5 \6 \7/p' "$out/log")
    set -- ${rt:-- - - - - - -}
    echo "| $n | $label | ${verdict:-?} | $1 | $2 | $3 | $4 | $5 | $6 | $7 of $n |"
  done
done
