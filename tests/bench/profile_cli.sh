#!/usr/bin/env bash
# tests/bench/profile_cli.sh — where the time of a lockstep `omnitwin run` goes, per bus and per
# tick (issue 17, item 2): `perf record` (Debian's linux-perf) of the whole process tree of the
# thesis line at PERIOD (default 0.001 s), every bus, then the CPU samples split by thread and
# symbol. In lockstep the twin's run-loop thread and the master take turns on one CPU, so
# their samples together are the loop's wall time; each share of them times the wall time
# of one tick (PERIOD / in-run RTF) is that part's microseconds per tick:
#   physics        libmujoco, libm, omnitwin::physics (MuJoCo, wheel motors, trigonometry)
#   scheduler      omnitwin::twin::Scheduler and the pacers
#   bus model      the emulators: omnitwin::{ethercat,can,canopen,tml,m3,drive,omni} and the
#                  twin's *Network classes (ESCs, wires, lines, drive cores, slave firmware)
#   hand-over      the transports' and the sim-clock channel's own code in user space, and
#     (user)       the libc wrappers of their system calls
#   kernel         the loop thread in the kernel: the transport's and the sim clock's system
#                  calls, the context switches of every hand-over, page faults
#   records        staging the records (CSV rows, pcap, event log) on the loop
#   other          everything else on the loop: the platform loop, the path, libstdc++/libc
#   master         the master process: its own code (user), and in the kernel (its system
#                  calls and switches)
# Beside them, "off the loop": the twin's other threads (the record writers, DDS), which run
# on the other core at the same time and cost the tick nothing, as a share of all samples.
# Root only (perf and veth).
#
#   tests/bench/profile_cli.sh [PERIOD] [OUT.md]   (default build/bench/profile.md)
set -euo pipefail
# shellcheck source=tests/bench/cli_common.sh
source "$(dirname "${BASH_SOURCE[0]}")/cli_common.sh"
period="${1:-0.001}"
out_md="${2:-$build/bench/profile.md}"
work="$(mktemp -d /tmp/omnitwin-profile-XXXXXX)"
trap 'rm -rf "$work"' EXIT
command -v perf >/dev/null || { echo "profile_cli.sh: needs perf (Debian: linux-perf)" >&2; exit 2; }

rows=""
for bus in "${buses[@]}"; do
  # shellcheck disable=SC2046
  perf record -q -F 4999 -o "$work/$bus.data" -- "$omnitwin" run "$scenario" \
    --bus "$bus" --set controller.period="$period" $(extra_sets "$bus" "$period") --out "$work/$bus" --no-video --no-report --no-progress > "$work/$bus.log" 2>&1 || true
  rtf=$(sed -n 's/.*(\([0-9.]*\)x real time).*/\1/p' "$work/$bus.log" | head -1)
  # One line per (thread, dso, symbol): "pct tid:comm dso [k|.] symbol…"
  perf report -i "$work/$bus.data" --no-children --sort pid,dso,sym --stdio -g none 2>/dev/null |
    grep -E '^ +[0-9.]+%' > "$work/$bus.txt" || true
  row=$(awk -v bus="$bus" -v rtf="$rtf" -v period="$period" '
    { pct = $1; sub("%", "", pct); split($2, id, ":"); n++
      P[n] = pct; T[n] = id[1] + 0; C[n] = id[2]; D[n] = $3; K[n] = $4
      sym = ""; for (i = 5; i <= NF; i++) sym = sym " " $i; S[n] = sym
      if (id[2] == "omnitwin-cli" && (main == 0 || id[1] + 0 < main)) main = id[1] + 0 }
    END {
      for (i = 1; i <= n; i++) {
        if (C[i] == "omni-master") { c[K[i] == "[k]" ? "master_k" : "master"] += P[i]; continue }
        if (C[i] != "omnitwin-cli") { other_proc += P[i]; continue }
        if (T[i] != main) { offloop += P[i]; continue }
        if (K[i] == "[k]") k = "kernel"
        else if (D[i] ~ /libmujoco|libm\.so/ || S[i] ~ /omnitwin::physics::/) k = "physics"
        else if (S[i] ~ /Transport|transport|SimClock|simclock|sim_clock|ReadableWaiter|SenderGate|__send|sendmsg|sendto|recv|__poll|epoll/) k = "handover"
        else if (S[i] ~ /omnitwin::twin::(Scheduler|LockstepPacer|RealtimePacer|VtimePacer|Pacer)/) k = "scheduler"
        else if (S[i] ~ /WriteBehind|CsvWriter|CsvEncoder|Pcap|pcap|EventLog|Records|CheckedFile|_IO_|fwrite|fflush/) k = "records"
        else if (S[i] ~ /omnitwin::(ethercat|can|canopen|tml|m3|drive|omni)::|omnitwin::twin::[A-Za-z]*(Network|Wire|Segment)/) k = "bus"
        else k = "other"
        c[k] += P[i]
      }
      loop = c["physics"] + c["scheduler"] + c["bus"] + c["handover"] + c["kernel"] + c["records"] + c["other"] + c["master"] + c["master_k"]
      tick = (rtf > 0) ? period * 1e6 / rtf : 0
      printf "| %s | %s× | %.1f |", bus, rtf, tick
      split("physics scheduler bus handover kernel records other master master_k", order, " ")
      for (j = 1; j <= 9; j++) printf " %.1f |", (loop > 0 ? c[order[j]] / loop * tick : 0)
      printf " %.0f %% |", offloop + other_proc }' \
    "$work/$bus.txt")
  rows+="$row"$'\n'
  echo "$row" >&2
done
mkdir -p "$(dirname "$out_md")"
{
  echo "Profiled $(date -u '+%Y-%m-%d %H:%M UTC') on $(nproc) cores, controller period $period s, by"
  echo "\`tests/bench/profile_cli.sh\` at $(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo '?') (perf, 4999 Hz, the whole process tree)."
  echo "Microseconds per tick of the run loop (twin loop thread and master, which take turns):"
  echo
  echo "| bus | in-run RTF | µs per tick | physics | scheduler | bus model | hand-over (user) | kernel | records | other | master (user) | master (kernel) | off the loop |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|"
  printf '%s' "$rows"
} > "$out_md"
cat "$out_md"
