// controller/mechatrolink3 — the `--bus m3` program path (see m3_program.hpp).
#include "controller/mechatrolink3/m3_program.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <poll.h>
#include <spdlog/spdlog.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <cmath>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <vector>

#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"
#include "controller/master_config.hpp"
#include "controller/mechatrolink3/m3_config.hpp"
#include "controller/mechatrolink3/m3_lockstep.hpp"
#include "controller/mechatrolink3/m3_servo_axis.hpp"
#include "controller/platform_loop.hpp"
#include "controller/program_support.hpp"
#include "controller/sim_clock.hpp"

namespace omnitwin::m3 {

namespace {

using controller::PlatformLoop;
constexpr int kExitOk = 0, kExitUsage = 2, kExitRuntime = 3;
constexpr auto kConnectTimeout = std::chrono::seconds(10);
constexpr int kGrantTimeoutMs = 60'000;
// The end of a run (wall clock, or a signal in lockstep): this long for every servo to answer
// SV_OFF and DISCONNECT.
constexpr SimTime kShutdownNs = 100'000'000;
constexpr int kRtPriority = 40;

struct RuntimeFailure {
  std::string message;
};

std::string stamp(SimTime t) { return fmt::format("[{:10.4f} ms]", static_cast<double>(t) * 1e-6); }

// The C1 master core, the four wheel axes and the platform loop, at the cyclic interrupt.
class Runner {
 public:
  Runner(const M3ProgramConfig& pc, std::optional<controller::MasterConfig> platform, C1Master::Emit emit)
      : pc_(pc), platform_(std::move(platform)) {
    ServoAxisConfig ac;
    ac.position_mode = pc.command == WheelCommand::interpolate;
    ac.synchronous = !pc.event_driven;
    ac.com_tim = 1;
    ac.params = pc.params;
    const std::vector<std::uint8_t> stations = station_addresses(pc);
    for (std::size_t i = 0; i < stations.size(); ++i)
      axes_.emplace_back(fmt::format("axis {} ({:02X}h)", i + 1, stations[i]), ac,
                         [](SimTime t, const std::string& s) { spdlog::info("{} {}", stamp(t), s); });
    misses_.assign(stations.size(), 0);
    answered_.assign(stations.size(), false);
    requested_.assign(stations.size(), 0);
    master_ = std::make_unique<C1Master>(
        make_master_config(pc), std::move(emit), [this](std::uint64_t n, SimTime t) { on_interrupt(n, t); },
        [](SimTime t, const std::string& s) { spdlog::info("{} driver: {}", stamp(t), s); });
    master_->on_event([this](int k, bool ok, SimTime latency) { on_exchange(k, ok, latency); });
    if (platform_) {
      controller::PlatformLoopConfig lc = platform_->loop;
      lc.counts_per_rev = static_cast<int>(std::lround(pc.wheel_counts_per_rev));
      loop_.emplace(lc, controller::build_path(platform_->path));
      every_ = std::max<std::int64_t>(1, std::llround(lc.period / pc.cycle));
    }
  }

  C1Master& master() { return *master_; }
  // Event-driven: each tick (one cycle) the misses, the platform loop, then one exchange
  // requested per axis (the driver queues them and runs one at a time). An axis whose last
  // cycle brought no fresh response misses one more, whether its exchange failed or is still
  // under way: lost_cycles counts cycles, as in cyclic communication, not exchanges (a silent
  // slave's exchange lasts three attempts). Cyclic communication needs none of this.
  void event_tick(SimTime t) {
    if (!pc_.event_driven || master_->state() != DriverState::event) return;
    for (std::size_t i = 0; i < axes_.size(); ++i) {
      misses_[i] = answered_[i] ? 0 : misses_[i] + 1;
      answered_[i] = false;
    }
    platform(t);
    for (int k = 0; k < static_cast<int>(axes_.size()); ++k) {
      requested_[static_cast<std::size_t>(k)] = t;
      master_->request(k, t);
    }
  }
  const C1Master& master() const { return *master_; }
  const ServoAxis& axis(int i) const { return axes_[static_cast<std::size_t>(i)]; }
  void start(SimTime t) {
    start_ns_ = t;
    master_->start(t);
  }
  // Past the start-up limit without every servo on, or the driver failed: nothing will come.
  bool failed() const { return failure_.has_value() || master_->state() == DriverState::failed; }
  const std::optional<std::string>& failure() const { return failure_; }
  bool finished() const { return finished_; }
  bool halted() const { return halted_; }

