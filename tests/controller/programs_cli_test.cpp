// Tests the master-side programs' command lines (omni-master, omni-pc, omni-tml) as a user
// runs them: the checks a review found missing. omni-tml send --group with a group number
// over 8 (a broadcast to every drive) and an unsupported --baud (abort / silently 9600);
// omni-pc --node out of range (silently the default target); time options that are NaN,
// negative or too large for the ns deadlines; a bad --sim-clock address on every bus; Ctrl-C
// while waiting for the twin's sim-clock socket; a --stats file that cannot be written; and
// --script with another bus or a directory. Each is exit 2 with a short message (3 for
// --stats; 0 for the signal, as for any signal), within a second or two; --sim-clock with the wall clock
// on every bus, and --stats on bus can. omni-tml send on CAN prints only the answer to its
// query (not a running master's traffic), and names the recovery of its link; omni-tml drive
// counts every drive on its line and its relay at the end. A signal in
// lockstep: the Omni master's NMT stop goes out in the next granted tick. omni-pc detect with
// no node on the bus says so (exit 1). UDP ports 48310-48321.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <stdlib.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "bus_emulators/can/transport.hpp"
#include "controller/sim_clock.hpp"
#include "tests/twin/cli_support.hpp"

namespace omnitwin::controller {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using twin::cli::Child;
using twin::cli::contains;
using testing::binary_path;
using testing::source_path;
using testing::TempDir;

constexpr const char* kCanIface = "udp:239.74.163.9:48310";

class ProgramsCli : public ::testing::Test {
 protected:
  struct Result {
    int code;
    std::string err, out;
  };
  // Runs controller/PROGRAM with `args`; -1 when it has not ended within `limit`.
  Result run(const std::string& program, const std::vector<std::string>& args, std::chrono::milliseconds limit = 3s) {
    Child c(binary_path("controller/" + program), args, dir_.path(), dir_.path(), "p" + std::to_string(++n_));
    const int code = c.wait(limit);
    return {code, c.err(), c.out()};
  }
  // Exit 2 and a one-line message holding `part`, not CLI11's range text with DBL_MAX in full.
  void expect_usage(const Result& r, const std::string& part) {
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_TRUE(contains(r.err, part)) << r.err;
    EXPECT_LT(r.err.size(), 200u) << r.err;
  }
  static std::string data(const std::string& rel) { return source_path("tests/data/" + rel); }
  // {bus, its master configuration, an address} for each of omni-master's five buses.
  static std::vector<std::vector<std::string>> every_bus() {
    return {{"can", data("master/loopback.yaml"), kCanIface},
            {"canopen", data("canopen/drives_only.yaml"), kCanIface},
            {"tml", data("tml/drives_only.yaml"), kCanIface},
            {"ethercat", data("ethercat/drives_only.yaml"), "udp:127.0.0.1:48311"},
            {"m3", data("m3/servos_only.yaml"), "udp:127.0.0.1:48312"}};
  }

  TempDir dir_{"omni-programs-cli"};
  int n_ = 0;
};

// omni-pc detect on a bus where no node answers: exit 1, as documented, and a line saying so
// (it printed nothing at all; found by a walkthrough of the docs).
TEST_F(ProgramsCli, PcDetectWithNoNodeSaysSo) {
  const Result r = run("omni-pc", {"--iface", "udp:239.74.163.9:48321", "detect", "--timeout-ms", "100"});
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_TRUE(contains(r.err, "no node answered the detection request within 100 ms on udp:239.74.163.9:48321"))
      << r.err;
  EXPECT_EQ(r.out, "");
}

// Found in review: run_send lacked encode's check; group_mask(9) is 0, a broadcast.
TEST_F(ProgramsCli, TmlSendRefusesAGroupNumberOver8) {
  const std::vector<std::string> line{"send", "-p", "rs485", "--port", "/dev/null", "--timeout-ms", "50"};
  auto args = line;
  args.insert(args.end(), {"--group", "-a", "9", "KPP=5"});
  expect_usage(run("omni-tml", args), "group number 1-8");
  args = line;
  args.insert(args.end(), {"--group", "KPP=5"});  // the default --axis 255
  expect_usage(run("omni-tml", args), "group number 1-8");
}

// Found in review: encode predicted the answer to axis 0 "from 0000"; every drive that takes
// axis 0 answers with its own axis ID, and on RS-485 the answers (and the 'O's) would collide.
TEST_F(ProgramsCli, TmlEncodeDoesNotPredictAnAnswerFromAxis0) {
  expect_usage(run("omni-tml", {"encode", "-p", "rs485", "-a", "0", "?KPP"}), "axis 0");
  Result r = run("omni-tml", {"encode", "-p", "rs485", "-a", "0", "KPP=5"});
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "expect:    nothing")) << r.out;
  for (const std::string p : {"rs232", "tmlcan"}) {
    r = run("omni-tml", {"encode", "-p", p, "-a", "0", "?KPP"});
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "give --from N")) << r.out;
  }
  r = run("omni-tml", {"encode", "-p", "rs232", "-a", "0", "--from", "3", "--value", "5", "?KPP"});
  EXPECT_TRUE(contains(r.out, "0A 0F F1 B4 04 00 30 02 5E 00 05")) << r.out;
}

