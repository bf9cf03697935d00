// Tests CiA 402 homing (cia402_homing) on a drive stepping the axis model with modelled
// negative/positive limit switches, a home switch (positive side, negative side or a cam) and
// an index pulse per motor revolution: every method 1–14, 17–22, 33, 34, 35, 37 (and the cam
// methods without index 23–30) is started from a position that makes it search (reversing at
// a switch or a limit where the method does), and must end with homing attained (bit 12),
// target reached (bit 10), position actual = home offset 0x607C, standing on the physical
// spot the method names (the index pulse or switch edge, computed here independently) within
// two counts. Homing error (bit 13) for a switch that is never found (search limit, limit
// switch hit) and an unknown method; halt interrupts; bit 4 falling does not (seed 004).
#include "bus_emulators/drive/cia402_homing.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>

#include "drive_rig.hpp"

namespace omnitwin::drive {
namespace {

using testing::Rig;
constexpr double kTwoPi = 6.283185307179586;
constexpr double kGear = 10, kIndexOffset = 0.3;  // index every 2π/10 load rad, phase 0.03
constexpr double kNl = -2.0, kPl = 2.0, kHome = 0.5, kHomeEnd = 1.0;

enum class Sw { pos_home, neg_home, cam, none };

DriveConfig config(Sw home, bool limits = true) {
  DriveConfig c;
  c.counts_per_rev = 10000;
  c.gear_ratio = kGear;
  c.index_offset_rad = kIndexOffset;
  c.max_speed_rad_s = 1000;
  if (limits) {
    c.switches.negative_limit = kNl;
    c.switches.positive_limit = kPl;
  }
  if (home != Sw::none) c.switches.home = kHome;
  if (home == Sw::neg_home) c.switches.home_active_below = true;
  if (home == Sw::cam) c.switches.home_end = kHomeEnd;
  return c;
}

// The first index pulse strictly beyond `edge` [load rad] in direction dir.
double index_beyond(double edge, int dir) {
  const double spacing = kTwoPi / kGear, phase = kIndexOffset / kGear;
  const double k = (edge - phase) / spacing;
  const double kk = dir > 0 ? std::floor(k) + 1 : std::ceil(k) - 1;
  return phase + kk * spacing;
}

struct Outcome {
  bool attained = false, error = false;
  std::uint16_t sw = 0;
  double load_counts = 0;
  std::int32_t position_actual = 0;
  double k = 1;
  double min_rad = 0, max_rad = 0;  // the path the search took
};

Outcome home_with(int method, const DriveConfig& c, double start_rad, double max_s = 30) {
  Rig r(c, {}, start_rad);
  r.enable();
  r.set_mode(Mode::hm);
  r.o().homing_method = static_cast<std::int8_t>(method);
  r.o().homing_speed_switch = 100000;
  r.o().homing_speed_zero = 10000;
  r.o().homing_acceleration = 1000000;
  r.o().home_offset = 777;
  r.o().controlword = cw::kEnableOperation | cw::start_homing;
  r.step();
  r.o().controlword = cw::kEnableOperation;  // the master clears bit 4 (seed 004)
  double lo = start_rad, hi = start_rad;
  r.run_until(
      [&] {
        lo = std::min(lo, r.axis.position_rad());
        hi = std::max(hi, r.axis.position_rad());
        return (r.sw() & (sw::homing_attained | sw::homing_error)) != 0;
      },
      max_s);
  r.run(0.2);  // settle (an error stop decelerates first)
  Outcome o;
  o.sw = r.sw();
  o.attained = (o.sw & sw::homing_attained) != 0;
  o.error = (o.sw & sw::homing_error) != 0;
  o.load_counts = r.load_counts();
  o.position_actual = r.o().position_actual;
  o.k = r.drive.counts_per_load_rad();
  o.min_rad = lo;
  o.max_rad = hi;
  EXPECT_EQ(r.drive.homed(), o.attained);
  return o;
}

struct MethodCase {
  int method;
  Sw home;
  double start_rad;
  double expected_rad;
  double must_reach = 0;  // > 0: the path reaches at least this; < 0: at most this [rad]
};

void expect_homed(const MethodCase& m) {
  SCOPED_TRACE(::testing::Message() << "method " << m.method << " from " << m.start_rad);
  const Outcome o = home_with(m.method, config(m.home), m.start_rad);
  ASSERT_TRUE(o.attained);
  EXPECT_FALSE(o.error);
  EXPECT_NE(o.sw & sw::target_reached, 0);
  EXPECT_NEAR(o.position_actual, 777, 1);
  EXPECT_NEAR(o.load_counts, m.expected_rad * o.k, 2.0);
  if (m.must_reach > 0) {
    EXPECT_GE(o.max_rad, m.must_reach);
  } else if (m.must_reach < 0) {
    EXPECT_LE(o.min_rad, m.must_reach);
  }
}

// Limit switch + index pulse: reverse at the limit, home at the first index after leaving it.
TEST(Homing, Method1NegativeLimitAndIndex) { expect_homed({1, Sw::none, 0.0, index_beyond(kNl, +1), kNl}); }
TEST(Homing, Method2PositiveLimitAndIndex) { expect_homed({2, Sw::none, 0.0, index_beyond(kPl, -1), kPl}); }
TEST(Homing, Method1StartingOnTheLimit) { expect_homed({1, Sw::none, -2.2, index_beyond(kNl, +1)}); }

// Home switch (positive side for 3/4, negative side for 5/6) + index pulse.
TEST(Homing, Method3) { expect_homed({3, Sw::pos_home, 0.0, index_beyond(kHome, -1), kHome}); }
TEST(Homing, Method3StartingOnTheSwitch) { expect_homed({3, Sw::pos_home, 1.2, index_beyond(kHome, -1)}); }
TEST(Homing, Method4) { expect_homed({4, Sw::pos_home, 1.0, index_beyond(kHome, +1)}); }
TEST(Homing, Method4FromBelow) { expect_homed({4, Sw::pos_home, -1.0, index_beyond(kHome, +1)}); }
TEST(Homing, Method5) { expect_homed({5, Sw::neg_home, 0.0, index_beyond(kHome, +1)}); }
TEST(Homing, Method6) { expect_homed({6, Sw::neg_home, 1.0, index_beyond(kHome, -1)}); }
TEST(Homing, Method6FromBelow) { expect_homed({6, Sw::neg_home, -1.0, index_beyond(kHome, -1), kHome}); }

// Home cam, reversing at the positive limit switch (7–10).
TEST(Homing, Method7ReversesAtPositiveLimit) { expect_homed({7, Sw::cam, 1.5, index_beyond(kHome, -1), kPl}); }
TEST(Homing, Method7FromTheLeft) { expect_homed({7, Sw::cam, 0.0, index_beyond(kHome, -1)}); }
TEST(Homing, Method8) { expect_homed({8, Sw::cam, 0.0, index_beyond(kHome, +1)}); }
TEST(Homing, Method8ReversesAtPositiveLimit) { expect_homed({8, Sw::cam, 1.5, index_beyond(kHome, +1), kPl}); }
TEST(Homing, Method9) { expect_homed({9, Sw::cam, 0.0, index_beyond(kHomeEnd, -1)}); }
TEST(Homing, Method10ReversesAtPositiveLimit) { expect_homed({10, Sw::cam, 1.5, index_beyond(kHomeEnd, +1), kPl}); }
TEST(Homing, Method10OnTheCam) { expect_homed({10, Sw::cam, 0.75, index_beyond(kHomeEnd, +1)}); }

// Home cam, reversing at the negative limit switch (11–14).
TEST(Homing, Method11ReversesAtNegativeLimit) { expect_homed({11, Sw::cam, 0.0, index_beyond(kHomeEnd, +1), kNl}); }
TEST(Homing, Method12) { expect_homed({12, Sw::cam, 1.5, index_beyond(kHomeEnd, -1)}); }
TEST(Homing, Method12ReversesAtNegativeLimit) { expect_homed({12, Sw::cam, 0.0, index_beyond(kHomeEnd, -1), kNl}); }
TEST(Homing, Method13OnTheCam) { expect_homed({13, Sw::cam, 0.75, index_beyond(kHome, +1)}); }
TEST(Homing, Method14ReversesAtNegativeLimit) { expect_homed({14, Sw::cam, -1.0, index_beyond(kHome, -1), kNl}); }

// Limit switch without index: home on the switch edge.
TEST(Homing, Method17) { expect_homed({17, Sw::none, 0.0, kNl, kNl}); }
TEST(Homing, Method18) { expect_homed({18, Sw::none, 0.0, kPl, kPl}); }

// Home switch without index.
TEST(Homing, Method19) { expect_homed({19, Sw::pos_home, 0.0, kHome, kHome}); }
TEST(Homing, Method20) { expect_homed({20, Sw::pos_home, 1.0, kHome}); }
TEST(Homing, Method21) { expect_homed({21, Sw::neg_home, 0.0, kHome}); }
TEST(Homing, Method22) { expect_homed({22, Sw::neg_home, 1.0, kHome}); }

// Cam methods without index (as 7–14).
TEST(Homing, Methods23To30OnTheCamEdges) {
  expect_homed({23, Sw::cam, 1.5, kHome, kPl});
  expect_homed({24, Sw::cam, 0.0, kHome});
  expect_homed({25, Sw::cam, 0.0, kHomeEnd});
  expect_homed({26, Sw::cam, 1.5, kHomeEnd, kPl});
  expect_homed({27, Sw::cam, 0.0, kHomeEnd, kNl});
  expect_homed({28, Sw::cam, 1.5, kHomeEnd});
  expect_homed({29, Sw::cam, 0.75, kHome});
  expect_homed({30, Sw::cam, -1.0, kHome, kNl});
}

// Index pulse only.
TEST(Homing, Method33NegativeIndex) { expect_homed({33, Sw::none, 0.1, index_beyond(0.1, -1)}); }
TEST(Homing, Method34PositiveIndex) { expect_homed({34, Sw::none, 0.1, index_beyond(0.1, +1)}); }

// Current position.
TEST(Homing, Method35) { expect_homed({35, Sw::none, 0.1, 0.1}); }
TEST(Homing, Method37) { expect_homed({37, Sw::none, -0.3, -0.3}); }

TEST(Homing, IndexPulseOffsetMovesTheHome) {
  // Same switch, another index phase: the home follows the index pulse.
  DriveConfig c = config(Sw::pos_home);
  c.index_offset_rad = 1.0;
  const Outcome o = home_with(4, c, 0.0);
  ASSERT_TRUE(o.attained);
  const double spacing = kTwoPi / kGear, phase = 1.0 / kGear;
  const double expected = phase + (std::floor((kHome - phase) / spacing) + 1) * spacing;
  EXPECT_NEAR(o.load_counts, expected * o.k, 2.0);
}

// ---- Errors.

TEST(Homing, ErrorWhenTheLimitSwitchIsNeverFound) {
  DriveConfig c = config(Sw::none, /*limits=*/false);
  c.homing_max_search_rev = 20;  // 2 load revolutions
  const Outcome o = home_with(1, c, 0.0);
  EXPECT_FALSE(o.attained);
  EXPECT_TRUE(o.error);
  EXPECT_NE(o.sw & sw::target_reached, 0);  // stopped after the error
}

TEST(Homing, ErrorWhenTheHomeSwitchIsMissingAndALimitIsHit) {
  const Outcome o = home_with(3, config(Sw::none), 0.0);
  EXPECT_TRUE(o.error);
  EXPECT_FALSE(o.attained);
  EXPECT_NEAR(o.load_counts, kPl * o.k, 0.2 * o.k);  // stopped at the positive limit switch
}

TEST(Homing, ErrorWhenTheCamIsMissingBetweenTheLimits) {
  // 7: positive first, reverse at PL, then the negative limit is hit → error.
  const Outcome o = home_with(7, config(Sw::none), 0.0);
  EXPECT_TRUE(o.error);
}

TEST(Homing, ErrorForAnUnknownMethod) {
  const Outcome o = home_with(15, config(Sw::pos_home), 0.0, 1.0);
  EXPECT_TRUE(o.error);
  EXPECT_FALSE(o.attained);
  EXPECT_FALSE(homing_method_supported(15));
  EXPECT_FALSE(homing_method_supported(36));
  EXPECT_TRUE(homing_method_supported(37));
}

TEST(Homing, HaltInterruptsAndANewStartHomes) {
  Rig r(config(Sw::pos_home), {}, 0.0);
  r.enable();
  r.set_mode(Mode::hm);
  r.o().homing_method = 19;
  r.o().homing_speed_switch = 50000;
  r.o().homing_speed_zero = 10000;
  r.o().homing_acceleration = 1000000;
  r.o().controlword = cw::kEnableOperation | cw::start_homing;
  r.run(0.02);
  EXPECT_EQ(r.sw() & (sw::target_reached | sw::homing_attained | sw::homing_error), 0);  // in progress
  r.o().controlword = cw::kEnableOperation | cw::start_homing | cw::halt;
  r.run(0.2);
  EXPECT_EQ(r.sw() & (sw::homing_attained | sw::homing_error), 0);
  EXPECT_NE(r.sw() & sw::target_reached, 0);  // interrupted, standing
  EXPECT_NEAR(r.axis.velocity_rad_s(), 0, 1e-3);
  EXPECT_FALSE(r.drive.homed());
  r.o().controlword = cw::kEnableOperation;
  r.step();
  r.o().controlword = cw::kEnableOperation | cw::start_homing;
  ASSERT_TRUE(r.run_until([&] { return r.drive.homed(); }, 10.0));
  r.run(0.05);
  EXPECT_EQ(r.o().position_actual, 0);
  EXPECT_NEAR(r.load_counts(), kHome * r.drive.counts_per_load_rad(), 2.0);
}

TEST(Homing, ExternalInputsDriveTheSearch) {
  // No modelled switches: the scenario raises the home input; the edge is taken where the
  // axis is when the input changes.
  Rig r(config(Sw::none, false), {}, 0.0);
  r.enable();
  r.set_mode(Mode::hm);
  r.o().homing_method = 20;  // positive home switch, approach from below, no index
  r.o().homing_speed_switch = 20000;
  r.o().homing_speed_zero = 20000;
  r.o().homing_acceleration = 1000000;
  r.o().controlword = cw::kEnableOperation | cw::start_homing;
  const double k = r.drive.counts_per_load_rad();
  ASSERT_TRUE(r.run_until([&] {
    if (r.axis.position_rad() >= 0.3) r.drive.set_external_inputs(4);
    return r.drive.homed();
  }, 5.0));
  EXPECT_EQ(r.o().digital_inputs & 4u, 4u);
  r.run(0.05);
  EXPECT_NEAR(r.load_counts(), 0.3 * k, 25);  // within one period of travel
  EXPECT_EQ(r.o().position_actual, 0);
}

}  // namespace
}  // namespace omnitwin::drive
