// twin layer — clock modes; see clock.hpp.
#include "twin/clock.hpp"

#include <poll.h>

#include <algorithm>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstring>
#include <numeric>

namespace omnitwin::twin {

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

RealtimePacer::RealtimePacer(SimTime tick_period, std::size_t expected_ticks)
    : tick_period_(tick_period) {
  lateness_us_.reserve(expected_ticks + 16);
}

namespace {
constexpr int kFifoPriority = 40;  // above ordinary work, below the kernel's own threads
}

RealtimePacer::~RealtimePacer() {
  if (restore_policy_) {
    sched_param sp{};
    sp.sched_priority = old_priority_;
    pthread_setschedparam(pthread_self(), old_policy_, &sp);
  }
  if (unlock_memory_) munlockall();
}

void RealtimePacer::start() {
  // Real-time scheduling and locked memory where permitted; otherwise say why not.
  sched_param old{};
  if (!restore_policy_ && pthread_getschedparam(pthread_self(), &old_policy_, &old) == 0) {
    old_priority_ = old.sched_priority;
    sched_param sp{};
    sp.sched_priority = kFifoPriority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    restore_policy_ = rc == 0;
    scheduling_ = rc == 0 ? "SCHED_FIFO " + std::to_string(kFifoPriority)
                          : std::string("SCHED_OTHER (SCHED_FIFO refused: ") + std::strerror(rc) + ")";
  }
  if (!unlock_memory_) unlock_memory_ = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
  wall_start_ = monotonic_ns();
}

void RealtimePacer::wait_until(SimTime t) {
  const std::int64_t deadline = wall_start_ + t;
  if (wake_fd_ >= 0) return wait_waking(deadline);
  if (monotonic_ns() >= deadline) return;
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(deadline / kNsPerSecond);
  ts.tv_nsec = static_cast<long>(deadline % kNsPerSecond);
  // Absolute deadline: an interrupted sleep simply resumes towards the same instant.
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

void RealtimePacer::set_wake(int fd, std::function<void(SimTime)> on_readable) {
  wake_fd_ = fd;
  on_wake_ = std::move(on_readable);
}

// Sleeps towards the deadline but answers the wake descriptor at once: a frame that arrives
// between two events is handed over at the instant it arrived (sim time = wall time since
// start), as a slave answers a frame on the wire, instead of at the next event.
void RealtimePacer::wait_waking(std::int64_t deadline) {
  for (;;) {
    const std::int64_t now = monotonic_ns();
    if (now >= deadline) {
      // Late: frames that came meanwhile are still handed over before the late event runs.
      pollfd p{wake_fd_, POLLIN, 0};
      if (::poll(&p, 1, 0) > 0 && (p.revents & POLLIN) != 0) on_wake_(now - wall_start_);
      return;
    }
    const std::int64_t left_ns = deadline - now;
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(left_ns / kNsPerSecond);
    ts.tv_nsec = static_cast<long>(left_ns % kNsPerSecond);
    pollfd p{wake_fd_, POLLIN, 0};
    const int n = ppoll(&p, 1, &ts, nullptr);
    if (n > 0 && (p.revents & POLLIN) != 0) on_wake_(monotonic_ns() - wall_start_);
    if (n < 0 && errno != EINTR) return;
  }
}

void RealtimePacer::tick(SimTime t) {
  const std::int64_t late = monotonic_ns() - (wall_start_ + t);
  if (tick_overran(late, tick_period_)) ++overruns_;
  lateness_us_.push_back(static_cast<double>(std::max<std::int64_t>(late, 0)) * 1e-3);
}

RealtimeStats RealtimePacer::stats() const {
  RealtimeStats s;
  s.scheduling = scheduling_;
  s.ticks = lateness_us_.size();
  s.overruns = overruns_;
  if (lateness_us_.empty()) return s;
  std::vector<double> sorted = lateness_us_;
  std::sort(sorted.begin(), sorted.end());
  s.jitter_mean_us = std::accumulate(sorted.begin(), sorted.end(), 0.0) / sorted.size();
  s.jitter_p99_us = sorted[std::min(sorted.size() - 1, static_cast<std::size_t>(0.99 * sorted.size()))];
  s.jitter_max_us = sorted.back();
  return s;
}

}  // namespace omnitwin::twin
