# tests/bench/cli_common.sh — sourced by bench_cli.sh and profile_cli.sh (not run on its own):
# where the build is, the scenario and buses both time, and the settings a bus needs at a
# given controller period.
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
build="${OMNITWIN_BUILD_DIR:-$root/build}"
omnitwin="$build/twin/omnitwin"
scenario="$root/models/scenarios/thesis_line.yaml"
buses=(direct can canopen tml ethercat m3)

# The thesis's CAN slaves run their velocity loop on their own 10 ms timer; at a 1 ms controller
# period they must run it at 1 ms too, or the master finds no feedback and stops.
extra_sets() {
  if [ "$1" = can ] && [ "$2" = 0.001 ]; then echo "--set platform.velocity_loop.period=0.001"; fi
}

# Wall clock in ns, and the median of numbers on stdin (one per line).
now_ns() { date +%s%N; }
median() { sort -g | awk '{a[NR] = $1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }
