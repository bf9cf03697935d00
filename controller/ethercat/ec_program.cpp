// controller/ethercat — the `--bus ethercat` program path (see ec_program.hpp).
#include "controller/ethercat/ec_program.hpp"

#include <editline/readline.h>
#include <fmt/format.h>
#include <poll.h>
#include <sched.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <sys/signalfd.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <mutex>
#include <numbers>
#include <optional>
#include <thread>
#include <vector>

#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "controller/botnana/botnana_interpreter.hpp"
#include "controller/ethercat/ec_config.hpp"
#include "controller/ethercat/ec_drive.hpp"
#include "controller/ethercat/ec_master.hpp"
#include "controller/master_config.hpp"
#include "controller/platform_loop.hpp"
#include "controller/program_support.hpp"
#include "controller/sim_clock.hpp"

namespace omnitwin::controller::ethercat {

namespace {

constexpr int kExitOk = 0, kExitUsage = 2, kExitRuntime = 3;
constexpr auto kConnectTimeout = std::chrono::seconds(10);
constexpr auto kGrantTimeout = std::chrono::seconds(60);
constexpr std::int64_t kDrainLimitNs = 5'000'000'000;
// The end of a run (wall clock, or a signal in lockstep): this long for the drives to stop and
// the slaves to reach INIT.
constexpr std::int64_t kShutdownNs = 100'000'000;
constexpr int kRtPriority = 40;

struct RuntimeFailure {
  std::string message;
};

// Lines typed in the shell, read by a libedit thread and evaluated on the cycle thread.
class LineQueue {
 public:
  void push(std::string s) {
    std::lock_guard<std::mutex> l(m_);
    q_.push_back(std::move(s));
  }
  std::optional<std::string> pop() {
    std::lock_guard<std::mutex> l(m_);
    if (q_.empty()) return std::nullopt;
    std::string s = std::move(q_.front());
    q_.pop_front();
    return s;
  }
  std::atomic<bool> eof{false};

 private:
  std::mutex m_;
  std::deque<std::string> q_;
};

// The master core, its drive layer, the platform loop and the interpreter, one cycle at a time.
class Runner {
 public:
  Runner(EcMasterConfig mc, const EcConfig& ec, std::optional<MasterConfig> platform,
         omnitwin::ethercat::EcTransport& tr)
      : ec_(ec),
        tr_(tr),
        master_(std::move(mc), [this](std::span<const std::uint8_t> pdu) {
          const bool ok = tr_.send(pdu);
          frames_tx += ok ? 1 : 0;
          return ok;
        }),
        drives_(master_),
        platform_(std::move(platform)) {
    master_.set_event_callback([](const std::string& e) {
      if (e.rfind("segment lost", 0) == 0) spdlog::warn("{}", e);
      else spdlog::info("{}", e);
    });
    for (int i = 0; i < 4; ++i) {
      if (ec_.user_pdos[i].first)
        drives_.set_user_pdo(static_cast<botnana::UserPdo>(i), botnana::ObjectRef{ec_.user_pdos[i].first, ec_.user_pdos[i].second});
    }
    if (platform_) {
      PlatformLoopConfig lc = platform_->loop;
      lc.counts_per_rev = static_cast<int>(std::lround(ec_.wheel_counts_per_rev));
      loop_.emplace(lc, build_path(platform_->path));
      every_ = std::max<std::int64_t>(1, std::llround(lc.period / ec_.cycle));
    }
    buf_.resize(2048);
  }

  EcMaster& master() { return master_; }
  EcDrives& drives() { return drives_; }

  // Every PDU waiting now; while the last frame sent is still out, waits up to `grace` for it.
  void receive(SimTime t, std::chrono::nanoseconds grace = std::chrono::nanoseconds(0)) {
    for (;;) {
      const int n = tr_.receive(buf_, master_.awaiting_reply() ? grace : std::chrono::nanoseconds(0));
      if (n <= 0) return;
      ++frames_rx;
      master_.on_frame(std::span<std::uint8_t>(buf_.data(), static_cast<std::size_t>(n)), t);
    }
  }
  // Until `target` PDUs were received in all (lockstep); false after kDrainLimitNs.
  bool drain_until(std::uint64_t target, SimTime t) {
    const std::int64_t give_up = monotonic_ns() + kDrainLimitNs;
    while (frames_rx < target) {
      const int n = tr_.receive(buf_, std::chrono::milliseconds(10));
      if (n > 0) {
        ++frames_rx;
        master_.on_frame(std::span<std::uint8_t>(buf_.data(), static_cast<std::size_t>(n)), t);
      } else if (n < 0 || monotonic_ns() >= give_up) {
        return false;
      }
    }
    receive(t);
    return true;
  }

