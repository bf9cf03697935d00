#!/usr/bin/env bash
# tests/bench/bench_ec_segment_cli.sh — the seeds' network sizes as a user runs them (issue 17,
# item 4): `omnitwin run` of the thesis line on bus ethercat at a 1 ms controller period with
# `bus.extra_axes` of seed 001's multi-axis slaves behind the four wheel drives, master and twin
# as two processes, every record written. Beside it, in the same invocation, the same run with
# no extra axes and bus direct (the baselines).
#   lockstep: the whole process's real-time factor and the in-run one, per axis count;
#   realtime: the run at 1 ms on the wall clock, from realtime.csv and metrics.json: ticks,
#             overruns (half a period late), lateness p99 of the worst second and max, and the
#             master's lost frames, WKC errors and segment losses.
#
#   tests/bench/bench_ec_segment_cli.sh [OUT.md]   (default build/bench/ec_segment_cli.md)
#   AXES="0 100 400 800" REALTIME_AXES="100 800" to choose the rows.
set -euo pipefail
# shellcheck source=tests/bench/cli_common.sh
source "$(dirname "${BASH_SOURCE[0]}")/cli_common.sh"
out_md="${1:-$build/bench/ec_segment_cli.md}"
axes_list=(${AXES:-0 100 400 800})
rt_list=(${REALTIME_AXES:-100 800})
work="$(mktemp -d /tmp/omnitwin-bench-ecseg-XXXXXX)"
trap 'rm -rf "$work"' EXIT

metric() { python3 -c "import json,sys; m=json.load(open(sys.argv[1])); print(m.get(sys.argv[2], 'nan'))" "$1" "$2"; }
master_metric() { python3 -c "import json,sys; m=json.load(open(sys.argv[1]))['master']; print(m.get(sys.argv[2], 'nan'))" "$1" "$2"; }

# One run: bus, extra axes, clock, dir. Prints "wall_s exit_code".
one_run() {
  local bus="$1" axes="$2" clock="$3" dir="$4" t0 t1 rc=0
  local sets=(--set controller.period=0.001)
  [ "$bus" = ethercat ] && sets+=(--set "bus.extra_axes=$axes")
  t0=$(now_ns)
  "$omnitwin" run "$scenario" --bus "$bus" --clock "$clock" "${sets[@]}" --out "$dir" --no-video --no-report \
    --no-progress > "$dir.log" 2>&1 || rc=$?
  t1=$(now_ns)
  awk -v a="$t0" -v b="$t1" -v rc="$rc" 'BEGIN {printf "%.4f %d\n", (b - a) / 1e9, rc}'
}

{
  echo "Measured $(date -u '+%Y-%m-%d %H:%M UTC') on $(nproc) cores by \`tests/bench/bench_ec_segment_cli.sh\` at $(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo '?'):"
  echo
  echo "**Lockstep** (thesis line, 1 ms controller period = EtherCAT cycle):"
  echo
  echo "| bus | extra axes (slaves) | slaves in OP | LRW bytes / frames | RTF, whole process | in-run RTF | ÷ direct (in-run) | WKC errors | lost frames | exit |"
  echo "|---|---|---|---|---|---|---|---|---|---|"
} > "$work/table.md"
read -r wall rc <<< "$(one_run direct 0 lockstep "$work/direct")"
direct_ir=$(metric "$work/direct/metrics.json" real_time_factor)
sim=$(metric "$work/direct/metrics.json" sim_time_s)
printf '| direct | — | — | — | %.1f× | %.1f× | 1.00 | — | — | %s |\n' "$(awk -v s="$sim" -v w="$wall" 'BEGIN {print s / w}')" "$direct_ir" "$rc" >> "$work/table.md"
for axes in "${axes_list[@]}"; do
  d="$work/lock-$axes"
  read -r wall rc <<< "$(one_run ethercat "$axes" lockstep "$d")"
  m="$d/metrics.json"
  sim=$(metric "$m" sim_time_s)
  ir=$(metric "$m" real_time_factor)
  image=$(sed -n 's/.*process image: \([0-9]*\) output bytes, \([0-9]*\) input bytes\(, overlapped in \([0-9]*\) bytes\)\?\(, in \([0-9]*\) frames of its own\)\?.*/\1+\2 \4 \6/p' "$d/master.log" | head -1)
  read -r sep ovl frames <<< "$image"
  bytes=${ovl:-$(( ${sep%+*} + ${sep#*+} ))}
  printf '| ethercat | %s (%s) | %s | %s / %s | %.1f× | %.1f× | %.2f | %s | %s | %s |\n' "$axes" "$(( (axes + 7) / 8 ))" \
    "$(master_metric "$m" slaves)" "$bytes" "${frames:-1}" "$(awk -v s="$sim" -v w="$wall" 'BEGIN {print s / w}')" "$ir" \
    "$(awk -v a="$ir" -v b="$direct_ir" 'BEGIN {print a / b}')" "$(master_metric "$m" wkc_errors)" \
    "$(master_metric "$m" lost_frames)" "$rc" >> "$work/table.md"
  echo "lockstep $axes axes: ${ir}x in-run" >&2
done
{
  echo
  echo "**Realtime** (the same run on the wall clock at 1 ms; lateness from realtime.csv, one row per second):"
  echo
  echo "| extra axes | ticks | overruns | worst second's p99 lateness [µs] | max lateness [µs] | master: lost frames | WKC errors | segment losses | exit |"
  echo "|---|---|---|---|---|---|---|---|---|"
} >> "$work/table.md"
for axes in "${rt_list[@]}"; do
  d="$work/rt-$axes"
  read -r wall rc <<< "$(one_run ethercat "$axes" realtime "$d")"
  m="$d/metrics.json"
  stats=$(awk -F, 'NR > 1 {t += $2; o += $3; if ($6 > p) p = $6; if ($7 > x) x = $7} END {printf "%d %d %.0f %.0f", t, o, p, x}' "$d/realtime.csv")
  read -r ticks over p99 mx <<< "$stats"
  printf '| %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' "$axes" "$ticks" "$over" "$p99" "$mx" \
    "$(master_metric "$m" lost_frames)" "$(master_metric "$m" wkc_errors)" "$(master_metric "$m" segment_losses)" "$rc" >> "$work/table.md"
  echo "realtime $axes axes: $ticks ticks, $over overruns, max ${mx} us" >&2
done
mkdir -p "$(dirname "$out_md")"
cp "$work/table.md" "$out_md"
cat "$out_md"
