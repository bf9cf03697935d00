// twin layer — the process table as /proc has it: who started whom, and who a pid is.
//
// The master a run starts may start others (a wrapper script that does not exec); ending it
// means reaching all of them, by pid and start time, so that a pid taken again by an unrelated
// process is never signalled. Shared by MasterProcess and omnitwin-guard (guard_main.cpp),
// which has to find them after the twin itself is gone. Scans /proc: not real-time safe.
#pragma once

#include <sys/types.h>

#include <optional>
#include <vector>

namespace omnitwin::twin {

// A process as /proc/PID/stat has it: its parent, state and start time (clock ticks after
// boot: with the pid, who it is, so that a pid taken again is never mistaken for it), and the
// CPU time it has used, user and system, all its threads [clock ticks].
struct ProcessEntry {
  pid_t pid = 0, ppid = 0;
  char state = 0;
  unsigned long long start = 0;
  unsigned long long cpu = 0;
};

// One process as /proc/PID/stat has it; none when it has no entry (gone).
std::optional<ProcessEntry> process_entry(pid_t pid);
// Every process as /proc/PID/stat has it.
std::vector<ProcessEntry> process_table();
// The descendants of `root` (not root itself), zombies left out.
std::vector<ProcessEntry> descendants_of(pid_t root, const std::vector<ProcessEntry>& all);
// The same process: the same pid started at the same time.
bool same_process(const ProcessEntry& a, const ProcessEntry& b);
// `p` in `all` and not a zombie.
bool alive_in(const ProcessEntry& p, const std::vector<ProcessEntry>& all);

}  // namespace omnitwin::twin
