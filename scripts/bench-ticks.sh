#!/usr/bin/env bash
# Ticks per second of `simulate` (in-process engine) and `launch` (one process per quadcopter)
# for generated teams, full plans, telemetry written every tick. Prints a Markdown table.
# Usage: [WINDOW=4] scripts/bench-ticks.sh [N ...]   (default: 10 40 100).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=target/release/orchestrator
out=$(mktemp -d /tmp/cdm-bench.XXXXXX)
trap 'rm -rf "$out"' EXIT
window=${WINDOW:-4}
ns=("$@"); [ ${#ns[@]} -gt 0 ] || ns=(10 40 100)
echo "| N | ticks | simulate ticks/s | launch ticks/s (window $window) | launch start-up s | launch/simulate |"
echo "|---|---|---|---|---|---|"
for n in "${ns[@]}"; do
  s=$("$bin" simulate --n "$n" --no-figures --out "$out/s$n" 2>/dev/null | grep "^simulate:")
  ticks=$(sed -E 's/.* ([0-9]+) ticks in .*/\1/' <<<"$s")
  sim=$(sed -E 's/.*\(([0-9]+) ticks\/s\).*/\1/' <<<"$s")
  l=$("$bin" launch --n "$n" --no-figures --window "$window" --team "bench$n$$" --out "$out/l$n" 2>/dev/null | grep ticking)
  lt=$(sed -E 's/.*\(([0-9]+) ticks\/s\).*/\1/' <<<"$l")
  su=$(sed -E 's/.*start-up ([0-9.]+) s.*/\1/' <<<"$l")
  cmp -s "$out/s$n/telemetry.csv" "$out/l$n/telemetry.csv" || { echo "telemetry of launch and simulate differ for N=$n" >&2; exit 1; }
  echo "| $n | $ticks | $sim | $lt | $su | $(awk -v a="$lt" -v b="$sim" 'BEGIN{printf "%.2f", a/b}') |"
done
