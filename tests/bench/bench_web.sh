#!/usr/bin/env bash
# tests/bench/bench_web.sh — what the live browser view costs a run (issue 18): the thesis
# line in lockstep, `omnitwin run` as a user runs it (records on, no video or report), with
# and without `--web 127.0.0.1:0 --web-wait` and one headless Chromium on the page from before
# the first step to the end (web_attach.mjs), alternating, REPS times each (default 5), for
# the buses in BUSES (default "can ethercat"). The figure is the in-run real-time factor
# (metrics.json real_time_factor: the run loop alone; the wait for the page to open is
# before it). Both sides run on this machine, the browser included (2 cores here: the
# browser's software WebGL competes with the twin and its master for them).
#
#   tests/bench/bench_web.sh [OUT.md]    (default build/bench/web.md)
set -euo pipefail
# shellcheck source=tests/bench/cli_common.sh
source "$(dirname "${BASH_SOURCE[0]}")/cli_common.sh"
out_md="${1:-$build/bench/web.md}"
reps="${REPS:-5}"
read -r -a web_buses <<< "${BUSES:-can ethercat}"
work="$(mktemp -d /tmp/omnitwin-bench-web-XXXXXX)"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$work"' EXIT

metric() { python3 -c "import json,sys; m=json.load(open(sys.argv[1])); print(m.get(sys.argv[2], 'nan'))" "$1" "$2"; }

# One run without the view: its in-run real-time factor.
plain_run() {
  "$omnitwin" run "$scenario" --bus "$1" --out "$2" --no-video --no-report --no-progress > "$2.log" 2>&1
  metric "$2/metrics.json" real_time_factor
}

# One run with the view and a browser on it: "rtf samples frames".
web_run() {
  local bus="$1" dir="$2"
  "$omnitwin" run "$scenario" --bus "$bus" --out "$dir" --no-video --no-report --no-progress \
    --web 127.0.0.1:0 --web-wait > "$dir.log" 2> "$dir.err" &
  local pid=$! url=""
  for _ in $(seq 100); do
    url=$(grep -o 'http://[^ ]*' "$dir.err" 2>/dev/null | head -1) && [ -n "$url" ] && break
    sleep 0.1
  done
  [ -n "$url" ] || { echo "no web view URL from the run: $(cat "$dir.err")" >&2; kill $pid; exit 1; }
  local seen
  seen=$(node "$root/tests/bench/web_attach.mjs" "$url" 120)
  wait $pid
  echo "$(metric "$dir/metrics.json" real_time_factor) $(awk '{print $2, $4}' <<< "$seen")"
}

{
  echo "| bus | in-run RTF, no view | with --web and one browser | ratio | samples on the page | 3D frames drawn |"
  echo "|---|---|---|---|---|---|"
} > "$work/table.md"
for bus in "${web_buses[@]}"; do
  plain=() web=() samples="" frames=""
  for ((r = 0; r < reps; r++)); do
    plain+=("$(plain_run "$bus" "$work/$bus-plain-$r")")
    read -r rtf samples frames <<< "$(web_run "$bus" "$work/$bus-web-$r")"
    web+=("$rtf")
    echo "  $bus rep $r: plain ${plain[-1]}x, web ${rtf}x ($samples samples, $frames frames)" >&2
  done
  p=$(printf '%s\n' "${plain[@]}" | median)
  w=$(printf '%s\n' "${web[@]}" | median)
  awk -v b="$bus" -v p="$p" -v w="$w" -v s="$samples" -v f="$frames" \
    'BEGIN {printf "| %s | %.1f | %.1f | %.3f | %s | %s |\n", b, p, w, w / p, s, f}' >> "$work/table.md"
done
mkdir -p "$(dirname "$out_md")"
{
  echo "Live view cost, $(date -u +%Y-%m-%d), $(nproc) cores, medians of $reps alternating runs"
  echo "(tests/bench/bench_web.sh; scenario $(basename "$scenario"), lockstep, 10 ms controller period)"
  echo
  cat "$work/table.md"
} > "$out_md"
cat "$out_md"
