// twin layer — clock modes; see clock.hpp.
#include "twin/clock.hpp"

#include <poll.h>

#include <algorithm>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <cmath>
#include <cerrno>
#include <cstring>

namespace omnitwin::twin {

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

std::size_t LatenessHistogram::bin_of(std::uint64_t us) noexcept {
  if (us < kExactUs) return static_cast<std::size_t>(us);
  const int e = 63 - __builtin_clzll(us);  // us in [2^e, 2^(e+1)), e ≥ 11
  const std::size_t octave = static_cast<std::size_t>(e) - 11;
  if (octave >= kOctaves) return kBins - 1;
  const std::size_t sub = static_cast<std::size_t>(us >> (e - 6)) & (kSubBins - 1);
  return kExactUs + octave * kSubBins + sub;
}

std::uint64_t LatenessHistogram::upper_edge_us(std::size_t bin) noexcept {
  if (bin < kExactUs) return bin + 1;
  const std::size_t octave = (bin - kExactUs) / kSubBins, sub = (bin - kExactUs) % kSubBins;
  const int shift = static_cast<int>(octave) + 11 - 6;  // bin width 2^(e-6)
  return (static_cast<std::uint64_t>(kSubBins + sub + 1)) << shift;
}

void LatenessHistogram::add(std::int64_t late_ns) noexcept {
  const std::int64_t ns = std::max<std::int64_t>(late_ns, 0);
  ++bins_[bin_of(static_cast<std::uint64_t>(ns / 1000))];
  ++count_;
  sum_ns_ += ns;
  max_ns_ = std::max(max_ns_, ns);
}

void LatenessHistogram::clear() noexcept {
  bins_.fill(0);
  count_ = 0;
  sum_ns_ = max_ns_ = 0;
}

double LatenessHistogram::mean_us() const {
  return count_ ? static_cast<double>(sum_ns_) * 1e-3 / static_cast<double>(count_) : 0.0;
}

double LatenessHistogram::quantile_us(double q) const {
  if (count_ == 0) return 0.0;
  // Nearest rank: the smallest sample with at least q·n samples at or below it (0-based
  // ceil(q·n) − 1), so p99 of 100 samples is the 99th, not the largest.
  const double at = std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(count_));
  const auto rank = std::min<std::uint64_t>(count_ - 1, at < 1.0 ? 0 : static_cast<std::uint64_t>(at) - 1);
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < kBins; ++i) {
    seen += bins_[i];
    if (seen > rank) return std::min(static_cast<double>(upper_edge_us(i)), max_us());
  }
  return max_us();
}

RealtimePacer::RealtimePacer(SimTime tick_period) : tick_period_(tick_period) {}

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

void RealtimePacer::set_window(SimTime length, std::function<void(const LatenessWindow&)> sink) {
  window_length_ = length;
  window_sink_ = std::move(sink);
}

void RealtimePacer::flush_window() {
  if (!window_sink_ || window_.count() == 0) return;
  const LatenessWindow w{window_start_,         window_.count(),         window_overruns_,     window_.mean_us(),
                         window_.quantile_us(0.5), window_.quantile_us(0.99), window_.max_us()};
  window_.clear();
  window_overruns_ = 0;
  window_sink_(w);
}

void RealtimePacer::tick(SimTime t) {
  const std::int64_t late = monotonic_ns() - (wall_start_ + t);
  const bool overran = tick_overran(late, tick_period_);
  if (overran) ++overruns_;
  lateness_.add(late);
  if (window_length_ <= 0) return;
  // A tick beyond the open window closes it; the next window starts where this tick falls.
  if (t >= window_start_ + window_length_) {
    flush_window();
    window_start_ = t - t % window_length_;
  }
  window_.add(late);
  if (overran) ++window_overruns_;
}

RealtimeStats RealtimePacer::stats() const {
  RealtimeStats s;
  s.scheduling = scheduling_;
  s.ticks = lateness_.count();
  s.overruns = overruns_;
  s.jitter_mean_us = lateness_.mean_us();
  s.jitter_p99_us = lateness_.quantile_us(0.99);
  s.jitter_max_us = lateness_.max_us();
  return s;
}

}  // namespace omnitwin::twin
