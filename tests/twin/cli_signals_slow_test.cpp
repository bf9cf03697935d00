// Signal and process-fault torture of `omnitwin run` (issue 16, item 4), slow-labelled:
//  - SIGINT or SIGTERM at 20 random moments of a lockstep run of the thesis line on each bus,
//    from the first milliseconds through the run, the video and the report: exit 3, metrics
//    saying interrupted, every record valid (CSV rows whole, the capture read by tshark to its
//    end, the MP4 decoded by ffmpeg, the report closed, nothing left under .part) and no
//    process of the run (master, report) alive afterwards;
//  - the master SIGKILLed or SIGSTOPped for 2 s mid-run on each bus with a master, in lockstep
//    and in realtime: a killed master ends the run with exit 3 and "master lost"; a stopped
//    one in realtime too (supervision); in lockstep, a 2 s stop is shorter than the handshake
//    timeout, so the run waits for it and ends exactly as a run alone (same trajectory).
// The moments come from a seeded generator: OMNITWIN_SIGNAL_SEED repeats a sequence (each
// failure names its seed, bus and moment).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <csignal>
#include <cstdlib>
#include <random>

#include "tests/twin/cli_support.hpp"

namespace {

using namespace omnitwin::twin::cli;

std::string thesis_line() { return source_path("models/scenarios/thesis_line.yaml"); }

// The lockstep run the moments fall in: the thesis line with its video (at 10 frames per
// simulated second, so that the video phase is seconds, not tens of seconds) and its report.
std::vector<std::string> full_run_args(const std::string& bus, const fs::path& out) {
  return {"run", thesis_line(), "--bus", bus, "--out", out.string(), "--no-progress", "--set", "outputs.video.fps=10"};
}

// Every line of a CSV record has the header's number of cells, and the file ends with a
// newline: no torn row.
std::string csv_problem(const fs::path& f) {
  if (!fs::exists(f)) return "";
  const std::string text = read_bytes(f);
  if (text.empty()) return "";
  if (text.back() != '\n') return f.filename().string() + " ends inside a row";
  std::size_t start = 0, commas = std::string::npos, row = 0;
  while (start < text.size()) {
    const std::size_t end = text.find('\n', start);
    const auto n = static_cast<std::size_t>(std::count(text.begin() + static_cast<long>(start),
                                                       text.begin() + static_cast<long>(end), ','));
    if (commas == std::string::npos) commas = n;
    if (n != commas) return f.filename().string() + " row " + std::to_string(row) + " has " + std::to_string(n + 1) +
                            " cells, the header " + std::to_string(commas + 1);
    start = end + 1;
    ++row;
  }
  return "";
}

// The pids of processes whose command line names `dir` (the run's master and report name
// the run directory); the test process itself excluded.
std::vector<int> processes_naming(const fs::path& dir) {
  std::vector<int> pids;
  for (const auto& e : fs::directory_iterator("/proc")) {
    const std::string name = e.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::string cmdline = read_bytes(e.path() / "cmdline");
    std::replace(cmdline.begin(), cmdline.end(), '\0', ' ');
    if (contains(cmdline, dir.string()) && std::stoi(name) != ::getpid()) pids.push_back(std::stoi(name));
  }
  return pids;
}

// Everything wrong with an interrupted run's directory (empty when it is all valid).
std::vector<std::string> record_problems(const fs::path& out) {
  std::vector<std::string> p;
  if (!fs::exists(out / "metrics.json")) return {"no metrics.json"};
  const nlohmann::json m = nlohmann::json::parse(read_bytes(out / "metrics.json"), nullptr, false);
  if (m.is_discarded()) return {"metrics.json does not parse"};
  if (m.value("interrupted", false) != true) p.push_back("metrics.json does not say interrupted");
  for (const char* f : {"trajectory.csv", "bus.csv"})
    if (const std::string why = csv_problem(out / f); !why.empty()) p.push_back(why);
  for (const auto& e : fs::directory_iterator(out)) {
    const std::string name = e.path().filename().string();
    if (name.ends_with(".part")) p.push_back(name + " left under a temporary name");
    if (name.ends_with(".pcap") && !capture_reads(e.path())) p.push_back(name + " does not read to its end in tshark");
  }
  if (fs::exists(out / "video.mp4") && !video_decodes(out / "video.mp4")) p.push_back("video.mp4 does not decode");
  if (fs::exists(out / "report.html") && !contains(read_bytes(out / "report.html"), "</html>"))
    p.push_back("report.html is cut short");
  if (fs::exists(out / "metrics.json.tmp")) p.push_back("metrics.json.tmp left");
  return p;
}

std::uint32_t seed() {
  const char* s = std::getenv("OMNITWIN_SIGNAL_SEED");
  return s && *s ? static_cast<std::uint32_t>(std::stoul(s)) : 20261126u;
}

class CliSignals : public CliTest, public ::testing::WithParamInterface<std::string> {};

TEST_P(CliSignals, TwentyRandomMomentsLeaveValidRecordsAndNoProcess) {
  const std::string bus = GetParam();
  // The whole run once, uninterrupted: its wall time spans the moments.
  const auto t0 = std::chrono::steady_clock::now();
  const Finished whole = run(full_run_args(bus, dir_ / "whole"));
  const double span_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_EQ(whole.code, 0) << whole.out << whole.err;
  ASSERT_TRUE(fs::exists(dir_ / "whole/video.mp4") && fs::exists(dir_ / "whole/report.html"));
  std::mt19937 rng(seed() + static_cast<std::uint32_t>(std::hash<std::string>{}(bus) & 0xffff));
  std::uniform_real_distribution<double> moment(0.0, 1.05 * span_s);
  // Twenty signals must land inside a run. The moments are drawn from one run's length,
  // measured while other tests may load the machine: later runs can be shorter, so a moment
  // after a run's end is drawn again (at most 60 draws).
  int interrupted = 0, finished_first = 0;
  for (int k = 0; k < 60 && interrupted < 20; ++k) {
    const double at = moment(rng);
    const int sig = (rng() & 1) ? SIGINT : SIGTERM;
    const std::string what = "seed " + std::to_string(seed()) + ", " + bus + " case " + std::to_string(k) + ": " +
                             (sig == SIGINT ? "SIGINT" : "SIGTERM") + " at " + std::to_string(at) + " s of " +
                             std::to_string(span_s) + " s";
    const fs::path out = dir_ / ("m" + std::to_string(k));
    Child c(full_run_args(bus, out), work(), io());
    std::this_thread::sleep_for(std::chrono::duration<double>(at));
    if (!c.running()) {
      ++finished_first;
      EXPECT_EQ(c.wait(1s), 0) << what << "\n" << c.out() << c.err();
      continue;
    }
    c.signal(sig);
    const int code = c.wait(60s);
    // A moment in the run's last 5 % can come after a faster run has written its last record
    // (the signal then meets a process on its way out): exit 0 with a whole, uninterrupted
    // run is that run finishing first, not a signal ignored mid-run.
    const std::vector<std::string> problems = record_problems(out);
    if (code == 0 && at > 0.95 * span_s && problems == std::vector<std::string>{"metrics.json does not say interrupted"} &&
        fs::exists(out / "video.mp4") && fs::exists(out / "report.html")) {
      ++finished_first;
      std::cout << "  " << what << ": exit 0, the run had finished\n";
      continue;
    }
    ++interrupted;
    EXPECT_EQ(code, 3) << what << "\n" << c.out() << c.err();
    for (const std::string& problem : problems) ADD_FAILURE() << what << ": " << problem << "\n" << c.out();
    std::this_thread::sleep_for(100ms);  // an orphan would still be there
    EXPECT_TRUE(processes_naming(out).empty()) << what << ": a process of the run survived it";
    std::cout << "  " << what << ": exit " << code << "\n";
  }
  std::cout << bus << ": " << interrupted << " interrupted, " << finished_first << " finished before the signal\n";
  EXPECT_EQ(interrupted, 20);
}

INSTANTIATE_TEST_SUITE_P(EveryBus, CliSignals, ::testing::Values("direct", "can", "canopen", "tml", "ethercat", "m3"),
                         [](const ::testing::TestParamInfo<std::string>& i) { return i.param; });

// ---------------------------------------------------------------------------------------
// The master killed or stopped mid-run.

struct MasterFault {
  std::string bus, clock;
  int sig;
};

void PrintTo(const MasterFault& f, std::ostream* os) {
  *os << f.bus << " " << f.clock << " " << (f.sig == SIGKILL ? "SIGKILL" : "SIGSTOP 2 s");
}

std::string fault_name(const ::testing::TestParamInfo<MasterFault>& i) {
  return i.param.bus + "_" + i.param.clock + "_" + (i.param.sig == SIGKILL ? "killed" : "stopped");
}

class CliMasterFault : public CliTest, public ::testing::WithParamInterface<MasterFault> {};

TEST_P(CliMasterFault, EndsWithTheDocumentedCodeAndValidRecords) {
  const MasterFault f = GetParam();
  const bool lockstep = f.clock == "lockstep";
  auto args = [&](const fs::path& out) {
    std::vector<std::string> a{"run", thesis_line(), "--bus", f.bus, "--clock", f.clock, "--no-video",
                               "--no-report", "--no-progress", "--out", out.string()};
    if (!lockstep && f.bus == "can") a.insert(a.end(), {"--set", kOwnCanBus});
    return a;
  };
  const fs::path out = dir_ / "fault";
  Child c(args(out), work(), io());
  const pid_t pid = master_pid(out, c);
  ASSERT_GT(pid, 0) << c.out() << c.err();
  // Lockstep runs the thesis line in about a second: act early; realtime once it moves.
  std::this_thread::sleep_for(lockstep ? 250ms : 1500ms);
  ASSERT_TRUE(c.running()) << "the run ended before the fault\n" << c.out() << c.err();
  ::kill(pid, f.sig);
  if (f.sig == SIGSTOP) {
    std::this_thread::sleep_for(2s);
    ::kill(pid, SIGCONT);
  }
  const int code = c.wait(60s);
  if (f.sig == SIGSTOP && lockstep) {
    // Shorter than the handshake timeout: the twin waited, and the run is the run alone.
    EXPECT_EQ(code, 0) << c.out() << c.err();
    const Finished alone = run(args(dir_ / "alone"));
    ASSERT_EQ(alone.code, 0) << alone.out << alone.err;
    EXPECT_EQ(read_bytes(out / "trajectory.csv"), read_bytes(dir_ / "alone/trajectory.csv"))
        << "a master paused for 2 s changed a lockstep run";
  } else {
    EXPECT_EQ(code, 3) << c.out() << c.err();
    EXPECT_TRUE(contains(c.out(), "master lost")) << c.out() << c.err();
    const nlohmann::json m = CliTest::metrics(out);
    EXPECT_EQ(m.at("master").at("lost"), true) << m.at("master").dump();
  }
  for (const char* rec : {"trajectory.csv", "bus.csv"}) EXPECT_EQ(csv_problem(out / rec), "");
  EXPECT_TRUE(part_files(out).empty()) << part_files(out).front();
  for (const auto& e : fs::directory_iterator(out))
    if (e.path().extension() == ".pcap") {
      EXPECT_TRUE(capture_reads(e.path())) << e.path();
    }
  std::this_thread::sleep_for(100ms);
  EXPECT_TRUE(processes_naming(out).empty()) << "a process of the run survived it";
}

std::vector<MasterFault> master_faults() {
  std::vector<MasterFault> v;
  for (const char* bus : {"can", "canopen", "tml", "ethercat", "m3"})
    for (const char* clock : {"lockstep", "realtime"})
      for (int sig : {SIGKILL, SIGSTOP}) v.push_back({bus, clock, sig});
  return v;
}

INSTANTIATE_TEST_SUITE_P(EveryBusAndClock, CliMasterFault, ::testing::ValuesIn(master_faults()), fault_name);

// ---------------------------------------------------------------------------------------
// The twin killed under an external master (CAN and EtherCAT: cli_test, cli_ethercat_test).

struct ExternalMaster {
  std::string bus, scenario, ready_line, transport, config;
};

class CliTwinKilled : public CliTest, public ::testing::WithParamInterface<ExternalMaster> {};

void PrintTo(const ExternalMaster& m, std::ostream* os) { *os << m.bus; }

// The master on its wall clock, the twin SIGKILLed once the drives run: the master notices
// (lost nodes / a lost axis), stops its drives, says so in its output and statistics, and
// ends at its --duration.
TEST_P(CliTwinKilled, TheMasterStopsAndSaysSo) {
  const ExternalMaster e = GetParam();
  Child twin({"twin", test_scenario(e.scenario), "--bus", e.bus, "--set", "bus.transport=" + e.transport, "--set",
              "duration=60", "--out", (dir_ / "twin").string(), "--no-progress", "--no-video", "--no-report"},
             work(), io());
  ASSERT_TRUE(twin.wait_for_output(e.ready_line)) << twin.out() << twin.err();
  const fs::path stats = dir_ / "master-stats.json";
  Child master(binary_path("controller/omni-master"),
               {"--bus", e.bus, "--iface", e.transport, "--config", source_path(e.config), "--duration", "20",
                "--stats", stats.string()},
               work(), io(), "master-");
  std::this_thread::sleep_for(3s);  // in operation well before this
  ASSERT_TRUE(master.running()) << master.out() << master.err();
  twin.signal(SIGKILL);
  // It runs to its --duration (as our EtherCAT master does: stopped, not gone), then exits.
  EXPECT_EQ(master.wait(40s), 0) << master.out() << master.err();
  ASSERT_TRUE(fs::exists(stats)) << master.out() << master.err();
  const nlohmann::json s = nlohmann::json::parse(read_bytes(stats));
  // TML says which axis "stopped answering"; the others name the lost node or axis.
  EXPECT_TRUE(contains(master.err(), e.bus == "tml" ? "stopped answering" : "lost"))
      << "the master does not say what happened\n" << master.err();
  if (e.bus == "tml") {
    EXPECT_EQ(s.at("phase"), "stopped") << s.dump(1);
    EXPECT_GE(s.at("axes_lost").get<int>(), 1) << s.dump(1);
  } else if (e.bus == "m3") {
    EXPECT_EQ(s.at("state"), "stopped") << s.dump(1);
    EXPECT_EQ(s.at("platform_stopped"), true);
    EXPECT_GE(s.at("lost_axis").get<int>(), 1);
  } else {
    for (const auto& n : s.at("nodes")) EXPECT_EQ(n.at("lost"), true) << n.dump();
  }
}

INSTANTIATE_TEST_SUITE_P(
    CanopenM3AndTml, CliTwinKilled,
    ::testing::Values(ExternalMaster{"canopen", "canopen_short.yaml", "waiting for a master", "udp:239.74.163.2:47723",
                                     "tests/data/canopen/drives_only.yaml"},
                      ExternalMaster{"m3", "m3_short.yaml", "a C1 master connects on", "udp:127.0.0.1:47724",
                                     "tests/data/m3/servos_only.yaml"},
                      ExternalMaster{"tml", "tml_short.yaml", "waiting for a master", "udp:239.74.163.2:47725",
                                     "tests/data/tml/drives_only.yaml"}),
    [](const ::testing::TestParamInfo<ExternalMaster>& i) { return i.param.bus; });

}  // namespace