  // The end of the run: the platform loop no longer runs; every axis to zero speed, SV_OFF and
  // DISCONNECT, in the exchanges that follow (ServoAxis::shutdown).
  void shutdown(SimTime t) {
    stopping_ = true;
    if (!communicating()) return;
    spdlog::info("{} shutdown: zero speed, SV_OFF and DISCONNECT to every servo", stamp(t));
    for (auto& a : axes_) a.shutdown(t);
  }
  // The driver exchanges commands with the servos (cyclic or event-driven communication).
  bool communicating() const { return master_->state() == DriverState::cyclic || master_->state() == DriverState::event; }
  // Every servo answered DISCONNECT, or none was ever connected (the driver not communicating).
  bool shut_down() const {
    if (!communicating()) return true;
    return std::all_of(axes_.begin(), axes_.end(), [](const ServoAxis& a) { return a.step() == AxisStep::released; });
  }

  // The program's state for --stats: failed | stopped | finished | running | starting.
  std::string state() const {
    if (failed()) return "failed";
    if (halted_) return "stopped";
    if (finished_) return "finished";
    return started_ ? "running" : "starting";
  }

  // Why the program stopped, as the sim clock's report names it and with what: "" while it
  // has not stopped (running, finished), else e.g. "feedback_missing: axis 2 (…)" — for
  // --stats, where a master on its own clock (realtime) reports its end.
  std::string stop_reason() const {
    const simclock::MasterReport r = report();
    if (r.state != simclock::MasterState::stopped) return "";
    std::string what = failure_.value_or(halted_ ? halt_detail_ : master_->why());
    return what.empty() ? simclock::to_string(r.reason) : fmt::format("{}: {}", simclock::to_string(r.reason), what);
  }

  simclock::MasterReport report() const {
    simclock::MasterReport r;
    if (failed()) {
      // A configuration the line cannot take, else slaves that did not come up in time (the
      // misfit first: the axes then never start, and the start-up timeout follows from it).
      r.state = simclock::MasterState::stopped;
      r.reason = master_->misfit() ? simclock::StopReason::config_failed : simclock::StopReason::startup_timeout;
    } else if (halted_) {
      r.state = simclock::MasterState::stopped;
      r.reason = simclock::StopReason::feedback_missing;
      r.node = static_cast<std::uint8_t>(lost_axis_ + 1);
    } else if (finished_) {
      r.state = simclock::MasterState::finished;
    } else {
      r.state = started_ ? simclock::MasterState::running : simclock::MasterState::detecting;
    }
    r.path_origin_ns = started_ ? origin_ : -1;
    if (loop_) {
      const controller::Pose2& ref = out_.reference.pose;
      const controller::Pose2& odo = loop_->odometry().pose();
      r.reference = {ref.x, ref.y, ref.phi};
      r.odometry = {odo.x, odo.y, odo.phi};
    }
    return r;
  }

