// The thesis slave's firmware and board, emulated; see drive_chain.hpp.
#include "physics/drive_chain.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace omnitwin::physics {

namespace {
constexpr double kTwoPi = 2.0 * std::numbers::pi;
}  // namespace

// ---- DA converter -----------------------------------------------------------------------------

int dac_max_code(const DacParams& dac) { return (1 << dac.bits) - 1; }

int dac_clamp_code(const DacParams& dac, double code) {
  // Round to nearest first, then clamp into the converter's range (NaN reads as 0).
  if (!(code > 0.0)) return 0;
  const double top = dac_max_code(dac);
  return static_cast<int>(std::lround(std::min(code, top)));
}

double dac_volts(const DacParams& dac, int code) {
  const int d = std::clamp(code, 0, dac_max_code(dac));
  return static_cast<double>(d) / static_cast<double>(1 << dac.bits) * dac.vref;
}

// ---- HCTL-2032 style quadrature counter ----------------------------------------------------

QuadratureCounter::QuadratureCounter(const EncoderParams& encoder, double angle)
    : cpr_(4 * encoder.lines),
      index_per_rev_(std::max(encoder.index_per_rev, 0)),
      angle_(angle),
      edge_(edge_of(angle)),
      edge_ref_(edge_),
      index_region_(index_of(angle)) {}

int64_t QuadratureCounter::edge_of(double angle) const {
  return static_cast<int64_t>(std::floor(angle * cpr_ / kTwoPi));
}

int64_t QuadratureCounter::index_of(double angle) const {
  return static_cast<int64_t>(std::floor(angle * index_per_rev_ / kTwoPi));
}

int32_t QuadratureCounter::wrap(int64_t edge) const {
  // Modular arithmetic on uint32 is the chip's two's-complement up/down counter.
  const uint32_t moved = static_cast<uint32_t>(static_cast<uint64_t>(edge - edge_ref_));
  return static_cast<int32_t>(preset_ + moved);
}

void QuadratureCounter::update(double angle) {
  // Count edges: the reading follows the fixed edge positions of the new angle.
  angle_ = angle;
  edge_ = edge_of(angle);
  if (index_per_rev_ == 0) return;
  // Index pulses: every crossing of a k·2π/n position is one event.
  const int64_t region = index_of(angle);
  if (region == index_region_) return;
  index_events_ += std::abs(region - index_region_);
  // The last index crossed: `region` moving up, `region + 1` moving down.
  const int64_t k = region > index_region_ ? region : region + 1;
  index_region_ = region;
  // Latch the count of the index position itself (floor(k·cpr/n), exact in integers).
  const int64_t num = k * cpr_;
  const int64_t edge = num >= 0 ? num / index_per_rev_ : -((-num + index_per_rev_ - 1) / index_per_rev_);
  index_count_ = wrap(edge);
  index_latched_ = true;
}

void QuadratureCounter::reset() {
  // RST: the current edge reads 0; the index history restarts.
  edge_ref_ = edge_;
  preset_ = 0;
  index_events_ = 0;
  index_latched_ = false;
  index_count_ = 0;
}

void QuadratureCounter::preset(int32_t count) {
  edge_ref_ = edge_;
  preset_ = static_cast<uint32_t>(count);
}

int32_t QuadratureCounter::count() const { return wrap(edge_); }

// ---- the 8051's velocity PI ----------------------------------------------------------------

VelocityLoop::VelocityLoop(const VelocityLoopParams& loop, const DacParams& dac,
                           const DriverParams& driver, int counts_per_rev)
    : loop_(loop), dac_(dac) {
  // code per volt × volt per (rad/s) × (rad/s) per (count/sample).
  const double codes_per_volt = static_cast<double>(1 << dac.bits) / dac.vref;
  const double rad_s_per_count_sample = kTwoPi / counts_per_rev / loop.period;
  codes_per_count_per_sample_ = codes_per_volt * rad_s_per_count_sample / driver.gain;
  zero_code_ = driver.zero_volts * codes_per_volt;
}

