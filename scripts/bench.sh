#!/usr/bin/env bash
# Every number of BENCHMARKS.md's main table in one run on this machine, so ratios hold when its
# speed drifts: the in-process engine alone (the arithmetic floor), `simulate` (engine + audit +
# telemetry, the same outputs as launch), `orchestrator launch` (one process per quadcopter), a
# bare iceoryx2 central barrier (no math), start-up (command to first tick) and peak memory.
# Also checks launch's telemetry is byte-identical to simulate's for every N.
#
# Then, at N = FORMATS_N (default 1000; FORMATS_N=0 skips it): the certificate (`plan`) against one
# in-process flight of the same plan (`simulate --every 1000`, almost no telemetry), and the
# full-telemetry `simulate` in each format (file size, wall time, peak memory); writing cost =
# that run's time minus the --every 1000 run's.
#
# Last, real time: `launch --realtime` at comm_hz = 100 for REALTIME_NS (default
# "10 40 100 250"; REALTIME_NS=0 skips it), REALTIME_S seconds of flight each (default 10): late
# ticks, neighbour age p50/p99/max and the CPU of the whole team over the flight (orchestrator and
# members, from /proc at the start instant and the last audit), all from audit.json's `realtime`;
# beside each row the 1-minute load average before and after the run (the machine may be shared).
# Each N flies twice: with ordinary scheduling, and with `--rt-priority RT_PRIORITY` (default 10;
# SCHED_FIFO, needs root or `ulimit -r`; RT_PRIORITY=0 skips these rows). After each N, the
# machine's own floor: N processes that only sleep to the same instants (`cdm-bench sleepers`).
# REALTIME_ONLY=1 runs only this section.
#
# Recording (RECORDING_ONLY=1, only on demand): for N in RECORDING_NS (default 40), ROUNDS
# (default 2) alternations of a real-time run of RECORDING_S seconds (default 10) with the
# members' recordings and with `--no-recording`: late ticks and the team's CPU, the recordings'
# and telemetry.csv's bytes per member-second, and the replay's wall time (and whether its
# telemetry is the run's) against `simulate` of the same plan.
#
# Scale, after the main table: for N in SCALE_NS (default 1000; SCALE_NS=0 skips it)
# and, opt-in, BENCH_N (e.g. BENCH_N=2000: 2000 processes, a full plan of about 66,000 ticks,
# tens of minutes on 2 cores): the engine alone, start-up (command to first tick) with
# `--on-loss stop` (10 ticks flown; not for BENCH_N), then the full plan with `--telemetry
# parquet` (its start-up is the one with the default `--on-loss repair`): ticks/s against the engine, the members' peak RSS (largest and sum of
# VmHWM) and the machine's used memory (`free`, before and the most seen during the flight).
# BENCH_N_FLAGS: extra launch flags for BENCH_N's flight only (e.g. "--agent-timeout 60").
# SCALE_ONLY=1 runs only this section.
#
# Before and after, with BEFORE_BIN=DIR (the binaries of an older build, e.g. `git worktree add
# /tmp/before <commit> && (cd /tmp/before && cargo build --release --bins)`): the same commands
# with both builds in this run, alternated ROUNDS times (default 3; medians and every run): the
# certificate (`plan --n FORMATS_N` against `simulate --every 1000` of the same build),
# `launch --n 40` (full plan) and `launch --n 1000 --max-ticks 2999` against each build's engine,
# and their start-up (command to first tick, default `--on-loss repair`; CSV telemetry on both
# sides). BEFORE_ONLY=1 runs only this section.
#
# Telemetry (TELEMETRY_ONLY=1 runs only this section; not part of a full run): at N = TELEMETRY_N
# (default 1000), TELEMETRY_TICKS ticks (default: the full plan), a flight with almost no
# telemetry (`--every 1000`) and the same flight writing every tick to telemetry.parquet
# (`--every 1`), alternated ROUNDS times: medians and every run of both wall times, the writing
# cost over the flight ((with - without) / without) and the file's bytes a row.
#
# Every flight above writes every tick (`--every 1`, as before the default --every grew with N),
# so the figures compare with earlier runs of this script.
#
# Usage: [BIN=DIR] [WINDOW=W] [QUICK=1] [FORMATS_N=1000] [REALTIME_NS="10 40"] [REALTIME_S=10]
#        [REALTIME_ONLY=1] [SCALE_NS="1000"] [BENCH_N=2000] [BENCH_N_FLAGS=...] [SCALE_ONLY=1]
#        [BEFORE_BIN=DIR] [ROUNDS=3] [BEFORE_ONLY=1]
#        [TELEMETRY_ONLY=1] [TELEMETRY_N=1000] [TELEMETRY_TICKS=K]
#        [RECORDING_ONLY=1] [RECORDING_NS="40 250"] [RECORDING_S=10] scripts/bench.sh [N ...]
#   (default N: 10 40 100 250 1000)
#   Full plans for N <= 100 and N = 1000; N = 250 flies 5000 ticks (stated in the table).
#   QUICK=1: N = 1000 flies 3000 ticks instead of its full plan (46,601 ticks, about 3 minutes).
set -euo pipefail
cd "$(dirname "$0")/.."
# BIN=DIR times the binaries in DIR (orchestrator, agent, leader, cdm-bench; e.g. an older
# commit's, for a before/after pair in one session) and builds nothing.
if [ -n "${BIN:-}" ]; then
  bin=$BIN
