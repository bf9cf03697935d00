// controller programs — `omni-master`: the thesis's Omni master (fig. 4-15) as its own
// process, talking to the twin (or real slaves) over a real CAN transport.
//
// A thin shell around the protocol core controller/omni_master: options, the configuration
// file, the transport, and the clock that drives the core's two interrupts. `--clock sim`
// follows the twin's sim-clock grants (lockstep, DESIGN §4); `--clock wall` runs on
// CLOCK_MONOTONIC absolute deadlines and keeps receiving frames between ticks. SIGINT and
// SIGTERM are read through a signalfd (no global flag): the loop ends, the master sends NMT
// stop all as a real master does on shutdown, and the process exits 0.
// Exit codes: 0 normal end; 2 bad usage, configuration or transport spec/interface (one-line
// message); 3 runtime failure (the twin vanished, frames the twin sent never arrived, the
// transport refused frames).
#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <sys/signalfd.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bus_emulators/can/transport.hpp"
#include "controller/ethercat/ec_program.hpp"
#include "controller/can_master_loop.hpp"
#include "controller/canopen/co_program.hpp"
#include "controller/tml/tml_program.hpp"
#include "controller/mechatrolink3/m3_program.hpp"
#include "controller/master_config.hpp"
#include "controller/omni_master.hpp"
#include "controller/program_support.hpp"
#include "controller/programs/cli_checks.hpp"
#include "controller/sim_clock.hpp"

using namespace omnitwin;
using controller::normalize_iface;
using controller::monotonic_ns;
using controller::open_signal_fd;
using controller::realtime_ns;
using controller::signalled;
using controller::to_timespec;
using controller::try_realtime;
using controller::MasterState;
using controller::OmniMaster;

namespace {

constexpr int kExitOk = 0;
constexpr int kExitUsage = 2;
constexpr int kExitRuntime = 3;
constexpr const char* kDefaultIface = "udp:239.74.163.2:43113";
constexpr auto kConnectTimeout = std::chrono::seconds(10);
constexpr auto kGrantTimeout = std::chrono::seconds(60);
constexpr int kRtPriority = 40;
constexpr int kDrainBatch = 256;  // frames handled before the wall loop looks at the clock again

struct Options {
  std::string bus = "can";
  std::string iface = kDefaultIface;
  std::string config;
  std::string clock = "wall";
  std::string sim_clock;
  double duration = -1;  // [s]; < 0: until a signal
  double frames_timeout = 5;  // sim: how long the frames a grant counts may take to arrive [s]
  std::string log_level = "info";
  bool print_config = false;
  std::string script;  // ethercat: a Botnana script to run
  std::string stats;   // ethercat: write the master's counters here (JSON) at exit
  bool shell = false;  // `omni-master shell` (ethercat)
};

// What the loops count besides the core's own statistics.
struct LoopStats {
  std::uint64_t frames_tx = 0;  // accepted by the transport
  std::uint64_t frames_rx = 0;  // received from the transport
  std::uint64_t overruns = 0;   // wall: ticks one period or more late
  std::int64_t max_late_ns = 0; // wall: the latest tick [ns]
  bool interrupted = false;     // SIGINT/SIGTERM ended the loop
  bool backlog = false;         // wall: the last drain stopped at kDrainBatch (more may wait,
                                // some already fetched by the transport, unseen by poll)
};

// Lockstep batches the master's frames: the send callback queues them, and after each tick
// they go to the transport in one send_many() (UDP: one segmented send), before DONE. The
// twin reads them only after DONE, so nothing it sees changes.
struct Outbox {
  bool hold = false;  // queue instead of sending (--clock sim)
  std::vector<can::TimedFrame> frames;
};

// Sends what the outbox holds; refusals reach the core as note_send_failures().
void flush(can::Transport& tr, Outbox& ob, OmniMaster& m, LoopStats& ls) {
  // The core's reaction to a refusal (NMT stop all) is queued too: send until nothing is left.
  while (!ob.frames.empty()) {
    const std::size_t sent = tr.send_many(ob.frames);
    const std::size_t refused = ob.frames.size() - sent;
    ls.frames_tx += sent;
    ob.frames.clear();
    m.note_send_failures(refused);
  }
}

// A runtime failure: the loop ends, the process exits 3 with this message.
struct RuntimeFailure {
  std::string message;
};


// Logs the master's state changes at info level (the only info output while running).
class StateLog {
 public:
  void check(const OmniMaster& m) {
    const simclock::MasterReport r = m.report();
    if (r.state == last_) return;
    if (r.reason == controller::StopReason::none) {
      spdlog::info("state {} -> {}", simclock::to_string(last_), simclock::to_string(r.state));
    } else {
      spdlog::info("state {} -> {} ({}{})", simclock::to_string(last_), simclock::to_string(r.state),
                   simclock::to_string(r.reason), r.node ? fmt::format(", node 0x{:02X}", r.node) : "");
    }
    if (r.state == MasterState::stopped) watchdog_line(m, r);
    last_ = r.state;
  }
  void reset(MasterState s) { last_ = s; }