  // One cycle at t: drive layer, platform loop, interpreter tasks, then the master's frame.
  void cycle(SimTime t, botnana::Interpreter* interp) {
    drives_.update();
    platform(t);
    if (interp) interp->step_tasks();
    master_.tick(t);
  }

  simclock::MasterReport report() const {
    simclock::MasterReport r;
    if (master_.phase() == MasterPhase::failed || failure_) {
      r.state = simclock::MasterState::stopped;
      r.reason = simclock::StopReason::startup_timeout;
    } else if (halted_ || master_.segment_lost()) {
      r.state = simclock::MasterState::stopped;  // a wheel's slave lost (its node), or the segment (no node: all)
      r.reason = simclock::StopReason::node_missing;
      r.node = static_cast<std::uint8_t>(lost_slave_);
    } else if (finished_) {
      r.state = simclock::MasterState::finished;
    } else if (started_) {
      r.state = simclock::MasterState::running;
    } else {
      r.state = simclock::MasterState::detecting;
    }
    for (int i = 0; i < master_.slave_count(); ++i) {
      if (master_.slave(i).step == SlaveStep::offline && r.state == simclock::MasterState::running) {
        r.reason = simclock::StopReason::node_missing;
        r.node = static_cast<std::uint8_t>(i + 1);
        break;
      }
    }
    r.path_origin_ns = started_ ? origin_ : -1;
    if (loop_) {
      const Pose2& ref = out_.reference.pose;
      const Pose2& odo = loop_->odometry().pose();
      r.reference = {ref.x, ref.y, ref.phi};
      r.odometry = {odo.x, odo.y, odo.phi};
    }
    return r;
  }
  const std::optional<std::string>& failure() const { return failure_; }
  bool finished() const { return finished_; }
  // The platform loop stopped: the segment was lost, or a wheel's slave (lost_slave(), 1-based).
  bool halted() const { return halted_; }
  int lost_slave() const { return lost_slave_; }
  // The program's state for --stats: failed | stopped (segment or a wheel's slave lost) |
  // finished | degraded (OP was reached, a slave is not in OP now) | running | starting.
  std::string state() const {
    if (master_.phase() == MasterPhase::failed || failure_) return "failed";
    if (halted_ || master_.segment_lost()) return "stopped";
    if (finished_) return "finished";
    if (master_.supervising() && !master_.operational()) return "degraded";
    return started_ || (!loop_ && master_.operational()) ? "running" : "starting";
  }
  // The end of the run: wheel commands zero and every drive to quick stop (the cycles go on).
  void stop_drives() {
    ending_ = true;
    drives_.stop_axes();
  }

  std::uint64_t frames_tx = 0, frames_rx = 0;

