// Tests `omnitwin run --bus tml` end to end through the real programs: the twin's four IDM
// drives on the simulated CAN wire and our TML master (`omni-master --bus tml`) as two
// processes over UDP multicast in lockstep, over TMLCAN and TechCAN. Lockstep runs are
// byte-identical (trajectory, bus records, capture); master.log tells the start-up; every
// drive answered and none saw an unknown opcode; tshark reads the capture with no malformed
// frame, as plain CAN and with the project's TML dissector (tools/wireshark/tml.lua).
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "tests/twin/cli_support.hpp"

namespace omnitwin::twin::cli {
namespace {

class CliTml : public CliTest {
 protected:
  Finished run_short(const fs::path& out, const std::vector<std::string>& sets = {}) {
    return run_test_scenario("tml_short.yaml", out, sets);
  }
};

std::string shell(const std::string& cmd) {
  std::string out;
  if (FILE* p = ::popen(cmd.c_str(), "r")) {
    char buf[4096];
    while (std::size_t n = std::fread(buf, 1, sizeof buf, p)) out.append(buf, n);
    ::pclose(p);
  }
  return out;
}

void expect_clean_run(const Finished& f, const nlohmann::json& m) {
  EXPECT_EQ(f.code, 0) << f.out << f.err;
  const nlohmann::json& ms = m.at("master");
  EXPECT_EQ(ms.at("state"), "finished") << ms.dump(2);
  EXPECT_EQ(ms.at("axes_lost"), 0);
  EXPECT_EQ(ms.at("not_tml"), 0);
  EXPECT_GT(ms.at("answers").get<int>(), 4 * 1500);
  for (const auto& s : m.at("slaves")) {
    EXPECT_EQ(s.at("unknown_opcodes"), 0);
    EXPECT_EQ(s.at("bad_frames"), 0);
    EXPECT_EQ(s.at("drive_state"), "ready to switch on") << "the master's shutdown after the run's end: AXISOFF";
  }
  EXPECT_GE(m.at("drives").at("all_running_at_s").get<double>(), 0.0) << m.at("drives").dump();
  EXPECT_EQ(m.at("master").at("stop_signal"), "stop in the grants");
  EXPECT_EQ(m.at("bus").at("error_frames"), 0);
  EXPECT_LT(m.at("platform").at("final_error_cm").get<double>(), 1.0);
}

// Our TML master on the wall clock keeps watching its axes (APOS, SR32) once it holds still:
// after its path has ended, and after it stopped the platform for a lost axis. It fell silent
// there, and the twin's supervision ended both runs with "master lost" (exit 3; found in
// review), though nothing was wrong but the fault the scenario asked for.
TEST_F(CliTml, OnTheWallClockAMasterHoldingStillIsNotLost) {
  const std::string bus = "bus.transport=udp:239.74.163.2:47345";
  const Finished ended = run_short(dir_ / "ended", {"clock=realtime", bus, "settle=1.5"});
  EXPECT_EQ(ended.code, 0) << ended.out << ended.err;
  EXPECT_FALSE(metrics(dir_ / "ended").at("master").at("lost").get<bool>());
  const Finished lost = run_short(dir_ / "lost", {"clock=realtime", bus, "expect={}",
                                                  "faults=[{power_loss: {node: 2, at: 1.5, duration: 0.5}}]"});
  EXPECT_EQ(lost.code, 0) << lost.out << lost.err;
  const nlohmann::json m = metrics(dir_ / "lost");
  EXPECT_FALSE(m.at("master").at("lost").get<bool>()) << m.at("master").dump(2);
  EXPECT_TRUE(contains(lost.out, "axes lost 1")) << lost.out;
  EXPECT_GT(m.at("sim_time_s").get<double>(), 4.0);  // to its end
}

TEST_F(CliTml, TmlcanLockstepIsByteIdentical) {
  const fs::path a = dir_ / "a", b = dir_ / "b";
  const Finished fa = run_short(a);
  const Finished fb = run_short(b);
  const nlohmann::json m = metrics(a);
  expect_clean_run(fa, m);
  EXPECT_EQ(m.at("bus").at("protocol"), "tmlcan");
  EXPECT_EQ(fb.code, 0);
  for (const char* f : {"trajectory.csv", "bus.csv", "bus-can.pcap"}) EXPECT_EQ(read_bytes(a / f), read_bytes(b / f)) << f;
  const std::string log = read_bytes(a / "master.log");
  for (const char* line : {"TMLCAN", "all four axes answered: speed mode, AXISON", "phase starting -> running", "path done"})
    EXPECT_NE(log.find(line), std::string::npos) << line << "\n" << log;
  if (std::system("command -v tshark >/dev/null 2>&1") != 0) GTEST_SKIP() << "tshark is not installed";
  const std::string base = "tshark -r " + (a / "bus-can.pcap").string();
  EXPECT_EQ(std::stoll(shell(base + " 2>/dev/null | wc -l")), m.at("bus").at("frames").get<long long>());
  EXPECT_EQ(shell(base + " 2>/dev/null | grep -ci malformed"), "0\n");
  // With the project's TML dissector every frame decodes as TML, none malformed.
  const std::string lua = "tshark -X lua_script:" + source_path("tools/wireshark/tml.lua") +
                          " -d can.subdissector,tml -r " + (a / "bus-can.pcap").string();
  EXPECT_EQ(std::stoll(shell(lua + " 2>/dev/null | grep -c ' TML '")), m.at("bus").at("frames").get<long long>());
  EXPECT_EQ(shell(lua + " 2>&1 | grep -ci 'malformed\\|lua error'"), "0\n");
  EXPECT_NE(shell(lua + " 2>/dev/null | head -3").find("GiveMeData2 16-bit to group mask 0x01"), std::string::npos);
}

TEST_F(CliTml, TechcanDrivesThePlatform) {
  const fs::path a = dir_ / "techcan";
  const Finished f = run_short(a, {"bus.protocol=techcan"});
  const nlohmann::json m = metrics(a);
  expect_clean_run(f, m);
  EXPECT_EQ(m.at("bus").at("protocol"), "techcan");
  EXPECT_NE(read_bytes(a / "master.log").find("TechCAN"), std::string::npos);
}

}  // namespace
}  // namespace omnitwin::twin::cli
