#!/usr/bin/env bash
# tests/bench/profile_cli.sh — where the time of a lockstep `omnitwin run` goes, per bus
# (issue 17, item 2): `perf record` (Debian's linux-perf) of the whole process tree of the
# thesis line at PERIOD (default 0.001 s), every bus, then the CPU samples split into
#   physics         libmujoco, libm (MuJoCo's and our trigonometry)
#   twin code       the twin's own code, libstdc++, libc: bus emulators, scheduler, records
#   twin kernel     the twin's system calls: transport, sim-clock hand-overs, file writes
#   master          the master process (user and kernel)
#   other           start-up (ld.so, `ip` for a veth pair, shells)
# In lockstep the twin and the master take turns, so a share of CPU samples is close to a
# share of wall time. Root only (perf and veth).
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
  perf record -q -F 1999 -o "$work/$bus.data" -- "$omnitwin" run "$scenario" \
    --bus "$bus" --set controller.period="$period" $(extra_sets "$bus" "$period") --out "$work/$bus" --no-video --no-report --no-progress > "$work/$bus.log" 2>&1 || true
  rtf=$(sed -n 's/.*(\([0-9.]*\)x real time).*/\1/p' "$work/$bus.log" | head -1)
  perf report -i "$work/$bus.data" --no-children --sort comm,dso --stdio -g none 2>/dev/null |
    grep -E '^ +[0-9.]+%' > "$work/$bus.txt" || true
  row=$(awk -v bus="$bus" -v rtf="$rtf" '
    { pct = $1; sub("%", "", pct); comm = $2; dso = $3
      if (comm == "omnitwin-cli") {
        if (dso ~ /libmujoco|libm\.so/) phys += pct
        else if (dso ~ /kernel/) tk += pct
        else tc += pct
      } else if (comm == "omni-master") master += pct
      else other += pct }
    END { printf "| %s | %s× | %.0f %% | %.0f %% | %.0f %% | %.0f %% | %.0f %% |", bus, rtf, phys, tc, tk, master, other }' \
    "$work/$bus.txt")
  rows+="$row"$'\n'
  echo "$row" >&2
done
mkdir -p "$(dirname "$out_md")"
{
  echo "Profiled $(date -u '+%Y-%m-%d %H:%M UTC') on $(nproc) cores, controller period $period s, by"
  echo "\`tests/bench/profile_cli.sh\` at $(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo '?') (perf, 1999 Hz, the whole process tree):"
  echo
  echo "| bus | in-run RTF | physics | twin code | twin kernel | master | other |"
  echo "|---|---|---|---|---|---|---|"
  printf '%s' "$rows"
} > "$out_md"
cat "$out_md"
