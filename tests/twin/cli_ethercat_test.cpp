// Tests `omnitwin run --bus ethercat` and `omnitwin twin --bus ethercat` end to end through
// the real programs: the twin's EtherCAT segment of four CiA 402 drives and our master
// (`omni-master --bus ethercat`) as two processes over a real transport (a veth pair made for
// the run, or EtherCAT over UDP). Lockstep runs are byte-identical (trajectory and capture);
// the capture decodes in tshark with no malformed frames and holds exactly the frames the
// segment saw; the master reaches OP with the expected working counter every cycle; and seed
// 004's PP-TEST, run by `omni-master --script` against the twin alone, reaches its target.
#include <gtest/gtest.h>
#include <pcap/pcap.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <nlohmann/json.hpp>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdlib>
#include <string>
#include <thread>

#include "bus_emulators/ethercat/ec_frame.hpp"
#include "tests/support/veth.hpp"
#include "tests/twin/cli_support.hpp"
#include "twin/bus_network.hpp"

namespace omnitwin::twin::cli {
namespace {

using omnitwin::testing::lines_of;

class CliEthercat : public CliTest {
 protected:
  // One lockstep run of the short scenario; the transport is given (or the default).
  Finished run_short(const fs::path& out, const std::string& transport = "") {
    std::vector<std::string> args{"run", test_scenario("ethercat_short.yaml"), "--out", out.string(), "--no-progress"};
    if (!transport.empty()) args.insert(args.end(), {"--set", "bus.transport=" + transport});
    return run(args);
  }
};

// The master configured the segment and ran the path with the expected WKC every cycle.
void expect_clean_run(const Finished& f, const nlohmann::json& m) {
  EXPECT_EQ(f.code, 0) << f.out << f.err;
  const nlohmann::json& ms = m.at("master");
  EXPECT_EQ(ms.at("state"), "finished");
  EXPECT_EQ(ms.at("stop_reason"), "none") << "the sim-clock report's, by name (master-stats.json's is \"\")";
  EXPECT_EQ(ms.at("slaves"), 4);
  EXPECT_EQ(ms.at("wkc_errors"), 0);
  EXPECT_EQ(ms.at("expected_wkc"), 12);
  EXPECT_EQ(ms.at("last_wkc"), 12);
  EXPECT_GT(ms.at("cycles").get<int>(), 300);
  EXPECT_GT(ms.at("path_origin_s").get<double>(), 0.0);
  EXPECT_LT(m.at("platform").at("final_error_cm").get<double>(), 1.0);
}

// Over a veth pair (root): two runs are byte-identical, and tshark reads every frame of the
// capture as EtherCAT, none malformed, with the commands of a scan, configuration and cycle.
TEST_F(CliEthercat, LockstepOverVethIsByteIdenticalAndDecodes) {
  if (const auto why = omnitwin::testing::VethPair::unavailable_reason()) GTEST_SKIP() << *why;
  const fs::path a = dir_ / "a", b = dir_ / "b";
  const Finished fa = run_short(a, "veth");
  const Finished fb = run_short(b, "veth");
  const nlohmann::json m = metrics(a);
  expect_clean_run(fa, m);
  EXPECT_TRUE(m.at("bus").at("transport").get<std::string>().starts_with("raw:"));
  EXPECT_EQ(read_bytes(a / "trajectory.csv"), read_bytes(b / "trajectory.csv"));
  EXPECT_EQ(read_bytes(a / "bus-ethercat.pcap"), read_bytes(b / "bus-ethercat.pcap"));
  if (std::system("command -v tshark >/dev/null 2>&1") != 0) GTEST_SKIP() << "tshark is not installed";
  const std::string pcap = (a / "bus-ethercat.pcap").string();
  const fs::path cmds = dir_ / "cmds.txt", bad = dir_ / "bad.txt";
  ASSERT_EQ(std::system(("tshark -r " + pcap + " -T fields -e ecat.cmd > " + cmds.string() + " 2>/dev/null").c_str()), 0);
  ASSERT_EQ(std::system(("tshark -r " + pcap + " -Y '_ws.malformed || _ws.expert.severity >= error' > " +
                         bad.string() + " 2>/dev/null").c_str()), 0);
  const auto lines = lines_of(read_bytes(cmds));
  const nlohmann::json& bus = m.at("bus");
  // Every frame the master sent that reached the segment before the end, and every frame that
  // came back.
  EXPECT_EQ(lines.size(), bus.at("frames_rx").get<std::size_t>() - bus.at("in_flight").get<std::size_t>() +
                              bus.at("frames_tx").get<std::size_t>());
  EXPECT_TRUE(read_bytes(bad).empty()) << read_bytes(bad);
  const auto has = [&](const std::string& cmd) {
    return std::any_of(lines.begin(), lines.end(), [&](const std::string& l) { return contains(l, cmd); });
  };
  for (const char* cmd : {"0x07", "0x02", "0x04", "0x05", "0x0c"})  // BRD APWR FPRD FPWR LRW
    EXPECT_TRUE(has(cmd)) << "no datagram with command " << cmd;
  // Issue 20: the addresses in the capture are the ones on the wire: the master's frames from
  // its veth end's MAC (the run sets 00:00:5e:00:53:10, not the capture's stand-in :01 for
  // transports without addresses) to broadcast, the returned ones with the first slave's
  // marking (bit 1 of the first source byte).
  const fs::path macs = dir_ / "macs.txt";
  ASSERT_EQ(std::system(("tshark -r " + pcap + " -T fields -e eth.src -e eth.dst | sort | uniq -c > " + macs.string() +
                         " 2>/dev/null").c_str()), 0);
  const auto pairs = lines_of(read_bytes(macs));
  ASSERT_EQ(pairs.size(), 2u) << read_bytes(macs);
  EXPECT_TRUE(contains(read_bytes(macs), "00:00:5e:00:53:10\tff:ff:ff:ff:ff:ff")) << read_bytes(macs);
  EXPECT_TRUE(contains(read_bytes(macs), "02:00:5e:00:53:10\tff:ff:ff:ff:ff:ff")) << read_bytes(macs);
}

// EtherCAT over UDP on loopback (what a run uses without root) drives the same run.
// `omni-master shell` ends on SIGINT as the other programs do, with its end line and exit 0
// (no slaves answer here: it is the signal that matters). Its reader thread used to be started
// before SIGINT and SIGTERM were blocked, took the signal with the default action and killed the
// program without an end line (found in review). stdin is a pipe kept open, as a terminal is.
TEST_F(CliEthercat, TheShellEndsOnSigintWithItsEndLine) {
  const std::string cmd = "exec " + binary_path("controller/omni-master") + " shell --iface udp:127.0.0.1:47719 --config " +
                          source_path("tests/data/ethercat/drives_only.yaml") + " 0< <(sleep 8)";
  Child shell("/bin/bash", {"-c", cmd}, work(), io(), "shell-");
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (!contains(shell.err(), "EtherCAT master on") && shell.running() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(20ms);
  ASSERT_TRUE(contains(shell.err(), "EtherCAT master on")) << shell.err();
  std::this_thread::sleep_for(300ms);
  shell.signal(SIGINT);
  EXPECT_EQ(shell.wait(10s), 0) << shell.err();
  EXPECT_TRUE(contains(shell.err(), "end: state")) << shell.err();
}

TEST_F(CliEthercat, LockstepOverUdp) {
  const fs::path out = dir_ / "udp";
  const Finished f = run_short(out, "udp:127.0.0.1:47611");
  const nlohmann::json m = metrics(out);
  expect_clean_run(f, m);
  EXPECT_EQ(m.at("bus").at("transport"), "udp:127.0.0.1:47611");
  EXPECT_EQ(m.at("bus").at("dropouts"), 0);
}

// A delay fault on the returned frames: each frame it held reaches the master extra_ms late,
// also the last one when the fault ends on a tick. At its end every held reply was released
// at once, a frame early: a 7 ms delay lasting one 5 ms cycle never reached the master, and
// one of 0.2 s cost 39 frames where 40 came back late (found in review).
TEST_F(CliEthercat, EveryFrameADelayFaultHoldsComesBackLate) {
  for (const auto& [duration, lost] : {std::pair{"0.005", 1}, std::pair{"0.2", 40}}) {
    const fs::path out = dir_ / (std::string("delay") + duration);
    const Finished f = run({"run", test_scenario("ethercat_short.yaml"), "--out", out.string(), "--no-progress",
                            "--set", "duration=2.3", "--set",
                            std::string("faults=[{delay: {node: master, at: 2.0, duration: ") + duration +
                                ", extra_ms: 7}}]"});
    ASSERT_NE(f.code, 2) << f.err;
    EXPECT_EQ(metrics(out).at("master").at("lost_frames").get<int>(), lost) << duration;
  }
}

// Under a delay longer than a cycle the capture stays in time order: a held reply was written
// when it was processed, before the frames the master sent meanwhile (200 of 920 records
// backwards under a 12 ms delay; found in review). Nothing is lost on the way.
TEST_F(CliEthercat, TheCaptureIsInTimeOrderUnderALongDelay) {
  const fs::path out = dir_ / "order";
  const Finished f = run({"run", test_scenario("ethercat_short.yaml"), "--out", out.string(), "--no-progress", "--set",
                          "duration=2.3", "--set", "faults=[{delay: {node: master, at: 1.0, duration: 1.0, extra_ms: 12}}]"});
  ASSERT_NE(f.code, 2) << f.err;
  char err[PCAP_ERRBUF_SIZE];
  pcap_t* p = pcap_open_offline_with_tstamp_precision((out / "bus-ethercat.pcap").c_str(), PCAP_TSTAMP_PRECISION_NANO, err);
  ASSERT_NE(p, nullptr) << err;
  pcap_pkthdr* h = nullptr;
  const u_char* data = nullptr;
  long n = 0, backwards = 0;
  double prev = -1;
  while (pcap_next_ex(p, &h, &data) == 1) {
    const double t = static_cast<double>(h->ts.tv_sec) + static_cast<double>(h->ts.tv_usec) * 1e-9;
    if (t < prev) ++backwards;
    prev = t;
    ++n;
  }
  pcap_close(p);
  EXPECT_EQ(backwards, 0) << n << " records";
  const nlohmann::json m = metrics(out);
  // Every frame in both directions (a frame still in the line at the end is counted received
  // but not captured back: run-directory.md).
  EXPECT_GE(n + 1, m.at("bus").at("frames_rx").get<long>() + m.at("bus").at("frames_tx").get<long>());
}

// The sim-clock report names the master's state and stop reason in metrics.json; the
// EtherCAT master's own words (master-stats.json: state "stopped", a free-text stop reason)
// overwrote them, leaving stop_reason "" for a master that stopped on a lost segment.
TEST_F(CliEthercat, AStoppedMastersStopReasonInTheMetricsIsTheSimClocksByName) {
  const fs::path out = dir_ / "master-stop";
  const Finished f = run({"run", source_path("tests/regression/ethercat_master_stop.yaml"), "--out", out.string(), "--no-progress",
                          "--no-video", "--no-report"});
  ASSERT_NE(f.code, 3) << f.out << f.err;
  const nlohmann::json ms = metrics(out).at("master");
  EXPECT_EQ(ms.at("state"), "stopped") << ms.dump(2);
  EXPECT_EQ(ms.at("stop_reason"), "node_missing") << ms.dump(2);
  EXPECT_EQ(ms.at("stop_reason_code"), 1);
  EXPECT_TRUE(contains(ms.at("stats_stop_reason").get<std::string>(), "segment lost")) << ms.dump(2);
  EXPECT_FALSE(contains(f.out + f.err, "master stopped ()")) << f.out;
}

// Seed 001's 100 axes as a run (bus.ethercat.extra_axes): 13 multi-axis slaves behind the
// four wheel drives, brought to OP by omni-master beside them (17 slaves, expected WKC 12 +
// 39 = 51, the image overlapped in one frame), every cycle with its WKC, and the platform still
// follows its path.
TEST_F(CliEthercat, AHundredAxesOfSeed001RunBehindTheWheels) {
  const fs::path out = dir_ / "extra";
  const Finished f = run({"run", test_scenario("ethercat_short.yaml"), "--out", out.string(), "--no-progress", "--set",
                          "bus.extra_axes=100", "--set", "bus.startup=3.5"});
  ASSERT_EQ(f.code, 0) << f.out << f.err;
  const nlohmann::json m = metrics(out);
  const nlohmann::json& ms = m.at("master");
  EXPECT_EQ(ms.at("state"), "finished");
  EXPECT_EQ(ms.at("slaves"), 17);
  EXPECT_EQ(ms.at("expected_wkc"), 51);
  EXPECT_EQ(ms.at("last_wkc"), 51);
  EXPECT_EQ(ms.at("wkc_errors"), 0);
  EXPECT_EQ(m.at("bus").at("dropouts"), 0);
  EXPECT_LT(m.at("platform").at("final_error_cm").get<double>(), 1.0);
  const std::string log = read_bytes(out / "master.log");
  EXPECT_NE(log.find("process image: 1272 output bytes, 1296 input bytes, overlapped in 1296 bytes"), std::string::npos)
      << log;
}

// The same segment without the longer start-up: the master needs about 2.6 s to configure 13
// extra slaves at this 5 ms cycle, beyond the 1.5 s allowance, so with a short settle the run
// ends while it is on its way. The error against its plan is small all the same; what says
// the platform is not at the goal is path_done_s, which the run reports as −1.
TEST_F(CliEthercat, AMasterStillOnItsPathWhenTheRunEndsIsNotAtTheGoal) {
  const fs::path out = dir_ / "late";
  const Finished f = run({"run", test_scenario("ethercat_short.yaml"), "--out", out.string(), "--no-progress", "--set",
                          "bus.extra_axes=100", "--set", "settle=0.2", "--set", "expect.platform.path_done_s.min=0"});
  EXPECT_EQ(f.code, 1) << f.out << f.err;
  const nlohmann::json m = metrics(out);
  EXPECT_EQ(m.at("master").at("state"), "running");
  EXPECT_GT(m.at("master").at("path_origin_s").get<double>(), 1.5);
  EXPECT_DOUBLE_EQ(m.at("platform").at("path_done_s").get<double>(), -1.0);
  EXPECT_NE((f.out + f.err).find("platform.path_done_s"), std::string::npos) << f.out << f.err;
}

// SIGINT half-way through a long EtherCAT run: both processes end, exit 3, and the records
// stay whole — the capture decodes in tshark with no malformed frame and holds what the
// segment saw up to the stop.
TEST_F(CliEthercat, SigintHalfWayLeavesAValidCapture) {
  const fs::path out = dir_ / "long";
  Child c({"run", test_scenario("run_long_line.yaml"), "--bus", "ethercat", "--set", "bus.transport=udp:127.0.0.1:47615",
           "--out", out.string(), "--no-progress"},
          work(), io());
  const fs::path part = out / ".trajectory.csv.part";
  for (int i = 0; i < 1000 && !(fs::exists(part) && fs::file_size(part) > 300'000); ++i) std::this_thread::sleep_for(10ms);
  c.signal(SIGINT);
  ASSERT_EQ(c.wait(60s), 3) << c.out() << c.err();
  const nlohmann::json m = metrics(out);
  EXPECT_TRUE(m.at("interrupted").get<bool>());
  EXPECT_GT(m.at("sim_time_s").get<double>(), 1.0);
  if (std::system("command -v tshark >/dev/null 2>&1") != 0) GTEST_SKIP() << "tshark is not installed";
  const std::string pcap = (out / "bus-ethercat.pcap").string();
  const fs::path cmds = dir_ / "cmds.txt", bad = dir_ / "bad.txt";
  ASSERT_EQ(std::system(("tshark -r " + pcap + " -T fields -e ecat.cmd > " + cmds.string() + " 2>/dev/null").c_str()), 0);
  ASSERT_EQ(std::system(("tshark -r " + pcap + " -Y _ws.malformed > " + bad.string() + " 2>/dev/null").c_str()), 0);
  const nlohmann::json& bus = m.at("bus");
  // Out: every frame taken that reached the segment; back: every frame returned, sent or still
  // held for the grant the interrupt cut off.
  EXPECT_EQ(lines_of(read_bytes(cmds)).size(),
            bus.at("frames_rx").get<std::size_t>() - bus.at("in_flight").get<std::size_t>() +
                bus.at("frames_tx").get<std::size_t>() + bus.at("replies_held").get<std::size_t>());
  EXPECT_TRUE(read_bytes(bad).empty()) << read_bytes(bad);
}

// Seed 004's PP-TEST, as `omni-master --script`, against the twin alone in real time: the
// master configures the drives, the script switches drive 1 to PP, enables it and moves it
// to 1000 counts; the twin's drive really moves its wheel there.
TEST_F(CliEthercat, PpTestScriptReachesItsTarget) {
  const std::string iface = "udp:127.0.0.1:47612";
  Child twin({"twin", test_scenario("ethercat_short.yaml"), "--bus", "ethercat", "--set",
              "bus.transport=" + iface, "--set", "duration=60", "--out", (dir_ / "twin").string(), "--no-progress"},
             work(), io());
  // The twin says where a master connects once its segment is up.
  twin.wait_for_output("a master connects on");
  ASSERT_TRUE(contains(twin.out(), "a master connects on " + iface)) << twin.out() << twin.err();
  Child master(binary_path("controller/omni-master"),
               {"--bus", "ethercat", "--iface", iface, "--config",
                source_path("tests/data/ethercat/drives_only.yaml"), "--script",
                source_path("tests/data/ethercat/pp_test.fs")},
               work(), io(), "master-");
  const int code = master.wait(60s);
  EXPECT_EQ(code, 0) << master.out() << master.err();
  EXPECT_TRUE(contains(master.out() + master.err(), "target reached")) << master.out() << master.err();
  twin.signal(SIGINT);
  EXPECT_NE(twin.wait(30s), -1);
}

// Issue 19's reproducer: the twin killed under an external master. The master must notice
// the vanished segment (every cycle a lost frame and a WKC error), leave OP, stop its drives
// and say so in its statistics, instead of "running", operational and 0 WKC errors.
TEST_F(CliEthercat, ExternalMasterNoticesTheTwinVanishing) {
  const std::string iface = "udp:127.0.0.1:47613";
  Child twin({"twin", test_scenario("ethercat_short.yaml"), "--bus", "ethercat", "--set",
              "bus.transport=" + iface, "--set", "duration=60", "--out", (dir_ / "twin").string(), "--no-progress"},
             work(), io());
  twin.wait_for_output("a master connects on");
  ASSERT_TRUE(contains(twin.out(), "a master connects on " + iface)) << twin.out() << twin.err();
  const fs::path stats = dir_ / "master-stats.json";
  Child master(binary_path("controller/omni-master"),
               {"--bus", "ethercat", "--iface", iface, "--config", source_path("tests/data/ethercat/drives_only.yaml"),
                "--duration", "6", "--stats", stats.string()},
               work(), io(), "master-");
  std::this_thread::sleep_for(3s);  // the segment is in OP well before this
  twin.signal(SIGKILL);
  EXPECT_EQ(master.wait(30s), 0) << master.out() << master.err();
  const nlohmann::json m = nlohmann::json::parse(read_bytes(stats));
  EXPECT_EQ(m.at("state"), "stopped") << m.dump(2);
  EXPECT_EQ(m.at("operational"), false);
  EXPECT_EQ(m.at("segment_lost"), true);
  EXPECT_GT(m.at("wkc_errors").get<int>(), 500);  // about 3 s of 1 ms cycles without an answer
  EXPECT_GT(m.at("lost_frames").get<int>(), 500);
  EXPECT_TRUE(contains(m.at("stop_reason").get<std::string>(), "segment lost")) << m.dump(2);
  EXPECT_TRUE(contains(master.out() + master.err(), "segment lost")) << master.err();
}

// A master started again against `omnitwin twin` on UDP sends from a new port. Once the first
// has been silent for the handover time the new one is the twin's master: answered even with
// bus.refuse_foreign, none of its frames foreign, and the change counted and said.
TEST_F(CliEthercat, AMasterStartedAgainOnTheWallClockIsTheTwinsMaster) {
  const std::string iface = "udp:127.0.0.1:47614";
  Child twin({"twin", test_scenario("ethercat_short.yaml"), "--bus", "ethercat", "--set", "bus.transport=" + iface,
              "--set", "bus.refuse_foreign=true", "--set", "duration=60", "--out", (dir_ / "twin").string(),
              "--no-progress"},
             work(), io());
  ASSERT_TRUE(twin.wait_for_output("a master connects on")) << twin.out() << twin.err();
  for (const char* name : {"first", "again"}) {
    const fs::path stats = dir_ / (std::string(name) + ".json");
    Child master(binary_path("controller/omni-master"),
                 {"--bus", "ethercat", "--iface", iface, "--config", source_path("tests/data/ethercat/drives_only.yaml"),
                  "--duration", "1", "--stats", stats.string()},
                 work(), io(), std::string(name) + "-");
    EXPECT_EQ(master.wait(30s), 0) << master.out() << master.err();
    const nlohmann::json m = nlohmann::json::parse(read_bytes(stats));
    EXPECT_TRUE(m.at("operational").get<bool>()) << name << ": " << m.dump(2);
    // Answered to the end (a host stall may cost a cycle's WKC on the wall clock; refused, it
    // would never have reached OP).
    EXPECT_EQ(m.at("last_wkc"), m.at("expected_wkc")) << name << ": " << m.dump(2);
    std::this_thread::sleep_for(std::chrono::nanoseconds(kMasterHandoverNs) + 100ms);
  }
  twin.signal(SIGINT);
  EXPECT_NE(twin.wait(30s), -1);
  const nlohmann::json b = nlohmann::json::parse(read_bytes(dir_ / "twin" / "metrics.json")).at("bus");
  EXPECT_EQ(b.at("master_changes"), 1) << b.dump(2);
  EXPECT_EQ(b.at("foreign_frames"), 0) << b.dump(2);
  EXPECT_EQ(b.at("refused_frames"), 0) << b.dump(2);
  EXPECT_TRUE(contains(twin.out(), "a new sender was taken for the master 1 time(s)")) << twin.out();
}

// Issue 16 item 7: the twin takes the first sender as the master. Frames from a second one (a
// second UDP socket here, as another program on the machine would be) are counted in
// bus.foreign_frames; with bus.refuse_foreign: true they get no answer and are counted as
// refused, while the master is answered throughout.
class ForeignSender : public CliEthercat {
 protected:
  struct Peer {
    int fd = -1;
    ~Peer() {
      if (fd >= 0) ::close(fd);
    }
  };
  // One BRD to 127.0.0.1:port from `p`; true when an answer came back within 1 s.
  static bool exchange(const Peer& p, int port) {
    std::array<std::uint8_t, omnitwin::ethercat::kMaxPdu> buf{};
    omnitwin::ethercat::PduBuilder b(buf);
    const std::uint8_t two[2] = {0, 0};
    b.add(omnitwin::ethercat::Cmd::brd, 1, 0, 0x0000, 2, two);
    const std::size_t n = b.finish();
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(static_cast<std::uint16_t>(port));
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::sendto(p.fd, buf.data(), n, 0, reinterpret_cast<const sockaddr*>(&to), sizeof to) != static_cast<ssize_t>(n))
      return false;
    pollfd pfd{p.fd, POLLIN, 0};
    if (::poll(&pfd, 1, 1000) != 1) return false;
    return ::recv(p.fd, buf.data(), buf.size(), 0) > 0;
  }
  nlohmann::json run_with_two_senders(const std::string& refuse, int port, int& master_answers, int& foreign_answers) {
    const fs::path out = dir_ / ("twin-" + refuse);
    Child twin({"twin", test_scenario("ethercat_short.yaml"), "--bus", "ethercat", "--set",
                "bus.transport=udp:127.0.0.1:" + std::to_string(port), "--set", "bus.refuse_foreign=" + refuse,
                "--out", out.string(), "--no-progress", "--no-video", "--no-report"},
               work(), io());
    twin.wait_for_output("a master connects on");
    EXPECT_TRUE(contains(twin.out(), "a master connects on")) << twin.out() << twin.err();
    Peer master, other;
    master.fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    other.fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    master_answers = foreign_answers = 0;
    // First a mailbox-gateway frame (EtherCAT header type 5): not for the slaves, dropped and
    // counted in bus.other_pdu_types (raw: it vanished uncounted in the kernel's filter).
    std::array<std::uint8_t, 16> gateway{};
    gateway[0] = 0x0e;
    gateway[1] = 0x50;
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(static_cast<std::uint16_t>(port));
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::sendto(master.fd, gateway.data(), gateway.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to),
              static_cast<ssize_t>(gateway.size()));
    for (int k = 0; k < 5; ++k) {
      master_answers += exchange(master, port) ? 1 : 0;
      foreign_answers += exchange(other, port) ? 1 : 0;
    }
    twin.signal(SIGINT);
    EXPECT_NE(twin.wait(30s), -1);
    return metrics(out);
  }
};

TEST_F(ForeignSender, ASecondSenderIsCountedAndRefusedWhenAsked) {
  int master = 0, foreign = 0;
  nlohmann::json m = run_with_two_senders("false", 47621, master, foreign);
  EXPECT_EQ(master, 5);
  EXPECT_EQ(foreign, 5);  // counted, still answered
  EXPECT_EQ(m.at("bus").at("foreign_frames"), 5);
  EXPECT_EQ(m.at("bus").at("refused_frames"), 0);
  EXPECT_EQ(m.at("bus").at("other_pdu_types"), 1);
  m = run_with_two_senders("true", 47622, master, foreign);
  EXPECT_EQ(master, 5);
  EXPECT_EQ(foreign, 0);
  EXPECT_EQ(m.at("bus").at("foreign_frames"), 5);
  EXPECT_EQ(m.at("bus").at("refused_frames"), 5);
}

}  // namespace
}  // namespace omnitwin::twin::cli
