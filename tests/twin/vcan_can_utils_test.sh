#!/usr/bin/env bash
# Tests the twin on a real SocketCAN vcan with the standard Linux CAN tools (can-utils), run
# inside scripts/vcan-vm where this kernel has no CAN: `omnitwin run --bus can` over
# socketcan:IFACE (master and twin as two processes in lockstep: under QEMU's software
# emulation a realtime run overruns nearly every tick); candump records the bus
# and must show the master's commands (0x102) and all four slaves' feedback; cansend then
# injects an NMT stop to all nodes (0x000 [00 02]) and the master must stop on it (master.log:
# "stopped (nmt_stop"), the slaves must report stopped, and no command or feedback may follow
# the stop by more than half a second in candump's record.
#
# Usage: vcan_can_utils_test.sh OMNITWIN SCENARIO [IFACE]   (IFACE defaults to vcan1)
set -euo pipefail
omnitwin=$1 scenario=$2 iface=${3:-vcan1}
out=$(mktemp -d /var/tmp/omnitwin-vcan-utils.XXXXXX)
dump_pid="" run_pid=""
cleanup() {
  [ -z "$run_pid" ] || kill "$run_pid" 2>/dev/null || true
  [ -z "$dump_pid" ] || kill "$dump_pid" 2>/dev/null || true
  rm -rf "$out"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; [ ! -f "$out/run.txt" ] || tail -n 20 "$out/run.txt"; exit 1; }
command -v candump >/dev/null && command -v cansend >/dev/null || fail "can-utils is not installed"

# candump -L: "(seconds.micros) IFACE ID#DATA", one frame per line, kernel timestamps.
candump -L "$iface" >"$out/candump.log" &
dump_pid=$!
"$omnitwin" run "$scenario" --bus can --clock lockstep --no-progress --set "bus.transport=socketcan:$iface" \
  --out "$out/run" >"$out/run.txt" 2>&1 &
run_pid=$!

# 1. The running system in candump's record: commands and every slave's feedback.
seen() { grep -c " $iface $1#" "$out/candump.log" 2>/dev/null || true; }
for _ in $(seq 1 200); do
  [ "$(seen 102)" -ge 20 ] && [ "$(seen 202)" -ge 5 ] && [ "$(seen 302)" -ge 5 ] &&
    [ "$(seen 502)" -ge 5 ] && [ "$(seen 602)" -ge 5 ] && break
  sleep 0.1
done
[ "$(seen 102)" -ge 20 ] || fail "candump saw $(seen 102) commands in 20 s"
for id in 202 302 502 602; do [ "$(seen $id)" -ge 5 ] || fail "candump saw no feedback $id"; done
echo "candump: $(seen 102) commands and feedback from all four slaves"

# 2. NMT stop to all nodes from cansend; its own time is candump's record of it.
cansend "$iface" 000#0002
wait "$run_pid" || true
run_pid=""
sleep 0.2
kill "$dump_pid" 2>/dev/null || true
wait "$dump_pid" 2>/dev/null || true
dump_pid=""
t_stop=$(awk -v i="$iface" '$2 == i && $3 == "000#0002" { gsub(/[()]/, "", $1); print $1; exit }' "$out/candump.log")
[ -n "$t_stop" ] || fail "candump did not record the NMT stop"
late=$(awk -v i="$iface" -v t="$t_stop" '$2 == i { ts = $1; gsub(/[()]/, "", ts); ts += 0; split($3, f, "#");
  if (ts > t + 0.5 && (f[1] == "102" || f[1] == "202" || f[1] == "302" || f[1] == "502" || f[1] == "602")) n++ }
  END { print n + 0 }' "$out/candump.log")
after=$(awk -v t="$t_stop" '{ ts = $1; gsub(/[()]/, "", ts); if (ts + 0 > t + 0) n++ } END { print n + 0 }' "$out/candump.log")
[ "$late" -eq 0 ] || fail "$late command/feedback frames more than 0.5 s after the NMT stop"
echo "after the NMT stop: $after frames, none of them a command or feedback later than 0.5 s"
grep -q "stopped (nmt_stop" "$out/run/master.log" || fail "master.log does not show the master stopping on the NMT stop"
/usr/bin/python3 - "$out/run/metrics.json" <<'PY' || fail "slaves did not all stop"
import json, sys
m = json.load(open(sys.argv[1]))
states = [s["state"] for s in m["slaves"]]
print("slave states:", states)
sys.exit(0 if all(s == "stopped" for s in states) else 1)
PY
echo "PASS: candump recorded the run on $iface, cansend's NMT stop stopped master and slaves"
