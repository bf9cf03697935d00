// Tests controller/mechatrolink3/m3_config: the C1 master program's configuration file. Every
// key is read, extra axes take the addresses after the wheels (62 stations at most),
// event-driven communication carries 64 bytes and refuses INTERPOLATE, a minimal file has the documented defaults, the core's configuration carries
// the cycle, slaves and T_RSP inputs in ns, a dump reads back the same, and each error names
// the file, the line and the key.
#include "controller/mechatrolink3/m3_config.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace omnitwin::m3 {
namespace {

std::string error_of(const std::string& yaml) {
  try {
    parse_m3_config(yaml, "t.yaml", "/cfg");
  } catch (const M3ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(M3Config, ReadsEveryKey) {
  const M3ProgramConfig c = parse_m3_config(
      "cycle: 0.002\nretry_slots: 2\nwheels: [0x10, 0x11, 0x12, 0x13]\ndata_bytes: 48\nresponse_us: 3\n"
      "margin_us: 50\nsoftware_us: 200\ndetect_timeout_ms: 5\nstartup_timeout: 4\nlost_cycles: 7\n"
      "wheel_command: interpolate\nwheel_counts_per_rev: 65536\nparams:\n  - {number: 0x0102, value: 5000}\n"
      "platform: platform.yaml\n",
      "t.yaml", "/cfg");
  EXPECT_EQ(c.cycle, 0.002);
  EXPECT_EQ(c.retry_slots, 2);
  EXPECT_EQ(c.wheels[0], 0x10);
  EXPECT_EQ(c.wheels[3], 0x13);
  EXPECT_EQ(c.data_bytes, 48u);
  EXPECT_EQ(c.response_us, 3);
  EXPECT_EQ(c.margin_us, 50);
  EXPECT_EQ(c.software_us, 200);
  EXPECT_EQ(c.detect_timeout_ms, 5);
  EXPECT_EQ(c.startup_timeout, 4);
  EXPECT_EQ(c.lost_cycles, 7);
  EXPECT_EQ(c.command, WheelCommand::interpolate);
  EXPECT_EQ(c.wheel_counts_per_rev, 65536);
  ASSERT_EQ(c.params.size(), 1u);
  EXPECT_EQ(c.params[0].first, 0x0102);
  EXPECT_EQ(c.params[0].second, 5000);
  EXPECT_EQ(c.platform_file, "/cfg/platform.yaml") << "resolved against the file's folder";
}

TEST(M3Config, AMinimalFileHasTheDefaultsAndTheCoreGetsNanoseconds) {
  const M3ProgramConfig c = parse_m3_config("cycle: 0.001\n", "t.yaml", "");
  EXPECT_EQ(c.wheels[0], 0x03);
  EXPECT_EQ(c.command, WheelCommand::velctrl);
  EXPECT_TRUE(c.platform_yaml.empty() && c.platform_file.empty());
  const MasterConfig m = make_master_config(c);
  ASSERT_EQ(m.slaves.size(), 4u);
  EXPECT_EQ(m.slaves[2].address, 0x05);
  EXPECT_EQ(m.slaves[2].data_bytes, 32u);
  EXPECT_EQ(m.slaves[2].response_ns, 2'000);
  EXPECT_EQ(m.cycle_ns, 1'000'000);
  EXPECT_EQ(m.retry_slots, 1);
  EXPECT_EQ(m.margin_ns, 1'000);
  EXPECT_EQ(m.software_ns, 100'000);
  EXPECT_EQ(m.detect_timeout_ns, 100'000);
}

TEST(M3Config, ExtraAxesFollowTheHighestWheelAddress) {
  const M3ProgramConfig c = parse_m3_config("wheels: [3, 4, 5, 6]\nextra_axes: 3\n", "t.yaml", "");
  EXPECT_EQ(station_addresses(c), (std::vector<std::uint8_t>{3, 4, 5, 6, 7, 8, 9}));
  EXPECT_EQ(make_master_config(c).slaves.size(), 7u);
  EXPECT_EQ(make_master_config(c).slaves[6].address, 9);
  EXPECT_EQ(station_addresses(parse_m3_config("extra_axes: 58\n", "t.yaml", "")).back(), 0x40) << "62 stations";
  EXPECT_EQ(error_of("wheels: [3, 4, 5, 10]\nextra_axes: 58\n"),
            "t.yaml:2: extra_axes: addresses after 0Ah run past 40h (62 stations at most)");
}

TEST(M3Config, EventDrivenCommunicationCarries64BytesAndNoInterpolate) {
  const M3ProgramConfig c = parse_m3_config("communication: event\n", "t.yaml", "");
  EXPECT_TRUE(c.event_driven);
  EXPECT_EQ(c.data_bytes, 64u);
  const MasterConfig m = make_master_config(c);
  EXPECT_TRUE(m.event_driven);
  EXPECT_EQ(m.slaves[0].data_bytes, 64u);
  EXPECT_TRUE(parse_m3_config(dump_m3_config(c), "dump.yaml", "").event_driven);
  EXPECT_EQ(error_of("communication: event\ndata_bytes: 32\n"), "t.yaml:2: data_bytes: event-driven data is 64 bytes");
  EXPECT_EQ(error_of("communication: event\nwheel_command: interpolate\n"),
            "t.yaml:2: wheel_command: INTERPOLATE needs phase 3, which event-driven communication never enters");
  EXPECT_EQ(error_of("communication: sometimes\n"), "t.yaml:1: communication: cyclic or event");
}

TEST(M3Config, ADumpReadsBackTheSame) {
  const M3ProgramConfig a = parse_m3_config(
      "cycle: 0.0005\nretry_slots: 0\nwheels: [7, 8, 9, 10]\nextra_axes: 2\nmargin_us: 80\nwheel_command: interpolate\n"
      "params:\n  - {number: 0x0105, value: -3}\n",
      "t.yaml", "");
  const M3ProgramConfig b = parse_m3_config(dump_m3_config(a), "dump.yaml", "");
  EXPECT_EQ(b.cycle, a.cycle);
  EXPECT_EQ(b.retry_slots, a.retry_slots);
  EXPECT_EQ(b.wheels, a.wheels);
  EXPECT_EQ(b.extra_axes, 2);
  EXPECT_EQ(b.margin_us, a.margin_us);
  EXPECT_EQ(b.command, a.command);
  EXPECT_EQ(b.params, a.params);
}

TEST(M3Config, ErrorsNameFileLineAndKey) {
  EXPECT_EQ(error_of("cycle: 0.2\n"), "t.yaml:1: cycle: must be in [0.000125, 0.032]");
  // The servos' CONNECT range (0.125 … 32 ms at COM_TIM 1): 62.5 µs and 64 ms were accepted
  // and then refused by every servo at CONNECT (found in review).
  EXPECT_EQ(error_of("cycle: 0.0000625\n"), "t.yaml:1: cycle: must be in [0.000125, 0.032]");
  EXPECT_EQ(error_of("cycle: 0.064\n"), "t.yaml:1: cycle: must be in [0.000125, 0.032]");
  EXPECT_EQ(error_of("cycle: 0.001\ndata_bytes: 16\n"), "t.yaml:2: data_bytes: the servo profile's lengths are 32 and 48");
  EXPECT_EQ(error_of("retry_slots: 9\n"), "t.yaml:1: retry_slots: must be in 0..4");
  EXPECT_EQ(error_of("wheels: [3, 4, 5]\n"), "t.yaml:1: wheels: expected four station addresses (wheel 1..4)");
  EXPECT_EQ(error_of("wheels: [3, 4, 4, 5]\n"), "t.yaml:1: wheels: station 04h named twice");
  EXPECT_EQ(error_of("wheels: [1, 4, 5, 6]\n"), "t.yaml:1: wheels: must be in 3..64");
  EXPECT_EQ(error_of("wheel_command: posing\n"), "t.yaml:1: wheel_command: velctrl or interpolate");
  EXPECT_EQ(error_of("params:\n  - {number: 1}\n"), "t.yaml:2: params: number and value are required");
  EXPECT_EQ(error_of("cycle: 0.001\nbogus: 1\n").rfind("t.yaml:2: bogus: unknown key", 0), 0u);
  EXPECT_EQ(error_of("cycle: 0.001\n---\ncycle: 0.002\n"), "t.yaml:3: 2 YAML documents; a configuration file holds one");
  EXPECT_EQ(error_of("platform: {a: 1}\n"),
            "t.yaml:1: platform: expected a block mapping (master configuration keys) or a file name");
}

}  // namespace
}  // namespace omnitwin::m3
