// twin layer — lockstep for a master we did not write: the twin's end of the virtual-time
// channel (twin/vtime/vt_protocol.hpp, docs/protocols/vtime.md) and the pacer that lets the
// master's waits decide how far the simulation runs.
//
// The master runs under libomnitwin_vtime.so. Its process reports each moment it waits as a
// whole (Wait: a deadline, whether a frame should wake it, the bus frames it has sent); the
// pacer takes those frames off the transport at the wait's instant, runs the simulation to the
// earlier of the deadline and the next frame the network puts on the master's transport, and
// answers Wake. The simulation therefore never runs ahead of the master, and the master never
// sees a frame before its simulated arrival. The wall clock appears only in watchdogs.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "twin/master_command.hpp"
#include "twin/scheduler.hpp"
#include "twin/vtime/vt_protocol.hpp"

namespace omnitwin::twin {

class BusNetwork;

// The twin's end: an abstract Unix SOCK_SEQPACKET socket, one master process on it.
class VtimeServer {
 public:
  enum class Status { ok, timeout, closed, protocol, second_process };

  VtimeServer();  // throws std::runtime_error when the socket cannot be created
  ~VtimeServer();
  VtimeServer(const VtimeServer&) = delete;
  VtimeServer& operator=(const VtimeServer&) = delete;

  // The environment the master process needs (LD_PRELOAD, the channel, the bus, the epoch).
  std::vector<std::string> environment(const std::string& library, const std::string& bus) const;

  // Waits up to `timeout` for the master's Hello and welcomes it at `now` [ns].
  Status accept(std::chrono::milliseconds timeout, SimTime now);
  // The master's next Wait, within `timeout` of wall time. A process that exec()s keeps its
  // place (same pid, new connection); any other process that connects is refused and ends the
  // wait with second_process (its pid in other_pid()).
  Status next_wait(vtime::Record& w, std::chrono::milliseconds timeout, SimTime now);
  // `signal`: the signal the twin has just sent the master (0: none); its library then waits
  // for the program's handler to run and ends the waits it interrupted (EINTR).
  bool wake(std::uint64_t seq, SimTime now, std::uint64_t frames, int signal = 0);
  void end(SimTime now);  // best effort

  pid_t other_pid() const { return other_pid_; }
  std::uint64_t waits() const { return waits_; }

 private:
  bool send(const vtime::Record& r);
  Status take_connection(SimTime now, bool first);

  int listen_fd_ = -1;
  int conn_fd_ = -1;
  std::string name_;
  pid_t pid_ = -1;
  pid_t other_pid_ = -1;
  std::uint64_t waits_ = 0;
};

const char* to_string(VtimeServer::Status s);

// Paces a run on the master's waits. wait_until(t) is the scheduler asking to run instant t:
// it meets the master (Wait, drain its frames, run the network to a frame for it or to its
// deadline, Wake) as often as needed before t may run. A failure (the master died, a watchdog,
// a second process) is reported through `fail` and stops the scheduler; `gone` is true where
// the master process left the virtual clock (ended or was killed): a lost master.
class VtimePacer : public Pacer {
 public:
  using FailFn = std::function<void(std::string why, bool gone)>;
  VtimePacer(VtimeServer& server, BusNetwork& net, Scheduler& sched, std::chrono::milliseconds watchdog,
             FailFn fail, std::function<std::string()> master_status);

  void start() override {}
  void wait_until(SimTime t) override;
  void tick(SimTime) override {}

  SimTime master_now() const { return now_; }
  bool failed() const { return failed_; }
  // From the run's end on, the master was asked to stop (`signal`, SIGTERM, just sent): its
  // leaving the clock is its end, not a lost master. A wait it holds ends now, as the signal
  // ends a wait on Linux: its handler's flag (or the signal's default action) acts at this
  // instant, not at the wait's deadline. ended(): it has left; the scheduler was stopped then,
  // and from then on time runs free (nothing is left to pace).
  void expect_end(int signal);
  bool ended() const { return ended_; }
  std::uint64_t wakes() const { return wakes_; }
  std::uint64_t frame_wakes() const { return frame_wakes_; }

 private:
  bool take_wait();
  bool wake_at(SimTime t, int signal = 0);
  void failure(std::string why, bool gone = false);

  VtimeServer& server_;
  BusNetwork& net_;
  Scheduler& sched_;
  std::chrono::milliseconds watchdog_;
  FailFn fail_;
  std::function<std::string()> master_status_;
  bool have_wait_ = false;
  bool failed_ = false;
  bool expect_end_ = false;
  bool ended_ = false;
  vtime::Record wait_{};
  SimTime now_ = 0;                    // the master's simulated time [ns]
  std::uint64_t delivered_at_wait_ = 0;
  std::uint64_t wakes_ = 0, frame_wakes_ = 0;
};

// libomnitwin_vtime.so: beside the omnitwin executable's build tree (twin/vtime/) or installed
// beside it. Throws std::runtime_error naming where it looked.
std::string find_vtime_library();

// Whether `program` (a path, or a name on PATH) is a dynamically linked ELF file: the only kind
// LD_PRELOAD reaches. "" when it is; else why not ("statically linked", "not found", …).
std::string preload_obstacle(const std::string& program);



}  // namespace omnitwin::twin