  nlohmann::json stats() const {
    const C1Master& m = *master_;
    nlohmann::json slaves = nlohmann::json::array();
    SlaveCounters sum;
    int recoveries = 0;
    for (int k = 0; k < m.slaves(); ++k) {
      const SlaveCounters& c = m.counters(k);
      const ServoAxis& a = axis(k);
      sum.exchanges += c.exchanges, sum.retries += c.retries, sum.retry_recovered += c.retry_recovered;
      sum.missed += c.missed, sum.late += c.late, sum.bad += c.bad;
      recoveries += a.recoveries();
      slaves.push_back({{"address", m.address(k)}, {"tr_dly_ns", m.tr_dly_ns(k)},
                        {"t_rsp_ns", m.t_rsp_ns(k)}, {"exchanges", c.exchanges}, {"retries", c.retries},
                        {"retry_recovered", c.retry_recovered}, {"missed", c.missed}, {"late", c.late},
                        {"bad", c.bad}, {"axis_step", to_string(a.step())}, {"recoveries", a.recoveries()},
                        {"device", a.device()}});
    }
    return {{"driver_state", to_string(m.state())}, {"state", state()}, {"stop_reason", stop_reason()}, {"why", m.why()},
            {"failure", failure_.value_or("")}, {"cycles", m.cycles()}, {"cycle_ns", std::llround(pc_.cycle * 1e9)},
            {"int_offset_ns", m.int_offset_ns()}, {"min_cycle_ns", m.min_cycle_ns()},
            {"foreign_master_frames", m.foreign_master_frames()}, {"platform_stopped", halted_},
            {"lost_axis", halted_ ? lost_axis_ + 1 : 0}, {"exchanges", sum.exchanges}, {"retries", sum.retries},
            {"retry_recovered", sum.retry_recovered}, {"missed", sum.missed}, {"late", sum.late}, {"bad", sum.bad},
            {"recoveries", recoveries}, {"slaves", slaves}};
  }

 private:
  // At INT_OFFSET of every cycle: the axes' step machines, then the platform loop.
  void on_interrupt(std::uint64_t, SimTime t) {
    for (int k = 0; k < static_cast<int>(axes_.size()); ++k) {
      auto& a = axes_[static_cast<std::size_t>(k)];
      const bool fresh = master_->fresh(k);
      misses_[static_cast<std::size_t>(k)] = fresh ? 0 : misses_[static_cast<std::size_t>(k)] + 1;
      a.on_interrupt(master_->response(k), fresh, master_->command(k), t);
    }
    platform(t);
  }

  // Event-driven: axis k's exchange ended (ok: its response came) latency after its request.
  void on_exchange(int k, bool ok, SimTime latency) {
    const auto i = static_cast<std::size_t>(k);
    answered_[i] = answered_[i] || ok;
    axes_[i].on_interrupt(master_->response(k), ok, master_->command(k), requested_[i] + latency);
  }

  void command(const std::array<double, 4>& ref_per_s) {
    for (std::size_t i = 0; i < 4; ++i) {
      if (pc_.command == WheelCommand::velctrl) {
        axes_[i].set_velocity(static_cast<std::int32_t>(std::lround(ref_per_s[i])));
      } else {
        target_[i] += ref_per_s[i] * pc_.cycle;
        axes_[i].set_position(static_cast<std::int32_t>(std::llround(target_[i])),
                              static_cast<std::int32_t>(std::lround(ref_per_s[i])));
      }
    }
  }
  controller::WheelCounts counts() const {
    controller::WheelCounts c{};
    for (int i = 0; i < 4; ++i) c[static_cast<std::size_t>(i)] = axis(i).position();
    return c;
  }
  // Which wheel axis is lost (no fresh response for lost_cycles, or out of operation), or -1.
  int lost_axis() const {
    for (int k = 0; k < 4; ++k)
      if (misses_[static_cast<std::size_t>(k)] >= pc_.lost_cycles || axis(k).step() != AxisStep::running) return k;
    return -1;
  }
  // Stops the platform for good: every wheel to zero speed, each held where its next response
  // says it is (INTERPOLATE: the APOS of now, not of the lost_cycles old responses it may have).
  void halt(int k, SimTime t) {
    halted_ = true;
    lost_axis_ = k;
    halt_detail_ = fmt::format("axis {} lost ({}, {} cycles without a response)", k + 1, to_string(axis(k).step()),
                               misses_[static_cast<std::size_t>(k)]);
    const controller::WheelCounts c = counts();
    for (std::size_t i = 0; i < 4; ++i) target_[i] = c[i];
    command({0, 0, 0, 0});
    for (auto& a : axes_) a.hold();
    spdlog::error("{} {} stopped: {}; wheels commanded to zero", stamp(t), loop_ ? "platform loop" : "servos",
                  halt_detail_);
  }
  // Without a platform loop (servos only, commissioning): running once every servo is on;
  // then a lost axis (the line gone, a servo off) stops them all, as the loop would.
  void supervise_axes(SimTime t) {
    if (!started_) {
      for (const auto& a : axes_)
        if (a.step() != AxisStep::running) return;
      started_ = true;
      spdlog::info("{} all {} servos on", stamp(t), axes_.size());
      return;
    }
    if (const int k = lost_axis(); k >= 0) halt(k, t);
  }
  // The path starts once every servo on the line is on (the extra axes too: the line is
  // commissioned as a whole).
  bool begin(SimTime t) {
    for (int k = 0; k < static_cast<int>(axes_.size()); ++k)
      if (axis(k).step() != AxisStep::running) {
        if (!failure_ && static_cast<double>(t - start_ns_) * 1e-9 > pc_.startup_timeout) {
          failure_ = fmt::format("axis {} not running {} s after the start (step {}{})", k + 1, pc_.startup_timeout,
                                 to_string(axis(k).step()), axis(k).why().empty() ? "" : ": " + axis(k).why());
          spdlog::error("{} {}", stamp(t), *failure_);
        }
        return false;
      }
    const controller::WheelCounts c = counts();
    for (std::size_t i = 0; i < 4; ++i) target_[i] = c[i];
    loop_->reset(loop_->path().start_pose(), c);
    origin_ = t;
    started_ = true;
    n_ = 0;
    spdlog::info("{} all {} servos on: platform loop running", stamp(t), axes_.size());
    return true;
  }
  void platform(SimTime t) {
    if (failed() || halted_ || stopping_) return;
    if (!loop_) return supervise_axes(t);
    if (!started_ && !begin(t)) return;
    if (const int k = lost_axis(); k >= 0) return halt(k, t);
    if (finished_) return command({0, 0, 0, 0});
    const double ts = static_cast<double>(t - origin_) * 1e-9;
    if (n_++ % every_ == 0) {
      out_ = loop_->step(ts, counts());
      const double k = pc_.wheel_counts_per_rev / (2 * std::numbers::pi);
      for (std::size_t i = 0; i < 4; ++i) ref_per_s_[i] = out_.wheel_rad_s[i] * k;
    }
    command(ref_per_s_);
    if (platform_->settle >= 0 && ts >= loop_->path().duration() + platform_->settle) {
      finished_ = true;
      command({0, 0, 0, 0});
      spdlog::info("{} path done", stamp(t));
    }
  }

