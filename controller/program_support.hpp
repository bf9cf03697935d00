// controller layer — small helpers shared by the master-side programs (omni-master on CAN and
// EtherCAT, omni-pc): how they name an interface, hear SIGINT/SIGTERM without a global flag,
// read the clocks and ask for real-time scheduling.
#pragma once

#include <cstdint>
#include <ctime>
#include <string>

namespace omnitwin::controller {

// "can0" means "socketcan:can0"; anything with a scheme ("udp:…", "mem:…") is a transport
// spec as it is. Not real-time safe.
std::string normalize_iface(const std::string& iface);

// Blocks SIGINT/SIGTERM for the process and returns a signalfd (non-blocking, close-on-exec)
// that becomes readable when one arrives; -1 if the kernel refuses. Set-up only.
int open_signal_fd();

// True (and the signal consumed) if SIGINT/SIGTERM is pending on the signalfd. Real-time safe.
bool signalled(int sigfd);

// A master the twin started (its environment holds OMNITWIN_TWIN_PID, the twin's pid) asks the
// kernel for a SIGTERM when the twin ends (PR_SET_PDEATHSIG), so that a twin killed outright
// does not leave a realtime master running on: it ends as on a Ctrl-C, drives stopped. Where a
// program stands between them (a shell of --master-cmd) nothing is asked. False when the twin
// is already gone (the caller then exits). Without the variable: true, nothing done. Set-up only.
bool watch_parent();

// CLOCK_MONOTONIC and CLOCK_REALTIME [ns]; ns → timespec. Real-time safe.
std::int64_t monotonic_ns();
std::int64_t realtime_ns();
timespec to_timespec(std::int64_t ns);

// --stats: writes `text` to path.tmp and renames it to `path`, so a reader never sees half a
// file; logs an error, removes path.tmp and returns false when it cannot (the caller then
// exits 3: a record that cannot be written is a runtime failure). Not real-time safe.
[[nodiscard]] bool write_stats_file(const std::string& path, const std::string& text);

// A time option's text (--duration, --seconds, --timeout-ms): "" when it is a finite number
// in [0, max], else a short message. For a CLI11 check: CLI::NonNegativeNumber lets NaN
// through, prints DBL_MAX in full, and a huge value overflows the programs' int64 ns deadlines.
// Set-up only.
std::string time_value_problem(const std::string& text, double max);
// The largest --duration / --seconds the programs take [s] (11.6 days).
inline constexpr double kMaxRunSeconds = 1e6;
// SCHED_FIFO at `priority` and locked memory where permitted; a debug line where not. Set-up.
void try_realtime(int priority);

}  // namespace omnitwin::controller
