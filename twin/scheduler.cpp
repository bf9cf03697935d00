// twin layer — the discrete-event scheduler; see scheduler.hpp.
#include "twin/scheduler.hpp"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace omnitwin::twin {

Scheduler::TimerId Scheduler::add_periodic(std::string name, Phase phase, SimTime first,
                                           SimTime period, Callback cb, double drift) {
  if (period <= 0) throw std::invalid_argument("scheduler: period must be > 0 for " + name);
  // NaN passed `drift <= -1` and made every later firing INT64_MIN: the run never ended (review).
  if (!std::isfinite(drift) || drift <= -1.0) throw std::invalid_argument("scheduler: drift must be finite and > -1 for " + name);
  const int id = static_cast<int>(timers_.size());
  timers_.push_back(Timer{std::move(name), phase, first, static_cast<double>(period),
                          static_cast<double>(period) * (1.0 + drift), 0, true, true, 0, std::move(cb)});
  push(id);
  return id;
}

void Scheduler::add_once(std::string name, Phase phase, SimTime t, Callback cb) {
  if (t < now_) throw std::invalid_argument("scheduler: " + name + " at a time already past");
  const int id = static_cast<int>(timers_.size());
  timers_.push_back(Timer{std::move(name), phase, t, 0.0, 0.0, 0, false, true, 0, std::move(cb)});
  push(id);
}

void Scheduler::cancel(TimerId id) {
  Timer& tm = timers_.at(static_cast<std::size_t>(id));
  tm.active = false;
  ++tm.generation;
}

void Scheduler::restart(TimerId id, SimTime t) {
  Timer& tm = timers_.at(static_cast<std::size_t>(id));
  // Time runs one way: a restart into the past replayed instants already run (review).
  if (t < now_) throw std::invalid_argument("scheduler: restart of " + tm.name + " at a time already past");
  tm.origin = t;
  tm.k = 0;
  tm.active = true;
  ++tm.generation;
  push(id);
}

void Scheduler::set_drift(TimerId id, double drift) {
  Timer& tm = timers_.at(static_cast<std::size_t>(id));
  if (!tm.periodic || !std::isfinite(drift) || drift <= -1.0)
    throw std::invalid_argument("scheduler: set_drift needs a periodic timer and a finite drift > -1");
  // The firing already due keeps its time; the periods after it run on the new oscillator.
  if (tm.active) {
    tm.origin = next_time(tm);
    tm.k = 0;
    ++tm.generation;
  }
  tm.period_ns = tm.nominal_ns * (1.0 + drift);
  if (tm.active) push(id);
}

SimTime Scheduler::next_time(const Timer& tm) const {
  if (!tm.periodic) return tm.origin;
  // Computed from k, not accumulated: no rounding walk over long runs.
  return tm.origin + static_cast<SimTime>(std::llround(static_cast<double>(tm.k) * tm.period_ns));
}

void Scheduler::push(int id) {
  const Timer& tm = timers_[static_cast<std::size_t>(id)];
  queue_.push(Entry{next_time(tm), static_cast<int>(tm.phase), id, tm.generation});
}

std::uint64_t Scheduler::run_until(SimTime end, Pacer& pacer, const std::function<bool()>& should_stop) {
  std::uint64_t ran = 0;
  SimTime paced = -1;
  stop_requested_ = false;
  while (!queue_.empty() && !stop_requested_) {
    const Entry e = queue_.top();
    if (e.t >= end) break;
    Timer& tm = timers_[static_cast<std::size_t>(e.id)];
    // Skip entries made stale by cancel() or restart().
    if (!tm.active || e.generation != tm.generation) {
      queue_.pop();
      continue;
    }
    // A new instant: let the pacer hold us back (realtime) and the caller stop us. The entry
    // stays queued until it runs, so a run resumed after should_stop keeps it (it was popped
    // first and a periodic timer was lost for good; review).
    if (e.t != paced) {
      if (should_stop && should_stop()) break;
      pacer.wait_until(e.t);
      paced = e.t;
    }
    queue_.pop();
    now_ = e.t;
    // Re-arm before running, so the callback may cancel or restart its own timer.
    if (tm.periodic) {
      ++tm.k;
      push(e.id);
    } else {
      tm.active = false;
    }
    timers_[static_cast<std::size_t>(e.id)].cb(e.t);
    ++ran;
  }
  events_run_ += ran;
  return ran;
}

}  // namespace omnitwin::twin
