// twin layer — the discrete-event scheduler: one simulated timeline in integer nanoseconds.
//
// Everything that happens in a run is an event on this timeline: physics steps, the master's
// control ticks, each device's timer interrupt on its own (drifting) oscillator, recording,
// scripted faults. Events at the same instant run in a fixed order (priority, then the order
// they were registered), so a run is deterministic whatever the wall clock does. The
// scheduler never reads the wall clock itself: a Pacer decides how simulated time maps to
// real time (lockstep: not at all; realtime: CLOCK_MONOTONIC), which keeps the same code
// path for both clock modes and for tests.
//
// Periodic timers are stored once and re-armed in place, so the cyclic path allocates
// nothing. A timer with a drifting oscillator fires at start + round(k·period·(1+drift)),
// computed from k (not accumulated), so there is no rounding walk over long runs.
#pragma once

#include <cstdint>
#include <functional>
#include <deque>
#include <queue>
#include <string>
#include <vector>

namespace omnitwin::twin {

using SimTime = std::int64_t;  // simulated time [ns]

constexpr SimTime kNsPerSecond = 1'000'000'000;
inline constexpr SimTime seconds_to_ns(double s) { return static_cast<SimTime>(s * 1e9 + (s >= 0 ? 0.5 : -0.5)); }
inline constexpr double ns_to_seconds(SimTime t) { return static_cast<double>(t) * 1e-9; }

// Order of events that fall on the same instant: lower runs first.
enum class Phase : int {
  fault = 0,     // scripted faults change the world before anyone looks at it
  sense = 10,    // sensors sample the state reached at this instant
  master = 20,   // the master's control tick
  device = 30,   // device (slave) timer interrupts
  record = 40,   // recorders see what the controllers decided
  physics = 50,  // physics integrates [t, t + dt] with the commands now in force
};

// Maps simulated time onto the wall clock. wait_until() is called before the first event at
// each new instant; tick() marks instants the caller wants jitter statistics for.
class Pacer {
 public:
  virtual ~Pacer() = default;
  virtual void start() = 0;
  virtual void wait_until(SimTime t) = 0;
  virtual void tick(SimTime t) = 0;
};

class Scheduler {
 public:
  using Callback = std::function<void(SimTime)>;
  using TimerId = int;

  // Adds a periodic timer: first at `first`, then every period·(1 + drift) [ns, -]; a drift
  // that is not finite or <= -1 throws std::invalid_argument.
  // Not real-time safe (allocates); call during set-up.
  TimerId add_periodic(std::string name, Phase phase, SimTime first, SimTime period,
                       Callback cb, double drift = 0.0);
  // Adds a one-shot event at t (>= now(); earlier throws std::invalid_argument). An event
  // added from a callback for the running instant runs after the current event, whatever its
  // phase. Not real-time safe.
  void add_once(std::string name, Phase phase, SimTime t, Callback cb);

  // Stops a periodic timer (e.g. a device that lost power). Real-time safe.
  void cancel(TimerId id);
  // Re-arms a periodic timer so its next firing is at `t` (>= now(); earlier throws
  // std::invalid_argument), counting periods from there (used by device resynchronisation).
  // Real-time safe.
  void restart(TimerId id, SimTime t);
  // Changes a periodic timer's oscillator drift from its next firing on (which keeps its
  // time): later firings are every period·(1 + drift). Throws std::invalid_argument for a
  // one-shot timer or drift <= -1 (programmer errors). Real-time safe.
  void set_drift(TimerId id, double drift);

  // Runs every event with time < end, in order, pacing through `pacer`. Returns the number
  // of events run. Stops early (returning) when stop() was called from a callback or when
  // `should_stop` (checked between instants) returns true.
  std::uint64_t run_until(SimTime end, Pacer& pacer, const std::function<bool()>& should_stop = {});

  void stop() { stop_requested_ = true; }
  SimTime now() const { return now_; }
  std::uint64_t events_run() const { return events_run_; }

 private:
  struct Timer {
    std::string name;
    Phase phase;
    SimTime origin;    // time of firing number 0 after the last (re)start
    double nominal_ns; // period without drift
    double period_ns;  // period·(1 + drift)
    std::int64_t k;    // number of the next firing
    bool periodic;
    bool active;
    std::uint64_t generation;  // bumps on cancel/restart so stale queue entries are skipped
    Callback cb;
  };
  struct Entry {
    SimTime t;
    int phase;
    int id;
    std::uint64_t generation;
    bool operator>(const Entry& o) const {
      if (t != o.t) return t > o.t;
      if (phase != o.phase) return phase > o.phase;
      return id > o.id;
    }
  };

  SimTime next_time(const Timer& tm) const;
  void push(int id);

  std::deque<Timer> timers_;  // deque: adding a timer from a callback keeps references valid
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> queue_;
  SimTime now_ = 0;
  std::uint64_t events_run_ = 0;
  bool stop_requested_ = false;
};

}  // namespace omnitwin::twin