 private:
  // A watchdog stop says in words what vanished: one node, or the whole bus (the twin gone).
  static void watchdog_line(const OmniMaster& m, const simclock::MasterReport& r) {
    if (r.reason != controller::StopReason::node_missing && r.reason != controller::StopReason::feedback_missing) return;
    const char* what = r.reason == controller::StopReason::node_missing ? "no answer to node detection"
                                                                          : "no speed feedback";
    if (m.missing_slaves() == 4) {
      spdlog::warn("bus silent: none of the four slaves heard ({}); slaves stopped (NMT stop all), no more commands",
                   what);
    } else {
      spdlog::warn("node 0x{:02X} missing ({}); slaves stopped (NMT stop all), no more commands", r.node, what);
    }
  }

  MasterState last_ = MasterState::waiting;
};

// ---------------------------------------------------------------------------------------
// Lockstep with the twin (--clock sim)

// Waits for the next grant while watching for signals, reading the bus meanwhile (frames held
// for the grant's instant: can_master_loop.hpp). ok / closed (End or twin gone) / …
simclock::WaitStatus next_grant(simclock::Client& client, int sigfd, can::Transport& tr, controller::HeldFrames& held,
                                simclock::Grant& g, simclock::End& end, LoopStats& ls) {
  const controller::GrantWait w = controller::wait_for_grant(client.fd(), sigfd, tr, held, kGrantTimeout);
  if (w == controller::GrantWait::timeout) return simclock::WaitStatus::timeout;
  if (w == controller::GrantWait::signal && signalled(sigfd)) {
    ls.interrupted = true;
    return simclock::WaitStatus::closed;
  }
  return client.next(g, std::chrono::seconds(1), &end);
}

// Hands the core every frame until `target` frames have been received in all; false when
// they do not arrive within `timeout`.
bool drain_until(can::Transport& tr, OmniMaster& m, std::uint64_t target, std::int64_t t_ns, LoopStats& ls,
                 std::chrono::milliseconds timeout) {
  const std::int64_t give_up = monotonic_ns() + timeout.count() * 1'000'000;
  while (ls.frames_rx < target) {
    if (auto tf = tr.receive()) {
      ++ls.frames_rx;
      m.on_frame(tf->frame, t_ns);
      continue;
    }
    if (monotonic_ns() >= give_up) return false;
    can::wait_readable(tr, std::chrono::milliseconds(10));
  }
  // Frames beyond the count (another node, e.g. the PC) are handled as well.
  while (auto tf = tr.receive()) ++ls.frames_rx, m.on_frame(tf->frame, t_ns);
  return true;
}

// HeldFrames hands its frames to a runner: the core, counted.
struct HeldSink {
  OmniMaster& m;
  LoopStats& ls;
  void on_frame(const can::Frame& f, std::int64_t t) {
    ++ls.frames_rx;
    m.on_frame(f, t);
  }
};

// Lockstep until the twin ends the run (End or a grant with `stop`) or a signal. The end (NMT
// stop all) goes out in the grant with `stop`, or after a signal in the next tick the twin grants, in place of that tick and counted in its Done, as the
// other CAN masters' loop does (can_master_loop.hpp); without such a grant (End, the twin gone,
// nothing in 1 s) it cannot reach the simulated bus and is not sent.
int run_sim(const Options& o, OmniMaster& m, can::Transport& tr, std::int64_t& stamp_ns, int sigfd,
            LoopStats& ls, Outbox& ob) {
  simclock::Client client(o.sim_clock, kConnectTimeout, sigfd);
  if (client.stopped()) {  // SIGINT/SIGTERM while waiting for the twin's socket
    ls.interrupted = true;
    return kExitOk;
  }
  spdlog::debug("connected to the twin's sim clock at {}", o.sim_clock);
  const std::int64_t rcvbuf_errors0 = can::udp_receive_buffer_errors();
  const auto frames_timeout = std::chrono::milliseconds(std::llround(o.frames_timeout * 1e3));
  controller::HeldFrames held;
  HeldSink sink{m, ls};
  StateLog log;
  log.reset(m.state());
  constexpr std::int64_t kNoEnd = std::numeric_limits<std::int64_t>::min();
  for (;;) {
    simclock::Grant g;
    simclock::End end{kNoEnd};
    simclock::WaitStatus w = next_grant(client, sigfd, tr, held, g, end, ls);
    if (ls.interrupted) {  // the signal came while awaiting this grant: it carries the end
      w = client.next(g, std::chrono::seconds(1), &end);
      if (w != simclock::WaitStatus::ok) {
        spdlog::warn("signal: the twin granted no further tick ({}): no NMT stop sent", simclock::to_string(w));
        return kExitOk;
      }
    }
    if (w == simclock::WaitStatus::closed && end.t_ns != kNoEnd) return kExitOk;
    if (w == simclock::WaitStatus::closed) throw RuntimeFailure{"sim clock: the twin went away (channel closed without End)"};
    if (w != simclock::WaitStatus::ok) throw RuntimeFailure{fmt::format("sim clock: {} while waiting for a grant", simclock::to_string(w))};
    stamp_ns = g.t_ns;
    held.hand_to(sink, g.t_ns);
    if (!drain_until(tr, m, g.frames[0], g.t_ns, ls, frames_timeout))
      throw RuntimeFailure{controller::drain_failure(g.tick, ls.frames_rx, g.frames[0], frames_timeout, tr, rcvbuf_errors0)};
    const bool stop = ls.interrupted || g.stop;  // a signal, or the run's end in simulated time
    if (stop) m.shutdown();
    else m.on_tick(g.t_ns);
    flush(tr, ob, m, ls);
    log.check(m);
    const simclock::Done done{g.tick, {ls.frames_tx, 0, 0, 0}, m.report(), stop};  // its end: one tick
    if (!client.done(done)) throw RuntimeFailure{"sim clock: the twin is gone"};
    if (stop) return kExitOk;
  }
}

// ---------------------------------------------------------------------------------------
// Real time (--clock wall)

// Handles up to kDrainBatch waiting frames at the current monotonic time (at most not_after_ns).
void drain_wall(can::Transport& tr, OmniMaster& m, std::int64_t start_ns, LoopStats& ls, StateLog& log,
                std::int64_t not_after_ns = std::numeric_limits<std::int64_t>::max()) {
  ls.backlog = false;
  for (int i = 0; i < kDrainBatch; ++i) {
    auto tf = tr.receive();
    if (!tf) return;
    ++ls.frames_rx;
    m.on_frame(tf->frame, std::min(monotonic_ns(), not_after_ns) - start_ns);
    log.check(m);
  }
  ls.backlog = true;
}

// One timer interrupt for the deadline that has passed; skips (and counts) missed periods.
void wall_tick(OmniMaster& m, std::int64_t start_ns, std::int64_t period_ns, std::int64_t& deadline,
               LoopStats& ls, StateLog& log) {
  const std::int64_t late = monotonic_ns() - deadline;
  ls.max_late_ns = std::max(ls.max_late_ns, late);
  if (late >= period_ns) {
    ++ls.overruns;
    deadline += (late / period_ns) * period_ns;
  }
  m.on_tick(deadline - start_ns, 2 * late >= period_ns);  // half a period late: judges no slave
  log.check(m);
  deadline += period_ns;
}

// Waits for frames, a signal or the wake-up time; sleeps to the wake-up time exactly.
void wall_wait(can::Transport& tr, OmniMaster& m, int sigfd, std::int64_t start_ns, std::int64_t wake_ns,
               LoopStats& ls, StateLog& log) {
  if (ls.backlog) {  // the rest of a burst first, without waiting (the loop checks the deadline)
    if (signalled(sigfd)) ls.interrupted = true;
    drain_wall(tr, m, start_ns, ls, log);
    return;
  }
  pollfd fds[2] = {{tr.poll_fd(), POLLIN, 0}, {sigfd, POLLIN, 0}};
  const timespec timeout = to_timespec(std::max<std::int64_t>(0, wake_ns - monotonic_ns()));
  const int r = ::ppoll(fds, 2, &timeout, nullptr);
  if (r < 0 && errno != EINTR) throw RuntimeFailure{fmt::format("poll failed: {}", std::strerror(errno))};
  if (r > 0 && (fds[1].revents & POLLIN) && signalled(sigfd)) ls.interrupted = true;
  if (r > 0 && (fds[0].revents & POLLIN)) drain_wall(tr, m, start_ns, ls, log);
  if (r == 0) {
    const timespec at = to_timespec(wake_ns);
    while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, nullptr) == EINTR) {
    }
  }
}

