#!/usr/bin/env bash
# tests/bench/bench_fast_model.sh — the fast physics model's speed as a user gets it (issue 17,
# item 3): `omnitwin run` of the thesis line, the circle and the rotation, the whole process
# with its records (no video, no report), on the reference (variant rollers), on the fast model
# (variant capsule) at the same 1 ms step, and on the fast model at a 2 ms step, interleaved
# REPS times (default 5) so machine drift hits all three alike; then the accuracy of the same
# configurations from `omnitwin experiment fast-model`. Writes OUT.md (default
# build/bench/fast_model.md). scripts/bench calls it.
#
#   tests/bench/bench_fast_model.sh [OUT.md]
#
# Real-time factor = simulated seconds / wall seconds of the whole process (start to exit).
set -euo pipefail
# shellcheck source=tests/bench/cli_common.sh
source "$(dirname "${BASH_SOURCE[0]}")/cli_common.sh"
out_md="${1:-$build/bench/fast_model.md}"
reps="${REPS:-5}"
work="$(mktemp -d /tmp/omnitwin-bench-fast-XXXXXX)"
trap 'rm -rf "$work"' EXIT

sim_s() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['sim_time_s'])" "$1"; }

# One timed run; prints its real-time factor. Any exit but 0 fails the benchmark: a model that
# misses the scenario's expectations is not a result.
timed() {
  local sc="$1" dir="$2"; shift 2
  local t0 t1
  t0=$(now_ns)
  "$omnitwin" run "$root/models/scenarios/$sc.yaml" --out "$dir" --no-video --no-report --no-progress "$@" > "$dir.log" 2>&1 ||
    { echo "bench_fast_model: $sc $* failed, see below" >&2; cat "$dir.log" >&2; exit 1; }
  t1=$(now_ns)
  awk -v s="$(sim_s "$dir/metrics.json")" -v w="$(( (t1 - t0) / 1000 ))" 'BEGIN {printf "%.3f\n", s / (w / 1e6)}'
}

{
  echo "| scenario | reference (rollers, 1 ms) | fast (capsule, 1 ms) | ÷ reference | fast (capsule, 2 ms) | ÷ reference |"
  echo "|---|---|---|---|---|---|"
} > "$work/table.md"
for sc in thesis_line circle rotate; do
  ref=() f1=() f2=()
  for ((r = 0; r < reps; r++)); do
    ref+=("$(timed "$sc" "$work/$sc-ref-$r")")
    f1+=("$(timed "$sc" "$work/$sc-fast1-$r" --set platform.sim.variant=capsule)")
    f2+=("$(timed "$sc" "$work/$sc-fast2-$r" --set platform.sim.variant=capsule --set platform.sim.timestep=0.002)")
  done
  a=$(printf '%s\n' "${ref[@]}" | median)
  b=$(printf '%s\n' "${f1[@]}" | median)
  c=$(printf '%s\n' "${f2[@]}" | median)
  awk -v sc="$sc" -v a="$a" -v b="$b" -v c="$c" \
    'BEGIN {printf "| %s | %.1f× | %.1f× | %.2f× | %.1f× | %.2f× |\n", sc, a, b, b / a, c, c / a}' >> "$work/table.md"
  echo "$sc: reference ${a}x, fast 1 ms ${b}x, fast 2 ms ${c}x" >&2
done

"$omnitwin" experiment fast-model --out "$work/accuracy" > "$work/accuracy.log"
mkdir -p "$(dirname "$out_md")"
{
  echo "Measured $(date -u '+%Y-%m-%d %H:%M UTC') on $(nproc) cores ($(uname -r)), $reps interleaved runs each"
  echo "(median), by \`tests/bench/bench_fast_model.sh\` at $(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo '?'):"
  echo
  echo "Real-time factor of the whole \`omnitwin run\` process (records, no video), bus direct, lockstep:"
  echo
  cat "$work/table.md"
  echo
  echo "Accuracy against the reference, from \`omnitwin experiment fast-model\` in the same invocation"
  echo "(its own in-process timings are in its table too):"
  echo
  sed -n '/^| scenario/,/^$/p' "$work/accuracy/fast_model.md"
  grep -E '^Accuracy bound|^Speed target' "$work/accuracy/fast_model.md"
} > "$out_md"
cat "$out_md"
