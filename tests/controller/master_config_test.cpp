// Tests controller/master_config: the Omni master's YAML configuration. Defaults when only
// the path is given; every key read from tests/data/master/all_keys.yaml; errors as one line
// "FILE:LINE: KEY: message" for unknown keys (top level and inside a segment), missing
// required keys, wrong types and out-of-range values, duplicate keys, YAML syntax errors,
// empty and missing files; settle "never" (negative or no value); dump → parse giving the
// same configuration; build_path() matching a hand-built Path for every segment kind; and
// validate_master_config() refusing bad values set in code.
#include "controller/master_config.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <string>

#include "tests/support/temp_dir.hpp"

namespace omnitwin::controller {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

std::string data_file(const std::string& name) {
  return std::string(OMNITWIN_SOURCE_DIR) + "/tests/data/master/" + name;
}

// Writes `text` to `name` in `dir` and returns the path.
std::string write_file(const testing::TempDir& dir, const std::string& name, const std::string& text) {
  const auto p = dir / name;
  std::ofstream(p) << text;
  return p.string();
}

// The message load/parse throws for `yaml` (file name "cfg.yaml"), or "" if none.
std::string error_of(const std::string& yaml) {
  try {
    parse_master_config(yaml, "cfg.yaml");
  } catch (const MasterConfigError& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << "one line: " << e.what();
    return e.what();
  }
  return "";
}

constexpr const char* kMinimal = "path:\n  segments:\n    - line: {dx: 1, duration: 2}\n";

TEST(MasterConfig, DefaultsWhenOnlyThePathIsGiven) {
  const MasterConfig c = parse_master_config(kMinimal);
  EXPECT_DOUBLE_EQ(c.loop.period, 0.010);
  EXPECT_EQ(c.loop.kp, (std::array<double, 3>{6, 6, 6}));
  EXPECT_EQ(c.loop.ki, (std::array<double, 3>{6, 6, 6}));
  EXPECT_FALSE(c.loop.feedforward);
  EXPECT_DOUBLE_EQ(c.loop.max_speed, 0.5);
  EXPECT_DOUBLE_EQ(c.loop.max_yaw_rate, 2.0);
  EXPECT_DOUBLE_EQ(c.loop.L, 0.25);
  EXPECT_DOUBLE_EQ(c.loop.r, 0.05);
  EXPECT_EQ(c.loop.counts_per_rev, 2000);
  EXPECT_DOUBLE_EQ(c.settle, 2.0);
  EXPECT_FALSE(c.wait_for_pc);
  EXPECT_EQ(c.detect_every, 1);
  EXPECT_EQ(c.detect_misses, 1);
  EXPECT_EQ(c.feedback_timeout, 10);
  EXPECT_DOUBLE_EQ(c.startup_timeout, 1.0);
  EXPECT_FALSE(c.slave_kp.has_value());
  EXPECT_DOUBLE_EQ(c.path.x, 0.0);
  ASSERT_EQ(c.path.segments.size(), 1u);
  EXPECT_EQ(c.path.segments[0].kind, SegmentSpec::Kind::line);
  EXPECT_DOUBLE_EQ(c.path.segments[0].dx, 1.0);
  EXPECT_DOUBLE_EQ(c.path.segments[0].duration, 2.0);
}

TEST(MasterConfig, ReadsEveryKeyFromAFile) {
  const MasterConfig c = load_master_config(data_file("all_keys.yaml"));
  EXPECT_DOUBLE_EQ(c.loop.period, 0.005);
  EXPECT_EQ(c.loop.kp, (std::array<double, 3>{5, 4, 3}));
  EXPECT_EQ(c.loop.ki, (std::array<double, 3>{2, 1.5, 0.5}));
  EXPECT_TRUE(c.loop.feedforward);
  EXPECT_DOUBLE_EQ(c.loop.max_speed, 0.8);
  EXPECT_DOUBLE_EQ(c.loop.max_yaw_rate, 1.5);
  EXPECT_DOUBLE_EQ(c.loop.L, 0.3);
  EXPECT_DOUBLE_EQ(c.loop.r, 0.06);
  EXPECT_EQ(c.loop.counts_per_rev, 4000);
  EXPECT_DOUBLE_EQ(c.settle, 0.5);
  EXPECT_TRUE(c.wait_for_pc);
  EXPECT_EQ(c.detect_every, 5);
  EXPECT_EQ(c.detect_misses, 3);
  EXPECT_EQ(c.feedback_timeout, 20);
  EXPECT_DOUBLE_EQ(c.startup_timeout, 2.5);
  EXPECT_EQ(c.slave_kp, std::optional<std::uint16_t>(250));
  EXPECT_DOUBLE_EQ(c.path.x, 0.1);
  EXPECT_DOUBLE_EQ(c.path.y, -0.2);
  EXPECT_DOUBLE_EQ(c.path.phi_deg, 90);
  using K = SegmentSpec::Kind;
  ASSERT_EQ(c.path.segments.size(), 7u);
  const auto& s = c.path.segments;
  EXPECT_EQ(s[0].kind, K::line);
  EXPECT_DOUBLE_EQ(s[0].dy, 0.25);
  EXPECT_DOUBLE_EQ(s[0].dphi_deg, 30);
  EXPECT_EQ(s[1].kind, K::arc);
  EXPECT_DOUBLE_EQ(s[1].cy, 0.5);
  EXPECT_DOUBLE_EQ(s[1].sweep_deg, 90);
  EXPECT_EQ(s[2].kind, K::rotate);
  EXPECT_DOUBLE_EQ(s[2].dphi_deg, -45);
  EXPECT_EQ(s[3].kind, K::dwell);
  EXPECT_EQ(s[4].kind, K::square);
  EXPECT_FALSE(s[4].ccw);
  EXPECT_DOUBLE_EQ(s[4].side, 0.4);
  EXPECT_EQ(s[5].kind, K::circle);
  EXPECT_TRUE(s[5].ccw);
  EXPECT_EQ(s[6].kind, K::figure_eight);
  EXPECT_DOUBLE_EQ(s[6].radius, 0.2);
  EXPECT_DOUBLE_EQ(s[6].duration, 6);
}

TEST(MasterConfig, TheShippedThesisLineLoads) {
  const MasterConfig c = load_master_config(data_file("thesis_line.yaml"));
  EXPECT_EQ(c.slave_kp, std::optional<std::uint16_t>(100));
  EXPECT_DOUBLE_EQ(build_path(c.path).duration(), 20.0);
  EXPECT_DOUBLE_EQ(build_path(c.path).end_pose().x, 2.0);
}

TEST(MasterConfig, UnknownKeysNameFileLineAndKey) {
  const std::string file = data_file("bad_unknown_key.yaml");
  try {
    load_master_config(file);
    FAIL() << "no error";
  } catch (const MasterConfigError& e) {
    EXPECT_EQ(e.file(), file);
    EXPECT_EQ(e.line(), 7);
    EXPECT_EQ(e.key(), "path.segments.1.line.dz");
    EXPECT_EQ(std::string(e.what()).rfind(file + ":7: path.segments.1.line.dz: unknown key", 0), 0u) << e.what();
  }
  EXPECT_EQ(error_of(std::string(kMinimal) + "perod: 0.01\n").rfind("cfg.yaml:4: perod: unknown key (expected one of:", 0), 0u);
  EXPECT_EQ(error_of("geometry: {L: 0.2, R: 0.05}\n" + std::string(kMinimal)).rfind("cfg.yaml:1: geometry.R: unknown key", 0), 0u);
  EXPECT_EQ(error_of("path:\n  start: {x: 1, z: 2}\n").rfind("cfg.yaml:2: path.start.z: unknown key", 0), 0u);
}

TEST(MasterConfig, MissingRequiredKeys) {
  EXPECT_EQ(error_of("period: 0.01\n"), "cfg.yaml:1: path: missing required key");
  EXPECT_EQ(error_of("period: 0.01\npath:\n"), "cfg.yaml:2: path: missing value");
  EXPECT_EQ(error_of("path:\n  segments:\n    - line: {dx: 1}\n"),
            "cfg.yaml:3: path.segments.0.line.duration: missing required key");
  EXPECT_EQ(error_of("path:\n  segments:\n    - arc: {cx: 1, sweep_deg: 90, duration: 1}\n"),
            "cfg.yaml:3: path.segments.0.arc.cy: missing required key");
  EXPECT_EQ(error_of("path:\n  segments:\n    - circle: {duration: 1}\n"),
            "cfg.yaml:3: path.segments.0.circle.radius: missing required key");
}

TEST(MasterConfig, WrongTypesAndRangesAreErrors) {
  const std::string p(kMinimal);
  EXPECT_EQ(error_of("period: 0\n" + p), "cfg.yaml:1: period: must be in [0.0001, 1]");
  // Found in review: 1e-10 became 0 ns (SIGFPE in the wall loop), 1e11 overflowed it.
  EXPECT_EQ(error_of("period: 1e-10\n" + p), "cfg.yaml:1: period: must be in [0.0001, 1]");
  EXPECT_EQ(error_of("period: 1e11\n" + p), "cfg.yaml:1: period: must be in [0.0001, 1]");
  EXPECT_EQ(error_of("period: 1e300\n" + p), "cfg.yaml:1: period: must be in [0.0001, 1]");
  EXPECT_EQ(error_of("period: 1\n" + p), "");
  EXPECT_EQ(error_of("period: 0.0001\n" + p), "");
  EXPECT_EQ(error_of("period: fast\n" + p), "cfg.yaml:1: period: expected a number, got 'fast'");
  EXPECT_EQ(error_of("period:\n" + p), "cfg.yaml:1: period: missing value");
  EXPECT_EQ(error_of("kp: [1, 2]\n" + p), "cfg.yaml:1: kp: expected a list of three numbers [x, y, phi]");
  EXPECT_EQ(error_of("ki: [1, -2, 3]\n" + p), "cfg.yaml:1: ki.1: must be >= 0");
  EXPECT_EQ(error_of("feedforward: maybe\n" + p), "cfg.yaml:1: feedforward: expected true or false, got 'maybe'");
  EXPECT_EQ(error_of("detect_misses: 0\n" + p), "cfg.yaml:1: detect_misses: must be in [1, 2147483647]");
  EXPECT_EQ(error_of("detect_every: 1.5\n" + p), "cfg.yaml:1: detect_every: expected an integer, got '1.5'");
  EXPECT_EQ(error_of("feedback_timeout: -1\n" + p), "cfg.yaml:1: feedback_timeout: must be in [0, 2147483647]");
  EXPECT_EQ(error_of("slave_kp: 65536\n" + p), "cfg.yaml:1: slave_kp: must be in [0, 65535]");
  EXPECT_EQ(error_of("startup_timeout: 0\n" + p), "cfg.yaml:1: startup_timeout: must be > 0");
  EXPECT_EQ(error_of("geometry: {counts_per_rev: 0}\n" + p), "cfg.yaml:1: geometry.counts_per_rev: must be in [1, 16777216]");
  EXPECT_EQ(error_of("geometry: 3\n" + p), "cfg.yaml:1: geometry: expected a mapping, got '3'");
  EXPECT_EQ(error_of("path:\n  segments:\n    - square: {side: 0, duration: 1}\n"),
            "cfg.yaml:3: path.segments.0.square.side: must be > 0");
  EXPECT_EQ(error_of("path:\n  segments:\n    - arc: {cx: 0, cy: 0, sweep_deg: 9, duration: 1}\n"),
            "cfg.yaml:3: path.segments.0.arc: arc centre (cx, cy) must differ from the start point");
  EXPECT_EQ(error_of("path:\n  segments:\n    - jump: {duration: 1}\n").rfind("cfg.yaml:3: path.segments.0.jump: unknown key", 0), 0u);
  EXPECT_EQ(error_of("path:\n  segments: {line: {duration: 1}}\n"), "cfg.yaml:2: path.segments: expected a list, got a mapping");
}

// Found in review: 1e10 s overflowed llround(s * 1e9) into a negative time-out, and the
// master stopped at its first tick without a detection request. Bounded as the other masters'.
TEST(MasterConfig, AStartupTimeoutBeyondAnHourIsRefusedNamingTheKey) {
  const std::string p(kMinimal);
  EXPECT_EQ(error_of("startup_timeout: 1e10\n" + p), "cfg.yaml:1: startup_timeout: must be at most 3600");
  EXPECT_EQ(error_of("startup_timeout: 3600.5\n" + p), "cfg.yaml:1: startup_timeout: must be at most 3600");
  EXPECT_EQ(error_of("startup_timeout: 3600\n" + p), "");
}

TEST(MasterConfig, FileLevelErrors) {
  testing::TempDir dir("omnitwin-master-config");
  EXPECT_EQ(error_of("period: 0.01\nperiod: 0.02\n" + std::string(kMinimal)), "cfg.yaml:2: period: duplicate key");
  EXPECT_EQ(error_of(""), "cfg.yaml: empty configuration file");
  EXPECT_EQ(error_of("- 1\n- 2\n"), "cfg.yaml:1: expected a mapping at the top level");
  EXPECT_EQ(error_of(std::string(kMinimal) + "---\nperiod: 0.02\n"),
            "cfg.yaml:5: 2 YAML documents; a configuration file holds one");
  EXPECT_EQ(error_of("period: [1, 2\n").rfind("cfg.yaml:", 0), 0u);
  const std::string missing = (dir / "nope.yaml").string();
  try {
    load_master_config(missing);
    FAIL() << "no error";
  } catch (const MasterConfigError& e) {
    EXPECT_EQ(std::string(e.what()), missing + ": cannot open configuration file");
    EXPECT_EQ(e.line(), 0);
  }
  try {
    load_master_config(dir.path().string());
    FAIL() << "no error";
  } catch (const MasterConfigError& e) {
    EXPECT_EQ(std::string(e.what()), dir.path().string() + ": a directory, not a configuration file");
  }
  const std::string broken = write_file(dir, "broken.yaml", "path:\n  segments: [\n");
  try {
    load_master_config(broken);
    FAIL() << "no error";
  } catch (const MasterConfigError& e) {
    EXPECT_EQ(e.file(), broken);
    EXPECT_GT(e.line(), 0);
  }
}

TEST(MasterConfig, SettleNeverWhenNegativeOrEmpty) {
  EXPECT_DOUBLE_EQ(parse_master_config("settle: -1\n" + std::string(kMinimal)).settle, -1.0);
  EXPECT_LT(parse_master_config("settle:\n" + std::string(kMinimal)).settle, 0.0);
  EXPECT_DOUBLE_EQ(parse_master_config("settle: 0\n" + std::string(kMinimal)).settle, 0.0);
}

TEST(MasterConfig, DumpReadsBackToTheSameConfiguration) {
  const MasterConfig a = load_master_config(data_file("all_keys.yaml"));
  const std::string text = dump_master_config(a);
  const MasterConfig b = parse_master_config(text, "dump");
  EXPECT_EQ(dump_master_config(b), text);
  EXPECT_EQ(b.loop.kp, a.loop.kp);
  EXPECT_EQ(b.loop.ki, a.loop.ki);
  EXPECT_EQ(b.loop.period, a.loop.period);
  EXPECT_EQ(b.slave_kp, a.slave_kp);
  EXPECT_EQ(b.wait_for_pc, a.wait_for_pc);
  ASSERT_EQ(b.path.segments.size(), a.path.segments.size());
  for (std::size_t i = 0; i < a.path.segments.size(); ++i) {
    EXPECT_EQ(b.path.segments[i].kind, a.path.segments[i].kind);
    EXPECT_EQ(b.path.segments[i].duration, a.path.segments[i].duration);
    EXPECT_EQ(b.path.segments[i].ccw, a.path.segments[i].ccw);
  }
  EXPECT_EQ(build_path(b.path).end_pose().x, build_path(a.path).end_pose().x);
  // Awkward numbers survive exactly; no slave_kp key is written when there is none.
  MasterConfig c = parse_master_config(kMinimal);
  c.loop.period = 0.1 + 0.2;
  c.settle = -1;
  const MasterConfig d = parse_master_config(dump_master_config(c));
  EXPECT_EQ(d.loop.period, c.loop.period);
  EXPECT_EQ(d.settle, -1.0);
  EXPECT_EQ(dump_master_config(c).find("slave_kp"), std::string::npos);
}

TEST(MasterConfig, BuildPathMatchesAHandBuiltPath) {
  const MasterConfig c = load_master_config(data_file("all_keys.yaml"));
  Path want(Pose2{0.1, -0.2, 90 * kDeg});
  want.add_line(0.5, 0.25, 30 * kDeg, 2)
      .add_arc(0, 0.5, 90 * kDeg, 10 * kDeg, 3)
      .add_rotate(-45 * kDeg, 1)
      .add_dwell(0.5)
      .add_square(0.4, 1.5, false)
      .add_circle(0.3, 4, true)
      .add_figure_eight(0.2, 6, false);
  const Path got = build_path(c.path);
  ASSERT_EQ(got.segment_count(), want.segment_count());
  EXPECT_DOUBLE_EQ(got.duration(), want.duration());
  for (double t = 0; t <= want.duration() + 0.5; t += 0.25) {
    const PathSample a = got.sample(t), b = want.sample(t);
    EXPECT_DOUBLE_EQ(a.pose.x, b.pose.x) << t;
    EXPECT_DOUBLE_EQ(a.pose.y, b.pose.y) << t;
    EXPECT_DOUBLE_EQ(a.pose.phi, b.pose.phi) << t;
  }
}

TEST(MasterConfig, ValidateRefusesBadValuesSetInCode) {
  MasterConfig c = parse_master_config(kMinimal);
  EXPECT_NO_THROW(validate_master_config(c));
  c.detect_misses = 0;
  EXPECT_THROW(validate_master_config(c), MasterConfigError);
  c.detect_misses = 1;
  c.loop.period = std::nan("");
  try {
    validate_master_config(c);
    FAIL() << "no error";
  } catch (const MasterConfigError& e) {
    EXPECT_EQ(e.key(), "period");
  }
}

}  // namespace
}  // namespace omnitwin::controller
