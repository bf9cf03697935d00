#!/usr/bin/env bash
# Benchmark (run on purpose, not in CI): what a user runs, through the CLI with all records.
# The thesis line on bus ethercat at a 1 ms cycle, three times each, alternated in one run:
#   sim      omni-master on the sim-clock handshake (the baseline)
#   vtime    omni-master --clock wall under libomnitwin_vtime.so (omnitwin run --master-cmd)
#   foreign  tests/ec_foreign_master (plain C, 1 ms cycle) under the library
# Prints each run's real-time factor, the medians, vtime/sim, and the wall time per wait the
# library reported (the whole hand-over: the wait, the twin's simulation up to it, the wake).
# Usage: tests/bench/bench_vtime.sh [BUILD_DIR]   (default: build)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
B=${1:-build}
OUT=$(mktemp -d /tmp/omnitwin-bench-vtime.XXXXXX)
trap 'rm -rf "$OUT"' EXIT
SC=models/scenarios/thesis_line.yaml
COMMON=(--bus ethercat --set controller.period=0.001 --no-video --no-report --no-progress)
run() {  # name, extra args…
  local name=$1; shift
  "$B/twin/omnitwin" run "$SC" "${COMMON[@]}" --out "$OUT/$name" "$@" >/dev/null 2>&1 || true
  python3 - "$OUT/$name/metrics.json" "$name" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
vt = m.get("master", {}).get("virtual_time")
per = f", {m['wall_time_s'] / vt['waits'] * 1e6:.1f} us wall per wait ({vt['waits']} waits)" if vt else ""
print(f"{sys.argv[2].split('-')[0]:8s} RTF {m['real_time_factor']:.2f}x  sim {m['sim_time_s']:.2f} s in {m['wall_time_s']:.2f} s{per}")
PY
}
for i in 1 2 3; do
  run "sim-$i"
  run "vtime-$i" --master-cmd "$B/controller/omni-master --bus ethercat --clock wall --iface {iface} --config {out}/master.yaml"
  run "foreign-$i" --set duration=10 --master-cmd "$B/tests/ec_foreign_master {iface} 60"
done | tee "$OUT/all.txt"
python3 - "$OUT/all.txt" <<'PY'
import re, statistics, sys
rtf = {}
for line in open(sys.argv[1]):
    k, v = line.split()[0], float(re.search(r"RTF ([0-9.]+)x", line).group(1))
    rtf.setdefault(k, []).append(v)
med = {k: statistics.median(v) for k, v in rtf.items()}
print("medians: " + ", ".join(f"{k} {v:.2f}x" for k, v in med.items()))
print(f"vtime / sim = {med['vtime'] / med['sim']:.2f} (target >= 0.8)")
PY
