#!/bin/sh
# CPU of an idle team over two "hosts" (docs/src/benchmarks/hosts.md): the orchestrator and the daemon
# of a 10-agent team whose members are all stopped (SIGSTOP), so nothing moves and every cycle
# the two processes spend is their own waiting (bridges, heartbeats, deadlines). Reads utime +
# stime from /proc/<pid>/stat over WINDOW seconds (default 10). Needs root and release binaries.
# Usage: scripts/bench-hosts-idle.sh [BIN_DIR]   (default: target/release of this checkout)
set -eu
. "$(dirname "$0")/two-hosts.sh"
dir=${1:-$(cd "$(dirname "$0")/.." && pwd)/target/release}
bin=$dir/orchestrator
window=${WINDOW:-10}
a=cdmidle$$a b=cdmidle$$b team=idle$$
out=$(mktemp -d)
cleanup() {
  [ -n "${members:-}" ] && kill -CONT $members 2>/dev/null
  [ -n "${orch:-}" ] && kill "$orch" 2>/dev/null; wait 2>/dev/null || true
  two_hosts_down; rm -rf "$out"
}
trap cleanup EXIT
two_hosts_up
link_args "${HOW:-tls}"
ip netns exec "$a" "$bin" launch --n 10 --t-total 600 --team "$team" --out "$out/run" \
  --no-figures --quiet --agent-timeout 120 --hosts 2 $listen_args \
  > "$out/log" 2>&1 &
orch=$!
daemon_in_b "$team" "$out/daemon"
i=0; until [ -s "$out/run/telemetry.csv" ] || [ $i -ge 600 ]; do sleep 0.1; i=$((i + 1)); done
# Every member on both hosts: agent or leader processes of this team.
members=$(pgrep -f -- "--team $team --id" || true)
kill -STOP $members
daemon=$(pgrep -f -- "host $connect_args --team $team" | tail -1)
sleep 1
cpu() { awk '{print $14 + $15}' "/proc/$1/stat"; }
o0=$(cpu "$orch"); d0=$(cpu "$daemon")
sleep "$window"
o1=$(cpu "$orch"); d1=$(cpu "$daemon")
hz=$(getconf CLK_TCK)
echo "| binaries | orchestrator CPU % | daemon CPU % |"
echo "|---|---|---|"
awk -v o=$((o1 - o0)) -v d=$((d1 - d0)) -v hz="$hz" -v w="$window" -v b="$dir" \
  'BEGIN { printf "| %s | %.1f | %.1f |\n", b, 100 * o / hz / w, 100 * d / hz / w }'
