#!/usr/bin/env bash
# Start-up of `launch` before/after in one run (docs/src/benchmarks/history.md, "Start-up and scale"):
# this tree's binaries against another build's (OLD_BIN, e.g. a worktree of an older commit
# built with `cargo build --release --bins`), alternating old and new ROUNDS times for each
# `--on-loss` mode so both see the same drift of a shared machine. Each run is
# `orchestrator launch --n N --telemetry parquet --no-figures --max-ticks 1 --on-loss MODE`
# (start-up is measured to the first tick, so flying longer would change nothing); the number
# kept is the printed "start-up X s (command to first tick)". Beside it, the CPU time of the whole
# run (orchestrator and members, `perf stat -e task-clock`: start-up, one tick and the stop),
# which a loaded machine disturbs far less than wall time. Prints each run, the medians and
# their ratio (new / old), and the load average before and after.
# Usage: OLD_BIN=/path/to/old/target/release [ROUNDS=3] [N=1000] scripts/startup.sh
set -euo pipefail
cd "$(dirname "$0")/.."
: "${OLD_BIN:?set OLD_BIN to the target/release of an older build}"
rounds=${ROUNDS:-3} n=${N:-1000}
cargo build --release --quiet --bins
new=target/release
out=$(mktemp -d /tmp/cdm-startup.XXXXXX)
trap 'rm -rf "$out"' EXIT
startup() { sed -nE 's/.*start-up ([0-9.]+) s .*/\1/p'; }
median() { sort -n | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
echo "Machine: nproc $(nproc), load average $(cut -d' ' -f1-3 /proc/loadavg); new $(git rev-parse --short HEAD), old $OLD_BIN; $(date -u +%Y-%m-%dT%H:%MZ)"
echo
echo "| N | --on-loss | old start-up s (runs) | new start-up s (runs) | new / old (medians) | old CPU s (runs) | new CPU s (runs) | new / old CPU (medians) | load average after |"
echo "|---|---|---|---|---|---|---|---|---|"
for mode in repair stop; do
  : >"$out/old"
  : >"$out/new"
  : >"$out/old.cpu"
  : >"$out/new.cpu"
  for _ in $(seq "$rounds"); do
    for side in old new; do
      bin=$new
      [ "$side" = old ] && bin=$OLD_BIN
      perf stat -x, -e task-clock -o "$out/perf" -- \
        "$bin/orchestrator" launch --n "$n" --telemetry parquet --no-figures --max-ticks 1 \
        --on-loss "$mode" --force --out "$out/run" 2>&1 | startup >>"$out/$side"
      awk -F, '/task-clock/ {printf "%.2f\n", $1 / 1000}' "$out/perf" >>"$out/$side.cpu"
    done
  done
  o=$(median <"$out/old")
  w=$(median <"$out/new")
  oc=$(median <"$out/old.cpu")
  wc=$(median <"$out/new.cpu")
  ratio() { awk -v a="$1" -v b="$2" 'BEGIN{printf "%.2f", a/b}'; }
  echo "| $n | $mode | $o ($(paste -sd' ' "$out/old")) | $w ($(paste -sd' ' "$out/new")) | $(ratio "$w" "$o") | $oc ($(paste -sd' ' "$out/old.cpu")) | $wc ($(paste -sd' ' "$out/new.cpu")) | $(ratio "$wc" "$oc") | $(cut -d' ' -f1-3 /proc/loadavg) |"
done
