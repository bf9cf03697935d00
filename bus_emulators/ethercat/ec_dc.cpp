// bus_emulators/ethercat — distributed clocks (see ec_dc.hpp).
#include "bus_emulators/ethercat/ec_dc.hpp"

#include <algorithm>
#include <cmath>

namespace omnitwin::ethercat {

namespace {
// Time arithmetic as the ESC's 64-bit registers do it: modulo 2^64 (no signed overflow).
std::int64_t wrap_add(std::int64_t a, std::uint64_t b) {
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(a) + b);
}
std::int64_t wrap_diff(std::int64_t a, std::int64_t b) {  // a − b, the nearest way round
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(a) - static_cast<std::uint64_t>(b));
}
}  // namespace

DcClock::DcClock(double drift, std::int64_t local_at_start, SimTime start)
    : drift_(drift), local_at_start_(local_at_start) {
  reset(start);
}

void DcClock::reset(SimTime t) {
  anchor_t_ = t;
  anchor_local_ = local_at_start_;
  corr_ = 0;
  rate_ = 1.0 + drift_;
  offset_ = 0;
  delay_ = 0;
  diff_ = 0;
  have_prev_ = false;
  sync0_active_ = false;
  sync0_invalid_ = false;
  next_sync0_ = 0;
  cycle0_ = 0;
}

std::int64_t DcClock::local(SimTime t) const {
  const long double dt = static_cast<long double>(t) - static_cast<long double>(anchor_t_);
  // The ESC's 64-bit time registers wrap modulo 2^64: add in unsigned arithmetic.
  return wrap_add(anchor_local_, static_cast<std::uint64_t>(std::llround(dt * rate_)));
}

std::int64_t DcClock::system(SimTime t) const { return wrap_add(local(t), offset_); }

SimTime DcClock::sim_time_of_system(std::int64_t s) const {
  // The first sim time at which system() reaches s (estimate, then exact on the rounding). The
  // distance s − offset − anchor is taken modulo 2^64 (the nearest way round, as the ESC's
  // wrapping compare does); a target beyond the sim time range answers the range's end.
  const auto dl = static_cast<std::int64_t>(static_cast<std::uint64_t>(s) - offset_ -
                                            static_cast<std::uint64_t>(anchor_local_));
  const long double est = static_cast<long double>(anchor_t_) + std::ceil(static_cast<long double>(dl) / rate_);
  constexpr long double kLimit = static_cast<long double>(kSimTimeLimit);
  if (est >= kLimit) return kSimTimeLimit;
  if (est <= -kLimit) return -kSimTimeLimit;
  SimTime t = static_cast<SimTime>(est);
  for (int i = 0; i < 4 && wrap_diff(system(t - 1), s) >= 0; ++i) --t;
  for (int i = 0; i < 4 && wrap_diff(system(t), s) < 0; ++i) ++t;
  return t;
}

void DcClock::set_drift(double drift, SimTime t) {
  anchor_local_ = local(t);
  anchor_t_ = t;
  drift_ = drift;
  rate_ = 1.0 + drift_ + corr_;
}

void DcClock::reanchor(SimTime t) {
  anchor_local_ = local(t);
  anchor_t_ = t;
  rate_ = 1.0 + drift_ + corr_;
}

void DcClock::reset_loop(SimTime t) {
  corr_ = 0;
  reanchor(t);
  have_prev_ = false;
  diff_ = 0;
}

void DcClock::set_offset(std::uint64_t o) {
  offset_ = o;
  have_prev_ = false;  // a step of the offset is not a drift: no proportional kick from it
}