else
  cargo build --release --quiet
  bin=target/release
fi
out=$(mktemp -d /tmp/cdm-bench.XXXXXX)
trap 'rm -rf "$out"' EXIT
# WINDOW=W flies the main table with --window W; unset, launch picks its default for each N.
window=${WINDOW:-}
window_flag=(); [ -z "$window" ] || window_flag=(--window "$window")
ns=("$@"); [ ${#ns[@]} -gt 0 ] || ns=(10 40 100 250 1000)

echo "Machine: nproc $(nproc), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'),"\
  "$(awk '/MemTotal/ {printf "%.0f GiB", $2/1048576}' /proc/meminfo), kernel $(uname -r);"\
  "commit $(git rev-parse --short HEAD 2>/dev/null || echo '?'), $(date -u +%Y-%m-%dT%H:%MZ)."
echo "Command:${window:+ WINDOW=$window}${QUICK:+ QUICK=$QUICK}${BIN:+ BIN=$BIN} scripts/bench.sh ${ns[*]}"
echo

# Real time: one `launch --realtime` per N, REALTIME_S seconds of a 60 s plan.
realtime_section() {
  local rns=(${REALTIME_NS:-10 40 100 250}) rs=${REALTIME_S:-10}
  [ "${rns[0]}" != 0 ] || return 0
  echo
  echo "Real time (\`launch --n N --t-total 60 --max-ticks $((rs * 100)) --realtime\`, comm_hz 100, $rs s of flight):"
  echo
  echo "| N | scheduling | member ticks | late ticks | late % | neighbour age p50 ms | p99 ms | max ms | slowest member (late ticks, max late ms) | wall s (start to last audit) | team CPU (cores) | load average before / after |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
  local prio=${RT_PRIORITY:-10} scheds=(normal)
  [ "$prio" = 0 ] || scheds+=("fifo")
  for n in "${rns[@]}"; do
  for sched in "${scheds[@]}"; do
    local load_before flags=() label="normal (CFS)"; load_before=$(cut -d' ' -f1 /proc/loadavg)
    [ "$sched" = normal ] || { flags=(--rt-priority "$prio"); label="SCHED_FIFO $prio"; }
    "$bin/orchestrator" launch --n "$n" --t-total 60 --max-ticks $((rs * 100)) --realtime \
      "${flags[@]}" --no-figures --quiet --out "$out/rt$n" >/dev/null 2>&1 || true
    python3 - "$out/rt$n/audit.json" "$n" "$load_before" "$(cut -d' ' -f1 /proc/loadavg)" "$label" <<'PY'
import json, sys
a = json.load(open(sys.argv[1]))
r = a["realtime"]
load = f"{sys.argv[3]} / {sys.argv[4]}"
s = r["slowest_member"] or {}
cpu = r.get("team_cpu_cores")
cpu = "?" if cpu is None else f"{cpu:.2f}"
print(f"| {sys.argv[2]} | {sys.argv[5]} | {r['ticks']} | {r['late_ticks']} | {r['late_ticks_pct']:.3f} | "
      f"{r['neighbor_age_ms_p50']:.2f} | {r['neighbor_age_ms_p99']:.2f} | {r['neighbor_age_ms_max']:.2f} | "
      f"{s.get('id')} ({s.get('late_ticks')}, {s.get('max_late_ms', 0):.1f}) | {r['wall_s']:.2f} | {cpu} "
      f"(verdict {a['verdict']}, {r['members_reported']}/{a['agents']} reported) | {load} |")
PY
    rm -rf "$out/rt$n"
  done
  # The machine's own floor in the same run: N processes that only sleep to the same 10 ms
  # instants (`cdm-bench sleepers`), with ordinary scheduling; late = more than a period after.
  if [ -x "$bin/cdm-bench" ] && "$bin/cdm-bench" sleepers --help >/dev/null 2>&1; then
    local lb fl; lb=$(cut -d' ' -f1 /proc/loadavg)
    fl=$("$bin/cdm-bench" sleepers --n "$n" --secs "$rs" || echo "sleepers failed")
    echo "$fl" | sed -E 's/^sleepers: ([0-9]+) processes .*: ([0-9]+) of ([0-9]+) wake-ups late \(([0-9.]+) %\), latest ([0-9.]+) ms.*/| \1 | floor: \1 processes that only sleep (CFS) | \3 | \2 | \4 | - | - | - | (latest wake-up \5 ms after its instant) | - | - | LOADS |/' \
      | sed "s#LOADS#$lb / $(cut -d' ' -f1 /proc/loadavg)#"
  fi
  done
}

# Scale: start-up and a full plan with Parquet telemetry at large N (see the header).
rate() { sed -E 's/.*\(([0-9]+) ticks\/s\).*/\1/'; }
startup_s() { sed -E 's/.*start-up ([0-9.]+) s.*/\1/'; }  # from launch's "ticking:" line
used_kib() { awk '/^Mem:/ {print $3}' < <(free -k); }
scale_section() {
  local sns=(${SCALE_NS:-1000})
  [ "${sns[0]}" != 0 ] || sns=()
  [ -z "${BENCH_N:-}" ] || sns+=("$BENCH_N")
  [ ${#sns[@]} -gt 0 ] || return 0
  echo
  echo "Scale (\`launch --n N --every 1 --telemetry parquet --no-figures\`, full plan; load average before: $(cut -d' ' -f1-3 /proc/loadavg)):"
  echo
  echo "| N | ticks flown | engine ticks/s | launch ticks/s | launch/engine | start-up s, --on-loss stop | start-up s, repair (default) | largest member MiB | all members MiB (sum of VmHWM) | orchestrator MiB | machine used MiB before / peak | load average after |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
  for n in "${sns[@]}"; do
    local eng l su_stop su_rep mem before peak=0 pid
    eng=$("$bin/cdm-bench" engine --n "$n" --ticks 1000 | rate)
    startup() {
      "$bin/orchestrator" launch --n "$n" --max-ticks 9 --no-figures --team "scale$n-$$" \
        --out "$out/su$n" --force "$@" 2>/dev/null | grep "ticking:" | startup_s
      rm -rf "$out/su$n"
    }
    # BENCH_N's row is long enough already: its start-up is the full flight's (repair) only.
    su_stop=-; [ "$n" = "${BENCH_N:-}" ] || su_stop=$(startup --on-loss stop)
    before=$(used_kib)
    local extra=(); [ "$n" != "${BENCH_N:-}" ] || extra=(${BENCH_N_FLAGS:-})
    "$bin/orchestrator" launch --n "$n" --every 1 --telemetry parquet --no-figures --team "scale$n-$$" \
      --out "$out/sc$n" "${extra[@]}" >"$out/sc$n.log" 2>/dev/null &
    pid=$!
    while kill -0 "$pid" 2>/dev/null; do
      local u; u=$(used_kib); [ "$u" -le "$peak" ] || peak=$u
      sleep 2
    done
    # A failed flight's reason, before the log is removed with the rest of $out.
    wait "$pid" || { echo "launch --n $n exited with $?" >&2; grep -v "^error: agent" "$out/sc$n.log" | tail -5 >&2; }
    l=$(cat "$out/sc$n.log")
    local lt ticks member orch all
    lt=$(grep "ticking:" <<<"$l" | rate)
    su_rep=$(grep "ticking:" <<<"$l" | startup_s)
    ticks=$(grep -E "^launch:" <<<"$l" | sed -E 's/.* ([0-9]+) ticks in .*/\1/')
    mem=$(grep "peak resident memory" <<<"$l")
    member=$(sed -E 's/.*largest member ([0-9.]+) MiB.*/\1/' <<<"$mem")
    orch=$(sed -E 's/.*orchestrator ([0-9.]+) MiB.*/\1/' <<<"$mem")
    all=$(sed -E 's/.*together ([0-9.]+) MiB.*/\1/' <<<"$mem")
    echo "| $n | $ticks | $eng | $lt | $(awk -v a="$lt" -v b="$eng" 'BEGIN{printf "%.2f", a/b}') | $su_stop | $su_rep | $member | $all | $orch | $((before / 1024)) / $((peak / 1024)) | $(cut -d' ' -f1-3 /proc/loadavg) |"
    rm -rf "$out/sc$n" "$out/sc$n.log"
  done
}
# Before and after (see the header): each figure from both builds, in this run. The launches
# alternate before / after, ROUNDS times (default 3), and the table gives each side's median with
# its runs: this machine drifts by 20 % or more between minutes, so only interleaved medians compare.
before_after_section() {
  [ -n "${BEFORE_BIN:-}" ] || return 0
  local fn=${FORMATS_N:-1000}; [ "$fn" -gt 0 ] || fn=1000
  local rounds=${ROUNDS:-3}
  echo
  echo "Before and after (before: $BEFORE_BIN, $("$BEFORE_BIN/orchestrator" --version 2>/dev/null || echo '?'); $rounds rounds, before and after alternated; load average before: $(cut -d' ' -f1-3 /proc/loadavg)):"
  echo
  echo "| figure | before: median (runs) | after: median (runs) | after / before (medians) |"
  echo "|---|---|---|---|"
  local b a
  cert() { # plan's wall time over one --every 1000 flight's, for the build in $1
    local p s
    p=$(secs "$1/orchestrator" plan --n "$fn" --quiet | cut -d' ' -f1)
    s=$(secs "$1/orchestrator" simulate --n "$fn" --every 1000 --no-figures --quiet --out "$out/ba" | cut -d' ' -f1)
    rm -rf "$out/ba"
    echo "$p $s"
  }
  read -r bp bs < <(cert "$BEFORE_BIN"); read -r ap as < <(cert "$bin")
  b=$(awk -v p="$bp" -v s="$bs" 'BEGIN{printf "%.3f", p/s}'); a=$(awk -v p="$ap" -v s="$as" 'BEGIN{printf "%.3f", p/s}')
  echo "| \`plan --n $fn\` / \`simulate --n $fn --every 1000\` (wall s) | $b ($bp / $bs) | $a ($ap / $as) | $(awk -v a="$a" -v b="$b" 'BEGIN{printf "%.3f", a/b}') |"
  for n in 40 1000; do
    local limit=() label="full plan" eng_ticks=5000
    [ "$n" = 40 ] || { limit=(--max-ticks 2999); label="3000 ticks"; eng_ticks=1000; }
    local side i rb=() ra=() sb=() sa=()
    for i in $(seq "$rounds"); do
      for side in "$BEFORE_BIN" "$bin"; do
        local e l r su
        e=$("$side/cdm-bench" engine --n "$n" --ticks "$eng_ticks" | rate)
        l=$("$side/orchestrator" launch --n "$n" "${limit[@]}" --every 1 --no-figures --team "ba$n-$$" --out "$out/ba" 2>/dev/null | grep "ticking:")
        rm -rf "$out/ba"
        r=$(awk -v l="$(rate <<<"$l")" -v e="$e" 'BEGIN{printf "%.3f", l/e}')
        su=$(startup_s <<<"$l")
        if [ "$side" = "$bin" ]; then ra+=("$r"); sa+=("$su"); else rb+=("$r"); sb+=("$su"); fi
      done
    done
    local mb ma
    mb=$(median <<<"${rb[*]}"); ma=$(median <<<"${ra[*]}")
    echo "| \`launch --n $n\` / engine, $label | $mb (${rb[*]}) | $ma (${ra[*]}) | $(awk -v a="$ma" -v b="$mb" 'BEGIN{printf "%.2f", a/b}') |"
    mb=$(median <<<"${sb[*]}"); ma=$(median <<<"${sa[*]}")
    echo "| start-up s, \`launch --n $n\` (command to first tick) | $mb (${sb[*]}) | $ma (${sa[*]}) | $(awk -v a="$ma" -v b="$mb" 'BEGIN{printf "%.2f", a/b}') |"
  done
}
# Recording (see the header): a real-time run with and without the members' recordings, alternated.
recording_section() {
  local rn=(${RECORDING_NS:-40}) rs=${RECORDING_S:-10} rounds=${ROUNDS:-2} n i rec
  echo "Recording (\`launch --n N --t-total 60 --max-ticks $((rs * 100)) --realtime [--no-recording]\`, $rs s of flight, $rounds rounds alternated):"
  echo
  echo "| N | recording | late ticks | late % | team CPU (cores) | recording bytes per member-second | telemetry.csv bytes per member-second | replay wall s (identical?) | simulate wall s | load average before / after |"
  echo "|---|---|---|---|---|---|---|---|---|---|"
  for n in "${rn[@]}"; do
  for i in $(seq "$rounds"); do
  for rec in on off; do
    local flags=() load_before; load_before=$(cut -d' ' -f1 /proc/loadavg)
    [ "$rec" = on ] || flags=(--no-recording)
    "$bin/orchestrator" launch --n "$n" --t-total 60 --max-ticks $((rs * 100)) --realtime \
      "${flags[@]}" --no-figures --quiet --out "$out/rec$n" >/dev/null 2>&1 || true
    local rbytes="-" tbytes replay="-" sim="-" rc=0
    tbytes=$(stat -c %s "$out/rec$n/telemetry.csv")
    if [ "$rec" = on ]; then
      rbytes=$(du -cb "$out/rec$n"/recording/*.mcap | tail -1 | cut -f1)
      # A replay exits with the run's outcome (1 a violation, 3 a fault: a member stale on a
      # loaded machine at N = 250) or 3 when it differs: a row either way, with the exit code,
      # never the end of the section (set -e).
      replay=$(secs "$bin/orchestrator" replay "$out/rec$n" --out "$out/rep$n" --no-figures | cut -d' ' -f1) || rc=$?
      cmp -s "$out/rec$n/telemetry.csv" "$out/rep$n/telemetry.csv" && replay="$replay (yes" || replay="$replay (no"
      [ "$rc" = 0 ] && replay="$replay)" || replay="$replay, exit $rc)"
      rc=0
      sim=$(secs "$bin/orchestrator" simulate --n "$n" --t-total 60 --max-ticks $((rs * 100)) --no-figures --quiet --out "$out/sim$n" | cut -d' ' -f1) || rc=$?
      [ "$rc" = 0 ] || sim="$sim (exit $rc)"
    fi
    python3 - "$out/rec$n/audit.json" "$n" "$rec" "$rbytes" "$tbytes" "$rs" "$replay" "$sim" "$load_before" "$(cut -d' ' -f1 /proc/loadavg)" <<'PY'
import json, sys
a = json.load(open(sys.argv[1])); r = a["realtime"]
n, s = int(sys.argv[2]), float(sys.argv[6])
per = lambda b: "-" if b == "-" else f"{int(b) / (n * s):.0f}"
cpu = r.get("team_cpu_cores"); cpu = "?" if cpu is None else f"{cpu:.2f}"
print(f"| {n} | {sys.argv[3]} | {r['late_ticks']} | {r['late_ticks_pct']:.3f} | {cpu} | {per(sys.argv[4])} | {per(sys.argv[5])} | "
      f"{sys.argv[7]} | {sys.argv[8]} | {sys.argv[9]} / {sys.argv[10]} |")
PY
    rm -rf "$out/rec$n" "$out/rep$n" "$out/sim$n"
  done
  done
  done
}
# Telemetry (see the header): the writing cost of telemetry.parquet, interleaved medians.
telemetry_section() {
  local tn=${TELEMETRY_N:-1000} rounds=${ROUNDS:-3} limit=() i
  [ -n "${TELEMETRY_TICKS:-}" ] && limit=(--max-ticks $((TELEMETRY_TICKS - 1)))
  local bare=() full=() size rows
  for i in $(seq "$rounds"); do
    bare+=("$(secs "$bin/orchestrator" simulate --n "$tn" "${limit[@]}" --every 1000 --no-figures --quiet --out "$out/tb" | cut -d' ' -f1)")
    rm -rf "$out/tb"
    full+=("$(secs "$bin/orchestrator" simulate --n "$tn" "${limit[@]}" --every 1 --telemetry parquet --no-figures --quiet --out "$out/tp" | cut -d' ' -f1)")
    size=$(stat -c %s "$out/tp/telemetry.parquet")
    rows=$(( $(jq .ticks "$out/tp/audit.json") * tn ))
    rm -rf "$out/tp"
  done
  local mb mf
  mb=$(median <<<"${bare[*]}"); mf=$(median <<<"${full[*]}")
  echo "Telemetry at N = $tn (${TELEMETRY_TICKS:-full plan}${TELEMETRY_TICKS:+ ticks}; $rounds rounds alternated; load average after: $(cut -d' ' -f1-3 /proc/loadavg)):"
  echo
  echo "| \`simulate --every 1000\` wall s: median (runs) | \`simulate --every 1 --telemetry parquet\` wall s: median (runs) | writing / flight (medians) | bytes a row |"
  echo "|---|---|---|---|"
  echo "| $mb (${bare[*]}) | $mf (${full[*]}) | $(awk -v a="$mf" -v b="$mb" 'BEGIN{printf "%.2f", (a-b)/b}') | $(awk -v s="$size" -v r="$rows" 'BEGIN{printf "%.2f (%.0f bytes, %.0f rows)", s/r, s, r}') |"
}
median() { tr ' ' '\n' | grep -v '^$' | sort -g | awk '{v[NR]=$1} END{if (NR%2) print v[(NR+1)/2]; else printf "%.3f\n", (v[NR/2]+v[NR/2+1])/2}'; }
secs() { /usr/bin/time -f "%e %M" "$@" 2>&1 >/dev/null | tail -1; }
if [ -n "${TELEMETRY_ONLY:-}" ]; then telemetry_section; exit 0; fi
if [ -n "${BEFORE_ONLY:-}" ]; then before_after_section; exit 0; fi
if [ -n "${SCALE_ONLY:-}" ]; then scale_section; exit 0; fi
if [ -n "${REALTIME_ONLY:-}" ]; then realtime_section; exit 0; fi
if [ -n "${RECORDING_ONLY:-}" ]; then recording_section; exit 0; fi
echo "| N | ticks flown | engine ticks/s | simulate ticks/s | launch ticks/s (window ${window:-default}) | barrier ticks/s | launch/engine | launch/simulate | launch/barrier | start-up s | largest member RSS MiB | orchestrator RSS MiB |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
for n in "${ns[@]}"; do
  limit=()
  case "$n" in
    250) limit=(--max-ticks 4999) ;;
    1000) [ -n "${QUICK:-}" ] && limit=(--max-ticks 2999) ;;
  esac
  eng_ticks=5000; [ "$n" -ge 1000 ] && eng_ticks=1000
  eng=$("$bin/cdm-bench" engine --n "$n" --ticks "$eng_ticks" | rate)
  s=$("$bin/orchestrator" simulate --n "$n" "${limit[@]}" --every 1 --no-figures --out "$out/s$n" 2>/dev/null | grep "^simulate:")
  sim=$(rate <<<"$s")
  ticks=$(sed -E 's/.* ([0-9]+) ticks in .*/\1/' <<<"$s")
  # simulate's telemetry (about 9 GB at N = 1000) is still being written back to disk: without
  # this, launch's start-up below would time the kernel's writeback too.
  sync
  l=$("$bin/orchestrator" launch --n "$n" "${limit[@]}" --every 1 --no-figures "${window_flag[@]}" \
      --team "bench$n-$$" --out "$out/l$n" 2>/dev/null)
  lt=$(grep "ticking:" <<<"$l" | rate)
  su=$(grep "ticking:" <<<"$l" | startup_s)
  mem=$(grep "peak resident memory" <<<"$l")
  member=$(sed -E 's/.*largest member ([0-9.]+) MiB.*/\1/' <<<"$mem")
  orch=$(sed -E 's/.*orchestrator ([0-9.]+) MiB.*/\1/' <<<"$mem")
  cmp -s "$out/s$n/telemetry.csv" "$out/l$n/telemetry.csv" \
    || { echo "telemetry of launch and simulate differ for N=$n" >&2; exit 1; }
  bar_ticks=2000; [ "$n" -ge 250 ] && bar_ticks=500; [ "$n" -ge 1000 ] && bar_ticks=200
  bar=$("$bin/cdm-bench" barrier --n "$n" --ticks "$bar_ticks" | rate)
  ratio() { awk -v a="$1" -v b="$2" 'BEGIN{printf "%.2f", a/b}'; }
  echo "| $n | $ticks | $eng | $sim | $lt | $bar | $(ratio "$lt" "$eng") | $(ratio "$lt" "$sim") | $(ratio "$lt" "$bar") | $su | $member | $orch |"
  rm -rf "$out/s$n" "$out/l$n"
done

fn=${FORMATS_N:-1000}
[ "$fn" -gt 0 ] || { scale_section; before_after_section; realtime_section; exit 0; }
echo
echo "Certificate and telemetry formats at N = $fn (one after the other, full plan):"
echo
echo "| command | wall s | peak RSS MiB | telemetry file MB | against simulate --every 1000 |"
echo "|---|---|---|---|---|"
read -r plan_s plan_kb < <(secs "$bin/orchestrator" plan --n "$fn" --quiet)
read -r base_s base_kb < <(secs "$bin/orchestrator" simulate --n "$fn" --every 1000 --no-figures --quiet --out "$out/base")
rm -rf "$out/base"
mib() { awk -v k="$1" 'BEGIN{printf "%.1f", k/1024}'; }
echo "| \`plan --n $fn\` | $plan_s | $(mib "$plan_kb") | | $(awk -v a="$plan_s" -v b="$base_s" 'BEGIN{printf "%.3f of the time", a/b}') |"
echo "| \`simulate --n $fn --every 1000\` | $base_s | $(mib "$base_kb") | | 1 |"
for fmt in csv parquet; do
  read -r f_s f_kb < <(secs "$bin/orchestrator" simulate --n "$fn" --every 1 --telemetry "$fmt" --no-figures --quiet --out "$out/$fmt")
  size=$(stat -c %s "$out/$fmt/telemetry.$fmt")
  echo "| \`simulate --n $fn --every 1 --telemetry $fmt\` | $f_s | $(mib "$f_kb") | $(awk -v b="$size" 'BEGIN{printf "%.0f", b/1e6}') | $(awk -v a="$f_s" -v b="$base_s" 'BEGIN{printf "writing costs %.1f s (%.2f x the flight)", a-b, (a-b)/b}') |"
  rm -rf "$out/$fmt"
done
echo
# A command's certificate (one hold while moving, one goto from where the team holds), which
# must stay well under a second at N = 1000: it runs between the request and the switch.
echo "Command certification (\`cdm-bench command --n N\`; load average before: $(cut -d' ' -f1-3 /proc/loadavg)):"
echo
for cn in 40 250 1000; do
  "$bin/cdm-bench" command --n "$cn" | sed 's/^/    /'
done
scale_section
before_after_section
realtime_section