double VelocityLoop::ideal_code(double command_counts_per_sample) const {
  return zero_code_ + codes_per_count_per_sample_ * command_counts_per_sample;
}

namespace {
// C on an 8051: a 16-bit int sum wraps modulo 2^16 (two's complement), it does not saturate.
int16_t wrap16(long value) { return static_cast<int16_t>(static_cast<uint16_t>(value)); }
}  // namespace

int VelocityLoop::step_int16(double command_counts_per_sample, double measured_counts_per_sample) {
  // Whole counts and whole-code gains, as the firmware holds them.
  const long c = std::lround(command_counts_per_sample);
  const long e = c - std::lround(measured_counts_per_sample);
  const long kp = std::lround(loop_.kp), ki = std::lround(loop_.ki);
  const long slope = std::lround(loop_.kff * codes_per_count_per_sample_);
  // Each product and sum is stored in a 16-bit int, wrapping on overflow.
  const int16_t ff = wrap16(std::lround(zero_code_) + wrap16(slope * c));
  integral_ = wrap16(static_cast<long>(integral_) + wrap16(ki * e));
  const int16_t u = wrap16(static_cast<long>(ff) + wrap16(kp * e) + static_cast<long>(integral_));
  // The DA port takes the 12 low bits' range: the firmware clamps before writing.
  const int top = dac_max_code(dac_);
  saturated_ = u < 0 || u > top;
  return std::clamp<int>(u, 0, top);
}

int VelocityLoop::step(double command_counts_per_sample, double measured_counts_per_sample) {
  if (loop_.arithmetic == LoopArithmetic::int16)
    return step_int16(command_counts_per_sample, measured_counts_per_sample);
  // Error in counts per sample and the feed-forward code for the command.
  const double e = command_counts_per_sample - measured_counts_per_sample;
  const double ff = zero_code_ + loop_.kff * (ideal_code(command_counts_per_sample) - zero_code_);
  // Tentative output with the integral advanced by this sample's error.
  const double candidate = integral_ + loop_.ki * e;
  const double u = ff + loop_.kp * e + candidate;
  const double top = dac_max_code(dac_);
  // Conditional integration: keep the step unless it drives further into a limit.
  const bool high = u > top, low = u < 0.0;
  saturated_ = high || low;
  if (!((high && e > 0.0) || (low && e < 0.0))) integral_ = candidate;
  return dac_clamp_code(dac_, ff + loop_.kp * e + integral_);
}

void VelocityLoop::reset() {
  integral_ = 0.0;
  saturated_ = false;
}

// ---- one wheel's node: counter + loop + DA ------------------------------------------------------

WheelDriveChain::WheelDriveChain(const PlatformParams& params, double shaft_angle)
    : dac_(params.dac),
      counter_(params.encoder, shaft_angle),
      loop_(params.velocity_loop, params.dac, params.driver, params.counts_per_rev()) {
  write_code(dac_clamp_code(dac_, loop_.zero_code()));
}

void WheelDriveChain::observe(double shaft_angle) { counter_.update(shaft_angle); }

double WheelDriveChain::sample(double shaft_angle, double command_counts_per_sample) {
  // Read the counter and form the speed in counts per sample.
  counter_.update(shaft_angle);
  const int32_t count = counter_.count();
  last_.delta_counts = counter_delta(count, previous_count_);
  last_.count = previous_count_ = count;
  last_.command = command_counts_per_sample;
  // PI → DA.
  write_code(loop_.step(command_counts_per_sample, last_.delta_counts));
  return last_.volts;
}

void WheelDriveChain::reset() {
  counter_.reset();
  loop_.reset();
  previous_count_ = 0;
  last_ = WheelDriveSample{};
  write_code(dac_clamp_code(dac_, loop_.zero_code()));
}

void WheelDriveChain::write_code(int code) {
  last_.code = code;
  last_.volts = dac_volts(dac_, code);
}

}  // namespace omnitwin::physics
