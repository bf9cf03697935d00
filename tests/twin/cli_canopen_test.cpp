// Tests `omnitwin run --bus canopen` end to end through the real programs: the twin's four
// CiA 402 CANopen drives on the simulated CAN wire and our CANopen master (`omni-master --bus
// canopen`) as two processes over UDP multicast in lockstep. Lockstep runs are byte-identical
// (trajectory, bus records, capture); master.log tells the start-up (device names read by
// segmented SDO, configuration, NMT and CiA 402 phases); tshark decodes the capture as
// CANopen with no malformed frame; the per-node metrics are filled; profile velocity mode
// drives the platform too; a drive losing power stops the platform and is brought back; a
// malformed EDS is bad input naming the file, line and key; our master on its own wall clock
// drives the drives of `omnitwin twin --bus canopen`.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>

#include "tests/twin/cli_support.hpp"

namespace omnitwin::twin::cli {
namespace {

class CliCanopen : public CliTest {
 protected:
  Finished run_short(const fs::path& out, const std::vector<std::string>& sets = {}) {
    return run_test_scenario("canopen_short.yaml", out, sets);
  }
};

void expect_clean_run(const Finished& f, const nlohmann::json& m) {
  EXPECT_EQ(f.code, 0) << f.out << f.err;
  const nlohmann::json& ms = m.at("master");
  EXPECT_EQ(ms.at("state"), "finished") << ms.dump(2);
  EXPECT_EQ(ms.at("sdo_aborts"), 0);
  EXPECT_EQ(ms.at("heartbeat_timeouts"), 0);
  EXPECT_GT(ms.at("syncs").get<int>(), 3000);
  EXPECT_GT(ms.at("path_origin_s").get<double>(), 0.0);
  EXPECT_LT(ms.at("path_origin_s").get<double>(), 0.2);
  // Operational through the run; the master's shutdown after its end stops every node (NMT).
  EXPECT_GE(m.at("drives").at("all_running_at_s").get<double>(), 0.0) << m.at("drives").dump();
  for (const auto& s : m.at("slaves")) {
    EXPECT_EQ(s.at("nmt_state"), "stopped");
    EXPECT_EQ(s.at("emcy"), 0);
    EXPECT_EQ(s.at("sdo_aborts"), 0);
    EXPECT_GT(s.at("rpdo_rx").get<int>(), 3000);
    EXPECT_GT(s.at("tpdo_tx").get<int>(), 3000);
  }
  EXPECT_EQ(m.at("bus").at("error_frames"), 0);
  EXPECT_LT(m.at("platform").at("final_error_cm").get<double>(), 1.0);
}

bool have_tshark() { return std::system("command -v tshark >/dev/null 2>&1") == 0; }

// A shell command's standard output.
std::string shell(const std::string& cmd) {
  std::string out;
  if (FILE* p = ::popen(cmd.c_str(), "r")) {
    char buf[4096];
    while (std::size_t n = std::fread(buf, 1, sizeof buf, p)) out.append(buf, n);
    ::pclose(p);
  }
  return out;
}

TEST_F(CliCanopen, LockstepIsByteIdenticalAndDecodesAsCanopen) {
  const fs::path a = dir_ / "a", b = dir_ / "b";
  const Finished fa = run_short(a);
  const Finished fb = run_short(b);
  const nlohmann::json m = metrics(a);
  expect_clean_run(fa, m);
  EXPECT_EQ(fb.code, 0);
  for (const char* f : {"trajectory.csv", "bus.csv", "bus-can.pcap"}) EXPECT_EQ(read_bytes(a / f), read_bytes(b / f)) << f;
  const std::string log = read_bytes(a / "master.log");
  for (const char* line : {"node 1: omnitwin CiA 402 drive", "node 4: configured", "phase configuring -> starting",
                           "phase starting -> enabling", "phase enabling -> running", "path done"})
    EXPECT_NE(log.find(line), std::string::npos) << line << "\n" << log;
  if (!have_tshark()) GTEST_SKIP() << "tshark is not installed";
  const std::string base = "tshark -r " + (a / "bus-can.pcap").string() + " -d can.subdissector,canopen";
  EXPECT_EQ(std::stoll(shell(base + " 2>/dev/null | wc -l")), m.at("bus").at("frames").get<long long>());
  EXPECT_EQ(shell(base + " 2>/dev/null | grep -ci malformed"), "0\n");
  const std::string kinds = shell(base + " 2>/dev/null | grep -o 'NMT: Reset communication\\|Boot-up\\|Initiate upload request"
                                      "\\|Upload segment response\\|Initiate download request\\|NMT: Start remote node\\|SYNC\\|PDO'"
                                      " | sort -u");
  for (const char* k : {"NMT: Reset communication", "Boot-up", "Initiate upload request", "Upload segment response",
                        "Initiate download request", "NMT: Start remote node", "SYNC", "PDO"})
    EXPECT_NE(kinds.find(k), std::string::npos) << k << "\n" << kinds;
}

TEST_F(CliCanopen, ProfileVelocityModeDrivesThePlatform) {
  const fs::path a = dir_ / "pv";
  const Finished f = run_short(a, {"bus.mode=pv"});
  expect_clean_run(f, metrics(a));
  EXPECT_NE(read_bytes(a / "master.log").find("PV"), std::string::npos);
}

// The axes' velocity figures are the records' own, as on buses direct and can: once per
// control sample while the drive runs, (w*_cmd_counts − w*_meas_counts) × the control period,
// in encoder pulses per sample. They were taken every 1 ms drive period and skipped samples
// with demand and actual both 0: σ came out ten times smaller than the records' and a
// std_velocity_pulse bound meant for bus direct passed (found in review).
TEST_F(CliCanopen, AxisFiguresAreTheRecordsVelocityErrorPerControlSample) {
  const fs::path a = dir_ / "axes";
  const Finished f = run_short(a);
  ASSERT_EQ(f.code, 0) << f.out << f.err;
  const std::string script = std::string("import csv, json, math, sys\n") +
      "d = sys.argv[1]\n"
      "m = json.load(open(d + '/metrics.json')); T = json.load(open(d + '/run.json'))['control_period_s']\n"
      "tr = list(csv.DictReader(open(d + '/trajectory.csv'))); bus = list(csv.DictReader(open(d + '/bus.csv')))\n"
      "assert len(tr) == len(bus) and len(tr) > 100\n"
      "for i in range(4):\n"
      "  e = [(float(r[f'w{i+1}_cmd_counts']) - float(r[f'w{i+1}_meas_counts'])) * T\n"
      "       for r, b in zip(tr, bus) if int(b[f's{i+1}_state']) == 2]\n"
      "  a = m['axes'][i]; iae = sum(abs(x) for x in e); std = math.sqrt(sum(x * x for x in e) / len(e))\n"
      "  ok = a['samples'] == len(e) and abs(a['iae_velocity_pulse'] - iae) < 1e-6 * max(1, iae)\n"
      "  ok = ok and abs(a['std_velocity_pulse'] - std) < 1e-9 * max(1, std) and len(e) > 100\n"
      "  if not ok: sys.exit(f'axis {i}: {a} against n {len(e)} iae {iae} std {std}')\n";
  std::ofstream(dir_ / "axes.py") << script;
  EXPECT_EQ(std::system(("python3 " + (dir_ / "axes.py").string() + " " + a.string()).c_str()), 0);
}

TEST_F(CliCanopen, ADriveLosingPowerStopsThePlatformAndComesBack) {
  const fs::path a = dir_ / "power";
  const Finished f = run({"run", test_scenario("canopen_power_loss.yaml"), "--out", a.string(), "--no-progress"});
  EXPECT_EQ(f.code, 0) << f.out << f.err;
  const nlohmann::json m = metrics(a);
  const nlohmann::json& ms = m.at("master");
  EXPECT_EQ(ms.at("state"), "stopped");
  EXPECT_EQ(ms.at("stop_reason"), "node_missing");
  EXPECT_EQ(ms.at("missing_node"), 2);
  EXPECT_GT(ms.at("stopped_at_s").get<double>(), 1.0);   // within the heartbeat consumer time (150 ms)
  EXPECT_LT(ms.at("stopped_at_s").get<double>(), 1.2);
  EXPECT_EQ(ms.at("recoveries"), 1);
  EXPECT_NE(read_bytes(a / "master.log").find("node 2 back in OPERATIONAL"), std::string::npos);
  // Back in OPERATIONAL by the run's end; then the master's shutdown stops it (NMT stop).
  const std::string events = read_bytes(a / "events.log");
  const std::size_t end = events.find("end of the run: stop in every grant");
  ASSERT_NE(end, std::string::npos) << events;
  EXPECT_NE(events.rfind("node 2 NMT operational", end), std::string::npos) << events;
  EXPECT_EQ(events.find("node 2 NMT stopped"), events.find("node 2 NMT stopped", end)) << "stopped only by the shutdown";
  EXPECT_EQ(m.at("slaves")[1].at("nmt_state"), "stopped");
}

// `omnitwin twin --bus canopen` for a master started by hand: our master on its own wall clock
// configures, starts and powers up the twin's four drives and holds them.
TEST_F(CliCanopen, AnExternalMasterOnTheWallClockRunsTheTwinsDrives) {
  const std::string iface = "udp:239.74.163.2:47712";
  Child twin({"twin", test_scenario("canopen_short.yaml"), "--bus", "canopen", "--set", "bus.transport=" + iface, "--set",
              "duration=30", "--out", (dir_ / "twin").string(), "--no-progress"},
             work(), io());
  twin.wait_for_output("waiting for a master");
  ASSERT_TRUE(contains(twin.out(), "CANopen bus of 4 CiA 402 drives (nodes 1-4) on " + iface)) << twin.out() << twin.err();
  const fs::path stats = dir_ / "master-stats.json";
  Child master(binary_path("controller/omni-master"),
               {"--bus", "canopen", "--iface", iface, "--config", source_path("tests/data/canopen/drives_only.yaml"),
                "--duration", "2", "--stats", stats.string()},
               work(), io(), "master-");
  EXPECT_EQ(master.wait(30s), 0) << master.out() << master.err();
  twin.signal(SIGINT);
  EXPECT_NE(twin.wait(30s), -1);
  const nlohmann::json s = nlohmann::json::parse(read_bytes(stats));
  EXPECT_EQ(s.at("phase"), "finished") << s.dump(2);
  EXPECT_EQ(s.at("sdo_aborts"), 0);
  EXPECT_EQ(s.at("heartbeat_timeouts"), 0);
  EXPECT_GT(s.at("syncs").get<int>(), 1500);
  for (const auto& n : s.at("nodes")) EXPECT_TRUE(n.at("configured").get<bool>()) << n.dump();
  const nlohmann::json m = metrics(dir_ / "twin");
  for (const auto& sl : m.at("slaves")) EXPECT_GT(sl.at("rpdo_rx").get<int>(), 1500);
}

TEST_F(CliCanopen, AMalformedEdsIsBadInputNamingFileLineAndKey) {
  const fs::path a = dir_ / "bad";
  const Finished f = run_short(a, {"bus.eds=" + source_path("tests/data/canopen/bad_access.eds")});
  EXPECT_EQ(f.code, 2) << f.out << f.err;
  EXPECT_NE(f.err.find("bad_access.eds:"), std::string::npos) << f.err;
  EXPECT_NE(f.err.find("AccessType"), std::string::npos) << f.err;
}

}  // namespace
}  // namespace omnitwin::twin::cli
