// Tests `omnitwin run --bus m3 --clock realtime` (slow: 10 s of wall clock): the twin and our
// C1 master as two processes on their own wall clocks hold a 1 ms transmission cycle with no
// communication alarm on any servo (no watchdog error, no missing SYNC or command twice in a
// row), the late responses the transport's jitter causes absorbed by retries, and the
// platform follows its path.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "tests/twin/cli_support.hpp"

namespace {

using namespace omnitwin::twin::cli;

class CliM3Slow : public CliTest {};

TEST_F(CliM3Slow, RealtimeHoldsA1msCycleWithoutACommunicationAlarm) {
  const fs::path out = dir_ / "rt";
  // 10 s of the 20 s path: the platform is still on its way at the end, which the scenario's
  // "at the goal" expectation (path_done_s) would rightly fail; this test judges the bus.
  const Finished f = run({"run", source_path("models/scenarios/thesis_line.yaml"), "--bus", "m3", "--clock", "realtime",
                          "--set", "duration=10", "--set", "expect.platform.path_done_s.min=-1", "--no-video",
                          "--no-report", "--out", out.string(), "--no-progress"});
  EXPECT_EQ(f.code, 0) << f.out << f.err;
  const nlohmann::json m = nlohmann::json::parse(read_bytes(out / "metrics.json"));
  const nlohmann::json& ms = m.at("master");
  EXPECT_EQ(ms.at("driver_state"), "cyclic communication") << ms.dump(2);
  EXPECT_EQ(ms.at("cycle_ns"), 1'000'000);
  EXPECT_GT(ms.at("cycles").get<int>(), 9000);
  EXPECT_FALSE(ms.at("platform_stopped").get<bool>()) << ms.dump(2);
  // Misses stay a small fraction of the exchanges (each costs one cycle's command, no alarm).
  EXPECT_LT(ms.at("missed").get<double>(), 0.02 * ms.at("exchanges").get<double>()) << ms.dump(2);
  for (const auto& s : m.at("slaves")) {
    EXPECT_EQ(s.at("comm_alarms"), 0) << s.dump(2);
    EXPECT_EQ(s.at("wdt_errors"), 0) << s.dump(2);
    EXPECT_EQ(s.at("phase"), 3);
  }
  // The twin's own ticks: at most one in a thousand half a period late on a shared machine.
  EXPECT_LE(m.at("realtime").at("overruns").get<int>(), m.at("realtime").at("ticks").get<int>() / 1000);
}

}  // namespace
