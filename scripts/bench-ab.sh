#!/usr/bin/env bash
# Before/after tick rates of `launch` in one run (docs/src/benchmarks/history.md): this tree's
# binaries against another build's (OLD_BIN, e.g. a worktree of an older commit built with
# `cargo build --release --bins`), alternating old and new ROUNDS times so both see the same
# drift of a shared machine. N = 40 flies its full plan; N = 1000 flies TICKS_1000 ticks (default
# 3000). Prints each run and the median ticks/s per side and their ratio (new / old).
#
# NEW_FLAGS: extra launch flags for the new side only (e.g. "--on-loss stop": the older build
# had no repair room to size).
# Usage: OLD_BIN=/path/to/old/target/release [ROUNDS=3] [TICKS_1000=3000] [NEW_FLAGS=...] scripts/bench-ab.sh
set -euo pipefail
cd "$(dirname "$0")/.."
: "${OLD_BIN:?set OLD_BIN to the target/release of an older build}"
rounds=${ROUNDS:-3} ticks_1000=${TICKS_1000:-3000}
cargo build --release --quiet
new=target/release
out=$(mktemp -d /tmp/cdm-ab.XXXXXX)
trap 'rm -rf "$out"' EXIT
rate() { sed -nE 's/.*ticking: .*\(([0-9]+) ticks\/s\).*/\1/p'; }
median() { sort -n | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
echo "Machine: nproc $(nproc), load average $(cut -d' ' -f1-3 /proc/loadavg); new $(git rev-parse --short HEAD)${NEW_FLAGS:+ with $NEW_FLAGS}, old $OLD_BIN; $(date -u +%Y-%m-%dT%H:%MZ)"
echo
echo "| N | ticks | old ticks/s (runs) | new ticks/s (runs) | new / old (medians) | load average after |"
echo "|---|---|---|---|---|---|"
for n in 40 1000; do
  extra=(); ticks=full
  [ "$n" = 40 ] || { extra=(--max-ticks "$ticks_1000"); ticks=$ticks_1000; }
  : >"$out/old" ; : >"$out/new"
  for _ in $(seq "$rounds"); do
    for side in old new; do
      bin=$new; [ "$side" = old ] && bin=$OLD_BIN
      flags=(); [ "$side" = new ] && read -ra flags <<<"${NEW_FLAGS:-}"
      "$bin/orchestrator" launch --n "$n" "${extra[@]}" "${flags[@]}" --no-figures --force --out "$out/run" 2>&1 \
        | rate >>"$out/$side"
    done
  done
  o=$(median <"$out/old"); w=$(median <"$out/new")
  echo "| $n | $ticks | $o ($(paste -sd' ' "$out/old")) | $w ($(paste -sd' ' "$out/new")) | $(awk -v a="$w" -v b="$o" 'BEGIN{printf "%.2f", a/b}') | $(cut -d' ' -f1-3 /proc/loadavg) |"
done