// Found in review: --baud 0 aborted (exit 134), 4800 opened the port at 9600.
TEST_F(ProgramsCli, TmlTakesOnlyTheSupportedBaudRates) {
  expect_usage(run("omni-tml", {"drive", "--baud", "0", "--duration", "0"}), "--baud");
  expect_usage(run("omni-tml", {"send", "-p", "rs232", "--port", "/dev/null", "--baud", "4800", "--timeout-ms", "50",
                                "KPP=5"}),
               "--baud");
}

// Found in review: -1 meant "not given", so --node -7 sent NMT to the default target.
TEST_F(ProgramsCli, PcRefusesANodeOutOfRange) {
  expect_usage(run("omni-pc", {"--iface", kCanIface, "start", "--node", "-7"}), "--node");
  expect_usage(run("omni-pc", {"--iface", kCanIface, "stop", "--node", "256"}), "--node");
  // Found in review: a slave setting over 0xFFFF was sent (exit 0) and the master refused it.
  expect_usage(run("omni-pc", {"--iface", kCanIface, "param", "70000"}), "0..65535");
}

// Found in review: 1e10 s overflowed the int64 ns deadline (the run ended at once), NaN ran
// until a signal, a negative timeout was taken.
TEST_F(ProgramsCli, TimeOptionsMustBeFiniteNonNegativeAndBounded) {
  const std::string cfg = data("master/loopback.yaml");
  for (const std::string v : {"1e10", "nan", "-1", "inf"})
    expect_usage(run("omni-master", {"--config", cfg, "--iface", kCanIface, "--duration", v}), "--duration");
  expect_usage(run("omni-master", {"--bus", "canopen", "--config", data("canopen/drives_only.yaml"), "--iface",
                                   kCanIface, "--duration", "1e10"}),
               "--duration");
  expect_usage(run("omni-pc", {"--iface", kCanIface, "monitor", "--seconds", "1e10"}), "--seconds");
  for (const std::string v : {"1e10", "nan"})
    expect_usage(run("omni-tml", {"drive", "--duration", v}), "--duration");
  for (const std::string v : {"-100", "nan"})
    expect_usage(run("omni-tml", {"send", "-p", "tmlcan", "--iface", kCanIface, "--timeout-ms", v, "KPP=5"}),
                 "--timeout-ms");
}

// Found in review: only --bus can parsed the address up front; the others failed to connect (3).
TEST_F(ProgramsCli, ABadSimClockAddressIsUsageOnEveryBus) {
  for (const auto& b : every_bus()) {
    SCOPED_TRACE(b[0]);
    expect_usage(run("omni-master", {"--bus", b[0], "--config", b[1], "--iface", b[2], "--clock", "sim", "--sim-clock",
                                     "tcp:localhost"}),
                 "expected unix:PATH");
  }
}

// Found in review: --sim-clock with --clock wall was refused on bus can only; the other four
// ran on the wall clock and ignored the address.
TEST_F(ProgramsCli, ASimClockAddressWithTheWallClockIsUsageOnEveryBus) {
  for (const auto& b : every_bus()) {
    SCOPED_TRACE(b[0]);
    expect_usage(run("omni-master", {"--bus", b[0], "--config", b[1], "--iface", b[2], "--clock", "wall", "--sim-clock",
                                     "unix:/tmp/x.sock", "--duration", "0.05"}),
                 "--sim-clock is only used with --clock sim");
  }
}

// Found in review: --stats was silently ignored on bus can (the help named the other four).
TEST_F(ProgramsCli, TheOmniCanMasterWritesItsStatsToo) {
  const fs::path stats = dir_.path() / "can-stats.json";
  const Result r = run("omni-master", {"--bus", "can", "--config", data("master/loopback.yaml"), "--iface",
                                       "udp:239.74.163.9:48317", "--duration", "0.1", "--stats", stats.string()});
  EXPECT_EQ(r.code, 0) << r.err;
  ASSERT_TRUE(fs::exists(stats)) << r.err;
  std::ifstream in(stats);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(contains(text, "\"ticks\":")) << text;
  EXPECT_TRUE(contains(text, "\"detection_requests\":")) << text;
  EXPECT_TRUE(contains(text, "\"state\":")) << text;
}