 private:
  WheelCounts counts() {
    WheelCounts c{};
    for (int i = 0; i < 4; ++i) {
      const auto v = drives_.read(ec_.wheels[i].slave, ec_.wheels[i].channel, 0x6064, 0);
      c[i] = static_cast<std::int32_t>(v.value_or(0));
    }
    return c;
  }
  void command(const std::array<double, 4>& counts_per_s) {
    for (int i = 0; i < 4; ++i) {
      const AxisRef& w = ec_.wheels[i];
      if (ec_.wheel_mode == WheelMode::csv) {
        drives_.write(w.slave, w.channel, 0x60FF, 0, std::llround(counts_per_s[i]));
      } else {
        target_[i] += counts_per_s[i] * ec_.cycle;
        drives_.write(w.slave, w.channel, 0x607A, 0, std::llround(target_[i]));
      }
    }
  }
  // The segment or a wheel's slave was lost once the drives had goals: the wheels get zero for
  // good, every drive quick stop.
  void halt(const std::string& why) {
    halted_ = true;
    const WheelCounts c = counts();
    for (int i = 0; i < 4; ++i) target_[i] = c[i];
    wheel_cps_ = {0, 0, 0, 0};
    command(wheel_cps_);
    drives_.stop_axes();
    spdlog::error("platform loop stopped ({}): wheel commands zero, drives to quick stop", why);
  }
  // The 1-based slave of the first wheel whose slave is not in OP (0 = none).
  int lost_wheel_slave() const {
    for (const auto& w : ec_.wheels)
      if (w.slave <= master_.slave_count() && master_.slave(w.slave - 1).step != SlaveStep::op) return w.slave;
    return 0;
  }
  // The 1-based slave of a wheel out of OP for wheel_loss_timeout by t (0 = none).
  int wheel_lost_too_long(SimTime t) {
    const int lost = lost_wheel_slave();
    if (lost == 0) {
      lost_since_ = -1;
      return 0;
    }
    if (lost_since_ < 0) lost_since_ = t;
    return static_cast<double>(t - lost_since_) * 1e-9 >= ec_.wheel_loss_timeout ? lost : 0;
  }
  // Once counted: every wheel names a slave the bus has (else failed, naming the entry).
  void check_wheel_slaves() {
    wheels_checked_ = true;
    for (std::size_t i = 0; i < ec_.wheels.size(); ++i) {
      if (ec_.wheels[i].slave <= master_.slave_count()) continue;
      failure_ = fmt::format("{}: wheels[{}]: slave {}, but the bus has {} slave(s)", ec_.file, i, ec_.wheels[i].slave,
                             master_.slave_count());
      spdlog::error("{}", *failure_);
      return;
    }
  }
  void platform(SimTime t) {
    if (!loop_ || failure_) return;
    if (halted_ || ending_) return command({0, 0, 0, 0});
    if (!wheels_checked_ && master_.slave_count() > 0) check_wheel_slaves();
    if (failure_) return;
    if (goals_set_ && master_.segment_lost()) return halt(master_.stop_reason());
    // A wheel's slave lost before the path is done, for longer than wheel_loss_timeout (once
    // finished, as on CANopen, it stops nothing; a shorter outage the master recovers, and the
    // loop pulls the platform back, as the regression scenario ethercat_power_loss runs it).
    if (goals_set_ && !finished_ && (lost_slave_ = wheel_lost_too_long(t)) != 0) {
      return halt(fmt::format("slave {} of wheel axis lost for {} s: {}", lost_slave_, ec_.wheel_loss_timeout,
                              to_string(master_.slave(lost_slave_ - 1).step)));
    }
    if (!started_) {
      if (!master_.operational()) return;
      if (!goals_set_) {
        for (const auto& w : ec_.wheels) {
          if (!drives_.has_drive(w.slave, w.channel)) {
            failure_ = fmt::format("wheel axis slave {} channel {} is not a drive on this bus", w.slave, w.channel);
            spdlog::error("{}", *failure_);
            return;
          }
          drives_.write(w.slave, w.channel, 0x6060, 0, ec_.wheel_mode == WheelMode::csv ? 9 : 8);
          drives_.set_goal(w.slave, w.channel, botnana::PdsGoal::operation_enabled);
        }
        goals_set_ = true;
        const WheelCounts c = counts();
        for (int i = 0; i < 4; ++i) target_[i] = c[i];
        command({0, 0, 0, 0});
        spdlog::info("all slaves in OP: enabling the wheel drives");
      }
      for (const auto& w : ec_.wheels)
        if (drives_.state(w.slave, w.channel) != PdsState::operation_enabled) return;
      counts_ = counts();
      loop_->reset(loop_->path().start_pose(), counts_);
      origin_ = t;
      started_ = true;
      n_ = 0;
      spdlog::info("wheel drives enabled: platform loop running");
    }
    if (finished_) {
      command({0, 0, 0, 0});
      return;
    }
    const double ts = static_cast<double>(t - origin_) * 1e-9;
    if (n_++ % every_ == 0) {
      counts_ = counts();
      out_ = loop_->step(ts, counts_);
      const double k = ec_.wheel_counts_per_rev / (2 * std::numbers::pi);
      for (int i = 0; i < 4; ++i) wheel_cps_[i] = out_.wheel_rad_s[i] * k;
    }
    command(wheel_cps_);
    if (platform_->settle >= 0 && ts >= loop_->path().duration() + platform_->settle) {
      finished_ = true;
      command({0, 0, 0, 0});
      spdlog::info("path done");
    }
  }

