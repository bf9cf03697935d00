// twin layer — `omnitwin-guard`: ends a run's master when the twin that started it is killed.
//
// A twin killed outright (SIGKILL, the OOM killer) cannot stop its master. Our masters ask
// the kernel for a SIGTERM at their parent's death, but a master started through a wrapper (a
// shell script that does not exec) has the wrapper as its parent, and the wrapper is not told:
// the master ran on with nobody serving it. So MasterProcess starts this small program beside
// each master, as the twin's child. It reads the master's /proc entry every 50 ms and ends as
// soon as the master has; the twin kills it when it has stopped the master itself. Once the
// twin is gone it gives the master the grace to end by itself (ours do, on the kernel's
// SIGTERM; a second one would read as a second Ctrl-C), then sends SIGTERM (and SIGCONT) to the
// master and every process it started, waits the grace again, and SIGKILLs those left. It
// ignores SIGINT, SIGTERM and SIGHUP, so that it outlives the twin to do its work (a Ctrl-C at
// the terminal reaches the master itself).
//
// Usage (MasterProcess's, not a user's): omnitwin-guard TWIN_PID MASTER_PID MASTER_START GRACE_MS
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "twin/process_tree.hpp"

using namespace omnitwin::twin;

namespace {

// The master and what it started that are still there (none: the master has ended).
std::vector<ProcessEntry> master_processes(const ProcessEntry& master) {
  const std::vector<ProcessEntry> all = process_table();
  std::vector<ProcessEntry> found;
  if (alive_in(master, all)) found.push_back(master);
  // Its descendants only while it lives: once it is gone its pid may be another process's.
  if (!found.empty())
    for (const ProcessEntry& p : descendants_of(master.pid, all)) found.push_back(p);
  return found;
}

// `sig` to each of `procs` that is still the process it was.
void signal_each(const std::vector<ProcessEntry>& procs, int sig) {
  const std::vector<ProcessEntry> all = process_table();
  for (const ProcessEntry& p : procs)
    if (alive_in(p, all)) ::kill(p.pid, sig);
}

// Whether all of `procs` have ended within `wait` (polled every 20 ms).
bool all_end_within(const std::vector<ProcessEntry>& procs, std::chrono::milliseconds wait) {
  const auto deadline = std::chrono::steady_clock::now() + wait;
  for (;;) {
    const std::vector<ProcessEntry> all = process_table();
    if (std::none_of(procs.begin(), procs.end(), [&](const ProcessEntry& p) { return alive_in(p, all); })) return true;
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

// Ends the master's processes: `grace` to end by themselves, then SIGTERM and SIGCONT, `grace`
// again, then SIGKILL.
void end_master(const ProcessEntry& master, std::chrono::milliseconds grace) {
  const std::vector<ProcessEntry> procs = master_processes(master);
  if (all_end_within(procs, grace)) return;
  signal_each(procs, SIGTERM);
  signal_each(procs, SIGCONT);  // a stopped master acts on SIGTERM only when continued
  if (all_end_within(procs, grace)) return;
  signal_each(procs, SIGKILL);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 5) return 2;
  ::signal(SIGINT, SIG_IGN);
  ::signal(SIGTERM, SIG_IGN);
  ::signal(SIGHUP, SIG_IGN);
  const pid_t twin = static_cast<pid_t>(std::atol(argv[1]));
  ProcessEntry master;
  master.pid = static_cast<pid_t>(std::atol(argv[2]));
  master.start = std::strtoull(argv[3], nullptr, 10);
  const std::chrono::milliseconds grace(std::atol(argv[4]));
  // Watch: the master ending ends the watch; the twin ending (we are reparented) ends the master.
  for (;;) {
    // One /proc file per look while the twin lives; the whole table only at the end.
    const auto now = process_entry(master.pid);
    if (!now || !same_process(*now, master) || now->state == 'Z') return 0;
    if (::getppid() != twin) {
      end_master(master, grace);
      return 0;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}
