// controller programs — `omni-pc`: the thesis's PC monitor node (node 0x01, the USB-CAN
// analyser of seed 002, 4-4-1) as a command-line tool.
//
// The PC's part in table 4-2: node detection, NMT start/stop of the master or the slaves,
// the slave controller setting sent to the master (0x702 type 0x0C), and watching the bus.
// One subcommand per action; frames are built and read only through the Omni codec. A tool,
// not a cyclic path: it blocks on the transport with timeouts and may allocate freely.
// SIGINT/SIGTERM end `monitor` (and `detect`) early through a signalfd.
// Exit codes: 0 ok; 1 detect: no node answered; 2 bad usage or transport spec/interface;
// 3 the transport refused a frame.
#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <poll.h>
#include <signal.h>
#include <sys/signalfd.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <variant>

#include "bus_emulators/can/transport.hpp"
#include "controller/program_support.hpp"
#include "controller/programs/cli_checks.hpp"
#include "bus_emulators/omni/omni_codec.hpp"

using namespace omnitwin;
using controller::normalize_iface;
using controller::open_signal_fd;
namespace node = omni::node;

namespace {

constexpr int kExitOk = 0;
constexpr int kExitNoAnswer = 1;
constexpr int kExitUsage = 2;
constexpr int kExitRuntime = 3;
constexpr const char* kDefaultIface = "udp:239.74.163.2:43113";

struct Options {
  std::string iface = kDefaultIface;
  int timeout_ms = 300;          // detect: how long to collect answers [ms]
  int node = -1;                 // start/stop target; -1 = the subcommand's default
  std::int64_t value = 0;        // param value
  int data_type = omni::data_type::slave_controller_setting;  // param data type
  double seconds = -1;           // monitor: stop after S seconds; < 0: until a signal
  std::int64_t count = -1;       // monitor: stop after N frames; < 0: no limit
};

std::int64_t monotonic_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}


// The role of a node id, for humans.
std::string role_of(std::uint8_t n) {
  if (n == node::all) return "all";
  if (n == node::pc) return "pc";
  if (n == node::master) return "master";
  if (const int axis = omni::axis_of_slave(n)) return fmt::format("slave axis {}", axis);
  return "unknown";
}

// One decoded message as "name field=value …".
std::string describe(const omni::Message& m) {
  if (const auto* c = std::get_if<omni::NmtCommand>(&m)) {
    return fmt::format("NMT {} target=0x{:02X} ({})", c->state == omni::NmtState::start ? "start" : "stop", c->target,
                       role_of(c->target));
  }
  if (std::holds_alternative<omni::DetectionRequest>(m)) return "detection request";
  if (const auto* a = std::get_if<omni::DetectionAnswer>(&m)) {
    return fmt::format("detection answer node=0x{:02X} ({})", a->node, role_of(a->node));
  }
  if (const auto* c = std::get_if<omni::SpeedCommand>(&m)) {
    return fmt::format("speed command from=0x{:02X} axis1={} axis2={} axis3={} axis4={} [counts/sample]", c->sender,
                       c->axis[0], c->axis[1], c->axis[2], c->axis[3]);
  }
  if (const auto* f = std::get_if<omni::SpeedFeedback>(&m)) {
    return fmt::format("speed feedback axis {} from=0x{:02X} type=0x{:02X} value={}", omni::axis_of_slave(f->sender),
                       f->sender, f->data_type, f->value);
  }
  const auto& p = std::get<omni::ParameterSetup>(m);
  return fmt::format("parameter set-up 0x{:02X} -> 0x{:02X} ({}) type=0x{:02X} value={}", p.sender, p.receiver,
                     role_of(p.receiver), p.data_type, p.value);
}

