// Tests controller/ethercat/ec_config: the EtherCAT master's YAML file — every key read
// (ESI list resolved against the file's folder, cycle, DC, start-up SDOs with hex values,
// wheels, wheel mode, counts per revolution, the platform section kept as text for
// controller/master_config), errors as "FILE:LINE: KEY: message", and ESI loading.
#include "controller/ethercat/ec_config.hpp"

#include <gtest/gtest.h>

using namespace omnitwin::controller::ethercat;

namespace {
const char* kFull = R"(# four wheel drives
esi:
  - ../../models/ethercat/omnitwin_drive.xml
cycle: 0.002
dc: {enabled: true, sync0_shift_us: 250}
expected_slaves: 4
startup:
  - {slave: all, index: 0x6060, sub: 0, size: 1, value: 9}
  - slave: 2
    index: 0x6081
    value: 100000
wheels:
  - {slave: 1}
  - {slave: 2, channel: 1}
  - {slave: 3}
  - {slave: 4}
wheel_mode: csp
wheel_counts_per_rev: 4096
user_pdo: {wpdo1: 0x60B1, rpdo2: "0x60FD:0"}
platform:
  period: 0.010
  geometry: {L: 0.25, r: 0.05, counts_per_rev: 2000}
  path:
    start: {x: 0, y: 0, phi_deg: 0}
    segments:
      - line: {dx: 1.0, dy: 0, duration: 10}
)";
std::string error_of(const std::string& yaml) {
  try {
    parse_ec_config(yaml, "t.yaml");
  } catch (const EcConfigError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(EcConfig, ReadsEveryKey) {
  const EcConfig c = parse_ec_config(kFull, "cfg/m.yaml", "cfg/sub");
  ASSERT_EQ(c.esi_files.size(), 1u);
  EXPECT_EQ(c.esi_files[0], "models/ethercat/omnitwin_drive.xml");  // cfg/sub/../../
  EXPECT_DOUBLE_EQ(c.cycle, 0.002);
  EXPECT_TRUE(c.dc);
  EXPECT_DOUBLE_EQ(c.sync0_shift_us, 250);
  EXPECT_EQ(c.expected_slaves, 4);
  ASSERT_EQ(c.startup.size(), 2u);
  EXPECT_EQ(c.startup[0].position, -1);
  EXPECT_EQ(c.startup[0].index, 0x6060);
  EXPECT_EQ(c.startup[0].data, std::vector<std::uint8_t>{9});
  EXPECT_EQ(c.startup[1].position, 1);
  EXPECT_EQ(c.startup[1].index, 0x6081);
  EXPECT_EQ(c.startup[1].data, (std::vector<std::uint8_t>{0xA0, 0x86, 0x01, 0x00}));
  EXPECT_TRUE(c.has_wheels);
  EXPECT_EQ(c.wheels[1], (AxisRef{2, 1}));
  EXPECT_EQ(c.wheels[3], (AxisRef{4, 1}));
  EXPECT_EQ(c.wheel_mode, WheelMode::csp);
  EXPECT_DOUBLE_EQ(c.wheel_counts_per_rev, 4096);
  EXPECT_EQ(c.user_pdos[0], (std::pair<std::uint16_t, std::uint8_t>{0x60B1, 0}));
  EXPECT_EQ(c.user_pdos[1].first, 0);
  EXPECT_EQ(c.user_pdos[3], (std::pair<std::uint16_t, std::uint8_t>{0x60FD, 0}));
  EXPECT_EQ(c.platform_yaml,
            "period: 0.010\ngeometry: {L: 0.25, r: 0.05, counts_per_rev: 2000}\npath:\n  start: {x: 0, y: 0, phi_deg: 0}\n"
            "  segments:\n    - line: {dx: 1.0, dy: 0, duration: 10}\n");
}

TEST(EcConfig, MinimalFileHasDefaults) {
  const EcConfig c = parse_ec_config("esi: a.xml\n", "m.yaml");
  EXPECT_EQ(c.esi_files, std::vector<std::string>{"a.xml"});
  EXPECT_DOUBLE_EQ(c.cycle, 0.001);
  EXPECT_FALSE(c.dc);
  EXPECT_FALSE(c.has_wheels);
  EXPECT_EQ(c.wheel_mode, WheelMode::csv);
  EXPECT_EQ(c.expected_slaves, -1);
  EXPECT_EQ(c.segment_loss_cycles, 10);
  EXPECT_EQ(c.segment_loss_ms, 10);
}

TEST(EcConfig, SegmentLossCyclesReachTheCore) {
  const EcConfig c = parse_ec_config("esi: a.xml\nsegment_loss_cycles: 4\n", "m.yaml");
  EXPECT_EQ(c.segment_loss_cycles, 4);
  EXPECT_EQ(parse_ec_config("esi: a.xml\nsegment_loss_cycles: 0\n", "m.yaml").segment_loss_cycles, 0);
  EcConfig loaded = parse_ec_config("esi: [models/ethercat/omnitwin_drive.xml]\nsegment_loss_cycles: 7\n", "m.yaml",
                                    OMNITWIN_SOURCE_DIR);
  EXPECT_EQ(make_master_config(loaded).segment_loss_cycles, 7);
  EcConfig timed = parse_ec_config("esi: [models/ethercat/omnitwin_drive.xml]\nsegment_loss_ms: 25\n", "m.yaml",
                                   OMNITWIN_SOURCE_DIR);
  EXPECT_EQ(timed.segment_loss_ms, 25);
  EXPECT_EQ(make_master_config(timed).segment_loss_ns, 25'000'000);
  EXPECT_EQ(error_of("esi: a.xml\nsegment_loss_ms: -2\n"), "t.yaml:2: segment_loss_ms: must be in 0..100000");
  EXPECT_EQ(error_of("esi: a.xml\nsegment_loss_cycles: -1\n"),
            "t.yaml:2: segment_loss_cycles: must be in 0..100000 (0 = off)");
}

TEST(EcConfig, ErrorsNameFileLineAndKey) {
  EXPECT_EQ(error_of("cycle: 0.001\n"), "t.yaml:1: esi: required (the ESI files describing the slaves)");
  EXPECT_EQ(error_of("esi: a.xml\ncycle: fast\n"), "t.yaml:2: cycle: expected a number, got 'fast'");
  EXPECT_EQ(error_of("esi: a.xml\ncycle: 0\n"), "t.yaml:2: cycle: must be in (0, 1] s");
  EXPECT_EQ(error_of("esi: a.xml\nbogus: 1\n").rfind("t.yaml:2: bogus: unknown key", 0), 0u);
  EXPECT_EQ(error_of("esi: a.xml\nstartup:\n  - {index: 0x6060, size: 3, value: 1}\n"),
            "t.yaml:3: startup.size: must be 1, 2, 4 or 8 bytes");
  EXPECT_EQ(error_of("esi: a.xml\nwheels: [{slave: 1}]\n"), "t.yaml:2: wheels: expected a list of four {slave, channel}");
  EXPECT_EQ(error_of("esi: a.xml\nwheels: [{slave: 1}, {slave: 2}, {slave: 3}, {slave: 4}]\n"),
            "t.yaml:2: platform: required with wheels (the platform loop and its path)");
  EXPECT_EQ(error_of("esi: a.xml\nwheel_mode: pp\n"), "t.yaml:2: wheel_mode: csv or csp");
  // yaml-cpp's own message, at the end of the input where it notices the missing ']'.
  EXPECT_EQ(error_of("esi: [a.xml\n"), "t.yaml:2: end of sequence flow not found");
  EXPECT_EQ(error_of("esi: a.xml\ncycle: 0.1\ncycle: 0.2\n"), "t.yaml:3: cycle: repeated key");
  EXPECT_EQ(error_of("esi: a.xml\n---\ncycle: 0.2\n"), "t.yaml:3: 2 YAML documents; a configuration file holds one");
}

TEST(EcConfig, LoadsTheEsiFilesIntoTheCoreConfig) {
  EcConfig c = parse_ec_config("esi: [models/ethercat/omnitwin_drive.xml]\ncycle: 0.004\ndc: true\n", "m.yaml",
                               OMNITWIN_SOURCE_DIR);
  const EcMasterConfig m = make_master_config(c);
  ASSERT_FALSE(m.devices.empty());
  EXPECT_EQ(m.devices[0].vendor_id, 0x00000F1Cu);
  EXPECT_EQ(m.cycle_ns, 4'000'000);
  EXPECT_TRUE(m.dc);
  c.esi_files = {"/nonexistent.xml"};
  EXPECT_THROW(make_master_config(c), EcConfigError);
}

TEST(EcConfig, MissingFileIsAnError) {
  EXPECT_THROW(load_ec_config("/nonexistent/ec.yaml"), EcConfigError);
}

TEST(EcConfig, ReadsTheFileTheTwinWrites) {
  // The shape twin/master_process.cpp writes for `bus: {type: ethercat}` scenarios.
  const char* twin = R"(# omni-master --bus ethercat configuration written by omnitwin for scenario s
esi: /models/ethercat/omnitwin_drive.xml
cycle: 0.01
dc: false
expected_slaves: 4
startup:
  - slave: all
    index: 0x6060
    sub: 0
    size: 1
    value: 8
wheels:
  - slave: 1
    channel: 1
  - slave: 2
    channel: 1
  - slave: 3
    channel: 1
  - slave: 4
    channel: 1
wheel_mode: csp
wheel_counts_per_rev: 65536
platform: /run/master-platform.yaml
)";
  const EcConfig c = parse_ec_config(twin, "master.yaml", "/run");
  EXPECT_EQ(c.esi_files, std::vector<std::string>{"/models/ethercat/omnitwin_drive.xml"});
  EXPECT_DOUBLE_EQ(c.cycle, 0.01);
  EXPECT_FALSE(c.dc);
  ASSERT_EQ(c.startup.size(), 1u);
  EXPECT_EQ(c.startup[0].position, -1);
  EXPECT_EQ(c.startup[0].data, std::vector<std::uint8_t>{8});
  EXPECT_TRUE(c.has_wheels);
  EXPECT_EQ(c.wheels[2], (AxisRef{3, 1}));
  EXPECT_EQ(c.wheel_mode, WheelMode::csp);
  EXPECT_DOUBLE_EQ(c.wheel_counts_per_rev, 65536);
  EXPECT_EQ(c.platform_file, "/run/master-platform.yaml");
  EXPECT_TRUE(c.platform_yaml.empty());
}

TEST(EcConfig, ListsMayStartAtTheirKeysIndentation) {
  const EcConfig c = parse_ec_config("esi:\n- a.xml\n- b.xml\ncycle: 0.002\n", "m.yaml");
  EXPECT_EQ(c.esi_files, (std::vector<std::string>{"a.xml", "b.xml"}));
  EXPECT_DOUBLE_EQ(c.cycle, 0.002);
}
