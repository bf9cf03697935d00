// Tests physics/drive_chain: the thesis node's firmware and board — 12-bit DA (eq. 4-8), the
// HCTL-2032 style counter (exact counts, direction, 32-bit wrap, index latching, RST), and
// the 8051 velocity PI closed around an amplifier (physics/amplifier.hpp) and a first-order
// motor simulated here (tracking within a count, anti-windup after saturation, a small
// command held up by the amplifier's dead band), and the 8051's 16-bit integer PI with its
// wrap-around on overflow. The chain ends at the DA's voltage.
#include "physics/drive_chain.hpp"

#include "physics/amplifier.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <numbers>

namespace omnitwin::physics {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

TEST(Dac, VoltsAtCodesZeroMidAndFull) {
  const DacParams dac;  // 12 bits, 5 V
  EXPECT_EQ(dac_max_code(dac), 4095);
  EXPECT_DOUBLE_EQ(dac_volts(dac, 0), 0.0);
  EXPECT_DOUBLE_EQ(dac_volts(dac, 2048), 2.5);
  EXPECT_DOUBLE_EQ(dac_volts(dac, 4095), 4095.0 / 4096.0 * 5.0);
}

TEST(Dac, CodesAreClampedToTheConverterRange) {
  const DacParams dac;
  EXPECT_DOUBLE_EQ(dac_volts(dac, -7), 0.0);
  EXPECT_DOUBLE_EQ(dac_volts(dac, 99999), dac_volts(dac, 4095));
  EXPECT_EQ(dac_clamp_code(dac, -3.2), 0);
  EXPECT_EQ(dac_clamp_code(dac, 5000.0), 4095);
  EXPECT_EQ(dac_clamp_code(dac, 1000.6), 1001);
}

TEST(Counter, ExactCountsForKnownAnglesBothDirections) {
  const EncoderParams enc;  // 500 lines → 2000 counts/rev
  QuadratureCounter c(enc);
  EXPECT_EQ(c.counts_per_rev(), 2000);
  const double step = kTwoPi / 2000.0;
  c.update(10.5 * step);
  EXPECT_EQ(c.count(), 10);
  c.update(kTwoPi * 1.25);  // a revolution and a quarter
  EXPECT_EQ(c.count(), 2500);
  c.update(-0.5 * step);    // just below zero: floor gives −1
  EXPECT_EQ(c.count(), -1);
  c.update(-kTwoPi * 3.0 - 0.5 * step);
  EXPECT_EQ(c.count(), -6001);
  c.update(0.5 * step);
  EXPECT_EQ(c.count(), 0);
}

TEST(Counter, CountsRelativeToTheResetPositionOnFixedEdges) {
  const EncoderParams enc;
  const double step = kTwoPi / 2000.0;
  QuadratureCounter c(enc, 100.7 * step);  // starts mid-way between edges 100 and 101
  EXPECT_EQ(c.count(), 0);
  c.update(101.1 * step);  // one edge crossed
  EXPECT_EQ(c.count(), 1);
  c.update(99.9 * step);   // back over two edges
  EXPECT_EQ(c.count(), -1);
  c.reset();               // RST at edge 99
  EXPECT_EQ(c.count(), 0);
  c.update(105.5 * step);
  EXPECT_EQ(c.count(), 6);
}

TEST(Counter, WrapsAsATwosComplement32BitCounter) {
  const EncoderParams enc;
  const double step = kTwoPi / 2000.0;
  QuadratureCounter c(enc, 0.5 * step);
  c.preset(INT32_MAX - 2);
  int32_t before = c.count();
  c.update(5.5 * step);  // five counts up over the top
  EXPECT_EQ(c.count(), INT32_MIN + 2);
  EXPECT_EQ(counter_delta(c.count(), before), 5);
  before = c.count();
  c.update(-2.5 * step);  // eight counts back down across the wrap
  EXPECT_EQ(c.count(), INT32_MAX - 5);
  EXPECT_EQ(counter_delta(c.count(), before), -8);
}

TEST(Counter, WrapsFromRealShaftTravelToo) {
  // 2^31 counts = 1073741.824 revolutions of shaft angle.
  const EncoderParams enc;
  QuadratureCounter c(enc);
  const double step = kTwoPi / 2000.0;
  c.update((2147483647.0 + 0.5) * step);
  EXPECT_EQ(c.count(), INT32_MAX);
  c.update((2147483647.0 + 3.5) * step);
  EXPECT_EQ(c.count(), INT32_MIN + 2);
}

TEST(Counter, IndexEventsLatchTheIndexPositionCountInEitherDirection) {
  EncoderParams enc;
  enc.index_per_rev = 2;  // index every half revolution
  QuadratureCounter c(enc, 0.001);  // edge 0: counts equal shaft edges
  EXPECT_FALSE(c.index_latched());
  c.update(2.0);          // no index yet (next at π)
  EXPECT_EQ(c.index_events(), 0);
  c.update(3.5);          // over π: count of the index position is 1000
  EXPECT_EQ(c.index_events(), 1);
  ASSERT_TRUE(c.index_latched());
  EXPECT_EQ(c.index_count(), 1000);
  c.update(7.0);          // over 2π: index position count 2000
  EXPECT_EQ(c.index_events(), 2);
  EXPECT_EQ(c.index_count(), 2000);
  c.update(3.0);          // back over 2π and π: the last one crossed is π
  EXPECT_EQ(c.index_events(), 4);
  EXPECT_EQ(c.index_count(), 1000);
  c.update(-0.5);         // back over 0: count 0 at the index
  EXPECT_EQ(c.index_events(), 5);
  EXPECT_EQ(c.index_count(), 0);
  c.reset();
  EXPECT_EQ(c.index_events(), 0);
  EXPECT_FALSE(c.index_latched());
}

TEST(Counter, IndexCountFollowsTheResetReference) {
  const EncoderParams enc;  // one index per revolution at shaft angle 0, 2π, …
  const double step = kTwoPi / 2000.0;
  QuadratureCounter c(enc, 1500.2 * step);  // count 0 at edge 1500
  c.update(2100.0 * step);
  EXPECT_EQ(c.index_events(), 1);
  EXPECT_EQ(c.index_count(), 500);  // edge 2000 reads 2000 − 1500
}

// The amplifier's input stage (physics/amplifier.hpp) and a first-order motor: speed
// follows the setpoint made of the DA's volts with time constant tau and a gain error; the
// shaft angle integrates it. Stepped at 1 ms under the slave's 10 ms loop.
struct MotorPlant {
  DriverParams driver;
  MotorParams motor{};
  double tau = 0.02, gain = 1.0, speed = 0.0, angle = 0.0;
  double setpoint(double volts) const { return driver_setpoint(driver, motor, volts); }
  void step(double setpoint, double dt) {
    speed += (gain * setpoint - speed) * (dt / tau);
    angle += speed * dt;
  }
};

// Runs the drive chain for `samples` samples of command c; returns the chain.
void run(WheelDriveChain& chain, MotorPlant& plant, double c, int samples, double period) {
  for (int k = 0; k < samples; ++k) {
    const double sp = plant.setpoint(chain.sample(plant.angle, c));
    for (int i = 0; i < 10; ++i) {
      plant.step(sp, period / 10.0);
      chain.observe(plant.angle);
    }
  }
}

TEST(VelocityLoop, IdealCodeMapsCommandToTheMatchingDriverSpeed) {
  const PlatformParams p;
  const VelocityLoop loop(p.velocity_loop, p.dac, p.driver, p.counts_per_rev());
  EXPECT_DOUBLE_EQ(loop.ideal_code(0.0), 2048.0);
  const double c = 12.0;  // counts/sample
  const double want = c * kTwoPi / p.counts_per_rev() / p.velocity_loop.period;
  const double volts = loop.ideal_code(c) / 4096.0 * p.dac.vref;
  EXPECT_NEAR(driver_setpoint(p.driver, p.motor, volts), want, 1e-12);
}

TEST(VelocityLoop, TracksTheCommandOnAFirstOrderMotorWithGainError) {
  const PlatformParams p;
  for (double c : {25.0, -13.0, 4.0}) {
    WheelDriveChain chain(p);
    MotorPlant plant;
    plant.gain = 0.8;  // the integral must make up 20 % missing gain
    run(chain, plant, c, 300, p.velocity_loop.period);
    // After 3 s: every sample within one count, the mean on the command.
    double sum = 0.0;
    for (int k = 0; k < 100; ++k) {
      run(chain, plant, c, 1, p.velocity_loop.period);
      EXPECT_LE(std::abs(chain.last().delta_counts - c), 1.0) << "c=" << c << " k=" << k;
      sum += chain.last().delta_counts;
    }
    EXPECT_NEAR(sum / 100.0, c, 0.05) << "c=" << c;
    EXPECT_FALSE(chain.loop().saturated());
  }
}

TEST(VelocityLoop, DeadBandMakesASmallCommandStallUntilTheIntegralPushesThrough) {
  // A command of 1 count/sample asks for 0.314 rad/s at 10 ms, 32 codes = 0.039 V; the
  // first sample adds kp·e = 20 and ki·e = 4 codes, 0.068 V in all, inside a 0.1 V dead band:
  // the wheel stays still and only the integral of the error (4 codes a sample) carries the
  // code out of the band after a few samples. Without the band the first sample moves it.
  for (const double band : {0.0, 0.1}) {
    PlatformParams p;
    p.driver.dead_band = band;
    WheelDriveChain chain(p);
    MotorPlant plant{.driver = p.driver};
    int still = 0;
    for (int k = 0; k < 20 && plant.setpoint(chain.volts()) == 0.0; ++k) {
      run(chain, plant, 1.0, 1, p.velocity_loop.period);
      if (plant.setpoint(chain.volts()) == 0.0) ++still;
    }
    if (band == 0.0) {
      EXPECT_EQ(still, 0);
    } else {
      EXPECT_GE(still, 3);   // 0.1 V = 82 codes; 56 at the first sample, +4 a sample
      EXPECT_LT(still, 20);  // but the integral gets there
    }
  }
}

TEST(VelocityLoop, Int16ArithmeticMatchesRealWhileSmallAndWrapsOnOverflow) {
  // In range, the integer PI gives the real one's code (integer gains, whole counts).
  PlatformParams p;
  PlatformParams q = p;
  q.velocity_loop.arithmetic = LoopArithmetic::int16;
  VelocityLoop real(p.velocity_loop, p.dac, p.driver, p.counts_per_rev());
  VelocityLoop fixed(q.velocity_loop, q.dac, q.driver, q.counts_per_rev());
  for (const auto& [c, m] : {std::pair{7.0, 5.0}, {7.0, 7.0}, {-3.0, 0.0}, {0.0, 2.0}}) {
    const int a = real.step(c, m), b = fixed.step(c, m);
    EXPECT_NEAR(a, b, 1) << c << " " << m;
  }
  // A large gain and a stuck wheel: the real integral is held by the anti-windup, so the
  // real loop keeps pushing forward; the 16-bit one runs past 32767, wraps negative and the
  // DA output falls to 0 — the firmware reverses the wheel it was pushing.
  p.velocity_loop.ki = q.velocity_loop.ki = 3000;
  VelocityLoop real2(p.velocity_loop, p.dac, p.driver, p.counts_per_rev());
  VelocityLoop fixed2(q.velocity_loop, q.dac, q.driver, q.counts_per_rev());
  int lowest_real = 4095;
  bool wrapped = false, top = false, dropped_after_top = false;
  for (int k = 0; k < 12; ++k) {
    lowest_real = std::min(lowest_real, real2.step(1.0, 0.0));
    const int code = fixed2.step(1.0, 0.0);
    if (fixed2.integral() < 0) wrapped = true;
    if (code == 4095) top = true;
    if (top && code == 0) dropped_after_top = true;
    EXPECT_GE(fixed2.integral(), -32768.0);
    EXPECT_LE(fixed2.integral(), 32767.0);
  }
  EXPECT_GE(lowest_real, 2100);  // never below feed-forward + kp·e: it keeps pushing forward
  EXPECT_TRUE(wrapped);
  EXPECT_TRUE(dropped_after_top);
}

TEST(VelocityLoop, AntiWindupKeepsTheIntegralBoundedInSaturation) {
  PlatformParams p;
  p.motor.speed_limit = 100.0;  // let the DA be the limit
  WheelDriveChain chain(p);
  MotorPlant plant;
  plant.gain = 0.5;  // the motor cannot reach 60 counts/sample even at full code
  // Command beyond reach for 5 s: the output pins at the top code, integral stops growing.
  run(chain, plant, 60.0, 500, p.velocity_loop.period);
  EXPECT_EQ(chain.last().code, 4095);
  EXPECT_TRUE(chain.loop().saturated());
  const double i_sat = chain.loop().integral();
  EXPECT_LT(i_sat, 4096.0);
  run(chain, plant, 60.0, 100, p.velocity_loop.period);
  EXPECT_DOUBLE_EQ(chain.loop().integral(), i_sat);
  // Then a reachable command: the loop comes off the limit quickly and does not overshoot
  // far below, settling within a count.
  const double c = 10.0;
  double min_delta = 1e9;
  for (int k = 0; k < 200; ++k) {
    run(chain, plant, c, 1, p.velocity_loop.period);
    if (k > 5) min_delta = std::min<double>(min_delta, chain.last().delta_counts);
    if (k >= 150) {
      EXPECT_LE(std::abs(chain.last().delta_counts - c), 1.0) << k;
    }
  }
  EXPECT_GT(min_delta, c - 6.0);
}

TEST(VelocityLoop, ResetClearsTheIntegralAndTheChainRestartsAtZeroSpeed) {
  const PlatformParams p;
  WheelDriveChain chain(p);
  EXPECT_EQ(chain.last().code, 2048);
  EXPECT_DOUBLE_EQ(chain.volts(), p.driver.zero_volts);
  MotorPlant plant;
  plant.gain = 0.8;
  run(chain, plant, 20.0, 50, p.velocity_loop.period);
  EXPECT_NE(chain.loop().integral(), 0.0);
  chain.reset();
  EXPECT_EQ(chain.loop().integral(), 0.0);
  EXPECT_EQ(chain.counter().count(), 0);
  EXPECT_DOUBLE_EQ(chain.volts(), p.driver.zero_volts);
}

}  // namespace
}  // namespace omnitwin::physics
