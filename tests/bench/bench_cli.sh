#!/usr/bin/env bash
# tests/bench/bench_cli.sh — what a user runs, timed (issue 17, item 1): `omnitwin run` of the
# thesis line for every bus at a 10 ms and a 1 ms controller period — the whole process, with
# its records (trajectory.csv, bus.csv, events.log, the bus capture), the master process and
# the transport the run picks (veth as root) — beside bus direct and beside physics alone
# (`omnitwin replay` of the direct run: the recorded set-points, no master, bus or records),
# all in one invocation on one machine. No video, no report (they are timed in
# bench_run_outputs). Each configuration runs REPS times (default 3); the median counts.
#
#   tests/bench/bench_cli.sh [OUT.md]    (scripts/bench calls it; OUT.md default build/bench/cli.md)
#
# The real-time factor of a row = simulated seconds / the wall seconds of the whole process
# (start to exit, as `time` measures it). The in-run factor (metrics.json real_time_factor:
# the run loop alone, without start-up and closing) is given beside it.
set -euo pipefail
# shellcheck source=tests/bench/cli_common.sh
source "$(dirname "${BASH_SOURCE[0]}")/cli_common.sh"
out_md="${1:-$build/bench/cli.md}"
reps="${REPS:-3}"
work="$(mktemp -d /tmp/omnitwin-bench-cli-XXXXXX)"
trap 'rm -rf "$work"' EXIT

metric() { python3 -c "import json,sys; m=json.load(open(sys.argv[1])); print(m.get(sys.argv[2], 'nan'))" "$1" "$2"; }

# One timed run: prints "wall_s sim_s in_run_rtf exit_code" or "refused <why>". Exit 1 (the
# scenario's expectations failed) is a timed run all the same; 2 and 3 are not.
timed_run() {
  local bus="$1" period="$2" dir="$3"
  local t0 t1 rc=0
  t0=$(now_ns)
  # shellcheck disable=SC2046
  "$omnitwin" run "$scenario" --bus "$bus" --set controller.period="$period" $(extra_sets "$bus" "$period") \
    --out "$dir" --no-video --no-report --no-progress > "$dir.log" 2>&1 || rc=$?
  t1=$(now_ns)
  if [ "$rc" -gt 1 ]; then
    echo "refused (exit $rc) $(grep -v '^ ' "$dir.log" | tail -1 | tr -d '|')"
    return
  fi
  echo "$(( (t1 - t0) / 1000 )) $(metric "$dir/metrics.json" sim_time_s) $(metric "$dir/metrics.json" real_time_factor) $rc" |
    awk '{printf "%.4f %s %s %s\n", $1 / 1e6, $2, $3, $4}'
}

{
  echo "| period | bus | RTF, whole CLI process | ÷ direct | in-run RTF | sim [s] | note |"
  echo "|---|---|---|---|---|---|---|"
} > "$work/table.md"
for period in 0.010 0.001; do
  direct_rtf="" direct_inrun=""
  for bus in "${buses[@]}"; do
    rtfs=() inrun=() sim="" refused="" note=""
    for ((r = 0; r < reps; r++)); do
      d="$work/$bus-$period-$r"
      line=$(timed_run "$bus" "$period" "$d")
      if [[ $line == refused* ]]; then refused="${line#refused }"; break; fi
      read -r wall s ir rc <<< "$line"
      sim=$s
      [ "$rc" = 1 ] && note="expectations failed"
      rtfs+=("$(awk -v s="$s" -v w="$wall" 'BEGIN {printf "%.3f", s / w}')")
      inrun+=("$ir")
    done
    if [ -n "$refused" ]; then
      echo "| $period | $bus | refused: $refused | | | | |" >> "$work/table.md"
      continue
    fi
    rtf=$(printf '%s\n' "${rtfs[@]}" | median)
    ir=$(printf '%s\n' "${inrun[@]}" | median)
    [ "$bus" = direct ] && direct_rtf=$rtf && direct_inrun=$ir
    ratio=$(awk -v a="$rtf" -v b="$direct_rtf" 'BEGIN {printf "%.2f", a / b}')
    [ -n "$(extra_sets "$bus" "$period")" ] && note="${note:+$note; }$(extra_sets "$bus" "$period")"
    printf '| %s | %s | %.1f× | %s | %.1f× | %.2f | %s |\n' "$period" "$bus" "$rtf" "$ratio" "$ir" "$sim" "$note" >> "$work/table.md"
    echo "period $period bus $bus: ${rtf}x (direct ${direct_rtf}x)" >&2
  done
  # Physics alone: the direct run's set-points, replayed (the whole process timed as well).
  # Its whole-process figure includes parsing trajectory.csv; the ratio compares the in-run
  # figures (the loop alone) of direct and of the replay.
  prts=() pins=()
  for ((r = 0; r < reps; r++)); do
    t0=$(now_ns)
    "$omnitwin" replay "$scenario" "$work/direct-$period-0" --set controller.period="$period" > "$work/replay.log"
    t1=$(now_ns)
    sim=$(sed -n 's/.* \([0-9.]*\) s simulated.*/\1/p' "$work/replay.log")
    pins+=("$(sed -n 's/.*(\([0-9.]*\)x real time).*/\1/p' "$work/replay.log")")
    prts+=("$(awk -v s="$sim" -v w="$(( (t1 - t0) / 1000 ))" 'BEGIN {printf "%.3f", s / (w / 1e6)}')")
  done
  prt=$(printf '%s\n' "${prts[@]}" | median)
  pin=$(printf '%s\n' "${pins[@]}" | median)
  ratio=$(awk -v a="$direct_inrun" -v b="$pin" 'BEGIN {printf "%.2f", a / b}')
  printf '| %s | physics alone (`omnitwin replay`) | %.1f× | in-run direct ÷ physics = %s | %.1f× | %s | reads trajectory.csv first |\n' \
    "$period" "$prt" "$ratio" "$pin" "$sim" >> "$work/table.md"
done
mkdir -p "$(dirname "$out_md")"
{
  echo "Measured $(date -u '+%Y-%m-%d %H:%M UTC') on $(nproc) cores ($(uname -r)), $reps runs each (median), by"
  echo "\`tests/bench/bench_cli.sh\` at $(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo '?'):"
  echo
  cat "$work/table.md"
} > "$out_md"
cat "$out_md"