  const M3ProgramConfig& pc_;
  std::optional<controller::MasterConfig> platform_;
  std::vector<ServoAxis> axes_;
  std::unique_ptr<C1Master> master_;
  std::optional<PlatformLoop> loop_;
  controller::PlatformLoopOutput out_;
  std::int64_t every_ = 1, n_ = 0;
  std::vector<int> misses_;  // per axis: cycles since its last fresh response
  std::vector<bool> answered_;  // event-driven: a fresh response came this cycle
  std::vector<SimTime> requested_;  // event-driven: when each axis's exchange was requested
  std::array<double, 4> ref_per_s_{}, target_{};
  bool started_ = false, finished_ = false, halted_ = false, stopping_ = false;
  int lost_axis_ = -1;
  SimTime start_ns_ = 0, origin_ = -1;
  std::optional<std::string> failure_;
  std::string halt_detail_;  // which axis was lost and how, once halted
};

void log_shutdown(const Runner& r) {
  if (r.shut_down()) {
    spdlog::info("shutdown: every servo off and disconnected");
    return;
  }
  for (int k = 0; k < r.master().slaves(); ++k)
    if (r.axis(k).step() != AxisStep::released)
      spdlog::warn("shutdown: axis {} not disconnected within {} ms (step {})", k + 1, kShutdownNs / 1'000'000,
                   to_string(r.axis(k).step()));
}

// Lockstep: one Grant per transmission cycle, every frame met with Sent/Horizon, until the
// twin ends the run (End) or a failure (throws). A grant with `stop` (the run's end) or
// SIGINT/SIGTERM ends it as the end of a wall-clock run does, in the ticks the twin still grants (kShutdownNs of simulated time at
// most): every servo to zero speed, SV_OFF and DISCONNECT; an End or the twin gone meanwhile
// ends it at once (no simulated time is left to send in), as does a second signal.
int run_sim(Runner& r, MasterLockstep& ls, int sigfd, SimTime cycle_ns) {
  simclock::Client& client = ls.clock();
  constexpr std::int64_t kNoEnd = std::numeric_limits<std::int64_t>::min();
  bool started = false, stopping = false;
  SimTime stop_from = -1;  // the first tick of the shutdown
  for (;;) {
    simclock::Grant g;
    simclock::End end{kNoEnd};
    pollfd fds[2] = {{client.fd(), POLLIN, 0}, {sigfd, POLLIN, 0}};
    const int pr = ::poll(fds, 2, kGrantTimeoutMs);
    if (pr == 0) throw RuntimeFailure{"sim clock: no grant within 60 s"};
    if (pr > 0 && (fds[1].revents & POLLIN) && controller::signalled(sigfd)) {
      if (stopping || !started) {
        if (stopping) spdlog::warn("shutdown: a second signal: ending without it");
        return kExitOk;
      }
      stopping = true;
      spdlog::info("signal: SV_OFF and DISCONNECT to every servo in the ticks the twin grants");
      continue;
    }
    const simclock::WaitStatus w = client.next(g, std::chrono::seconds(1), &end);
    if (w == simclock::WaitStatus::closed && stopping) {
      spdlog::warn("shutdown: the twin ended the run before every servo answered DISCONNECT");
      return kExitOk;
    }
    if (w == simclock::WaitStatus::closed && end.t_ns != kNoEnd) return kExitOk;
    if (w == simclock::WaitStatus::closed) throw RuntimeFailure{"sim clock: the twin went away (channel closed without End)"};
    if (w != simclock::WaitStatus::ok) throw RuntimeFailure{fmt::format("sim clock: {} while waiting for a grant", simclock::to_string(w))};
    if (!started) r.start(g.t_ns), started = true;
    if (g.stop && !stopping) {  // the run's end, in simulated time: as a signal
      stopping = true;
      spdlog::info("end of the run: SV_OFF and DISCONNECT to every servo");
    }
    if (stopping && stop_from < 0) r.shutdown(stop_from = g.t_ns);
    ls.begin_tick(g);
    r.master().advance(g.t_ns);
    r.event_tick(g.t_ns);
    if (const auto st = ls.run_tick(r.master(), g, cycle_ns); st != simclock::WaitStatus::ok)
      throw RuntimeFailure{fmt::format("tick {}: the twin stopped answering inside the tick ({})", g.tick, simclock::to_string(st))};
    const bool last = stopping && (r.shut_down() || g.t_ns + cycle_ns - stop_from >= kShutdownNs);
    simclock::Done done{g.tick, {ls.frames_sent(), 0, 0, 0}, r.report(), last};
    if (!client.done(done)) throw RuntimeFailure{"sim clock: the twin is gone"};
    if (last) {
      if (r.communicating()) log_shutdown(r);
      return kExitOk;
    }
  }
}

// Wall clock: how late the program reached the core's deadlines in cyclic communication (a
// host that stalls the master: its SYNC then goes out late and the servos may raise COMM_ALM).
// late: cycles whose deadlines it reached half a cycle or more after they were due (a stall of
// N cycles counts N: each of them is run late, in a burst). Real-time safe.
// add() says whether this one was late; the first kLogged are logged with their instant.
struct WallLateness {
  static constexpr std::uint64_t kLogged = 20;
  SimTime max_ns = 0;
  std::uint64_t late = 0;
  std::uint64_t logged = 0;  // stalls logged so far
  bool add(SimTime late_ns, SimTime cycle_ns) {
    max_ns = std::max(max_ns, late_ns);
    if (2 * late_ns < cycle_ns) return false;
    late += static_cast<std::uint64_t>(std::max<SimTime>(1, (late_ns + cycle_ns / 2) / cycle_ns));
    return true;
  }
};

// Wall clock: the core's next deadline is waited for on the transport; frames are handed over
// as they arrive. A driver that failed detection (the twin not up yet) starts again. At the end
// (--duration, SIGINT/SIGTERM) every servo to zero speed, SV_OFF and DISCONNECT, the exchanges
// going on until every servo answered or kShutdownNs is over.
int run_wall(const ProgramOptions& o, const M3ProgramConfig& pc, const std::function<std::unique_ptr<Runner>()>& make,
             std::unique_ptr<Runner>& r, M3Transport& tr, int sigfd, std::uint64_t& rx, WallLateness& lateness) {
  controller::try_realtime(kRtPriority);
  const std::int64_t start = controller::monotonic_ns();
  const std::int64_t end = o.duration >= 0 ? std::llround(o.duration * 1e9) : std::numeric_limits<std::int64_t>::max();
  std::array<std::uint8_t, 2 * kMaxFrame> buf{};
  r->start(0);
  const SimTime tick = std::llround(pc.cycle * 1e9);
  SimTime next_tick = 0;
  // One wait on the transport, until the core's next deadline or the next event-driven tick
  // (10 ms at most), then the frame that came and everything due.
  auto serve = [&](SimTime now) {
    if (pc.event_driven && now >= next_tick) {
      r->event_tick(now);
      next_tick += tick * (1 + (now - next_tick) / tick);
    }
    SimTime wake = r->master().next_wakeup();
    if (pc.event_driven) wake = wake < 0 ? next_tick : std::min(wake, next_tick);
    const SimTime wait = wake < 0 ? 10'000'000 : std::max<SimTime>(0, wake - now);
    const int n = tr.receive(buf, std::chrono::nanoseconds(std::min<SimTime>(wait, 10'000'000)));
    now = controller::monotonic_ns() - start;
    if (n > 0) ++rx;
    if (n > 0) r->master().on_frame(std::span<const std::uint8_t>(buf.data(), static_cast<std::size_t>(n)), now);
    const SimTime due = r->master().next_wakeup();
    if (due >= 0 && due <= now && r->master().state() == DriverState::cyclic && lateness.add(now - due, tick) &&
        ++lateness.logged <= WallLateness::kLogged)
      spdlog::warn("{} deadline reached {} µs late{}", stamp(now), (now - due) / 1000,
                   lateness.logged == WallLateness::kLogged ? " (later ones are only counted)" : "");
    r->master().advance(now);
  };
  for (;;) {
    const SimTime now = controller::monotonic_ns() - start;
    if (controller::signalled(sigfd) || now >= end) break;
    if (r->master().state() == DriverState::failed) {
      if (static_cast<double>(now) * 1e-9 > pc.startup_timeout) return kExitRuntime;
      spdlog::warn("{} driver failed ({}); starting again in 20 ms", stamp(now), r->master().why());
      ::usleep(20'000);  // the twin may not be up yet: the whole driver sequence again
      r = make();
      r->start(controller::monotonic_ns() - start);
      continue;
    }
    serve(now);
  }
  const SimTime stop_from = controller::monotonic_ns() - start;
  if (r->communicating()) {
    r->shutdown(stop_from);
    for (SimTime now = stop_from; !r->shut_down() && now - stop_from < kShutdownNs; now = controller::monotonic_ns() - start)
      serve(now);
    log_shutdown(*r);
  }
  return r->failed() ? kExitRuntime : kExitOk;
}

// lateness: the wall clock's, nullptr in lockstep (simulated time is never late).
bool write_stats(const std::string& path, const Runner& r, std::uint64_t tx, std::uint64_t rx,
                 const WallLateness* lateness) {
  nlohmann::json j = r.stats();
  j["frames_tx"] = tx;
  j["frames_rx"] = rx;
  if (lateness) {
    j["wakes_late"] = lateness->late;
    j["wake_late_max_ns"] = lateness->max_ns;
  }
  return controller::write_stats_file(path, j.dump());
}

void log_end(const Runner& r) {
  const C1Master& m = r.master();
  spdlog::info("end: state {}, driver {}, cycles {}, INT_OFFSET {} ns, shortest cycle {} ns, foreign C1 frames {}",
               r.state(), to_string(m.state()), m.cycles(), m.int_offset_ns(), m.min_cycle_ns(), m.foreign_master_frames());
  if (!m.why().empty()) spdlog::error("driver: {}", m.why());
  for (int k = 0; k < m.slaves(); ++k) {
    const SlaveCounters& c = m.counters(k);
    spdlog::info("slave {}: TR_DLY {} ns, T_RSP {} ns, exchanges {}, retries {} (recovered {}), missed {}, late {}, bad {}, "
                 "axis {}, recoveries {}",
                 k + 1, m.tr_dly_ns(k), m.t_rsp_ns(k), c.exchanges, c.retries, c.retry_recovered, c.missed, c.late, c.bad,
                 to_string(r.axis(k).step()), r.axis(k).recoveries());
  }
}

}  // namespace

int run_m3_program(const ProgramOptions& o) {
  M3ProgramConfig pc;
  std::optional<controller::MasterConfig> platform;
  try {
    pc = load_m3_config(o.config);
    platform = controller::load_platform_section(pc.platform_file, pc.platform_yaml, o.config);
  } catch (const M3ConfigError& e) {
    spdlog::error("{}", e.what());
    return kExitUsage;
  } catch (const controller::MasterConfigError& e) {
    spdlog::error("{}", e.what());
    return kExitUsage;
  }
  if (o.print_config) {
    std::cout << dump_m3_config(pc);
    if (platform) std::cout << controller::dump_master_config(*platform);
    return kExitOk;
  }
  std::unique_ptr<M3Transport> tr;
  try {
    tr = open_transport(o.iface, Role::master);
  } catch (const std::exception& e) {
    spdlog::error("--iface {}: {}", o.iface, e.what());
    return kExitUsage;
  }
  const SimTime cycle_ns = std::llround(pc.cycle * 1e9);
  const int sigfd = controller::open_signal_fd();
  if (pc.event_driven)
    spdlog::info("M-III C1 master on {} (clock {}, event-driven: one exchange per axis every {} µs, {} bytes, VELCTRL)",
                 tr->describe(), o.clock, cycle_ns / 1000, pc.data_bytes);
  else
    spdlog::info("M-III C1 master on {} (clock {}, transmission cycle {} µs, {} retry slot(s), {} bytes, {})", tr->describe(),
                 o.clock, cycle_ns / 1000, pc.retry_slots, pc.data_bytes,
                 pc.command == WheelCommand::velctrl ? "VELCTRL" : "INTERPOLATE");
  int code = kExitOk;
  std::unique_ptr<Runner> runner;
  std::uint64_t tx = 0, rx = 0;
  WallLateness lateness;
  try {
    if (o.clock == "sim") {
      simclock::Client client(o.sim_clock, kConnectTimeout, sigfd);
      if (!client.stopped()) {  // else SIGINT/SIGTERM while waiting for the twin's socket: exit 0
        MasterLockstep ls(*tr, client);
        runner = std::make_unique<Runner>(pc, platform, [&ls](std::span<const std::uint8_t> f, SimTime t) { ls.emit(f, t); });
        try {
          code = run_sim(*runner, ls, sigfd, cycle_ns);
        } catch (const RuntimeFailure&) {
          tx = ls.frames_sent(), rx = ls.frames_received();
          throw;
        }
        tx = ls.frames_sent(), rx = ls.frames_received();
      }
    } else {
      auto make = [&] {
        return std::make_unique<Runner>(pc, platform, [&tr, &tx](std::span<const std::uint8_t> f, SimTime) {
          if (tr->send(f)) ++tx;
        });
      };
      runner = make();
      code = run_wall(o, pc, make, runner, *tr, sigfd, rx, lateness);
      if (lateness.late > 0)
        spdlog::warn("{} of the master's cycles ran half a cycle or more late (at worst {} µs): the "
                     "host stalled this process, so SYNC and commands went out late",
                     lateness.late, lateness.max_ns / 1000);
    }
  } catch (const RuntimeFailure& f) {
    spdlog::error("{}", f.message);
    code = kExitRuntime;
  } catch (const simclock::ChannelError& e) {
    spdlog::error("{}", e.what());
    code = kExitRuntime;
  }
  if (runner) {
    if (runner->failed()) code = kExitRuntime;
    log_end(*runner);
    if (!o.stats.empty() && !write_stats(o.stats, *runner, tx, rx, o.clock == "sim" ? nullptr : &lateness)) code = kExitRuntime;
  }
  if (sigfd >= 0) ::close(sigfd);
  return code;
}

}  // namespace omnitwin::m3