int run_wall(const Options& o, OmniMaster& m, can::Transport& tr, std::int64_t& stamp_ns, int sigfd, LoopStats& ls) {
  try_realtime(kRtPriority);
  const std::int64_t period_ns = std::llround(m.config().loop.period * 1e9);
  const std::int64_t start_ns = monotonic_ns();
  const std::int64_t end_ns = o.duration >= 0 ? start_ns + std::llround(o.duration * 1e9)
                                              : std::numeric_limits<std::int64_t>::max();
  std::int64_t deadline = start_ns;  // the first tick is at once
  StateLog log;
  log.reset(m.state());
  while (!ls.interrupted) {
    const std::int64_t now = monotonic_ns();
    if (now >= end_ns) break;
    stamp_ns = realtime_ns();  // as python-can stamps frames
    if (now >= deadline) {
      // Late (this process did not run for a while: a host stall): the frames that came
      // meanwhile go first, stamped no later than the tick, as the eCAN receive interrupt
      // would have taken them before the timer interrupt. Otherwise a stall of a few ms
      // reads as "none of the four slaves answered node detection" (found by the CAN soak).
      if (now > deadline) drain_wall(tr, m, start_ns, ls, log, deadline);
      wall_tick(m, start_ns, period_ns, deadline, ls, log);
      continue;
    }
    wall_wait(tr, m, sigfd, start_ns, std::min(deadline, end_ns), ls, log);
  }
  return kExitOk;
}

