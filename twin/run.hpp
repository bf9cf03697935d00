// twin layer — one run of a scenario: the platform twin wired onto the scheduler.
//
// A run owns the MuJoCo platform, the four wheels' drive chains (HCTL-2032 counter, the
// slave's velocity PI, DA, analog driver) and the master's platform loop, and puts each on
// the discrete-event timeline: physics every dt, the master every control period, each
// wheel's slave on its own oscillator. With bus `direct` the master and the slaves share
// memory with zero delay: the baseline that bus effects are measured against. The buses of
// later issues replace that link with frames over a real transport.
//
// Records are written into the run directory (docs/run-directory.md): run.json and
// platform.xml before the first step, trajectory.csv and bus.csv (every control sample),
// events.log, metrics.json. Video and report are made from them afterwards (run_outputs).
// A run validates and builds everything before it creates the directory, so a bad input
// never leaves half-written files behind.
#pragma once

#include <atomic>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "twin/run_state.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin {

// metrics.json master.stop_signal of a lockstep master of ours asked to end in simulated time
// (Grant.stop), beside "SIGTERM" and "SIGINT from the terminal".
inline constexpr const char* kStopInTheGrants = "stop in the grants";

// A live consumer of the run (DDS, the web view). Called on the run's own thread: on_state at every
// control sample from the cyclic path, so it must be real-time safe (copy and return; never
// block, never allocate); the others are called rarely and may allocate.
class RunObserver {
 public:
  virtual ~RunObserver() = default;
  virtual void on_start(const RunInfo& info) = 0;
  virtual void on_state(const StateSample& s) = 0;
  virtual void on_event(const RunEvent& e) = 0;
  // The run's end, with what metrics.json holds.
  virtual void on_end(const nlohmann::json& metrics) = 0;
};

// Hands each observer call to several observers (DDS and the web view at once).
class ObserverFan : public RunObserver {
 public:
  void add(RunObserver* o) {
    if (o) all_.push_back(o);
  }
  bool empty() const { return all_.empty(); }
  void on_start(const RunInfo& i) override {
    for (auto* o : all_) o->on_start(i);
  }
  void on_state(const StateSample& s) override {
    for (auto* o : all_) o->on_state(s);
  }
  void on_event(const RunEvent& e) override {
    for (auto* o : all_) o->on_event(e);
  }
  void on_end(const nlohmann::json& m) override {
    for (auto* o : all_) o->on_end(m);
  }

 private:
  std::vector<RunObserver*> all_;
};

struct RunOptions {
  std::string out_dir;                        // run directory (created if missing)
  bool progress = false;                      // terminal progress bar on stderr
  const std::atomic<bool>* interrupt = nullptr;  // set by SIGINT/SIGTERM: end cleanly
  // How many SIGINT/SIGTERM came, and whether the first came from the terminal (the kernel's
  // Ctrl-C to the whole foreground process group, which holds the master too). With them, a
  // realtime run interrupted while its master runs serves the master's own shutdown (a second
  // signal ends that at once); null: the run ends at the signal.
  const std::atomic<int>* signals = nullptr;
  const std::atomic<bool>* terminal_signal = nullptr;
  // A bus: the master is someone else's program on the transport (`omnitwin twin`); the twin
  // starts none and runs in realtime.
  bool external_master = false;
  // With external_master: run until *interrupt is set (SIGINT/SIGTERM), not for the scenario's
  // duration; that signal is then the normal end (not an interruption: records whole,
  // expectations judged, exit 0/1). A run in which no master sent a frame fails its
  // expectations ("no master connected").
  bool until_stopped = false;
  // Told, once the bus network is up, where a master must connect (the transport spec it
  // should use, e.g. the master's end of a veth pair made for the run). May be empty.
  std::function<void(const std::string& master_iface)> on_bus_ready;
  RunObserver* observer = nullptr;            // live state and events (may be null)
  // For commands that run many scenarios at once (check -j, sweep -j): lockstep runs are
  // isolated on buses of their own, but a realtime run uses its scenario's bus and the wall
  // clock, so it holds this lock from its network's start to its end (null: run alone).
  std::mutex* realtime_turn = nullptr;
};

struct RunResult {
  int exit_code = 0;          // DESIGN §9: 0 ok, 1 expectations failed, 3 runtime failure
  bool passed = false;        // expectations held and every record was written whole
  bool interrupted = false;
  std::string error;          // why the run ended early (a record write failed…); "" if not
  std::vector<std::string> missing_records;  // records absent at the end (names in the run dir)
  std::vector<std::string> partial_records;  // records left only under ".NAME.part"
  std::string out_dir;
  nlohmann::json metrics;     // what metrics.json holds
};

// A scenario that cannot run as given (e.g. a bus that is not built yet): exit code 2.
class RunSetupError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Runs a loaded scenario to its end. Throws RunSetupError for inputs it cannot run (before
// anything is written) and std::runtime_error when the run directory or metrics.json cannot
// be written. A record write that fails mid-run ends the run early with exit_code 3 and
// `error` set; trajectory.csv then stays under its temporary name. Not real-time safe as a
// whole; the per-tick path inside is.
RunResult run_scenario(const Scenario& scenario, const RunOptions& options);

}  // namespace omnitwin::twin