// Found in review: SIGINT/SIGTERM are blocked for the signalfd, and the connect retry slept
// through them for up to 10 s. Now the wait ends at once and the program exits as on a signal.
TEST_F(ProgramsCli, CtrlCEndsTheWaitForTheSimClockSocket) {
  const std::string sock = "unix:" + (dir_.path() / "nobody.sock").string();
  const std::vector<std::vector<std::string>> buses{{"can", data("master/loopback.yaml"), "udp:239.74.163.9:48313"},
                                                    {"canopen", data("canopen/drives_only.yaml"), "udp:239.74.163.9:48314"}};
  for (const auto& b : buses) {
    SCOPED_TRACE(b[0]);
    Child c(binary_path("controller/omni-master"),
            {"--bus", b[0], "--config", b[1], "--iface", b[2], "--clock", "sim", "--sim-clock", sock}, dir_.path(),
            dir_.path(), "sig" + b[0]);
    // Both log their start line right around opening the signalfd; then give it a moment.
    const auto until = std::chrono::steady_clock::now() + 3s;
    while (!contains(c.err(), "info:") && c.running() && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(10ms);
    std::this_thread::sleep_for(200ms);
    ASSERT_TRUE(c.running()) << c.err();
    c.signal(SIGINT);
    EXPECT_EQ(c.wait(2s), 0) << c.err();
  }
}

// Found in review: on a signal in lockstep the Omni master sent NMT stop after its loop had
// ended, outside any granted tick: the twin never took it off the transport (it counted one
// frame fewer than the master had sent) and the capture had no NMT stop. It now goes out in
// the next tick the twin grants, counted in that tick's Done.
TEST_F(ProgramsCli, ASignalInLockstepSendsTheOmniMastersNmtStopInTheNextGrantedTick) {
  const std::string iface = "udp:239.74.163.9:48320";
  const std::unique_ptr<can::Transport> bus = can::open_transport(iface);
  ASSERT_TRUE(bus);
  const std::string sock = "unix:" + (dir_.path() / "clock.sock").string();
  simclock::Server server(sock);
  Child c(binary_path("controller/omni-master"),
          {"--bus", "can", "--config", data("master/loopback.yaml"), "--iface", iface, "--clock", "sim", "--sim-clock", sock},
          dir_.path(), dir_.path(), "omni-lockstep-signal");
  ASSERT_EQ(server.accept(5s), simclock::WaitStatus::ok) << c.err();
  simclock::Done d;
  ASSERT_EQ(server.grant(simclock::Grant{1, 10'000'000, {}}, d, 2s), simclock::WaitStatus::ok) << c.err();
  const std::uint64_t before = d.frames[0];
  c.signal(SIGTERM);
  std::this_thread::sleep_for(300ms);  // the master reads the signal while it awaits its grant
  ASSERT_EQ(server.grant(simclock::Grant{2, 20'000'000, {}}, d, 2s), simclock::WaitStatus::ok)
      << "the master left without an end tick: " << c.err();
  EXPECT_EQ(d.frames[0], before + 1) << "the NMT stop, counted in the Done so the twin delivers it";
  EXPECT_EQ(c.wait(3s), 0) << c.err();
  bool nmt_stop = false;
  can::wait_readable(*bus, 500ms);
  while (auto tf = bus->receive())
    nmt_stop = nmt_stop || (tf->frame.id == 0 && tf->frame.dlc == 2 && tf->frame.data[0] == 0 && tf->frame.data[1] == 0x02);
  EXPECT_TRUE(nmt_stop) << "NMT stop all (00 02, omni-can.md) on the bus";
}

// Found in review: an unwritable --stats logged "cannot write" and exited 0, and a failed
// rename left PATH.tmp behind.
TEST_F(ProgramsCli, AStatsFileThatCannotBeWrittenIsExit3WithoutAStrayTempFile) {
  const std::string cfg = data("canopen/drives_only.yaml");
  const fs::path missing = dir_.path() / "no-such-dir" / "stats.json";
  Result r = run("omni-master", {"--bus", "canopen", "--config", cfg, "--iface", "udp:239.74.163.9:48315",
                                 "--duration", "0.05", "--stats", missing.string()});
  EXPECT_EQ(r.code, 3) << r.err;
  EXPECT_TRUE(contains(r.err, "cannot write")) << r.err;
  const fs::path dir = dir_.path() / "a-directory";  // path.tmp is written, the rename fails
  fs::create_directories(dir);
  r = run("omni-master", {"--bus", "canopen", "--config", cfg, "--iface", "udp:239.74.163.9:48315", "--duration",
                          "0.05", "--stats", dir.string()});
  EXPECT_EQ(r.code, 3) << r.err;
  EXPECT_FALSE(fs::exists(dir.string() + ".tmp"));
}

// Found by a walkthrough: on the wall clock with no drives on the bus, the CANopen master's
// start-up failed after its timeout, and the program ran on until killed. It now ends the run
// (exit 3) once its core has failed.
TEST_F(ProgramsCli, AFailedStartUpEndsAWallClockRun) {
  const Result r = run("omni-master", {"--bus", "canopen", "--config", data("canopen/drives_only.yaml"), "--iface",
                                       "udp:239.74.163.9:48322"},
                       20s);
  EXPECT_EQ(r.code, 3) << r.err;
  EXPECT_TRUE(contains(r.err, "the master failed: ending the run")) << r.err;
}

// Found in review: --script switched any --bus to EtherCAT, and a directory ran as an empty script.
TEST_F(ProgramsCli, ScriptNeedsTheEthercatBusAndAFile) {
  expect_usage(run("omni-master", {"--bus", "canopen", "--config", data("canopen/drives_only.yaml"), "--iface",
                                   kCanIface, "--script", data("ethercat/pp_test.fs")}),
               "--script needs --bus ethercat");
  expect_usage(run("omni-master", {"--bus", "ethercat", "--config", data("ethercat/drives_only.yaml"), "--iface",
                                   "udp:127.0.0.1:48316", "--script", dir_.path().string(), "--duration", "0.5"}),
               "a directory");
}

// A TMLCAN frame written by hand (seed ch. 4: opcode[15:9] in 28-22, the ID code's GROUP, ID and
// HOST bits in 21-9, opcode[8:0] in 8-0; words low byte first).
can::Frame tmlcan_frame(std::uint16_t opcode, std::uint16_t id_code, std::initializer_list<std::uint16_t> words) {
  can::Frame f;
  f.extended = true;
  f.id = static_cast<std::uint32_t>(opcode >> 9) << 22 | static_cast<std::uint32_t>(id_code & 0x1FF1) << 9 | (opcode & 0x1FFu);
  for (const std::uint16_t w : words) {
    f.data[f.dlc++] = static_cast<std::uint8_t>(w);
    f.data[f.dlc++] = static_cast<std::uint8_t>(w >> 8);
  }
  return f;
}

// Found in review: on CAN, `send` took any TakeData/TakeData2 on the bus for its answer: beside
// a running master, `?KPP` to an axis that does not exist printed the master's APOS answers as
// "received" and exited 0. Only the TakeData of KPP from axis 9 to host 100 answers it.
TEST_F(ProgramsCli, TmlSendOnCanTakesOnlyTheAnswerToItsQuery) {
  const std::string iface = "udp:239.74.163.9:48318";
  const std::unique_ptr<can::Transport> bus = can::open_transport(iface);
  std::atomic<bool> stop{false}, answer{false};
  std::thread traffic([&] {
    const std::uint16_t host = 100 << 4, master = 120 << 4, axis1 = 1 << 4, axis9 = 9 << 4;
    while (!stop) {
      bus->send(tmlcan_frame(0xD501, master, {0x0228, 0x1234, 0x0000}), 0);       // axis 1's APOS to a master
      bus->send(tmlcan_frame(0xB404, host, {axis1, 0x025E, 0x0120}), 0);          // KPP, but from axis 1
      bus->send(tmlcan_frame(0xB404, host, {axis9, 0x022A, 0x0002}), 0);          // axis 9, but POSERR
      bus->send(tmlcan_frame(0xB405, host, {axis9, 0x025E, 0x0120, 0x0000}), 0);  // axis 9, KPP, but 32-bit
      bus->send(tmlcan_frame(0xB404, master, {axis9, 0x025E, 0x0120}), 0);        // axis 9, KPP, to another host
      if (answer) bus->send(tmlcan_frame(0xB404, host, {axis9, 0x025E, 0x0120}), 0);  // the answer
      std::this_thread::sleep_for(2ms);
    }
  });
  const std::vector<std::string> args{"send", "-p", "tmlcan", "--iface", iface, "--axis", "9", "--host", "100",
                                      "--timeout-ms", "150", "?KPP"};
  const Result none = run("omni-tml", args);
  answer = true;
  const Result one = run("omni-tml", args);
  stop = true;
  traffic.join();
  EXPECT_EQ(none.code, 3) << none.out;
  EXPECT_FALSE(contains(none.out, "received:")) << none.out;
  EXPECT_TRUE(contains(none.out, "no answer")) << none.out;
  EXPECT_EQ(one.code, 0) << one.out;
  EXPECT_TRUE(contains(one.out, "received:  168C8004#90005E022001")) << one.out;
  EXPECT_FALSE(contains(one.out, "POSERR")) << one.out;
}

// Found in review: on RS-485 a lost 'O' was reported as "SYNC bytes echoed", but no RS-485 drive
// echoes SYNC (the host sends 15 and resends). A pseudo-terminal where nobody answers.
TEST_F(ProgramsCli, TmlSendNamesTheSyncRecoveryOfItsLink) {
  const int line = ::posix_openpt(O_RDWR | O_NOCTTY);
  ASSERT_GE(line, 0);
  ASSERT_EQ(::grantpt(line), 0);
  ASSERT_EQ(::unlockpt(line), 0);
  const std::string port = ::ptsname(line);
  const Result r = run("omni-tml", {"send", "-p", "rs485", "--port", port, "--axis", "1", "--host", "15",
                                    "--timeout-ms", "50", "KPP=5"});
  ::close(line);
  EXPECT_EQ(r.code, 3) << r.out;
  EXPECT_TRUE(contains(r.out, "15 SYNC bytes sent, command sent again")) << r.out;
  EXPECT_FALSE(contains(r.out, "echo")) << r.out;
}

// `omni-tml drive`'s end counts each drive on its RS-485 line and what its RS-232 relay axis
// carried to CAN. It said "0 messages handled" after exchanges with a dropped drive or through
// the relay, counting only its own axis (found in a docs walkthrough).
TEST_F(ProgramsCli, TmlDriveEndCountsEveryDriveOnTheLineAndTheRelay) {
  // A drive for 1.5 s, and the pseudo-terminal it names in its first line ("… on /dev/pts/N…").
  const auto start_drive = [this](std::vector<std::string> args, const std::string& tag, std::string& port) {
    args.insert(args.end(), {"--duration", "1.5"});
    auto c = std::make_unique<Child>(binary_path("controller/omni-tml"), args, dir_.path(), dir_.path(), tag);
    c->wait_for_output("or Ctrl-C)");  // with --duration: "(ends after 1.5 s, or Ctrl-C)"
    const std::string banner = c->out();
    EXPECT_TRUE(contains(banner, "(ends after 1.5 s, or Ctrl-C)")) << banner;
    const std::size_t on = banner.find(" on /dev/pts/");
    port = on == std::string::npos ? "" : banner.substr(on + 4, banner.find_first_of(", ", on + 4) - on - 4);
    return c;
  };
  std::string port;
  const auto line = start_drive({"drive", "-p", "rs485", "--axis", "1", "--host", "15", "--drop", "3"}, "line-", port);
  ASSERT_FALSE(port.empty()) << line->out() << line->err();
  const Result dropped = run("omni-tml", {"send", "-p", "rs485", "--port", port, "--axis", "3", "--host", "15",
                                          "--timeout-ms", "500", "?KPP"});
  EXPECT_EQ(dropped.code, 0) << dropped.out << dropped.err;
  EXPECT_EQ(line->wait(10s), 0) << line->out() << line->err();
  EXPECT_TRUE(contains(line->out(), "omni-tml: drive end, axis 3 (drop): 1 messages handled, 1 answers")) << line->out();
  // The relay: a write for axis 7 goes onto CAN (nobody answers there).
  const auto relay = start_drive(
      {"drive", "-p", "rs232", "--axis", "20", "--host", "20", "--relay", "udp:239.74.163.9:48319"}, "relay-", port);
  ASSERT_FALSE(port.empty()) << relay->out() << relay->err();
  const Result relayed = run("omni-tml", {"send", "-p", "rs232", "--port", port, "--axis", "7", "--host", "20",
                                          "--timeout-ms", "300", "KPP=5"});
  EXPECT_EQ(relayed.code, 0) << relayed.out << relayed.err;
  EXPECT_EQ(relay->wait(10s), 0) << relay->out() << relay->err();
  EXPECT_TRUE(contains(relay->out(), "omni-tml: relay end: 1 messages onto CAN")) << relay->out();
}

}  // namespace
}  // namespace omnitwin::controller