// ---------------------------------------------------------------------------------------
// main

void add_options(CLI::App& app, Options& o) {
  app.add_option("--bus", o.bus, "bus kind: can, canopen, tml, ethercat or m3")->capture_default_str();
  app.add_option("--iface", o.iface, "transport: udp:GROUP[:PORT], socketcan:IFACE (or IFACE), mem:NAME")
      ->capture_default_str();
  app.add_option("--config", o.config, "the master's configuration file (YAML)");
  app.add_option("--script", o.script, "ethercat: run this Botnana script, exit when its tasks end");
  app.add_option("--stats", o.stats, "write the master's counters to this JSON file at exit");
  app.add_option("--clock", o.clock, "sim: lockstep with the twin; wall: real time")
      ->check(CLI::IsMember({"sim", "wall"}))
      ->capture_default_str();
  app.add_option("--sim-clock", o.sim_clock, "the twin's sim-clock address unix:PATH (with --clock sim)");
  app.add_option("--duration", o.duration, "wall clock: stop after S seconds (default: until SIGINT/SIGTERM)")
      ->check(controller::time_check(controller::kMaxRunSeconds));
  app.add_option("--frames-timeout", o.frames_timeout,
                 "sim, buses can, canopen and tml: seconds the frames a grant counts may take to arrive")
      ->capture_default_str();
  app.add_option("--log-level", o.log_level, "trace, debug, info, warn, error, off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}))
      ->capture_default_str();
  app.add_flag("--print-config", o.print_config, "print the configuration as loaded (YAML) and exit");
}

// Option combinations CLI11 cannot check; the message of the first problem, or "".
std::string usage_problem(const Options& o) {
  if (o.config.empty()) return "--config is required";
  if (!(o.frames_timeout > 0) || !std::isfinite(o.frames_timeout)) return "--frames-timeout: a positive number of seconds";
  if (o.bus != "can" && o.bus != "canopen" && o.bus != "tml" && o.bus != "ethercat" && o.bus != "m3")
    return fmt::format("--bus {}: not supported (can, canopen, tml, ethercat or m3)", o.bus);
  if (!o.script.empty() && o.bus != "ethercat") return "--script needs --bus ethercat (Botnana scripts drive the EtherCAT master)";
  if (!o.script.empty() && std::filesystem::is_directory(o.script)) return fmt::format("--script {}: a directory, not a script", o.script);
  // Every bus: a bad address is bad usage (exit 2) before anything starts, not a failed
  // connect (exit 3) after the configuration and transport (found in review).
  try {
    if (o.clock == "sim" && !o.sim_clock.empty()) simclock::parse_address(o.sim_clock);
  } catch (const std::exception& e) {
    return e.what();
  }
  // Every bus: an address that would be ignored is a mistake to say, not to pass over (four
  // buses accepted it; found in review).
  if (o.clock == "wall" && !o.sim_clock.empty()) return "--sim-clock is only used with --clock sim";
  if (o.bus == "m3" || o.bus == "canopen" || o.bus == "tml") {
    if (o.clock == "sim" && o.sim_clock.empty()) return "--clock sim needs --sim-clock unix:PATH";
    if (o.clock == "sim" && o.duration >= 0) return "--duration is only used with --clock wall (the twin ends a sim run)";
    return "";
  }
  if (o.bus == "ethercat") {
    if (o.clock == "sim" && o.sim_clock.empty()) return "--clock sim needs --sim-clock unix:PATH";
    if (o.shell && o.clock == "sim") return "shell runs on the wall clock";
    return "";
  }
  if (o.clock == "sim" && o.sim_clock.empty()) return "--clock sim needs --sim-clock unix:PATH";
  if (o.clock == "sim" && o.duration >= 0) return "--duration is only used with --clock wall (the twin ends a sim run)";
  try {
    can::parse_transport_spec(normalize_iface(o.iface));
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

void setup_logging(const std::string& level) {
  auto logger = spdlog::stderr_color_mt("omni-master");
  spdlog::set_default_logger(logger);
  spdlog::set_pattern("omni-master: %^%l%$: %v");
  spdlog::set_level(spdlog::level::from_str(level));
}

void print_summary(const OmniMaster& m, const LoopStats& ls, const std::string& clock) {
  const simclock::MasterReport r = m.report();
  const auto& s = m.stats();
  spdlog::info("end: state {}, reason {}{}, frames tx {} rx {} (decode errors {}, ignored {}), ticks {}{}",
               simclock::to_string(r.state), simclock::to_string(r.reason),
               r.node ? fmt::format(" (node 0x{:02X})", r.node) : "", ls.frames_tx, ls.frames_rx, s.decode_errors,
               s.frames_ignored, s.ticks,
               clock == "wall" ? fmt::format(", overruns {}, max late {:.3f} ms", ls.overruns, ls.max_late_ns / 1e6) : "");
}

// --stats of the Omni CAN master: its counters, the loop's and how it ended, as JSON
// (written atomically); false (error logged) when the file cannot be written.
bool write_stats(const std::string& path, const OmniMaster& m, const LoopStats& ls) {
  const simclock::MasterReport r = m.report();
  const auto& s = m.stats();
  const nlohmann::json j = {
      {"state", simclock::to_string(r.state)}, {"reason", simclock::to_string(r.reason)}, {"node", r.node},
      {"ticks", s.ticks}, {"frames_tx", ls.frames_tx}, {"frames_rx", ls.frames_rx},
      {"overruns", ls.overruns}, {"max_late_ms", ls.max_late_ns / 1e6},
      {"frames_received", s.frames_received}, {"frames_handled", s.frames_handled},
      {"frames_ignored", s.frames_ignored}, {"frames_refused", s.frames_refused},
      {"decode_errors", s.decode_errors}, {"frames_sent", s.frames_sent}, {"send_failures", s.send_failures},
      {"commands_sent", s.commands_sent}, {"saturated_commands", s.saturated_commands},
      {"feedback", s.feedback}, {"feedback_other_type", s.feedback_other_type},
      {"detection_requests", s.detection_requests}, {"detection_rounds", s.detection_rounds},
      {"detection_misses", s.detection_misses}, {"detection_answers", s.detection_answers},
      {"late_ticks", s.late_ticks}, {"starts", s.starts}};
  return controller::write_stats_file(path, j.dump());
}

// Runs the loop for the chosen clock with the transport open; returns the exit code.
int run(const Options& o, const controller::MasterConfig& cfg, can::Transport& tr) {
  LoopStats ls;
  std::int64_t stamp_ns = 0;
  Outbox ob;
  ob.hold = o.clock == "sim";
  ob.frames.reserve(64);
  OmniMaster master(cfg, [&](const can::Frame& f) {
    if (ob.hold) {
      ob.frames.push_back(can::TimedFrame{f, stamp_ns});
      return true;
    }
    const bool ok = tr.send(f, stamp_ns);
    ls.frames_tx += ok ? 1 : 0;
    return ok;
  });
  const int sigfd = open_signal_fd();
  spdlog::info("state {} (transport {}, clock {})", simclock::to_string(master.state()), tr.spec(), o.clock);
  int code = kExitOk;
  try {
    code = o.clock == "sim" ? run_sim(o, master, tr, stamp_ns, sigfd, ls, ob) : run_wall(o, master, tr, stamp_ns, sigfd, ls);
  } catch (const RuntimeFailure& f) {
    spdlog::error("{}", f.message);
    code = kExitRuntime;
  } catch (const simclock::ChannelError& e) {
    spdlog::error("{}", e.what());
    code = kExitRuntime;
  }
  // Shutdown as a real master: stop the slaves unless they already are (in lockstep a signal's
  // end went out in a granted tick: run_sim).
  if (code == kExitOk && o.clock == "wall") master.shutdown();
  flush(tr, ob, master, ls);  // what a failed tick or the shutdown queued
  ob.hold = false;
  if (master.report().reason == controller::StopReason::bus_error) code = kExitRuntime;
  print_summary(master, ls, o.clock);
  if (!o.stats.empty() && !write_stats(o.stats, master, ls)) code = kExitRuntime;
  if (sigfd >= 0) ::close(sigfd);
  return code;
}

// Loads the configuration; nullopt (message printed) when it is bad.
std::optional<controller::MasterConfig> load(const std::string& path) {
  try {
    return controller::load_master_config(path);
  } catch (const controller::MasterConfigError& e) {
    spdlog::error("{}", e.what());
    return std::nullopt;
  }
}

}  // namespace

namespace {
// The bus's program for options `o` (parsed and checked); its exit code.
int dispatch(const Options& o);
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"omni-master: the master program — the thesis's Omni CAN master (seed 002, fig. 4-15), or our CANopen, EtherCAT or MECHATROLINK-III master"};
  Options o;
  add_options(app, o);
  CLI::App* shell = app.add_subcommand("shell", "interactive Botnana shell on the EtherCAT master (wall clock)");
  shell->add_option("--iface", o.iface, "EtherCAT transport: raw:IFACE, udp:HOST:PORT, mem:NAME");
  shell->add_option("--config", o.config, "the EtherCAT master's configuration file (YAML)");
  shell->add_option("--script", o.script, "Botnana source to evaluate first");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "omni-master: " << e.what() << "\n";
    return kExitUsage;
  }
  if (shell->parsed()) o.shell = true, o.bus = "ethercat", o.clock = "wall";
  // Botnana scripts drive the EtherCAT master: --script alone picks it; another --bus is an
  // error (usage_problem), not silently overridden (found in review).
  if (!o.script.empty() && app.get_option("--bus")->count() == 0) o.bus = "ethercat";
  setup_logging(o.log_level);
  if (o.bus == "ethercat" && o.iface == kDefaultIface) o.iface = "udp:127.0.0.1:34980";
  if (o.bus == "m3" && o.iface == kDefaultIface) o.iface = "udp:127.0.0.1:34997";
  if (const std::string p = usage_problem(o); !p.empty()) {
    spdlog::error("{}", p);
    return kExitUsage;
  }
  if (!controller::watch_parent()) {
    spdlog::error("the twin that started this master (OMNITWIN_TWIN_PID) is gone");
    return kExitRuntime;
  }
  // Nothing a user can give is meant to throw past the programs' own error handling (the
  // master_config fuzzer holds them to it); if something does, say what and exit as a runtime
  // failure instead of aborting with a core dump the twin can only call "killed by signal 6".
  try {
    return dispatch(o);
  } catch (const std::exception& e) {
    spdlog::critical("internal error, please report it: {}", e.what());
    return kExitRuntime;
  }
}