void DcClock::sample(std::uint64_t received, bool wide, SimTime t) {
  const std::uint64_t expected = received + delay_;
  const auto mine = static_cast<std::uint64_t>(system(t));
  std::int64_t e = 0;
  if (wide) {
    e = static_cast<std::int64_t>(mine - expected);
  } else {
    e = static_cast<std::int32_t>(static_cast<std::uint32_t>(mine) - static_cast<std::uint32_t>(expected));
  }
  diff_ = e;
  if (have_prev_ && t > prev_sample_t_) {
    const double h = static_cast<double>(t) - static_cast<double>(prev_sample_t_);
    // e − e_prev in floating point: two far-apart samples (up to ±2^63 each) must not overflow;
    // the correction then saturates at ±kMaxCorrection as the ESC's speed counter does.
    const double de = static_cast<double>(e) - static_cast<double>(prev_diff_);
    corr_ -= (kKi * static_cast<double>(e) + kKp * de) / h;
    corr_ = std::clamp(corr_, -kMaxCorrection, kMaxCorrection);
    reanchor(t);
  }
  prev_diff_ = e;
  prev_sample_t_ = t;
  have_prev_ = true;
}

std::uint32_t DcClock::difference_register() const {
  // |e| saturated to 31 bits; |INT64_MIN| is taken in unsigned arithmetic.
  const std::uint64_t mag = diff_ < 0 ? 0 - static_cast<std::uint64_t>(diff_) : static_cast<std::uint64_t>(diff_);
  auto v = static_cast<std::uint32_t>(std::min<std::uint64_t>(mag, 0x7FFFFFFF));
  if (diff_ < 0) v |= 0x80000000u;
  return v;
}

void DcClock::configure_sync(std::uint8_t activation, std::uint64_t start, std::uint32_t cycle0, SimTime t) {
  cycle0_ = cycle0;
  const bool requested = (activation & 0x03) == 0x03;
  sync0_invalid_ = requested && cycle0 != 0 && cycle0 < kMinSyncCycleNs;
  sync0_active_ = requested && !sync0_invalid_;  // an invalid cycle: the unit stays off, no pulses
  if (!sync0_active_) return;
  next_sync0_ = start;
  const auto now = static_cast<std::uint64_t>(system(t));
  if (next_sync0_ < now && cycle0_ > 0) {
    const std::uint64_t k = (now - next_sync0_ + cycle0_ - 1) / cycle0_;
    next_sync0_ += k * cycle0_;
  }
}

bool DcClock::pop_sync0(SimTime t, SimTime& when) {
  if (!sync0_active_) return false;
  if (static_cast<std::uint64_t>(system(t)) < next_sync0_) return false;
  when = std::min(t, sim_time_of_system(static_cast<std::int64_t>(next_sync0_)));
  arm_sync1(next_sync0_);
  if (cycle0_ == 0) {
    sync0_active_ = false;
  } else {
    next_sync0_ += cycle0_;
  }
  return true;
}

void DcClock::configure_sync1(bool active, std::uint32_t cycle1) {
  sync1_active_ = active;
  cycle1_ = cycle1;
  sync1_pending_ = false;
  sync0_count_ = 0;
  if (cycle0_ == 0 || cycle1 < cycle0_) {
    sync1_every_ = 1;
    sync1_shift_ = cycle1;
  } else {
    sync1_every_ = cycle1 / cycle0_;
    sync1_shift_ = cycle1 % cycle0_;
  }
}

void DcClock::arm_sync1(std::uint64_t sync0_time) {
  if (sync1_active_ && sync0_count_ % sync1_every_ == 0) {
    next_sync1_ = sync0_time + sync1_shift_;
    sync1_pending_ = true;
  }
  ++sync0_count_;
}

bool DcClock::pop_sync1(SimTime t, SimTime& when) {
  if (!sync1_active() || !sync1_pending_) return false;
  if (static_cast<std::uint64_t>(system(t)) < next_sync1_) return false;
  when = std::min(t, sim_time_of_system(static_cast<std::int64_t>(next_sync1_)));
  sync1_pending_ = false;
  return true;
}

void DcClock::skip_sync0_to(SimTime t) {
  if (!sync0_active_ || cycle0_ == 0) return;
  const auto now = static_cast<std::uint64_t>(system(t));
  if (next_sync0_ > now) return;
  next_sync0_ += ((now - next_sync0_) / cycle0_ + 1) * cycle0_;  // the first boundary after now
}

}  // namespace omnitwin::ethercat
