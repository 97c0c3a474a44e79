#!/usr/bin/env bash
# A command to a running team (docs/src/benchmarks/features.md, "Commands to a running team"):
# for each N, `orchestrator launch --n N` in lockstep (a long --t-total, so the team is still
# flying), then `orchestrator command TEAM hold` and `... land`, each timed from the command's
# start to its exit (the answer: process start, connection, certificate, reply). Beside it, the
# team's own time to decide (`decided in X ms`: reading the request and certifying) and, from
# the launch's log, the time from the answer to the switch tick flown by every member
# (`every member flew the switch tick`). Prints a table and the load average.
# REALTIME=1 launches with --realtime instead: the switch is then chosen ahead and every leader
# acknowledges it first; the last column is how far ahead of the switch instant the command
# became final (the launch's log, `ahead_ms`).
# Usage: [REALTIME=1] [NS="40 250 1000"] scripts/bench-command.sh
set -euo pipefail
cd "$(dirname "$0")/.."
ns=${NS:-40 250 1000}
cargo build --release --quiet --bins
bin=target/release
out=$(mktemp -d /tmp/cdm-bench-command.XXXXXX)
trap 'rm -rf "$out"' EXIT
root=/dev/shm/cdm-iceoryx2-$(id -u)
echo "Machine: nproc $(nproc), load average $(cut -d' ' -f1-3 /proc/loadavg); $(git rev-parse --short HEAD); $(date -u +%Y-%m-%dT%H:%MZ)"
echo
echo "| N | command | to the answer (wall ms) | decided by the team (ms) | answer to switch flown (ms) |"
echo "|---|---|---|---|---|"
mode=()
switch_re='s/.*every member flew the switch tick.*after_ms=([0-9.]+).*/\1/p'
if [ -n "${REALTIME:-}" ]; then
  mode=(--realtime)
  switch_re='s/.*command: final.*ahead_ms=([0-9.e-]+).*/\1/p'
fi
for n in $ns; do
  team="bench_cmd_${n}_$$"
  RUST_LOG=info "$bin/orchestrator" launch --n "$n" --team "$team" --out "$out/run$n" "${mode[@]}" \
    --no-figures --t-total 600 --agent-timeout 120 >"$out/launch$n.out" 2>"$out/launch$n.log" &
  pid=$!
  until [ -S "$root/$team.command" ] && [ -s "$out/run$n/telemetry.csv" ]; do sleep 0.2; done
  sleep 1
  for c in hold land; do
    t0=$(date +%s%N)
    "$bin/orchestrator" command "$team" "$c" >"$out/$c$n.out"
    t1=$(date +%s%N)
    decided=$(sed -nE 's/decided in ([0-9.]+) ms/\1/p' "$out/$c$n.out")
    echo "$n $c $(( (t1 - t0) / 1000000 )) $decided" >>"$out/rows"
    sleep 1
  done
  kill -TERM "$pid"
  wait "$pid" || true
  # The launch's log lines of each switch, in command order.
  sed -nE "$switch_re" "$out/launch$n.log" >"$out/switch$n"
  k=0
  grep "^$n " "$out/rows" | while read -r nn c wall decided; do
    k=$((k + 1))
    sw=$(sed -n "${k}p" "$out/switch$n")
    [ -n "$sw" ] && sw=$(printf '%.1f' "$sw")
    printf '| %s | %s | %s | %s | %s |\n' "$nn" "$c" "$wall" "$decided" "${sw:-n/a}"
  done
done
echo
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