namespace {

int dispatch(const Options& o) {
  if (o.bus == "tml") {
    controller::tml::ProgramOptions to{o.iface, o.config, o.clock, o.sim_clock, o.duration, o.print_config, o.stats, o.frames_timeout};
    return controller::tml::run_tml_program(to);
  }
  if (o.bus == "canopen") {
    controller::canopen::ProgramOptions co{o.iface, o.config, o.clock, o.sim_clock, o.duration, o.print_config, o.stats, o.frames_timeout};
    return controller::canopen::run_canopen_program(co);
  }
  if (o.bus == "m3") {
    m3::ProgramOptions mo{o.iface, o.config, o.clock, o.sim_clock, o.duration, o.print_config, o.stats};
    return m3::run_m3_program(mo);
  }
  if (o.bus == "ethercat") {
    controller::ethercat::ProgramOptions eo{o.iface, o.config, o.clock, o.sim_clock, o.duration, o.shell, o.script,
                                            o.print_config, o.stats};
    return controller::ethercat::run_ethercat_program(eo);
  }
  const auto cfg = load(o.config);
  if (!cfg) return kExitUsage;
  if (o.print_config) {
    std::cout << controller::dump_master_config(*cfg);
    return kExitOk;
  }
  const std::unique_ptr<can::Transport> tr = controller::open_can_iface(o.iface);
  if (!tr) return kExitUsage;
  return run(o, *cfg, *tr);
}

}  // namespace
