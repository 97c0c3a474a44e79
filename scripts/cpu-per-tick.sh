#!/usr/bin/env bash
# CPU time per tick of `orchestrator launch` (orchestrator + members; the replay drawing, measured
# again with `orchestrator view`, subtracted) against the in-process engine's, for the binaries in
# BIN at N = N, one line per run. CPU time does not depend on what else the machine runs, so on a
# shared machine it compares builds where wall-clock rates cannot (docs/src/benchmarks/history.md).
#
# Usage: scripts/cpu-per-tick.sh BIN N   (e.g. scripts/cpu-per-tick.sh target/release 40)
# Environment: ENGINE_TICKS (default 20000) ticks of `cdm-bench engine`; MAX_TICKS flies only
# ticks 0..=MAX_TICKS and subtracts a second launch of 10 ticks (start-up and stop, which dominate
# a short run at N = 1000); LAUNCH_ARGS are added to both launches (e.g. "--telemetry parquet").
set -euo pipefail
bin=$1; n=$2; eticks=${ENGINE_TICKS:-20000}; out=$(mktemp -d /tmp/cdm-cpu.XXXXXX)
trap 'rm -rf "$out"' EXIT
cpu() { /usr/bin/time -f "%U %S" "$@" 2>&1 >/dev/null | tail -1 | awk '{print $1+$2}'; }
# One launch (extra arguments appended) in $out/$1: prints "CPU-seconds-minus-replay ticks rate".
fly() {
  local name=$1; shift
  local dir=$out/$name l lc rate ticks v
  # shellcheck disable=SC2086 # LAUNCH_ARGS is a list of words
  l=$( { /usr/bin/time -f "CPU %U %S" "$bin/orchestrator" launch --n "$n" --no-figures \
        --out "$dir" --team "cpu$$$name" ${LAUNCH_ARGS:-} "$@" ; } 2>&1 )
  lc=$(grep "^CPU" <<<"$l" | awk '{print $2+$3}')
  rate=$(grep "ticking:" <<<"$l" | sed -E 's/.*\(([0-9]+) ticks\/s\).*/\1/' || echo 0)
  ticks=$(python3 -c "import json;print(json.load(open('$dir/audit.json')).get('ticks', 0))" 2>/dev/null || echo 0)
  v=$(cpu "$bin/orchestrator" view "$dir")
  echo "$(awk -v a="$lc" -v b="$v" 'BEGIN{print a-b}') $ticks ${rate:-0}"
}
e=$(cpu "$bin/cdm-bench" engine --n "$n" --ticks "$eticks")
if [ -n "${MAX_TICKS:-}" ]; then
  read -r lc ticks rate < <(fly long --max-ticks "$MAX_TICKS")
  read -r lc0 ticks0 _ < <(fly short --max-ticks 9)
else
  read -r lc ticks rate < <(fly full)
  lc0=0; ticks0=0
fi
python3 - "$e" "$lc" "$lc0" "$ticks" "$ticks0" "$rate" "$n" "$eticks" <<'PY'
import sys
e, lc, lc0, ticks, ticks0, rate, n, eticks = map(float, sys.argv[1:])
if ticks <= ticks0:
    sys.exit("no tick count in audit.json")
eng_us = e / eticks * 1e6
launch_us = (lc - lc0) / (ticks - ticks0) * 1e6
print(f"N={int(n)} engine {eng_us:.1f} us CPU/tick, launch {launch_us:.1f} us CPU/tick "
      f"({int(ticks - ticks0)} ticks, replay subtracted), CPU ratio engine/launch "
      f"{eng_us/launch_us:.3f}, x2 cores {2*eng_us/launch_us:.2f}; wall rate {int(rate)}")
PY
