#!/usr/bin/env bash
# Benchmark (run on purpose, not in CI): issue 15's standstill and what it costs, through the
# CLI with all records. The thesis line on bus direct run to 62 s (the path ends at 20 s),
# three times each, alternated in one run:
#   motor    the default wheel motor (kv 2 N·m·s/rad behind a 2 ms electrical lag)
#   stiff    the motor before issue 15 (kv 20, no lag): --set platform.motor.kv=20 …tau=0
# Prints each run's real-time factor, how far the true pose moved from 22 s (path end plus the
# scenario's 2 s settle) to the end [mm], and the true final error [cm]; then the medians.
# Usage: tests/bench/bench_standstill.sh [BUILD_DIR]   (default: build)
#   SCENARIO=FILE  another scenario (default models/scenarios/thesis_line.yaml), e.g. the fitted
#                  line, which hunts on direct (docs/platform.md, "Standstill")
#   BUS=can        the thesis's bus instead of direct (the master program beside the twin; on
#                  the fitted line, the CAN settings of its fitted row, which its file carries)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
B=${1:-build}
OUT=$(mktemp -d /tmp/omnitwin-bench-standstill.XXXXXX)
trap 'rm -rf "$OUT"' EXIT
SC=${SCENARIO:-models/scenarios/thesis_line.yaml}
COMMON=(--bus "${BUS:-direct}" --set duration=62 --no-video --no-report --no-progress)
echo "$SC on bus ${BUS:-direct}"
run() {  # name, extra args…
  local name=$1; shift
  "$B/twin/omnitwin" run "$SC" "${COMMON[@]}" --out "$OUT/$name" "$@" >/dev/null 2>&1 || true
  python3 - "$OUT/$name" "$name" <<'PY'
import csv, json, math, sys
d, name = sys.argv[1], sys.argv[2]
rtf = json.load(open(d + "/metrics.json"))["real_time_factor"]
rows = list(csv.DictReader(open(d + "/trajectory.csv")))
a = min(rows, key=lambda r: abs(float(r["t"]) - 22.0))
b = rows[-1]
moved = 1e3 * math.hypot(float(b["x"]) - float(a["x"]), float(b["y"]) - float(a["y"]))
final = 100 * math.hypot(float(b["x"]) - float(b["ref_x"]), float(b["y"]) - float(b["ref_y"]))
print(f"{name.split('-')[0]:6s} RTF {rtf:.2f}x  moved {moved:.3f} mm after 22 s  final error {final:.3f} cm")
PY
}
for i in 1 2 3; do
  run "motor-$i"
  run "stiff-$i" --set platform.motor.kv=20 --set platform.motor.electrical_tau=0
done | tee "$OUT/all.txt"
python3 - "$OUT/all.txt" <<'PY'
import re, statistics, sys
rtf, moved = {}, {}
for line in open(sys.argv[1]):
    k = line.split()[0]
    rtf.setdefault(k, []).append(float(re.search(r"RTF ([0-9.]+)x", line).group(1)))
    moved.setdefault(k, []).append(float(re.search(r"moved ([0-9.]+) mm", line).group(1)))
for k in rtf:
    print(f"median {k}: RTF {statistics.median(rtf[k]):.2f}x, moved {statistics.median(moved[k]):.3f} mm")
print(f"motor/stiff RTF: {statistics.median(rtf['motor']) / statistics.median(rtf['stiff']):.3f}")
PY
