// Tests `omnitwin run --bus m3` and `omnitwin twin --bus m3` end to end through the real
// programs: the twin's MECHATROLINK-III line of four standard servos and our C1 master
// (`omni-master --bus m3`) as two processes over a real transport (a veth pair made for the
// run, or M-III over UDP), in exchange-level lockstep. Lockstep runs are byte-identical
// (trajectory, bus records and capture); master.log holds the driver sequence of seed 000
// figs. 9-11 and the servo start-up of fig. 8; the capture decodes with the project's
// Wireshark dissector with no malformed frame and exactly the frames the line saw; position
// mode (INTERPOLATE) and a relative run directory work; a cycle the line cannot fit is
// refused naming the shortest one that fits; event-driven communication drives the platform;
// a transport that cannot be opened is bad input;
// and an external master on its own wall clock drives the twin's servos.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <string>
#include <thread>

#include "tests/support/veth.hpp"
#include "tests/twin/cli_support.hpp"

namespace omnitwin::twin::cli {
namespace {

using omnitwin::testing::lines_of;

class CliM3 : public CliTest {
 protected:
  Finished run_short(const fs::path& out, const std::vector<std::string>& sets = {}) {
    return run_test_scenario("m3_short.yaml", out, sets);
  }
};

// The master ran the whole path with every exchange answered in time.
void expect_clean_run(const Finished& f, const nlohmann::json& m) {
  EXPECT_EQ(f.code, 0) << f.out << f.err;
  const nlohmann::json& ms = m.at("master");
  EXPECT_EQ(ms.at("state"), "finished") << ms.dump(2);
  EXPECT_EQ(ms.at("driver_state"), "cyclic communication");
  EXPECT_EQ(ms.at("missed"), 0);
  EXPECT_EQ(ms.at("late"), 0);
  EXPECT_EQ(ms.at("retries"), 0);
  EXPECT_GT(ms.at("cycles").get<int>(), 4000);
  EXPECT_GT(ms.at("path_origin_s").get<double>(), 0.0);
  EXPECT_FALSE(ms.contains("wakes_late")) << "simulated time is never late: " << ms.dump(2);
  // Every servo on to the run's end; the master's shutdown after it switches each off and
  // disconnects it (fig. 8's end: phase 1), as on the wall clock.
  EXPECT_EQ(m.at("drives").at("running_at_duration"), 4) << m.at("drives").dump();
  EXPECT_EQ(m.at("drives").at("running_at_end"), 0) << m.at("drives").dump();
  EXPECT_EQ(ms.at("stop_signal"), "stop in the grants");
  EXPECT_GE(ms.at("shutdown_s").get<double>(), 0.0) << ms.dump(2);
  EXPECT_LT(ms.at("shutdown_s").get<double>(), 0.1) << ms.dump(2);
  for (const auto& s : m.at("slaves")) {
    EXPECT_EQ(s.at("phase"), 1);
    EXPECT_EQ(s.at("comm_alarms"), 0);
    EXPECT_EQ(s.at("wdt_errors"), 0);
  }
  EXPECT_LT(m.at("platform").at("final_error_cm").get<double>(), 1.0);
}

bool have_tshark() { return std::system("command -v tshark >/dev/null 2>&1") == 0; }

std::string tshark(const fs::path& capture, const std::string& args) {
  return "tshark -X lua_script:" + source_path("tools/wireshark/mechatrolink3.lua") + " -r " + capture.string() + " " +
         args;
}

// Over a veth pair (root): two runs are byte-identical; master.log tells the driver sequence
// and the servo start-up; the dissector reads every frame of the capture, none malformed.
TEST_F(CliM3, LockstepOverVethIsByteIdenticalAndDecodes) {
  if (const auto why = omnitwin::testing::VethPair::unavailable_reason()) GTEST_SKIP() << *why;
  const fs::path a = dir_ / "a", b = dir_ / "b";
  const Finished fa = run_short(a, {"bus.transport=veth"});
  const Finished fb = run_short(b, {"bus.transport=veth"});
  const nlohmann::json m = metrics(a);
  expect_clean_run(fa, m);
  EXPECT_EQ(fb.code, 0);
  EXPECT_TRUE(m.at("bus").at("transport").get<std::string>().starts_with("raw:"));
  for (const char* f : {"trajectory.csv", "bus.csv", "bus-m3.pcap"}) EXPECT_EQ(read_bytes(a / f), read_bytes(b / f)) << f;
  const std::string log = read_bytes(a / "master.log");
  for (const char* step : {"initialisation request", "connected-station detection", "station 06h detected",
                           "delay-time measurement request", "station 03h TR_DLY", "INT_OFFSET", "station 06h T_RSP",
                           "transmission-cycle notification: 1000 µs", "communication start: cyclic",
                           "axis 1 (03h): CONNECT", "axis 1 (03h): SYNC_SET", "axis 1 (03h): ID_RD",
                           "axis 4 (06h): SENS_ON", "axis 4 (06h): SV_ON", "axis 4 (06h): running",
                           "all 4 servos on: platform loop running", "path done"})
    EXPECT_TRUE(contains(log, step)) << step << "\n" << log;
  if (!have_tshark()) GTEST_SKIP() << "tshark is not installed";
  const fs::path pcap = a / "bus-m3.pcap", info = dir_ / "info.txt", bad = dir_ / "bad.txt";
  ASSERT_EQ(std::system((tshark(pcap, "-T fields -e _ws.col.Info > ") + info.string() + " 2>/dev/null").c_str()), 0);
  ASSERT_EQ(std::system((tshark(pcap, "-Y '_ws.malformed || _ws.expert.severity >= error' > ") + bad.string() +
                         " 2>/dev/null").c_str()), 0);
  const auto lines = lines_of(read_bytes(info));
  const nlohmann::json& bus = m.at("bus");
  EXPECT_EQ(lines.size(), bus.at("frames_rx").get<std::size_t>() + bus.at("frames_tx").get<std::size_t>());
  EXPECT_TRUE(read_bytes(bad).empty()) << read_bytes(bad);
  for (const char* what : {"DETECT", "DLY_REQ", "CYC_NOTIFY", "COMM_START", "SYNC", "CONNECT", "SYNC_SET", "ID_RD",
                           "SENS_ON", "SV_ON", "VELCTRL"}) {
    EXPECT_TRUE(std::any_of(lines.begin(), lines.end(), [&](const std::string& l) { return contains(l, what); }))
        << "no frame with " << what;
  }
}

// M-III over UDP on loopback, position mode, and a run directory given relative to the
// working directory (the master resolves its configuration's paths against the file's folder).
TEST_F(CliM3, LockstepOverUdpInPositionModeWithARelativeRunDirectory) {
  const Finished f = run_short("relative-out", {"bus.transport=udp:127.0.0.1:0", "bus.mode=interpolate"});
  const nlohmann::json m = metrics(work() / "relative-out");
  expect_clean_run(f, m);
  EXPECT_TRUE(m.at("bus").at("transport").get<std::string>().starts_with("udp:127.0.0.1:"));
  EXPECT_TRUE(contains(read_bytes(work() / "relative-out" / "master.log"), "INTERPOLATE"));
}

// A transmission cycle too short for four slaves with a retry slot and the software time:
// the master refuses to start cyclic communication and names the shortest cycle that fits.
TEST_F(CliM3, ACycleTheLineCannotFitIsRefusedNamingTheShortestThatFits) {
  const fs::path out = dir_ / "short-cycle";
  // Past the master's 3 s start-up timeout: the misfit, not the timeout, is the reason. (0.1 ms
  // is below what a servo connects at.)
  run_short(out, {"bus.cycle=0.00015", "duration=4"});
  const std::string log = read_bytes(out / "master.log");
  EXPECT_TRUE(contains(log, "a 0.150 ms transmission cycle is too short")) << log;
  EXPECT_TRUE(contains(log, "the shortest cycle that fits is 172 µs")) << log;
  const nlohmann::json m = metrics(out);
  EXPECT_EQ(m.at("master").at("state"), "stopped") << "what it reported on the sim clock";
  EXPECT_EQ(m.at("master").at("stats_state"), "failed") << "the master's own word (master-stats.json)";
  // Found in review: reported as startup_timeout, as a silent slave would be.
  EXPECT_EQ(m.at("master").at("stop_reason"), "config_failed") << "what it reported on the sim clock";
  EXPECT_EQ(m.at("master").at("stop_reason_code"), 7);
  EXPECT_EQ(m.at("master").at("driver_state"), "failed");
  EXPECT_EQ(m.at("master").at("exit"), "exit 3");
}

// Event-driven communication: no SYNC, the servos connected asynchronously and left in phase
// 2, one exchange per axis every millisecond driving the platform to its goal; at the end the
// master's shutdown disconnects them (phase 1).
TEST_F(CliM3, EventDrivenCommunicationDrivesThePlatform) {
  const fs::path out = dir_ / "event";
  const Finished f = run_short(out, {"bus.communication=event", "bus.transport=udp:127.0.0.1:0"});
  EXPECT_EQ(f.code, 0) << f.out << f.err;
  const nlohmann::json m = metrics(out);
  EXPECT_EQ(m.at("master").at("driver_state"), "event-driven communication");
  EXPECT_EQ(m.at("master").at("state"), "finished");
  EXPECT_EQ(m.at("master").at("missed"), 0);
  EXPECT_GT(m.at("master").at("exchanges").get<int>(), 4 * 4000);
  for (const auto& s : m.at("slaves")) {
    EXPECT_EQ(s.at("phase"), 1) << "disconnected by the shutdown";
    EXPECT_EQ(s.at("missed_syncs"), 0);
  }
  EXPECT_GE(m.at("bus").at("servos_on_since_s").get<double>(), 0.0);
  EXPECT_LT(m.at("platform").at("final_error_cm").get<double>(), 1.0);
  EXPECT_TRUE(contains(read_bytes(out / "master.log"), "communication start: event-driven"));
  EXPECT_FALSE(contains(read_bytes(out / "events.log"), "phase 3")) << "event-driven: never phase 3";
}

// A transport that cannot be opened is bad input named by its key; nothing is written.
TEST_F(CliM3, AnUnopenableTransportIsRefused) {
  const fs::path out = dir_ / "never";
  const Finished f = run_short(out, {"bus.transport=udp:no.such.host.invalid:1"});
  EXPECT_EQ(f.code, 2) << f.out << f.err;
  EXPECT_TRUE(contains(f.err, "bus.transport")) << f.err;
  EXPECT_FALSE(fs::exists(out));
}

// `omnitwin twin --bus m3` and `omni-master --bus m3` started by hand, both on the wall clock:
// the master finds the four servos, measures the line (the transport's round trip included)
// and brings every servo into operation; at the end of --duration it switches each off and
// disconnects it (SV_OFF, DISCONNECT). At an 8 ms cycle: at 2 ms the 2-core CI machine's host
// stalls (up to 5.8 ms measured) lost an axis in three fresh-clone runs; a short cycle across
// processes on the wall clock is CliM3Slow's (1 ms, slow label).
TEST_F(CliM3, AnExternalMasterOnTheWallClockStartsTheTwinsServos) {
  const std::string iface = "udp:127.0.0.1:47711";
  Child twin({"twin", test_scenario("m3_short.yaml"), "--bus", "m3", "--set", "bus.transport=" + iface, "--set",
              "duration=30", "--out", (dir_ / "twin").string(), "--no-progress"},
             work(), io());
  twin.wait_for_output("a C1 master connects on");
  ASSERT_TRUE(contains(twin.out(), "a C1 master connects on " + iface)) << twin.out() << twin.err();
  const fs::path stats = dir_ / "master-stats.json";
  Child master(binary_path("controller/omni-master"),
               {"--bus", "m3", "--iface", iface, "--config", source_path("tests/data/m3/servos_only_8ms.yaml"),
                "--duration", "2", "--stats", stats.string()},
               work(), io(), "master-");
  EXPECT_EQ(master.wait(30s), 0) << master.out() << master.err();
  twin.signal(SIGINT);
  EXPECT_NE(twin.wait(30s), -1);
  const nlohmann::json s = nlohmann::json::parse(read_bytes(stats));
  EXPECT_EQ(s.at("driver_state"), "cyclic communication") << s.dump(2);
  EXPECT_EQ(s.at("cycle_ns"), 8'000'000) << s.dump(2);
  EXPECT_GT(s.at("cycles").get<int>(), 200);  // 2 s at an 8 ms cycle, less the start-up
  // Where the host held the master and the twin for two cycles or more between them, a servo
  // misses two in a row and raises its communication alarm as the protocol requires: then the
  // stop is the right answer (as CliM3Slow judges). Both sides measure their own worst wake:
  // the master's statistics and the twin's realtime pacer (three fresh-clone CI runs had the
  // master alone 4.0, 5.8 and 3.7 ms late at the 2 ms cycle this test used; the twin's pacer
  // woke 3 ms late as the master started, on an idle machine).
  const auto cycle_ns = s.at("cycle_ns").get<std::int64_t>();
  const nlohmann::json tm = nlohmann::json::parse(read_bytes(dir_ / "twin" / "metrics.json"));
  const double twin_late_ns = tm.at("realtime").at("jitter_max_us").get<double>() * 1e3;
  const double stalled_ns = static_cast<double>(s.at("wake_late_max_ns").get<std::int64_t>()) + twin_late_ns;
  if (stalled_ns >= 2.0 * static_cast<double>(cycle_ns) && s.at("state") != "running") {
    EXPECT_GE(s.at("lost_axis").get<int>(), 1) << s.dump(2);
    EXPECT_EQ(s.at("platform_stopped"), true) << s.dump(2);
    GTEST_SKIP() << "the host stalled the master " << s.at("wake_late_max_ns").get<std::int64_t>() / 1e6
                 << " ms and the twin " << twin_late_ns / 1e6
                 << " ms (two cycles or more together): its servos alarmed, as they must; not judged as a start-up";
  }
  EXPECT_EQ(s.at("state"), "running") << "every servo in operation, none lost: " << s.dump(2);
  EXPECT_LE(s.at("wakes_late").get<std::uint64_t>(), s.at("cycles").get<std::uint64_t>()) << s.dump(2);
  for (const auto& sl : s.at("slaves")) {
    EXPECT_EQ(sl.at("axis_step"), "released") << s.dump(2);
    EXPECT_GT(sl.at("tr_dly_ns").get<int>(), 1000) << "across processes the round trip is microseconds";
  }
}

// A master the host stalls (here SIGSTOP for 50 ms) says so: its statistics count the deadlines
// it reached half a cycle or more late and the worst lateness, and its log names the instant.
TEST_F(CliM3, AMasterStalledOnTheWallClockCountsItsLateDeadlines) {
  const std::string iface = "udp:127.0.0.1:47713";
  Child twin({"twin", test_scenario("m3_short.yaml"), "--bus", "m3", "--set", "bus.transport=" + iface, "--set",
              "duration=30", "--out", (dir_ / "twin").string(), "--no-progress"},
             work(), io());
  ASSERT_TRUE(twin.wait_for_output("a C1 master connects on")) << twin.out() << twin.err();
  const fs::path stats = dir_ / "master-stats.json";
  Child master(binary_path("controller/omni-master"),
               {"--bus", "m3", "--iface", iface, "--config", source_path("tests/data/m3/servos_only.yaml"), "--duration",
                "2", "--stats", stats.string()},
               work(), io(), "master-");
  for (int i = 0; i < 1000 && !contains(master.err(), "(06h): running") && master.running(); ++i)
    std::this_thread::sleep_for(10ms);
  ASSERT_TRUE(contains(master.err(), "(06h): running")) << master.err();
  master.signal(SIGSTOP);
  std::this_thread::sleep_for(50ms);
  master.signal(SIGCONT);
  EXPECT_NE(master.wait(30s), -1) << master.err();
  twin.signal(SIGINT);
  EXPECT_NE(twin.wait(30s), -1);
  const nlohmann::json s = nlohmann::json::parse(read_bytes(stats));
  EXPECT_GE(s.at("wakes_late").get<int>(), 20) << "50 ms of 2 ms cycles, each run late: " << s.dump(2);
  EXPECT_GE(s.at("wake_late_max_ns").get<std::int64_t>(), 40'000'000) << s.dump(2);
  EXPECT_TRUE(contains(master.err(), "deadline reached")) << master.err();
  EXPECT_TRUE(contains(master.err(), "the host stalled this process")) << master.err();
}

}  // namespace
}  // namespace omnitwin::twin::cli
