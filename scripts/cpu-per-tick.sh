#!/usr/bin/env bash
# CPU time per tick of `orchestrator launch` (orchestrator + members; the replay drawing, measured
# again with `orchestrator view`, subtracted) against the in-process engine's, for the binaries in
# BIN at N = N, one line per run. CPU time does not depend on what else the machine runs, so on a
# shared machine it compares builds where wall-clock rates cannot (BENCHMARKS.md, issue 17).
#
# Usage: scripts/cpu-per-tick.sh BIN N   (e.g. scripts/cpu-per-tick.sh target/release 40)
set -euo pipefail
bin=$1; n=$2; eticks=${ENGINE_TICKS:-20000}; out=$(mktemp -d /tmp/cdm-cpu.XXXXXX)
trap 'rm -rf "$out"' EXIT
cpu() { /usr/bin/time -f "%U %S" "$@" 2>&1 >/dev/null | tail -1 | awk '{print $1+$2}'; }
e=$(cpu "$bin/cdm-bench" engine --n "$n" --ticks "$eticks")
l=$( { /usr/bin/time -f "CPU %U %S" "$bin/orchestrator" launch --n "$n" --no-figures --out "$out/l" --team "cpu$$" ; } 2>&1 )
lc=$(grep "^CPU" <<<"$l" | awk '{print $2+$3}')
rate=$(grep "ticking:" <<<"$l" | sed -E 's/.*\(([0-9]+) ticks\/s\).*/\1/')
ticks=$(python3 -c "import json;print(json.load(open('$out/l/audit.json')).get('ticks', 0))" 2>/dev/null || echo 0)
v=$(cpu "$bin/orchestrator" view "$out/l")
python3 - "$e" "$lc" "$v" "$rate" "$n" "$ticks" "$eticks" <<'PY'
import sys
e, lc, v, rate, n, ticks, eticks = map(float, sys.argv[1:])
if not ticks:
    sys.exit("no tick count in audit.json")
eng_us = e / eticks * 1e6
launch_us = (lc - v) / ticks * 1e6
print(f"N={int(n)} engine {eng_us:.1f} us CPU/tick, launch {launch_us:.1f} us CPU/tick (view {v:.2f} s subtracted), "
      f"CPU ratio engine/launch {eng_us/launch_us:.3f}, x2 cores {2*eng_us/launch_us:.2f}; wall rate {int(rate)}")
PY