  const EcConfig& ec_;
  omnitwin::ethercat::EcTransport& tr_;
  EcMaster master_;
  EcDrives drives_;
  std::optional<MasterConfig> platform_;
  std::optional<PlatformLoop> loop_;
  PlatformLoopOutput out_;
  std::int64_t every_ = 1, n_ = 0;
  bool goals_set_ = false, started_ = false, finished_ = false, halted_ = false, ending_ = false, wheels_checked_ = false;
  int lost_slave_ = 0;  // 1-based slave of the wheel that stopped the platform (0: none / the segment)
  SimTime lost_since_ = -1;  // when a wheel's slave left OP (-1: every wheel's slave is in OP)
  SimTime origin_ = -1;
  WheelCounts counts_{};
  std::array<double, 4> wheel_cps_{}, target_{};
  std::optional<std::string> failure_;
  std::vector<std::uint8_t> buf_;
};

// The interpreter side of shell and script.
struct Botnana {
  std::unique_ptr<botnana::Interpreter> interp;
  std::vector<std::string> script;  // lines still to evaluate once the bus is up
  std::string script_file;          // their file, which errors name (FILE:LINE:COLUMN)
  bool script_mode = false, script_loaded = false;
  LineQueue* lines = nullptr;
  std::optional<std::string> error;

