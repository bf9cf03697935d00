// Tests `omnitwin run --bus m3 --clock realtime` (slow: 10 s of wall clock): the twin and our
// C1 master as two processes on their own wall clocks hold a 1 ms transmission cycle with no
// communication alarm on any servo (no watchdog error, no missing SYNC or command twice in a
// row), the late responses the transport's jitter causes absorbed by retries, the platform
// follows its path, and at the run's end the master's own shutdown (servo off, DISCONNECT)
// is served, so every servo ends in phase 1. The alarms are judged only when the master kept
// every deadline within a cycle: on a host that stalls it longer (its wake_late_max_ns), the
// test says so and skips them.
#include <gtest/gtest.h>

#include <fmt/format.h>
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
  const nlohmann::json m = nlohmann::json::parse(read_bytes(out / "metrics.json"));
  const nlohmann::json& ms = m.at("master");
  EXPECT_EQ(ms.at("driver_state"), "cyclic communication") << ms.dump(2);
  EXPECT_EQ(ms.at("cycle_ns"), 1'000'000);
  EXPECT_GT(ms.at("cycles").get<int>(), 9000);
  // The master ended on the run's SIGTERM, its shutdown served on the bus.
  EXPECT_EQ(ms.at("exit_code"), 0) << ms.dump(2);
  EXPECT_LT(ms.at("shutdown_s").get<double>(), 0.5) << ms.dump(2);
  const std::string events = read_bytes(out / "events.log");
  for (const auto& s : m.at("slaves")) {
    // Phase 1 at the end is the master's DISCONNECT; phase 3 with the servo on came before it.
    EXPECT_EQ(s.at("phase"), 1) << s.dump(2);
    EXPECT_EQ(s.at("servo"), "ready to switch on") << s.dump(2);
    const std::string running = fmt::format("({:02X}h) phase 3, COMM_ALM normal, CMD_ALM normal, servo operation enabled",
                                            s.at("address").get<int>());
    EXPECT_TRUE(contains(events, running)) << running << "\n" << events;
  }
  // The twin's own ticks: its work leaves fewer than one in a hundred half a period late (p99
  // under 500 µs); the rarer stalls are the host's (a bare SCHED_FIFO 1 ms loop on the 2-core
  // CI machines wakes up to 5 ms late a few times in 10 s; docs/reliability.md).
  const nlohmann::json& rt = m.at("realtime");
  EXPECT_LT(rt.at("jitter_p99_us").get<double>(), 500.0) << rt.dump(2);
  EXPECT_LE(rt.at("overruns").get<int>(), rt.at("ticks").get<int>() / 100) << rt.dump(2);
  // A master the host stalled for a whole cycle left a cycle without SYNC; the servos' COMM_ALM
  // is then the protocol's right answer, not a fault of the bus: judged only when it did not.
  ASSERT_TRUE(ms.contains("wake_late_max_ns")) << ms.dump(2);
  if (ms.at("wake_late_max_ns").get<std::int64_t>() >= ms.at("cycle_ns").get<std::int64_t>())
    GTEST_SKIP() << "the host stalled the master: " << ms.at("wakes_late") << " deadlines half a cycle or more late, at "
                 << "worst " << ms.at("wake_late_max_ns").get<double>() * 1e-6 << " ms; the alarms are not judged";
  EXPECT_EQ(f.code, 0) << f.out << f.err;
  EXPECT_FALSE(ms.at("platform_stopped").get<bool>()) << ms.dump(2);
  // Misses stay a small fraction of the exchanges (each costs one cycle's command, no alarm).
  EXPECT_LT(ms.at("missed").get<double>(), 0.02 * ms.at("exchanges").get<double>()) << ms.dump(2);
  for (const auto& s : m.at("slaves")) {
    EXPECT_EQ(s.at("comm_alarms"), 0) << s.dump(2);
    EXPECT_EQ(s.at("wdt_errors"), 0) << s.dump(2);
  }
}

}  // namespace
