// twin layer — the master program as a child process of `omnitwin run`.
//
// `omnitwin run --bus can` starts the real master (controller/, `omni-master`) beside the twin
// and supervises it: its configuration file is written from the scenario into the run
// directory (master.yaml), its output goes to master.log there, and whatever ends the run
// (its end, an error, Ctrl-C) ends the master too: End on the sim-clock channel, then
// SIGTERM, then SIGKILL after a grace period. The two programs share no memory and no code
// at run time; they meet only on the CAN transport and the sim-clock channel.
//
// The signals go to the program and to every process it started (its descendants, found in
// /proc when the SIGTERM goes out): a master started through a wrapper (a shell script that
// does not exec) is reached itself, not only its shell, and it has ended only when all of
// them have (the shell dying of the SIGTERM while the master ran on passed as a clean end;
// found in review). The master stays in the twin's process group, so that a Ctrl-C at the
// terminal or a SIGKILL to the group (a CI cancel) reaches it too.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <string>
#include <vector>

#include "controller/master_config.hpp"
#include "twin/process_tree.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin {

class MasterProcess {
 public:
  // Starts `program` with `args` (argv[1…]); stdout and stderr go to `log_path`. Throws
  // std::runtime_error when it cannot be started. Not real-time safe.
  // `env` adds or replaces NAME=VALUE entries of this process's environment for the child. A
  // program named without a '/' is looked up on PATH.
  MasterProcess(const std::string& program, const std::vector<std::string>& args, const std::string& log_path,
                const std::vector<std::string>& env = {});
  ~MasterProcess();  // stops it if still running
  MasterProcess(const MasterProcess&) = delete;
  MasterProcess& operator=(const MasterProcess&) = delete;

  // True while the child has not exited (reaps it when it has). Not real-time safe.
  bool running();
  // Waits up to `timeout` for it to exit on its own; true when it did.
  bool wait(std::chrono::milliseconds timeout);
  // SIGTERM to it and its descendants, up to `grace` for all of them to end, then SIGKILL to
  // those left. Returns once the program is reaped.
  void stop(std::chrono::milliseconds grace);
  // SIGTERM (and SIGCONT) to the program and its descendants, and return at once: the caller
  // serves it while it shuts down.
  void terminate();
  // Whether a process it started is left (one signalled by terminate(), or a descendant of the
  // program now); zombies do not count. Scans /proc: not real-time safe.
  bool descendants_alive() const;
  // Exit code (0…255), 128 + signal when killed, -1 while it runs.
  int exit_code() const { return exit_code_; }
  std::string describe_exit() const;  // "exit 0", "killed by signal 9", "running"
  pid_t pid() const { return pid_; }
  // omnitwin-guard's pid while it has not been reaped (-1: none).
  pid_t guard_pid() const { return guard_pid_; }

 private:
  // The grace the destructor and omnitwin-guard give it between SIGTERM and SIGKILL.
  static constexpr std::chrono::milliseconds kGuardGrace{2000};
  void reap(int status);
  void signal_all(int sig);
  // omnitwin-guard (twin/guard_main.cpp) beside it: it ends the master and what it started when
  // this process is killed outright; killed and reaped by end_guard(). Without the program
  // found: a warning, and no guard.
  void start_guard();
  void end_guard();
  pid_t pid_ = -1;
  pid_t guard_pid_ = -1;
  int exit_code_ = -1;
  std::vector<ProcessEntry> signalled_;  // its descendants when a signal went out
};

// The last `max_lines` non-empty lines of a master's log file joined by " | " (a master that
// exits at start-up says why there, e.g. "master.yaml:2: period: must be in [0.0001, 1]"); ""
// when there are none or the file cannot be read. Reads at most the file's last 4 KiB.
std::string log_tail(const std::string& path, int max_lines);

// A file the build makes beside the running executable: the first of `beside` (relative to
// the executable's folder, `folder` on return) and then `in_build` (this build's tree) that
// access(path, mode) accepts, as a normal path; "" when none does. Not real-time safe.
std::string find_beside_executable(const std::vector<std::string>& beside, const std::string& in_build, int mode,
                                   std::string& folder);

// The master program to run: `configured` when given; else omni-master beside the omnitwin
// executable (build tree: ../controller/omni-master; installed: same folder). Throws
// RunSetupError-compatible std::runtime_error naming where it looked.
std::string find_master_program(const std::string& configured);

// The master's configuration for this scenario: the control loop, geometry, path and the CAN
// settings the master owns. The twin's direct link runs the same loop and path from it.
// Not real-time safe.
controller::MasterConfig master_config(const Scenario& s);
// The same as the master's configuration file (docs/protocols/omni-master.md).
std::string master_config_yaml(const Scenario& s);

// bus ethercat: the platform loop's file (master_config vocabulary, counts = the drives'
// position units) and the master's own file naming it (controller/ethercat/ec_config.hpp).
std::string ethercat_platform_yaml(const Scenario& s);
std::string ethercat_master_config_yaml(const Scenario& s, const std::string& platform_file);
// The same for `omni-master --bus m3` (controller/mechatrolink3/m3_config's vocabulary).
std::string m3_platform_yaml(const Scenario& s);
std::string m3_master_config_yaml(const Scenario& s, const std::string& platform_file);
// bus canopen: the platform loop (odometry on position actual counts) and the CANopen master's
// configuration file (the drives' EDS, SYNC period, heartbeat times, wheel mode).
std::string canopen_platform_yaml(const Scenario& s);
std::string canopen_master_config_yaml(const Scenario& s, const std::string& platform_file);
// bus tml: the platform loop (odometry on APOS) and the TML master's configuration file.
std::string tml_platform_yaml(const Scenario& s);
std::string tml_master_config_yaml(const Scenario& s, const std::string& platform_file);

}  // namespace omnitwin::twin