  // After each cycle: evaluates the script once the master is operational, and typed lines.
  // Returns false when the program should end.
  bool after_cycle(Runner& r) {
    if (!interp) return true;
    if (script_mode) {
      if (!script_loaded) {
        if (!r.master().operational()) return true;
        for (std::size_t i = 0; i < script.size(); ++i) {
          const botnana::Status s = interp->evaluate(script[i], i + 1);
          if (!s) {
            error = s.located(script_file);
            return false;
          }
        }
        script_loaded = true;
      }
      if (!interp->last_task_error().ok) {
        error = interp->last_task_error().located(script_file);
        return false;
      }
      return interp->tasks_running() > 0;
    }
    while (auto line = lines->pop()) {
      const botnana::Status s = interp->evaluate(*line);
      std::cout << (s ? " ok" : " " + s.to_string()) << std::endl;
    }
    return !lines->eof.load();
  }
};

// One cycle of the end of a run at t, `elapsed` [ns] after it began with Runner::stop_drives():
// once no drive is enabled (or after half of kShutdownNs) the master's shutdown (AL SAFE-OP,
// then INIT). False, without a cycle, when every slave answered INIT or kShutdownNs is over.
bool shutdown_cycle(Runner& r, SimTime t, std::int64_t elapsed) {
  EcMaster& m = r.master();
  if (!m.shutting_down() && (!r.drives().any_enabled() || elapsed >= kShutdownNs / 2)) m.shutdown();
  if (m.shutdown_done() || elapsed >= kShutdownNs) return false;
  r.cycle(t, nullptr);
  return true;
}

void log_shutdown(const EcMaster& m) {
  if (m.slave_count() == 0) return;  // nothing was brought up; the master said "shutdown: no slaves"
  if (m.shutdown_done()) spdlog::info("shutdown: drives stopped, slaves in INIT");
  else spdlog::warn("shutdown: not every slave confirmed INIT within {} ms", kShutdownNs / 1'000'000);
}

// Lockstep until the twin ends the run (End), the script ends, or a failure (throws). A grant
// with `stop` (the run's end) or SIGINT/SIGTERM ends it as the end of a wall-clock run does,
// in the ticks the twin still grants
// (kShutdownNs of simulated time at most): the drives stopped, the slaves taken to INIT; an End
// or the twin gone meanwhile ends it at once (no simulated time is left to send in), as does
// a second signal.
int run_sim(const ProgramOptions& o, Runner& r, int sigfd, Botnana& bn) {
  simclock::Client client(o.sim_clock, kConnectTimeout, sigfd);
  if (client.stopped()) return kExitOk;  // SIGINT/SIGTERM while waiting for the twin's socket
  constexpr std::int64_t kNoEnd = std::numeric_limits<std::int64_t>::min();
  bool stopping = false;
  SimTime stop_from = -1;  // the first tick of the shutdown
  for (;;) {
    simclock::Grant g;
    simclock::End end{kNoEnd};
    pollfd fds[2] = {{client.fd(), POLLIN, 0}, {sigfd, POLLIN, 0}};
    const int pr = ::poll(fds, 2, static_cast<int>(std::chrono::milliseconds(kGrantTimeout).count()));
    if (pr == 0) throw RuntimeFailure{"sim clock: no grant within 60 s"};
    if (pr > 0 && (fds[1].revents & POLLIN) && signalled(sigfd)) {
      if (stopping) {
        spdlog::warn("shutdown: a second signal: ending without it");
        return kExitOk;
      }
      stopping = true;
      r.stop_drives();
      spdlog::info("signal: stopping the drives and taking the slaves to INIT in the ticks the twin grants");
      continue;
    }
    const simclock::WaitStatus w = client.next(g, std::chrono::seconds(1), &end);
    if (w == simclock::WaitStatus::closed && stopping) {
      spdlog::warn("shutdown: the twin ended the run before the slaves confirmed INIT");
      return kExitOk;
    }
    if (w == simclock::WaitStatus::closed && end.t_ns != kNoEnd) return kExitOk;
    if (w == simclock::WaitStatus::closed) throw RuntimeFailure{"sim clock: the twin went away (channel closed without End)"};
    if (w != simclock::WaitStatus::ok) throw RuntimeFailure{fmt::format("sim clock: {} while waiting for a grant", simclock::to_string(w))};
    if (!r.drain_until(g.frames[0], g.t_ns)) {
      throw RuntimeFailure{fmt::format("tick {}: only {} of the {} frames the twin sent arrived within 5 s", g.tick,
                                       r.frames_rx, g.frames[0])};
    }
    if (g.stop && !stopping) {  // the run's end, in simulated time: as a signal
      stopping = true;
      r.stop_drives();
      spdlog::info("end of the run: stopping the drives and taking the slaves to INIT");
    }
    bool go_on = true;
    if (stopping) {
      if (stop_from < 0) stop_from = g.t_ns;
      go_on = shutdown_cycle(r, g.t_ns, g.t_ns - stop_from);
    } else {
      r.cycle(g.t_ns, bn.interp.get());
      go_on = bn.after_cycle(r);
    }
    // The end sequence's last tick says so (the script's end leaves too, but was not asked).
    const simclock::Done done{g.tick, {r.frames_tx, 0, 0, 0}, r.report(), stopping && !go_on};
    if (!client.done(done)) throw RuntimeFailure{"sim clock: the twin is gone"};
    if (stopping && !go_on) log_shutdown(r.master());
    if (!go_on) return bn.error ? kExitRuntime : kExitOk;
  }
}

// Sleeps until `at` [monotonic ns].
void sleep_until(std::int64_t at) {
  const timespec ts{static_cast<time_t>(at / 1'000'000'000), static_cast<long>(at % 1'000'000'000)};
  while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

// The end of a wall-clock run, within kShutdownNs: wheel commands zero and every drive to
// quick stop (until none is enabled, at most half of it), then the master's shutdown (AL
// SAFE-OP, then INIT) until every slave answers in INIT. Logs how it ended.
void shutdown_wall(Runner& r, std::int64_t start, std::int64_t period_ns) {
  r.stop_drives();
  const std::int64_t t0 = monotonic_ns();
  for (std::int64_t at = t0;; at += period_ns) {
    sleep_until(at);
    const SimTime t = at - start;
    r.receive(t, std::chrono::nanoseconds(period_ns / 4));
    if (!shutdown_cycle(r, t, at - t0)) break;
  }
  log_shutdown(r.master());
}

int run_wall(const ProgramOptions& o, Runner& r, int sigfd, Botnana& bn, std::int64_t period_ns) {
  try_realtime(kRtPriority);
  const std::int64_t start = monotonic_ns();
  const std::int64_t end = o.duration >= 0 ? start + std::llround(o.duration * 1e9) : std::numeric_limits<std::int64_t>::max();
  std::int64_t deadline = start;
  std::uint64_t overruns = 0;
  for (;;) {
    sleep_until(deadline);
    if (signalled(sigfd) || deadline >= end) break;
    const SimTime t = deadline - start;
    r.receive(t, std::chrono::nanoseconds(period_ns / 4));  // the previous cycle's frame
    r.cycle(t, bn.interp.get());
    if (!bn.after_cycle(r)) break;
    if (r.master().phase() == MasterPhase::failed && !o.shell) break;
    deadline += period_ns;
    const std::int64_t now = monotonic_ns();
    if (now - deadline >= period_ns) {
      ++overruns;
      deadline += ((now - deadline) / period_ns) * period_ns;
    }
  }
  if (overruns) spdlog::info("{} cycles overran", overruns);
  const bool never_op = deadline >= end && !r.master().supervising() && r.master().phase() != MasterPhase::failed;
  shutdown_wall(r, start, period_ns);
  if (never_op) {
    spdlog::error("--duration ended before every slave reached OP (phase {})", to_string(r.master().phase()));
    return kExitRuntime;
  }
  return bn.error ? kExitRuntime : kExitOk;
}

}  // namespace

int run_ethercat_program(const ProgramOptions& o) {
  EcConfig ec;
  EcMasterConfig mc;
  std::optional<MasterConfig> platform;
  try {
    ec = load_ec_config(o.config);
    mc = make_master_config(ec);
    platform = load_platform_section(ec.platform_file, ec.platform_yaml, o.config);
  } catch (const EcConfigError& e) {
    spdlog::error("{}", e.what());
    return kExitUsage;
  } catch (const MasterConfigError& e) {
    spdlog::error("{}", e.what());
    return kExitUsage;
  }
  if (o.print_config) {
    std::cout << fmt::format("esi: {} device(s) from {} file(s)\ncycle: {}\ndc: {}\nstartup SDOs: {}\nwheels: {}\n",
                             mc.devices.size(), ec.esi_files.size(), ec.cycle, ec.dc ? "on" : "off", ec.startup.size(),
                             ec.has_wheels ? "yes" : "no");
    if (platform) std::cout << dump_master_config(*platform);
    return kExitOk;
  }
  std::vector<std::string> script;
  if (!o.script.empty()) {
    std::ifstream in(o.script);
    if (!in) {
      spdlog::error("--script {}: cannot read the file", o.script);
      return kExitUsage;
    }
    for (std::string line; std::getline(in, line);) script.push_back(line);
    // Bad input (an unknown word, a definition left open at the end, …) is found before the
    // bus is brought up: exit 2, naming the file and line.
    if (const botnana::Status s = botnana::Interpreter::check_script(script); !s) {
      spdlog::error("{}", s.located(o.script));
      return kExitUsage;
    }
  }
  std::unique_ptr<omnitwin::ethercat::EcTransport> tr;
  try {
    tr = omnitwin::ethercat::open_transport(o.iface, omnitwin::ethercat::Role::master);
  } catch (const omnitwin::ethercat::TransportError& e) {
    spdlog::error("--iface {}: {}", o.iface, e.what());
    return kExitUsage;
  }
  const std::int64_t period_ns = mc.cycle_ns;
  Runner runner(std::move(mc), ec, std::move(platform), *tr);
  // SIGINT and SIGTERM are blocked (and read from this descriptor) before the shell's reader
  // thread exists: a thread inherits the mask, and one that did not block them took the signal
  // with its default action, killing the program without its end line or statistics.
  const int sigfd = open_signal_fd();
  Botnana bn;
  // Shared with the detached reader thread, which may outlive this function.
  const auto lines = std::make_shared<LineQueue>();
  if (o.shell || !o.script.empty()) {
    bn.interp = std::make_unique<botnana::Interpreter>(runner.drives(), [](std::string_view s) { std::cout << s << std::flush; });
    bn.interp->set_cycle_period_ns(period_ns);
    bn.script = std::move(script);
    bn.script_file = o.script;
    bn.script_mode = !o.shell;
    bn.lines = lines.get();
  }
  if (o.shell) {
    for (const auto& line : bn.script) lines->push(line);  // --script with shell: evaluated first
    bn.script.clear();
    std::thread([lines] {
      using_history();
      for (;;) {
        char* raw = ::readline("botnana> ");
        if (!raw) break;
        std::string line(raw);
        std::free(raw);
        if (!line.empty()) add_history(line.c_str());
        lines->push(std::move(line));
      }
      lines->eof = true;
    }).detach();
  }
  spdlog::info("EtherCAT master on {} (clock {}, cycle {} µs)", tr->describe(), o.clock, period_ns / 1000);
  int code = kExitOk;
  try {
    code = o.clock == "sim" ? run_sim(o, runner, sigfd, bn) : run_wall(o, runner, sigfd, bn, period_ns);
  } catch (const RuntimeFailure& f) {
    spdlog::error("{}", f.message);
    code = kExitRuntime;
  } catch (const simclock::ChannelError& e) {
    spdlog::error("{}", e.what());
    code = kExitRuntime;
  }
  if (bn.error) spdlog::error("script: {}", *bn.error);
  const EcMaster& m = runner.master();
  if (m.phase() == MasterPhase::failed) {
    spdlog::error("master failed: {}", m.error());
    code = kExitRuntime;
  }
  if (runner.failure()) code = kExitRuntime;
  const auto& s = m.stats();
  spdlog::info("end: state {}, phase {}{}, {} slaves, frames tx {} rx {}, cycles {}, WKC errors {}, lost frames {}, "
               "timeouts {}, SDO done {} failed {}, slaves lost {}, recoveries {}, segment losses {} returns {}, "
               "emergencies {}",
               runner.state(), to_string(m.phase()), m.operational() ? " (OP)" : " (not OP)", m.slave_count(),
               runner.frames_tx, runner.frames_rx, s.cycles, s.wkc_errors, s.lost_frames, s.timeouts, s.sdo_done,
               s.sdo_failed, s.slaves_lost, s.recoveries, s.segment_losses, s.segment_returns, s.emergencies);
  if (!m.stop_reason().empty()) spdlog::warn("stop reason: {}", m.stop_reason());
  if (!o.stats.empty()) {
    const nlohmann::json j = {{"ecat_phase", to_string(m.phase())}, {"state", runner.state()},
                              {"slaves", m.slave_count()}, {"operational", m.operational()},
                              {"segment_lost", m.segment_lost()}, {"stop_reason", m.stop_reason()},
                              {"segment_losses", s.segment_losses}, {"segment_returns", s.segment_returns},
                              {"platform_stopped", runner.halted()}, {"lost_slave", runner.lost_slave()},
                              {"frames_tx", runner.frames_tx},
                              {"frames_rx", runner.frames_rx}, {"cycles", s.cycles}, {"wkc_errors", s.wkc_errors},
                              {"expected_wkc", s.expected_wkc}, {"last_wkc", s.last_wkc},
                              {"lost_frames", s.lost_frames}, {"stray_frames", s.stray_frames},
                              {"timeouts", s.timeouts}, {"sdo_done", s.sdo_done}, {"sdo_failed", s.sdo_failed},
                              {"slaves_lost", s.slaves_lost}, {"recoveries", s.recoveries},
                              {"emergencies", s.emergencies}, {"master_error", m.error()}};
    nlohmann::json per = nlohmann::json::array();  // emergencies per slave: count, last code
    for (int i = 0; i < m.slave_count(); ++i)
      per.push_back({{"emergencies", m.slave(i).emergencies}, {"last_emergency", m.slave(i).last_emergency}});
    nlohmann::json out = j;
    out["slave_emergencies"] = per;
    if (!write_stats_file(o.stats, out.dump())) code = kExitRuntime;
  }
  for (int i = 0; i < m.slave_count(); ++i) {
    const SlaveStatus& sl = m.slave(i);
    // An offline slave's last AL status read is stale: its state is not known.
    spdlog::info("slave {} station 0x{:04X}: step {}, AL {} (code 0x{:04X}), recoveries {}, emergencies {} (last 0x{:04X})",
                 sl.number(), sl.station, to_string(sl.step), sl.step == SlaveStep::offline ? "unknown" : to_string(sl.al_state),
                 sl.al_code, sl.recoveries, sl.emergencies, sl.last_emergency);
  }
  if (sigfd >= 0) ::close(sigfd);
  return code;
}

}  // namespace omnitwin::controller::ethercat