// Encodes and sends one message: kExitOk, kExitUsage (not a valid Omni message, e.g. an
// NMT target that is no node) or kExitRuntime (the transport refused it); message printed.
int send(can::Transport& tr, const omni::Message& m) {
  const omni::EncodeResult r = omni::encode(m);
  if (const auto* e = std::get_if<omni::EncodeError>(&r)) {
    std::cerr << "omni-pc: cannot send " << describe(m) << ": " << omni::to_string(*e) << "\n";
    return kExitUsage;
  }
  if (!tr.send(std::get<can::Frame>(r))) {
    std::cerr << "omni-pc: the transport refused " << can::to_string(std::get<can::Frame>(r)) << "\n";
    return kExitRuntime;
  }
  return kExitOk;
}

// Waits up to `left_ns` for a frame or a signal; nullopt on timeout or signal (*stop set).
std::optional<can::TimedFrame> next_frame(can::Transport& tr, int sigfd, std::int64_t left_ns, bool& stop) {
  if (auto f = tr.receive()) return f;
  pollfd fds[2] = {{tr.poll_fd(), POLLIN, 0}, {sigfd, POLLIN, 0}};
  const std::int64_t ns = std::max<std::int64_t>(0, left_ns);
  const timespec timeout{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
  if (::ppoll(fds, 2, &timeout, nullptr) > 0 && (fds[1].revents & POLLIN)) stop = true;
  return stop ? std::nullopt : tr.receive();
}

// ---------------------------------------------------------------------------------------
// Subcommands

int cmd_detect(can::Transport& tr, const Options& o, int sigfd) {
  if (const int code = send(tr, omni::DetectionRequest{}); code != kExitOk) return code;
  std::set<std::uint8_t> seen;
  const std::int64_t end = monotonic_ns() + std::int64_t{o.timeout_ms} * 1'000'000;
  bool stop = false;
  while (!stop && monotonic_ns() < end) {
    const auto tf = next_frame(tr, sigfd, end - monotonic_ns(), stop);
    if (!tf) continue;
    const omni::DecodeResult r = omni::decode(tf->frame);
    const auto* m = std::get_if<omni::Message>(&r);
    const auto* a = m ? std::get_if<omni::DetectionAnswer>(m) : nullptr;
    if (a == nullptr || !seen.insert(a->node).second) continue;
    std::cout << fmt::format("0x{:02X} {}\n", a->node, role_of(a->node)) << std::flush;
  }
  if (seen.empty() && !stop)
    std::cerr << fmt::format("omni-pc: no node answered the detection request within {} ms on {}\n", o.timeout_ms,
                             tr.spec());
  return seen.empty() ? kExitNoAnswer : kExitOk;
}

int cmd_nmt(can::Transport& tr, const Options& o, omni::NmtState state) {
  const int target = o.node >= 0 ? o.node : (state == omni::NmtState::start ? node::master : node::all);
  if (target < 0 || target > 0xFF) {
    std::cerr << "omni-pc: --node must be a node id 0..255\n";
    return kExitUsage;
  }
  return send(tr, omni::NmtCommand{static_cast<std::uint8_t>(target), state});
}

int cmd_param(can::Transport& tr, const Options& o) {
  if (o.value < 0 || o.value > 0xFFFFFFFFLL || o.data_type < 0 || o.data_type > 0xFF) {
    std::cerr << "omni-pc: VALUE must be 0..4294967295 and --type 0..255\n";
    return kExitUsage;
  }
  // The slaves' setting (0x0C) travels on as a 2-byte value: the master refuses a larger one,
  // which was sent with exit 0 (found in review).
  if (o.data_type == omni::data_type::slave_controller_setting && o.value > 0xFFFF) {
    std::cerr << "omni-pc: VALUE of a slave setting (--type 0x0C) must be 0..65535: the master forwards 2 bytes\n";
    return kExitUsage;
  }
  const omni::ParameterSetup p{node::master, node::pc, static_cast<std::uint8_t>(o.data_type),
                               omni::ParamWidth::four_bytes, static_cast<std::uint32_t>(o.value)};
  return send(tr, p);
}

// One monitor line: time [s since start], the frame, what it means.
void print_frame(const can::Frame& f, double t_s) {
  const omni::DecodeResult r = omni::decode(f);
  const auto* e = std::get_if<omni::DecodeError>(&r);
  const std::string meaning = e ? fmt::format("not Omni: {}", omni::to_string(*e)) : describe(std::get<omni::Message>(r));
  std::cout << fmt::format("{:10.6f}  {:<28}  {}\n", t_s, can::to_string(f), meaning) << std::flush;
}

int cmd_monitor(can::Transport& tr, const Options& o, int sigfd) {
  const std::int64_t start = monotonic_ns();
  const std::int64_t end = o.seconds >= 0 ? start + static_cast<std::int64_t>(o.seconds * 1e9)
                                          : std::numeric_limits<std::int64_t>::max();
  std::int64_t n = 0;
  bool stop = false;
  while (!stop && (o.count < 0 || n < o.count)) {
    const std::int64_t now = monotonic_ns();
    if (now >= end) break;
    const std::int64_t slice = std::min<std::int64_t>(end - now, 200'000'000);  // re-check the clock
    const auto tf = next_frame(tr, sigfd, slice, stop);
    if (!tf) continue;
    print_frame(tf->frame, static_cast<double>(monotonic_ns() - start) / 1e9);
    ++n;
  }
  return kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"omni-pc: the PC monitor node (0x01) of the thesis's Omni CAN protocol"};
  Options o;
  app.add_option("--iface", o.iface, "transport: udp:GROUP[:PORT], socketcan:IFACE (or IFACE), mem:NAME")
      ->capture_default_str();
  app.require_subcommand(1);
  auto* detect = app.add_subcommand("detect", "send node detection (0x000 remote) and list the nodes that answer");
  detect->add_option("--timeout-ms", o.timeout_ms, "how long to collect answers [ms]")->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  auto* start = app.add_subcommand("start", "NMT start (0x000 [node 01]); default node: the master 0x02");
  // Range-checked here: -1 stands for "not given", so a negative --node silently became the
  // default target (found in review).
  start->add_option("--node", o.node, "target node id (0 = all)")->check(CLI::Range(0, 0xFF));
  auto* stop = app.add_subcommand("stop", "NMT stop (0x000 [node 02]); default node: 0 = all");
  stop->add_option("--node", o.node, "target node id (0 = all)")->check(CLI::Range(0, 0xFF));
  auto* param = app.add_subcommand("param", "slave controller setting to the master (0x702 [01 0C value])");
  param->add_option("VALUE", o.value, "the value (4 bytes, big-endian on the wire)")->required();
  param->add_option("--type", o.data_type, "data type (default 0x0C, slave controller setting)");
  auto* monitor = app.add_subcommand("monitor", "print every frame with its decoded meaning");
  monitor->add_option("--seconds", o.seconds, "stop after S seconds")
      ->check(controller::time_check(controller::kMaxRunSeconds));
  monitor->add_option("--count", o.count, "stop after N frames")->check(CLI::NonNegativeNumber);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "omni-pc: " << e.what() << "\n";
    return kExitUsage;
  }
  std::unique_ptr<can::Transport> tr;
  try {
    tr = can::open_transport(normalize_iface(o.iface));
  } catch (const can::TransportError& e) {
    std::cerr << "omni-pc: --iface " << o.iface << ": " << e.what() << "\n";
    return kExitUsage;
  }
  const int sigfd = open_signal_fd();
  if (detect->parsed()) return cmd_detect(*tr, o, sigfd);
  if (start->parsed()) return cmd_nmt(*tr, o, omni::NmtState::start);
  if (stop->parsed()) return cmd_nmt(*tr, o, omni::NmtState::stop);
  if (param->parsed()) return cmd_param(*tr, o);
  return cmd_monitor(*tr, o, sigfd);
}
