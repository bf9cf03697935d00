#!/usr/bin/env bash
# Tests that the thesis line on bus `can` gives the same run over a real SocketCAN vcan as over
# UDP multicast: master and twin as two processes in lockstep, once over
# udp:239.74.163.2:PORT here, once over socketcan:vcan0 through scripts/vcan-vm (a QEMU guest
# with Debian's kernel where this kernel has no CAN). trajectory.csv must be byte-identical
# (lockstep makes the run independent of the transport), the master must have finished its path
# both times, and the vcan run's capture must hold the master's commands.
#
# Usage: vcan_thesis_line_test.sh OMNITWIN VCAN_VM SCENARIO PORT
set -euo pipefail
omnitwin=$1 vcan_vm=$2 scenario=$3 port=$4
# Outputs under /var/tmp: the guest sees this machine's /var/tmp, but has a /tmp of its own.
out=$(mktemp -d /var/tmp/omnitwin-vcan-line.XXXXXX)
trap 'rm -rf "$out"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

common=(run "$scenario" --bus can --clock lockstep --no-video --no-report --no-progress)
# Exit 0 (or 1: an expectation missed, which the comparison below still judges) both times.
rc=0
"$omnitwin" "${common[@]}" --set "bus.transport=udp:239.74.163.2:$port" --out "$out/udp" >"$out/udp.txt" 2>&1 || rc=$?
[ "$rc" -le 1 ] || { cat "$out/udp.txt"; fail "the UDP run exited $rc"; }
rc=0
"$vcan_vm" run -- "$omnitwin" "${common[@]}" --set bus.transport=socketcan:vcan0 --out "$out/vcan" >"$out/vcan.txt" 2>&1 || rc=$?
[ "$rc" -le 1 ] || { cat "$out/vcan.txt"; fail "the SocketCAN run exited $rc"; }
grep -E "simulated|real time" "$out/vcan.txt" || true

for run in udp vcan; do
  grep -q '"lost": *false' "$out/$run/metrics.json" || fail "$run: the twin lost its master"
  grep -q '"state": *"finished"' "$out/$run/metrics.json" || fail "$run: the master did not finish its path"
done
rows=$(wc -l <"$out/vcan/trajectory.csv")
[ "$rows" -gt 2000 ] || fail "the vcan trajectory has only $rows rows"
cmp "$out/udp/trajectory.csv" "$out/vcan/trajectory.csv" || fail "trajectory.csv differs between UDP and SocketCAN"
# The capture of the vcan run: the master's 0x102 commands, one per 10 ms sample.
commands=$(tshark -r "$out/vcan/bus-can.pcap" -Y 'can.id == 0x102' 2>/dev/null | wc -l)
[ "$commands" -gt 2000 ] || fail "the vcan run's capture holds only $commands command frames"
echo "PASS: $rows trajectory rows byte-identical over UDP and socketcan:vcan0; $commands commands captured"
