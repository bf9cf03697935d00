// twin layer — one run of a scenario; see run.hpp.
#include "twin/run.hpp"

#include <spdlog/spdlog.h>

#include <array>
#include <atomic>
#include <fstream>
#include <limits>
#include <csignal>
#include <sched.h>
#include <unistd.h>
#include <cmath>
#include <filesystem>
#include <memory>
#include <numbers>

#include "bus_emulators/can/transport.hpp"
#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "controller/path.hpp"
#include "controller/platform_loop.hpp"
#include "controller/sim_clock.hpp"
#include "physics/drive_chain.hpp"
#include "physics/platform_mjcf.hpp"
#include "physics/platform_sim.hpp"
#include "twin/bus_claim.hpp"
#include "twin/can_network.hpp"
#include "twin/ethercat_network.hpp"
#include "twin/m3_network.hpp"
#include "twin/canopen_network.hpp"
#include "twin/tml_network.hpp"
#include "twin/clock.hpp"
#include "twin/expectations.hpp"
#include "twin/master_process.hpp"
#include "twin/master_vtime.hpp"
#include "twin/metrics.hpp"
#include "twin/progress.hpp"
#include "twin/records.hpp"
#include "twin/run_directory.hpp"
#include "twin/scheduler.hpp"

namespace omnitwin::twin {

// How long a twin that runs until stopped may run at most [s] (a scenario's own limit).
constexpr double kUntilStoppedSeconds = 1e6;
namespace {

namespace fs = std::filesystem;
constexpr double kDeg = std::numbers::pi / 180.0;

// What MuJoCo runs: a generated variant, or the hand-written file the scenario named.
std::string model_name(const physics::PlatformParams& p) {
  return p.sim.mjcf.empty() ? std::string(physics::to_string(p.sim.variant)) : p.sim.mjcf;
}

// A message as one line (MuJoCo's own errors span several).
std::string one_line(std::string text) {
  for (char& c : text)
    if (c == '\n' || c == '\r') c = ' ';
  return text;
}

// Lockstep: the master and the run's thread strictly take turns, so on one CPU each hand-over
// is a plain context switch instead of a cross-CPU wake-up. The pin is the run's only: the
// thread's previous affinity comes back when the run ends (the master ends with it), and a run
// pins only while it is the process's only pinned run, so concurrent runs (omnitwin check -j N)
// keep every CPU instead of all sitting on the one the first was found on.
class CpuShare {
 public:
  CpuShare() = default;
  CpuShare(const CpuShare&) = delete;
  CpuShare& operator=(const CpuShare&) = delete;
  ~CpuShare() { release(); }

  // Pins the calling thread and `pid` to the CPU the thread runs on now (best effort).
  void pin_with(pid_t pid) {
    if (pinned_ || ::sched_getaffinity(0, sizeof saved_, &saved_) != 0) return;
    if (pinned_runs().fetch_add(1) != 0) {  // another run holds a pin: share no CPU with it
      pinned_runs().fetch_sub(1);
      return;
    }
    pinned_ = true;
    const int cpu = ::sched_getcpu();
    cpu_set_t set;
    CPU_ZERO(&set);
    if (cpu >= 0) CPU_SET(cpu, &set);
    if (cpu < 0 || ::sched_setaffinity(0, sizeof set, &set) != 0 || ::sched_setaffinity(pid, sizeof set, &set) != 0)
      spdlog::debug("could not pin the master and the twin to CPU {}", cpu);
  }
  // The thread's affinity as it was before pin_with().
  void release() {
    if (!pinned_) return;
    ::sched_setaffinity(0, sizeof saved_, &saved_);
    pinned_ = false;
    pinned_runs().fetch_sub(1);
  }

 private:
  static std::atomic<int>& pinned_runs() {
    static std::atomic<int> n{0};
    return n;
  }
  cpu_set_t saved_{};
  bool pinned_ = false;
};

// The master's last error line in its log ("" when none): why a master that ended before
// answering a tick ended (frames lost in its receive path, say). Not real-time safe.
std::string last_error_line(const fs::path& log) {
  std::ifstream f(log);
  std::string last;
  for (std::string line; std::getline(f, line);) {
    const std::size_t at = line.find("error: ");
    if (at != std::string::npos) last = line.substr(at + 7);
  }
  return last;
}

std::vector<std::string> bus_header() {
  std::vector<std::string> h{"t", "frames_tx", "frames_rx", "dropouts", "errors", "load", "active_faults"};
  for (int i = 1; i <= 4; ++i) h.push_back(fmt::format("s{}_state", i));
  return h;
}

// realtime.csv: one row per second of sim time (docs/run-directory.md).
std::vector<std::string> realtime_header() {
  return {"t", "ticks", "overruns", "late_mean_us", "late_p50_us", "late_p99_us", "late_max_us"};
}

std::string fault_target(const FaultSpec& f) {
  if (f.kind == FaultSpec::Kind::wheel_slip) return fmt::format("wheel {}", f.wheel + 1);
  if (f.kind == FaultSpec::Kind::link_break) return f.wheel == 0 ? "master" : fmt::format("after slave {}", f.wheel);
  if (f.wheel == FaultSpec::kMaster) return "master";
  if (f.wheel == FaultSpec::kAllNodes) return "all";
  return fmt::format("node {}", f.wheel + 1);
}

std::vector<std::string> trajectory_header() {
  std::vector<std::string> h{"t",      "ref_x",   "ref_y",   "ref_phi", "x",       "y",       "phi",
                             "odom_x", "odom_y",  "odom_phi", "vx",     "vy",      "wz",      "cmd_vx",
                             "cmd_vy", "cmd_wz"};
  for (int i = 1; i <= 4; ++i) {
    for (const char* f : {"cmd_rad_s", "speed_rad_s", "angle_rad", "count", "cmd_counts", "meas_counts",
                          "dac_code", "setpoint_rad_s", "torque_nm"})
      h.push_back(fmt::format("w{}_{}", i, f));
  }
  return h;
}

// Everything one run owns, wired onto one scheduler.
class PlatformRun {
 public:
  PlatformRun(const Scenario& s, const RunOptions& o)
      : s_(s),
        o_(o),
        sim_(s.platform),
        path_(controller::build_path(master_config(s).path)),
        loop_(master_config(s).loop, path_) {
    sim_.reset(s.path.x0, s.path.y0, s.path.phi0_deg * kDeg);
    for (int i = 0; i < 4; ++i) chains_[i] = std::make_unique<physics::WheelDriveChain>(s.platform, sim_.wheel_angle(i));
    loop_.reset(controller::Pose2{s.path.x0, s.path.y0, s.path.phi0_deg * kDeg}, counts());
    end_ = seconds_to_ns(o.until_stopped ? kUntilStoppedSeconds : s.duration);
  }

  // The bus network (bus `can` or `ethercat`): built after the platform, whose wheels it
  // drives. Throws the transport's error for a transport that cannot be opened.
  void build_network();
  double wheel_angle_now(int wheel) const;
  std::string master_iface() const { return net_ ? net_->master_iface() : std::string(); }

  RunResult execute();

 private:
  controller::WheelCounts counts() const {
    controller::WheelCounts c{};
    for (int i = 0; i < 4; ++i) c[i] = chains_[i]->counter().count();
    return c;
  }
  void schedule();
  void on_physics();
  void on_master(SimTime t);
  void on_device(int wheel);
  void on_record(SimTime t);
  void record_bus(SimTime t, const physics::Pose& p, const Eigen::Vector3d& v);
  // bus.csv and the observers' sample, from the row just recorded. Real-time safe.
  void record_bus_and_state(SimTime t);
  std::uint32_t active_faults(SimTime t) const;
  // One event: events.log and the observer. Returns false when the log write failed.
  bool log_event(SimTime t, std::string_view kind, std::string_view text);
  // run.json and platform.xml: what ran, for render and report (before the first step).
  void write_run_description() const;
  void on_fault(const FaultSpec& f, bool begin, SimTime t);
  void log_faults_still_active();
  // A bus network: the master process, the sim-clock tick, the master's report.
  bool on_bus() const { return net_ != nullptr; }
  void start_master();
  void start_own_master(const std::string& dir);
  void serve_master_shutdown();
  double master_grace_s() const;
  void stop_master();
  void rename_master_log();
  std::string why_not_joined(bool timed_out, const std::string& status, double limit_s);
  void on_master_bus(SimTime t);
  static simclock::Horizon answer_sent(void* self, const simclock::Sent& sent);
  // How often the master is met: its bus cycle on M-III (a polling master exchanges with
  // every slave each cycle) and CANopen (one SYNC per tick), else the control period.
  SimTime master_period_ns() const {
    if (s_.bus.kind == BusKind::m3) return seconds_to_ns(s_.bus.m3.cycle);
    if (s_.bus.kind == BusKind::canopen)  // one SYNC per tick, unless a drive produces SYNC
      return seconds_to_ns(s_.bus.canopen.sync_producer == "drive" ? s_.controller.period : s_.bus.canopen.cycle);
    if (s_.bus.kind == BusKind::tml) return seconds_to_ns(s_.bus.tml.cycle);
    return seconds_to_ns(s_.controller.period);
  }
  void on_physics_bus(SimTime t);
  void note_report(const simclock::MasterReport& r, SimTime t, bool last = false);
  void fail(std::string why);
  void supervise_master(SimTime t);
  // always_fail: the run ends whatever on_master_loss says (lockstep: nobody answers ticks).
  void master_lost(SimTime t, std::string why, bool always_fail = false);
  std::vector<std::string> expected_records() const;
  const char* master_kind() const;
  controller::Pose2 bus_reference(SimTime t) const;
  SimTime plan_origin() const;  // when the plan's path time was 0 (−1: not started)
  // A record write that failed (disk full…) ends the run as a runtime failure: remember
  // the first reason and stop the scheduler. Real-time safe on the success path.
  template <class Writer>
  void note(bool ok, const Writer& w) {
    if (ok || !error_.empty()) return;
    error_ = w.error();
    sched_.stop();
  }
  nlohmann::json metrics_json(double wall_s, bool interrupted) const;
  void last_row_totals(nlohmann::json& bus) const;
  RunResult finish(double wall_s, const RealtimePacer* realtime);
  // SIGINT/SIGTERM has asked the run to end. Real-time safe.
  bool signalled() const { return o_.interrupt && o_.interrupt->load(); }

  const Scenario& s_;
  const RunOptions& o_;
  physics::PlatformSim sim_;
  controller::Path path_;
  controller::PlatformLoop loop_;
  std::array<std::unique_ptr<physics::WheelDriveChain>, 4> chains_;
  Scheduler sched_;
  Pacer* pacer_ = nullptr;
  SimTime end_;

  // What the master last decided, and what the slaves do with it (the `direct` link).
  controller::PlatformLoopOutput out_{};
  std::array<double, 4> wheel_cmd_rad_s_{};
  int segment_ = -1;
  std::uint64_t physics_steps_ = 0;
  std::string error_;  // why the run ended early ("" = it did not)

  // Records and indices.
  std::unique_ptr<CsvWriter> csv_;
  std::unique_ptr<CsvWriter> bus_csv_;
  std::unique_ptr<CsvWriter> realtime_csv_;  // realtime runs: tick lateness per second
  std::unique_ptr<EventLog> events_;
  std::vector<double> bus_row_;
  StateSample state_{};
  std::int64_t last_busy_ns_ = 0;
  SimTime last_record_ns_ = 0;
  std::uint64_t records_ = 0;  // control samples recorded
  std::unique_ptr<ProgressBar> progress_;
  PoseErrorStats truth_stats_, odom_stats_;
  DriveHistory drive_history_;
  std::array<double, 3> final_pose_{};  // x, y [m], phi [rad] at the last control sample
  SimTime path_done_ns_ = -1;           // when the plan reached the path's end (−1: not in this run)
  std::array<VelocityErrorStats, 4> axis_stats_;
  std::array<VelocityErrorStats, 4> axis_master_stats_;  // the same per control period, as the master sees it
  std::vector<double> row_;

  // a bus network (`can`, `ethercat`)
  std::unique_ptr<BusNetwork> net_;
  std::unique_ptr<simclock::Server> clock_server_;
  // a master of the user's own (master.command): on the virtual clock in lockstep
  std::unique_ptr<VtimeServer> vtime_server_;
  std::unique_ptr<VtimePacer> vtime_pacer_;
  std::string master_command_;  // as run, {iface}, {ifname} and {out} substituted
  std::unique_ptr<MasterProcess> master_;
  CpuShare cpu_share_;  // lockstep: the run's thread and its master on one CPU, until stop_master()
  std::string master_program_;
  simclock::MasterReport report_{};
  simclock::MasterReport run_report_{};  // the last report before the run's end (metrics: not the shutdown's)
  std::uint64_t tick_ = 0;
  SimTime master_stop_ns_ = -1;
  // realtime supervision of the master process we started
  std::uint64_t heard_frames_ = 0;   // frames from the transport at the last master tick
  bool heard_master_ = false;        // a frame of the master's has arrived
  int silent_periods_ = 0;           // control periods without one since
  SimTime master_lost_ns_ = -1;
  std::string master_lost_why_;
  bool master_hung_ = false;  // a lockstep master left a grant unanswered after an interrupt
  // the run's end: SIGTERM to a master on its own clock, `stop` in the grants of a lockstep
  // master of ours; either is served until the master exits
  SimTime sigterm_ns_ = -1;       // when it was asked (−1: not asked)
  std::string stop_signal_;       // what asked it: "SIGTERM" (the twin's), the terminal's SIGINT, or the grants
  SimTime master_exit_ns_ = -1;   // when the master was seen to exit after it (−1: not seen)
  SimTime last_done_ns_ = -1;     // lockstep: the tick of the master's last Done
  std::array<double, 4> bus_setpoint_{};  // what the network last asked of each wheel [rad/s]
  double handshake_timeout_s_ = 10;
};

// Wheel shaft angle [rad] at the scheduler's time: MuJoCo's state is up to one physics step
// ahead of a device event, so the event reads the angle of its own instant.
double PlatformRun::wheel_angle_now(int wheel) const { return sim_.wheel_angle_at(wheel, ns_to_seconds(sched_.now())); }

void PlatformRun::build_network() {
  BusNetwork::Hooks h;
  h.wheel_angle = [this](int i) { return wheel_angle_now(i); };
  h.wheel_angle_at = [this](int i, SimTime t) { return sim_.wheel_angle_at(i, ns_to_seconds(t)); };
  h.wheel_speed = [this](int i) { return sim_.wheel_speed(i); };
  h.set_setpoint = [this](int i, double w) {
    sim_.set_wheel_speed_setpoint(i, w);
    bus_setpoint_[static_cast<std::size_t>(i)] = sim_.wheel_setpoint(i);
  };
  h.set_amplifier_input = [this](int i, double volts) {
    sim_.set_wheel_amplifier_input(i, volts);
    bus_setpoint_[static_cast<std::size_t>(i)] = sim_.wheel_setpoint(i);
  };
  h.axis_sample = [this](int i, double e) {
    if (sched_.now() <= end_) axis_stats_[static_cast<std::size_t>(i)].add(e);  // not the master's shutdown
  };
  h.axis_sample_at_master = [this](int i, double e) {
    if (sched_.now() <= end_) axis_master_stats_[static_cast<std::size_t>(i)].add(e);
  };
  h.log = [this](SimTime t, std::string_view kind, const std::string& text) {
    if (events_) note(log_event(t, kind, text), *events_);
  };
  if (s_.bus.kind == BusKind::ethercat) {
    master_program_ = find_master_program(s_.bus.ethercat.master);
    handshake_timeout_s_ = s_.bus.ethercat.handshake_timeout;
    net_ = std::make_unique<EthercatNetwork>(s_, sched_, std::move(h));
  } else if (s_.bus.kind == BusKind::m3) {
    master_program_ = find_master_program(s_.bus.m3.master);
    handshake_timeout_s_ = s_.bus.m3.handshake_timeout;
    net_ = std::make_unique<M3Network>(s_, sched_, std::move(h));
  } else if (s_.bus.kind == BusKind::canopen) {
    master_program_ = find_master_program(s_.bus.can.master);
    handshake_timeout_s_ = s_.bus.can.handshake_timeout;
    net_ = std::make_unique<CanopenNetwork>(s_, sched_, std::move(h));
  } else if (s_.bus.kind == BusKind::tml) {
    master_program_ = find_master_program(s_.bus.can.master);
    handshake_timeout_s_ = s_.bus.can.handshake_timeout;
    net_ = std::make_unique<TmlNetwork>(s_, sched_, std::move(h));
  } else {
    master_program_ = find_master_program(s_.bus.can.master);
    handshake_timeout_s_ = s_.bus.can.handshake_timeout;
    net_ = std::make_unique<OmniCanNetwork>(s_, sched_, std::move(h));
  }
}

void PlatformRun::fail(std::string why) {
  if (error_.empty()) error_ = std::move(why);
  sched_.stop();
}

// What a master that exited before joining the clock last wrote to its log (usually why),
// as ": it said: …"; "" while it runs or when it wrote nothing.
std::string last_words(MasterProcess& master, const std::string& log) {
  if (master.running()) return "";
  const std::string tail = log_tail(log, 3);
  return tail.empty() ? "" : ": it said: " + tail;
}

// The master process: its configuration and log in the run directory; lockstep meets it on
// the sim-clock channel, realtime lets it run on its own wall clock.
void PlatformRun::start_master() {
  // Absolute: the master resolves the paths inside its configuration against the file's folder.
  const fs::path dir = fs::absolute(o_.out_dir);
  const std::string cfg = (dir / "master.yaml").string();
  if (s_.bus.kind == BusKind::ethercat) {
    const std::string platform = (dir / "master-platform.yaml").string();
    write_text_atomic(platform, ethercat_platform_yaml(s_));
    write_text_atomic(cfg, ethercat_master_config_yaml(s_, platform));
  } else if (s_.bus.kind == BusKind::m3) {
    const std::string platform = (dir / "master-platform.yaml").string();
    write_text_atomic(platform, m3_platform_yaml(s_));
    write_text_atomic(cfg, m3_master_config_yaml(s_, platform));
  } else if (s_.bus.kind == BusKind::canopen) {
    const std::string platform = (dir / "master-platform.yaml").string();
    write_text_atomic(platform, canopen_platform_yaml(s_));
    write_text_atomic(cfg, canopen_master_config_yaml(s_, platform));
  } else if (s_.bus.kind == BusKind::tml) {
    const std::string platform = (dir / "master-platform.yaml").string();
    write_text_atomic(platform, tml_platform_yaml(s_));
    write_text_atomic(cfg, tml_master_config_yaml(s_, platform));
  } else {
    write_text_atomic(cfg, master_config_yaml(s_));
  }
  // A master of the user's own may read them too ({out}/master.yaml).
  if (!s_.master.command.empty()) return start_own_master(dir.string());
  std::vector<std::string> args{"--bus", net_->name(), "--iface", net_->master_iface(), "--config", cfg};
  if (s_.bus.kind == BusKind::ethercat || s_.bus.kind == BusKind::m3 || s_.bus.kind == BusKind::canopen ||
      s_.bus.kind == BusKind::tml)
    args.insert(args.end(), {"--stats", (dir / "master-stats.json").string()});
  const bool lockstep = s_.clock == ClockMode::lockstep;
  if (lockstep) {
    // An abstract socket: no file, so no directory (/tmp on 9p, a read-only TMPDIR) can refuse
    // it, and a short name whatever the run directory is (sun_path holds 108 bytes).
    static std::atomic<int> serial{0};
    const std::string addr = fmt::format("unix:@omnitwin-{}-{}.clock", ::getpid(), serial++);
    clock_server_ = std::make_unique<simclock::Server>(addr);
    clock_server_->set_stop_flag(o_.interrupt);  // a Ctrl-C does not wait out a hung master's timeout
    args.insert(args.end(), {"--clock", "sim", "--sim-clock", addr});
    // A CAN master waits for the frames a grant counts as long as the twin waits for its Done.
    if (s_.bus.kind == BusKind::can || s_.bus.kind == BusKind::canopen || s_.bus.kind == BusKind::tml)
      args.insert(args.end(), {"--frames-timeout", fmt::format("{}", handshake_timeout_s_)});
  } else {
    args.insert(args.end(), {"--clock", "wall"});
  }
  // Its output goes to DIR/.master.log.part, renamed to master.log once it has ended.
  master_ = std::make_unique<MasterProcess>(master_program_, args, (dir / ".master.log.part").string());
  if (lockstep) {
    // The two processes strictly take turns: on one CPU each hand-over is a plain context
    // switch instead of a cross-CPU wake-up (3× cheaper per tick on this VM).
    cpu_share_.pin_with(master_->pid());
    // Wait for its Hello, noticing at once a master that died instead of connecting.
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::milliseconds(std::llround(handshake_timeout_s_ * 1e3));
    simclock::WaitStatus st = simclock::WaitStatus::timeout;
    while (st == simclock::WaitStatus::timeout && master_->running() && std::chrono::steady_clock::now() < deadline)
      st = clock_server_->accept(std::chrono::milliseconds(100));
    if (st != simclock::WaitStatus::ok)
      throw std::runtime_error(fmt::format("the master did not connect to the sim clock ({}; see master.log){}",
                                           why_not_joined(st == simclock::WaitStatus::timeout, simclock::to_string(st),
                                                          handshake_timeout_s_),
                                           last_words(*master_, (dir / ".master.log.part").string())));
  }
  log_event(0, "master", fmt::format("{} started (pid {}, clock {})", master_program_, master_->pid(),
                                     lockstep ? "sim" : "wall"));
}

// Why a master started in lockstep did not join its clock, for the start error: it ended first
// (with its exit), it was still running when `limit_s` ran out (it is then stopped with the short
// grace, stop_master), or the connection's own status (`status`: refused, closed, a protocol error).
std::string PlatformRun::why_not_joined(bool timed_out, const std::string& status, double limit_s) {
  if (!master_->running()) return "it ended first: " + master_->describe_exit();
  if (!timed_out) return status + "; " + master_->describe_exit();
  master_hung_ = true;
  return fmt::format("none within {:g} s; it was still running and was stopped", limit_s);
}

// A master the user brings: its command line with {iface}, {ifname} and {out} filled in, started under
// the virtual-time library (lockstep) or plainly (realtime). Throws std::runtime_error when it
// cannot start or, in lockstep, never joins the virtual clock.
void PlatformRun::start_own_master(const std::string& dir) {
  std::vector<std::string> words;
  try {
    words = split_command(s_.master.command);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(fmt::format("master.command: {}", e.what()));
  }
  if (words.empty()) throw std::runtime_error("master.command: empty");
  const std::string iface = net_->master_iface();
  const std::string ifname = iface.starts_with("raw:") ? iface.substr(4) : iface;
  for (std::string& w : words) {
    for (std::size_t at; (at = w.find("{iface}")) != std::string::npos;) w.replace(at, 7, net_->master_iface());
    // The bare interface name (raw:NAME → NAME) for masters that take one, as SOEM's samples do.
    for (std::size_t at; (at = w.find("{ifname}")) != std::string::npos;) w.replace(at, 8, ifname);
    for (std::size_t at; (at = w.find("{out}")) != std::string::npos;) w.replace(at, 5, dir);
  }
  master_program_ = words[0];
  for (const std::string& w : words) master_command_ += (master_command_.empty() ? "" : " ") + w;
  const std::vector<std::string> args(words.begin() + 1, words.end());
  const std::string log = (fs::path(dir) / ".master.log.part").string();
  const bool vtime = s_.virtual_time_master();
  if (!vtime) {
    master_ = std::make_unique<MasterProcess>(master_program_, args, log);
    log_event(0, "master", fmt::format("{} started (pid {}, clock wall)", master_command_, master_->pid()));
    return;
  }
  if (const std::string why = preload_obstacle(master_program_); !why.empty())
    throw std::runtime_error(fmt::format("master: {} is {}: it cannot run on the virtual clock (lockstep); run it "
                                         "with --clock realtime, or set master.on_static: realtime",
                                         master_program_, why));
  vtime_server_ = std::make_unique<VtimeServer>();
  master_ = std::make_unique<MasterProcess>(master_program_, args, log,
                                            vtime_server_->environment(find_vtime_library(), net_->master_iface()));
  cpu_share_.pin_with(master_->pid());  // the two take turns: a context switch, not a cross-CPU wake-up
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(std::llround(s_.master.watchdog * 1e3));
  VtimeServer::Status st = VtimeServer::Status::timeout;
  while (st == VtimeServer::Status::timeout && master_->running() && std::chrono::steady_clock::now() < deadline)
    st = vtime_server_->accept(std::chrono::milliseconds(100), 0);
  if (st != VtimeServer::Status::ok)
    throw std::runtime_error(fmt::format("master: {} did not join the virtual clock ({}; see master.log){}",
                                         master_program_,
                                         why_not_joined(st == VtimeServer::Status::timeout, to_string(st), s_.master.watchdog),
                                         last_words(*master_, log)));
  log_event(0, "master", fmt::format("{} started (pid {}, clock virtual)", master_command_, master_->pid()));
}

// How long a master on its own clock may take to end after the SIGTERM of the run's end [s]:
// master.stop_grace (default 3 s), for ours as for a program of the user's (ours was held to a
// fixed 3 s that the setting did not change; found in review).
double PlatformRun::master_grace_s() const { return s_.master.stop_grace; }

// The run has reached its end. A master on its own clock (realtime, or a program of the user's
// on the virtual clock) is sent SIGTERM, and the bus, the physics and the records (and the
// virtual clock) go on until it has exited, for at most its grace: the frames of its own
// shutdown (drives disabled, slaves to INIT, NMT stop) are answered and recorded, and the
// records end at the first control sample a control period or more after its exit. A lockstep
// master of ours is asked in simulated time instead: every grant from then on carries `stop`
// (docs/protocols/sim-clock.md), so its shutdown is recorded the same every run; it has ended
// when the grant after its last Done finds it gone. A lost or failed run is not extended.
//
// Interrupted (SIGINT/SIGTERM to the twin) with a master on the wall clock or a lockstep master
// of ours, the same: the master is asked to stop (SIGTERM, unless the signal was the terminal's
// Ctrl-C, which the master had too: a second signal would cut its shutdown short; in lockstep
// the grants' `stop`) and served until it has
// exited; the run stays interrupted (exit 3) and its figures end at the interrupt. A second
// signal to the twin ends the serving at once. (Before, the twin stopped answering at the
// Ctrl-C and the master's shutdown ran on a bus no one served.)
void PlatformRun::serve_master_shutdown() {
  if (!master_ || !error_.empty() || master_lost_ns_ >= 0) return;
  const bool interrupted = signalled();
  if (interrupted && (vtime_pacer_ || !o_.signals || o_.until_stopped)) return;
  // Lockstep: the terminal's Ctrl-C reached a master of ours too, and it ran its end sequence
  // in the ticks already granted and left (on_master_bus saw it end); that was its shutdown.
  const bool ended_itself = clock_server_ && interrupted && master_exit_ns_ >= 0;
  if (!ended_itself && !master_->running()) return;
  // A signal to the twin (Ctrl-C, SIGTERM) beyond those seen now ends the serving at once.
  const int seen = o_.signals ? o_.signals->load() : 0;
  const auto signal_came = [this, seen, interrupted] {
    return o_.signals ? o_.signals->load() > seen : (!interrupted && signalled());
  };
  sigterm_ns_ = ended_itself ? master_exit_ns_ : sched_.now();
  // The terminal's Ctrl-C went to its foreground group: the master had it only if it is still
  // in the twin's group (a master that left it by setsid/setpgid gets SIGTERM; found in review).
  const bool terminal = ended_itself || (interrupted && o_.terminal_signal && o_.terminal_signal->load() &&
                                         ::getpgid(master_->pid()) == ::getpgrp());
  // A lockstep master of ours is asked in simulated time (Grant.stop), so its shutdown is the
  // same every run; a terminal's Ctrl-C reached it too, and it ends as at either.
  const bool grants = clock_server_ != nullptr && !ended_itself;
  stop_signal_ = grants ? kStopInTheGrants : terminal ? "SIGINT from the terminal" : "SIGTERM";
  if (interrupted) end_ = std::min(end_, sigterm_ns_);  // the figures and faults end at the interrupt
  if (!terminal && !grants) master_->terminate();
  const std::string why = interrupted ? "interrupted" : "end of the run";
  const std::string more = interrupted ? "; another signal ends that" : "";
  note(log_event(sigterm_ns_, "master",
                 grants     ? fmt::format("{}: stop in every grant from now on; the bus is served until the master "
                                          "exits (at most {} s{})",
                                          why, master_grace_s(), more)
                 : ended_itself ? fmt::format("{}: the terminal's signal reached the master too; it ran its end "
                                              "sequence in the ticks it had and left",
                                              why)
                 : terminal ? fmt::format("{}: the terminal's signal reached the master too; the bus is served until "
                                          "it exits (at most {} s; another signal ends that)",
                                          why, master_grace_s())
                            : fmt::format("{}: SIGTERM; the bus is served until the master exits (at most {} s{})", why,
                                          master_grace_s(), more)),
       *events_);
  if (vtime_pacer_) vtime_pacer_->expect_end(SIGTERM);  // a wait it holds ends now, as on Linux
  // (Under the virtual clock a master the signal killed in its wait has left already.)
  if (!ended_itself && (!vtime_pacer_ || !vtime_pacer_->ended()))
    sched_.run_until(sigterm_ns_ + seconds_to_ns(master_grace_s()) + 1, *pacer_, signal_came);
  if (vtime_pacer_ && vtime_pacer_->ended()) master_exit_ns_ = vtime_pacer_->master_now();
  if (master_exit_ns_ < 0) return;
  // Its exit in time order in events.log (it has left the clock; reaped within a moment).
  master_->wait(std::chrono::milliseconds(std::llround(master_grace_s() * 1e3)));
  log_event(master_exit_ns_, "master", fmt::format("ended: {}", master_->describe_exit()));
  if (signal_came() || !error_.empty()) return;
  // To the first control sample a control period or more after it: the last record shows the
  // state the master left behind, and its last AL or NMT change is logged (the slaves' next
  // cycles log it).
  const SimTime tm = seconds_to_ns(s_.controller.period);
  sched_.run_until((master_exit_ns_ + 2 * tm - 1) / tm * tm + 1, *pacer_, signal_came);
}

void PlatformRun::stop_master() {
  if (!master_) return;
  // Whether it was still there when its grace ran out: asked before End, which a lockstep
  // master obeys at once (it then looked gone, and a master of ours not yet asked passed).
  const bool was_running = master_->running() || master_->descendants_alive();
  if (clock_server_) clock_server_->end(sched_.now());
  if (vtime_server_) vtime_server_->end(vtime_pacer_ ? vtime_pacer_->master_now() : sched_.now());
  // The master exits on End (lockstep); in realtime, and a master of the user's, by SIGTERM,
  // sent at the run's end (serve_master_shutdown) and again here. A master already found lost,
  // or one that had its grace while it was served, gets a short one: the end is not kept
  // waiting on it.
  const bool own = !s_.master.command.empty();
  const auto grace = std::chrono::milliseconds(master_lost_ns_ >= 0 || sigterm_ns_ >= 0 || master_hung_ ? 300
                                                                                   : std::llround(master_grace_s() * 1e3));
  if (!clock_server_ || !master_->wait(grace)) master_->stop(grace);
  cpu_share_.release();  // the thread's own affinity again, the master gone
  if (master_exit_ns_ < 0) log_event(sched_.now(), "master", fmt::format("ended: {}", master_->describe_exit()));
  if (!error_.empty() || signalled()) return rename_master_log();
  const int code = master_->exit_code();
  // Served for its whole grace and still there: the verdict does not hang on how it ended
  // after (a master failing on the unserved bus in the last 0.3 s passed; found in review).
  const bool outlived = sigterm_ns_ >= 0 && master_exit_ns_ < 0 && was_running;
  if (outlived || (own && was_running && code == 128 + SIGKILL))
    error_ = fmt::format("master: {} did not end within {:g} s of {}: {}", master_program_, master_grace_s(),
                         stop_signal_ == kStopInTheGrants ? "the stop in its grants" : "SIGTERM",
                         code == 128 + SIGKILL ? std::string("killed") : "it ended after (" + master_->describe_exit() + ")");
  // Exited while served, but not cleanly: its shutdown failed (exit 0, or killed by the SIGTERM
  // itself for a program without a handler, are clean).
  else if (master_exit_ns_ >= 0 && code != 0 && code != 128 + SIGTERM)
    error_ = fmt::format("master: {} ended its shutdown with {} (see master.log)", master_program_,
                         master_->describe_exit());
  rename_master_log();
}

// .master.log.part becomes master.log once the master is gone.
void PlatformRun::rename_master_log() {
  const fs::path dir(o_.out_dir);
  std::error_code ec;
  fs::rename(dir / ".master.log.part", dir / "master.log", ec);
  if (ec && error_.empty()) error_ = fmt::format("cannot rename {}: {}", (dir / ".master.log.part").string(), ec.message());
}

// One master tick in lockstep: the bus is run to t, the master is granted t with the count
// of frames put on the transport so far, and its frames (exactly as many as it says it sent)
// are queued on the wire at t + T_pre.
void PlatformRun::on_master_bus(SimTime t) {
  pacer_->tick(t);
  net_->advance(t);
  if (!vtime_pacer_) net_->flush_transport();  // lockstep: this tick's slave frames, before the grant counts them
  net_->flush_pcap();  // a record boundary per tick; write-behind: a kill loses the last 20 ms
  if (std::string why = net_->pcap_error(); !why.empty()) return fail(why);  // a full disk
  if (vtime_pacer_) return;  // the master's waits pace the run (VtimePacer)
  if (!clock_server_) return supervise_master(t);  // realtime: the master keeps its own time
  if (master_exit_ns_ >= 0) return;  // it ended its shutdown: nothing left to grant
  const auto timeout = std::chrono::milliseconds(std::llround(handshake_timeout_s_ * 1e3));
  simclock::Grant g;
  g.tick = tick_++;
  g.t_ns = t;
  g.frames[0] = net_->frames_to_transport();
  g.stop = sigterm_ns_ >= 0;  // the run's end (serve_master_shutdown)
  simclock::Done d;
  // A polling bus (M-III) meets each of the master's frames inside the tick.
  const simclock::WaitStatus st = net_->answers_inside_tick()
                                      ? clock_server_->grant(g, d, timeout, &PlatformRun::answer_sent, this)
                                      : clock_server_->grant(g, d, timeout);
  // Asked to stop, it ran its end sequence and left after its last Done: it ended then.
  if (st == simclock::WaitStatus::closed && g.stop && master_->wait(std::chrono::milliseconds(500))) {
    master_exit_ns_ = last_done_ns_ >= 0 ? last_done_ns_ : t;
    sched_.stop();
    return;
  }
  if (st == simclock::WaitStatus::closed && master_->wait(std::chrono::milliseconds(500))) {
    // A Ctrl-C at a terminal reaches the master too (one process group): its end is then the
    // interruption's, and the run ends as interrupted, not with a lost master (seen gone now:
    // its shutdown, if it ran one, is served as the interruption's; serve_master_shutdown).
    if (signalled()) {
      master_exit_ns_ = t;
      return sched_.stop();
    }
    // The master ended mid-run (crash, kill): a lost master, as realtime supervision says it,
    // but always the run's end: in lockstep nothing else answers the ticks.
    const std::string why = last_error_line(fs::path(o_.out_dir) / ".master.log.part");
    return master_lost(t,
                       fmt::format("the master process ended ({}) before answering tick {}{}", master_->describe_exit(),
                                   g.tick, why.empty() ? "" : ": " + why),
                       true);
  }
  if (st == simclock::WaitStatus::timeout && signalled() && !g.stop) {
    master_hung_ = true;  // it gets the short grace at the end (stop_master)
    return fail(fmt::format("master: no answer to tick {} within 1 s of the interrupt ({})", g.tick,
                            master_->running() ? "still running" : master_->describe_exit()));
  }
  if (st != simclock::WaitStatus::ok)
    return fail(fmt::format("master: no answer to tick {} ({}; {})", g.tick, simclock::to_string(st),
                            master_->running() ? "still running" : master_->describe_exit()));
  if (!net_->drain_transport(d.frames[0], t, timeout))
    return fail(fmt::format("master: tick {} said {} frames sent, {} arrived on {}", g.tick, d.frames[0],
                            net_->frames_from_transport(), net_->master_iface()));
  last_done_ns_ = t;
  // Its end sequence asked for (stop, or the interrupt that reached it too) and over: it leaves
  // now, so it ended at this tick and nothing later is recorded before its end.
  const bool ended = d.last && (g.stop || signalled());
  note_report(d.report, t, ended);
  if (ended) {
    master_exit_ns_ = t;
    sched_.stop();
  }
}

// The Sent handler of a polling bus: the network answers; a transport that did not deliver
// the master's frames in time fails the run after the grant (its Done never matches).
simclock::Horizon PlatformRun::answer_sent(void* self, const simclock::Sent& sent) {
  auto* run = static_cast<PlatformRun*>(self);
  const auto timeout = std::chrono::milliseconds(std::llround(run->handshake_timeout_s_ * 1e3));
  return run->net_->on_sent(sent, timeout);
}

// Realtime: the master is watched instead of met. Its process must live, and once it has
// been heard its frames must keep coming (the masters send every control period); before
// its first frame it has handshake_timeout to start. Real-time safe but for waitpid().
void PlatformRun::supervise_master(SimTime t) {
  if (!master_ || master_lost_ns_ >= 0) return;
  // Shutting down after the end's SIGTERM: it may fall silent, and it has ended when it and all
  // it started have (a wrapper's shell may go first); the records end a period later.
  if (sigterm_ns_ >= 0) {
    if (master_exit_ns_ < 0 && !master_->running() && !master_->descendants_alive()) {
      master_exit_ns_ = t;
      sched_.stop();
    }
    return;
  }
  if (!master_->running()) {
    if (signalled()) return;  // the same Ctrl-C ended it (see on_master_bus())
    return master_lost(t, fmt::format("the master process ended ({})", master_->describe_exit()));
  }
  const std::uint64_t rx = net_->frames_from_transport();
  if (rx != heard_frames_) {
    heard_frames_ = rx;
    heard_master_ = true;
    silent_periods_ = 0;
    return;
  }
  // A master that stopped its bus on purpose may be silent (it is still watched for its end).
  if (!net_->master_must_talk()) {
    silent_periods_ = 0;
    return;
  }
  const int limit = s_.bus.supervision.silent_periods;
  if (heard_master_ && ++silent_periods_ >= limit)
    return master_lost(t, fmt::format("no frame from the master for {} master periods ({:.0f} ms): it stopped answering",
                                      limit, limit * ns_to_seconds(master_period_ns()) * 1e3));
  if (!heard_master_ && ns_to_seconds(t) > handshake_timeout_s_)
    master_lost(t, fmt::format("no frame from the master within {:.1f} s of its start", handshake_timeout_s_));
}

void PlatformRun::master_lost(SimTime t, std::string why, bool always_fail) {
  master_lost_ns_ = t;
  master_lost_why_ = why;
  note(log_event(t, "master", "lost: " + why), *events_);
  if (always_fail || s_.bus.supervision.on_master_loss == SupervisionSpec::OnLoss::fail) fail("master lost: " + why);
}

// last: the Done that ended its end sequence. A report in the end sequence (asked, or an
// interrupt that reached the master too) is not what the run left: stopping then is no reaction.
void PlatformRun::note_report(const simclock::MasterReport& r, SimTime t, bool last) {
  const bool ending = sigterm_ns_ >= 0 || last || signalled();
  if (r.state != report_.state || r.reason != report_.reason) {
    std::string text = fmt::format("state {}", simclock::to_string(r.state));
    if (r.reason != simclock::StopReason::none)
      text += fmt::format(" ({}{})", simclock::to_string(r.reason), r.node ? fmt::format(", node 0x{:02X}", r.node) : "");
    note(log_event(t, "master", text), *events_);
    // Stopped at the run's end as asked is its shutdown, not a reaction (master.stopped_at_s).
    if (r.state == simclock::MasterState::stopped && master_stop_ns_ < 0 && !ending) master_stop_ns_ = t;
  }
  report_ = r;
  if (!ending) run_report_ = r;
}

void PlatformRun::on_physics_bus(SimTime t) {
  net_->advance(t);
  if (!clock_server_ && !vtime_server_) net_->poll_transport(t);  // realtime: frames as they come
  sim_.step();
  ++physics_steps_;
  net_->observe_wheels();
}

// Path time 0 of the plan: bus direct's loop starts at 0; a lockstep master reports its own;
// otherwise the path starts when the master's start-all completed.
SimTime PlatformRun::plan_origin() const {
  if (!on_bus()) return 0;
  return clock_server_ ? report_.path_origin_ns : net_->master_start_ns();
}

// The plan at t: the master's own (lockstep), else the path from when its start-all completed.
controller::Pose2 PlatformRun::bus_reference(SimTime t) const {
  const SimTime origin = plan_origin();
  if (origin < 0) return path_.start_pose();
  return path_.sample(std::max(0.0, ns_to_seconds(t - origin))).pose;
}

void PlatformRun::schedule() {
  const SimTime dt = seconds_to_ns(s_.platform.sim.timestep);
  const SimTime tm = seconds_to_ns(s_.controller.period);
  const SimTime ts = seconds_to_ns(s_.platform.velocity_loop.period);
  if (on_bus()) {
    // The slaves' timers belong to the network (CAN: they start with NMT start). The master
    // is met every master period (its bus cycle on M-III), the records every control period.
    sched_.add_periodic("master", Phase::master, 0, master_period_ns(), [this](SimTime t) { on_master_bus(t); });
    sched_.add_periodic("record", Phase::record, 0, tm, [this](SimTime t) { on_record(t); });
    sched_.add_periodic("physics", Phase::physics, 0, dt, [this](SimTime t) { on_physics_bus(t); });
  } else {
    sched_.add_periodic("master", Phase::master, 0, tm, [this](SimTime t) { on_master(t); });
    for (int i = 0; i < 4; ++i)
      sched_.add_periodic(fmt::format("slave{}", i + 1), Phase::device, 0, ts, [this, i](SimTime) { on_device(i); });
    sched_.add_periodic("record", Phase::record, 0, tm, [this](SimTime t) { on_record(t); });
    sched_.add_periodic("physics", Phase::physics, 0, dt, [this](SimTime) { on_physics(); });
  }
  for (const FaultSpec& f : s_.faults) {
    sched_.add_once("fault", Phase::fault, seconds_to_ns(f.at), [this, &f](SimTime t) { on_fault(f, true, t); });
    if (f.duration > 0)
      sched_.add_once("fault-end", Phase::fault, seconds_to_ns(f.at + f.duration),
                      [this, &f](SimTime t) { on_fault(f, false, t); });
  }
}

void PlatformRun::on_physics() {
  sim_.step();
  ++physics_steps_;
  // The HCTL-2032 samples its lines far faster than anything else: follow every step.
  for (int i = 0; i < 4; ++i) chains_[i]->observe(sim_.wheel_angle(i));
}

void PlatformRun::on_master(SimTime t) {
  pacer_->tick(t);
  out_ = loop_.step(ns_to_seconds(t), counts());
  for (int i = 0; i < 4; ++i) wheel_cmd_rad_s_[i] = out_.wheel_rad_s(i);
  if (out_.reference.segment != segment_) {
    segment_ = out_.reference.segment;
    if (segment_ >= 0 && segment_ < static_cast<int>(s_.path.segments.size()))
      note(log_event(t, "path", fmt::format("segment {} starts", segment_ + 1)), *events_);
  }
}

void PlatformRun::on_device(int wheel) {
  // The slave converts the speed it was sent into counts per its own nominal sample.
  const double per_sample = s_.platform.velocity_loop.period * s_.platform.counts_per_rev() / (2 * std::numbers::pi);
  // The node ends at its DA; the amplifier, motor and wheel are physics.
  const double volts = chains_[wheel]->sample(sim_.wheel_angle(wheel), wheel_cmd_rad_s_[wheel] * per_sample);
  sim_.set_wheel_amplifier_input(wheel, volts);
  const physics::WheelDriveSample& last = chains_[wheel]->last();
  axis_stats_[wheel].add(last.command - last.delta_counts);
}

void PlatformRun::on_record(SimTime t) {
  const physics::Pose p = sim_.pose();
  const Eigen::Vector3d v = sim_.twist_world();
  if (on_bus()) {
    record_bus(t, p, v);
  } else {
    const controller::Pose2& ref = out_.reference.pose;
    const controller::Pose2& odo = out_.odom_pose;
    truth_stats_.add(ref.x - p.x, ref.y - p.y, ref.phi - p.phi);
    odom_stats_.add(ref.x - odo.x, ref.y - odo.y, ref.phi - odo.phi);
    row_.assign({ns_to_seconds(t), ref.x, ref.y, ref.phi, p.x, p.y, p.phi, odo.x, odo.y, odo.phi, v(0), v(1), v(2),
                 out_.twist_command(0), out_.twist_command(1), out_.twist_command(2)});
    for (int i = 0; i < 4; ++i) {
      const physics::WheelDriveSample& w = chains_[i]->last();
      row_.insert(row_.end(), {wheel_cmd_rad_s_[i], sim_.wheel_speed(i), sim_.wheel_angle(i),
                               static_cast<double>(chains_[i]->counter().count()), w.command,
                               static_cast<double>(w.delta_counts), static_cast<double>(w.code), sim_.wheel_setpoint(i),
                               sim_.wheel_torque(i)});
    }
  }
  // The plan's end, once a control sample reaches it: final_error_cm means "at the goal" only
  // when this is set (a master that started late leaves the run mid-path).
  const SimTime origin = plan_origin();
  if (path_done_ns_ < 0 && origin >= 0 && t <= end_ && t - origin >= seconds_to_ns(path_.duration())) {
    path_done_ns_ = origin + seconds_to_ns(path_.duration());
  }
  note(csv_->row(row_), *csv_);
  record_bus_and_state(t);
  if (progress_) progress_->update(ns_to_seconds(t));
}

std::uint32_t PlatformRun::active_faults(SimTime t) const {
  std::uint32_t n = 0;
  for (const FaultSpec& f : s_.faults) {
    const SimTime from = seconds_to_ns(f.at);
    if (t >= from && (f.duration <= 0 || t < from + seconds_to_ns(f.duration))) ++n;
  }
  return n;
}

// row_ holds the trajectory row just written (docs/run-directory.md column order).
void PlatformRun::record_bus_and_state(SimTime t) {
  StateSample& st = state_;
  st.t_ns = t;
  st.seq = records_++;
  st.ref_x = row_[1], st.ref_y = row_[2], st.ref_phi = row_[3];
  st.x = row_[4], st.y = row_[5], st.phi = row_[6];
  st.vx = row_[10], st.vy = row_[11], st.wz = row_[12];
  st.cmd_vx = row_[13], st.cmd_vy = row_[14], st.cmd_wz = row_[15];
  for (std::size_t i = 0; i < 4; ++i) {
    const double* w = &row_[16 + 9 * i];
    st.wheel_cmd[i] = w[0], st.wheel_speed[i] = w[1], st.wheel_angle[i] = w[2], st.wheel_torque[i] = w[8];
    DriveSample& d = st.drives[i];
    d.node = on_bus() ? net_->wheel_record(static_cast<int>(i)).node : 0;
    d.state = on_bus() ? net_->drive_state(static_cast<int>(i)) : DriveStateCode::running;
    if (on_bus() && o_.observer) {  // only live views show them
      const BusNetwork::DriveDetail dd = net_->drive_detail(static_cast<int>(i));
      d.comm_state = dd.comm, d.device_state = dd.device;
    }
    d.command_rad_s = w[0], d.setpoint_rad_s = w[7];
    d.dac_code = static_cast<std::int32_t>(w[6]);
    d.encoder_count = static_cast<std::int64_t>(w[3]);
  }
  st.bus = on_bus() ? net_->bus_sample() : BusSample{};
  if (on_bus()) {
    // Load over the last control period, from the wire's busy time.
    const std::int64_t busy = net_->wire_busy_ns();
    st.bus.load = t > last_record_ns_ ? static_cast<double>(busy - last_busy_ns_) / static_cast<double>(t - last_record_ns_) : 0.0;
    last_busy_ns_ = busy;
  }
  last_record_ns_ = t;
  st.active_faults = active_faults(std::min(t, end_));  // frozen after `duration` (on_fault)
  bus_row_.assign({ns_to_seconds(t), static_cast<double>(st.bus.frames_tx), static_cast<double>(st.bus.frames_rx),
                   static_cast<double>(st.bus.dropouts), static_cast<double>(st.bus.errors), st.bus.load,
                   static_cast<double>(st.active_faults)});
  for (const DriveSample& d : st.drives) bus_row_.push_back(static_cast<double>(d.state));
  drive_history_.add(ns_to_seconds(t), {st.drives[0].state, st.drives[1].state, st.drives[2].state, st.drives[3].state},
                     t <= end_);
  if (t <= end_) final_pose_ = {st.x, st.y, st.phi};  // the platform at the run's end (as its figures)
  note(bus_csv_->row(bus_row_), *bus_csv_);
  if (o_.observer) o_.observer->on_state(st);
}

bool PlatformRun::log_event(SimTime t, std::string_view kind, std::string_view text) {
  const bool ok = events_->log(ns_to_seconds(t), kind, text);
  if (o_.observer) o_.observer->on_event(RunEvent{t, run_event_kind(kind), std::string(kind), std::string(text)});
  return ok;
}

// The drive chain's parameters as loaded: what platform.xml does not hold (driver, DA, encoder,
// the slave's velocity loop) and the master's platform loop, so a run's record says which
// gains, dead band and arithmetic it ran with. The velocity loop is the thesis slave's (bus
// direct and can); the other buses' drives have their own (docs/run-directory.md).
nlohmann::json drive_chain_json(const physics::PlatformParams& p) {
  const physics::DriverParams& d = p.driver;
  const physics::VelocityLoopParams& v = p.velocity_loop;
  return {{"driver", {{"zero_volts", d.zero_volts}, {"gain_rad_s_per_v", d.gain}, {"dead_band_v", d.dead_band},
                      {"gain_error", d.gain_error}}},
          {"dac", {{"bits", p.dac.bits}, {"vref_v", p.dac.vref}}},
          {"encoder", {{"lines", p.encoder.lines}, {"counts_per_rev", p.counts_per_rev()}}},
          {"velocity_loop", {{"period_s", v.period}, {"kp", v.kp}, {"ki", v.ki}, {"kff", v.kff},
                             {"arithmetic", v.arithmetic == physics::LoopArithmetic::int16 ? "int16" : "real"}}}};
}

nlohmann::json controller_json(const ControllerSpec& c) {
  return {{"period_s", c.period}, {"kp", c.kp}, {"ki", c.ki}, {"feedforward", c.feedforward},
          {"max_speed_m_s", c.max_speed}, {"max_yaw_rate_rad_s", c.max_yaw_rate}};
}

void PlatformRun::write_run_description() const {
  const fs::path dir(o_.out_dir);
  const std::string mjcf = s_.platform.sim.mjcf.empty() ? physics::platform_mjcf(s_.platform) : [this] {
    std::ifstream f(s_.platform.sim.mjcf);
    return std::string(std::istreambuf_iterator<char>(f), {});
  }();
  write_text_atomic((dir / "platform.xml").string(), mjcf);
  nlohmann::json faults = nlohmann::json::array();
  for (const FaultSpec& f : s_.faults) {
    const std::string target = fault_target(f);
    faults.push_back({{"kind", to_string(f.kind)}, {"target", target}, {"at_s", f.at}, {"duration_s", f.duration},
                      {"text", fmt::format("{} {}", to_string(f.kind), target)}});
  }
  nlohmann::json expect = nlohmann::json::array();
  for (const Expectation& e : s_.expectations)
    expect.push_back({{"metric", e.metric}, {"min", e.min ? nlohmann::json(*e.min) : nlohmann::json()},
                      {"max", e.max ? nlohmann::json(*e.max) : nlohmann::json()}});
  const nlohmann::json j = {{"format", 1}, {"scenario", s_.name}, {"scenario_file", s_.file},
                            {"description", s_.description}, {"bus", to_string(s_.bus.kind)},
                            {"clock", to_string(s_.clock)}, {"model", "platform.xml"},
                            {"model_variant", model_name(s_.platform)}, {"control_period_s", s_.controller.period},
                            {"physics_timestep_s", s_.platform.sim.timestep}, {"duration_s", s_.duration},
                            {"start_pose", {s_.path.x0, s_.path.y0, s_.path.phi0_deg * kDeg}},
                            {"overrides", s_.overrides}, {"notes", s_.notes},
                            {"controller", controller_json(s_.controller)},
                            {"drive_chain", drive_chain_json(s_.platform)}, {"master_kind", master_kind()},
                            {"faults", faults}, {"expectations", expect}};
  write_json_atomic((dir / "run.json").string(), j);
}

// A bus run's row: the master's plan and odometry (lockstep; NaN where it cannot be known),
// the drives' held commands and what they measure.
void PlatformRun::record_bus(SimTime t, const physics::Pose& p, const Eigen::Vector3d& v) {
  const controller::Pose2 ref = bus_reference(t);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const bool lockstep = clock_server_ != nullptr;
  const std::array<double, 3> odo = lockstep ? report_.odometry : std::array<double, 3>{nan, nan, nan};
  // The tracking figures cover the run to `duration`; rows after it are a master's shutdown.
  const bool in_run = t <= end_;
  if (in_run) truth_stats_.add(ref.x - p.x, ref.y - p.y, ref.phi - p.phi);
  if (lockstep && in_run) odom_stats_.add(ref.x - odo[0], ref.y - odo[1], ref.phi - odo[2]);
  row_.assign({ns_to_seconds(t), ref.x, ref.y, ref.phi, p.x, p.y, p.phi, odo[0], odo[1], odo[2], v(0), v(1), v(2),
               nan, nan, nan});
  for (int i = 0; i < 4; ++i) {
    const WheelRecord w = net_->wheel_record(i);
    row_.insert(row_.end(), {w.command_rad_s, sim_.wheel_speed(i), sim_.wheel_angle(i), w.count, w.command_counts,
                             w.measured_counts, w.output, bus_setpoint_[static_cast<std::size_t>(i)],
                             sim_.wheel_torque(i)});
    // A drive's velocity error per control sample while it runs, in encoder pulses per
    // sample as the thesis's tables (its demand and actual are counts/s): the figure is the
    // records' (cmd_counts − meas_counts) × period, whatever the drive's own period.
    if (in_run && !net_->samples_axes() && net_->drive_state(i) == DriveStateCode::running)
      axis_stats_[static_cast<std::size_t>(i)].add((w.command_counts - w.measured_counts) * s_.controller.period);
  }
}

// Each fault that began and never ended (duration 0, or an end past the run's) gets its last
// line in events.log, so that every "(begins)" there has its counterpart. A fault active at
// `duration` stays so through a master's shutdown after it (on_fault), and its line comes last.
void PlatformRun::log_faults_still_active() {
  if (!events_) return;
  const SimTime t = std::min(sched_.now(), end_);
  for (const FaultSpec& f : s_.faults) {
    const SimTime from = seconds_to_ns(f.at);
    if (from > t || (f.duration > 0 && from + seconds_to_ns(f.duration) <= t)) continue;
    // Named as run.json names it (kind and target), so it pairs with its "(begins)" line.
    // A fault given by --set has no line of the file (0): say where it came from instead.
    const std::string where = f.line > 0 ? fmt::format("scenario line {}", f.line) : std::string("given by --set");
    note(log_event(sched_.now(), "fault", fmt::format("{} {} ({}), from {} s (still active at the end of the run)",
                                           to_string(f.kind), fault_target(f), where, f.at)),
         *events_);
  }
}

void PlatformRun::on_fault(const FaultSpec& f, bool begin, SimTime t) {
  // Past `duration` (a master's shutdown) the world stays as the run left it: no fault begins
  // or ends there.
  if (t > end_) return;
  if (f.kind != FaultSpec::Kind::wheel_slip) return net_->apply_fault(f, begin, t);
  const double scale = begin ? f.friction_scale : 1.0;
  sim_.set_wheel_friction_scale(f.wheel, scale);
  note(log_event(t, "fault",
                 fmt::format("wheel_slip wheel {} friction x{} ({})", f.wheel + 1, scale, begin ? "begins" : "ends")),
       *events_);
}

// bus.* totals as bus.csv's last row has them. A run stopped between two control samples (a
// signal ends it at the next instant) has run the bus cycles since, when they are shorter than
// the control period (M-III, CANopen): their frames are in the slaves' and master's counters.
void PlatformRun::last_row_totals(nlohmann::json& bus) const {
  if (records_ == 0) return;  // no row yet: the network's own totals
  bus["frames_tx"] = state_.bus.frames_tx;
  bus["frames_rx"] = state_.bus.frames_rx;
  bus["dropouts"] = state_.bus.dropouts;
  bus["errors"] = state_.bus.errors;
}

nlohmann::json PlatformRun::metrics_json(double wall_s, bool interrupted) const {
  const double sim_s = ns_to_seconds(sched_.now());
  nlohmann::json m;
  m["scenario"] = s_.name;
  m["scenario_file"] = s_.file;
  if (on_bus()) {
    m["bus"] = net_->bus_metrics(sched_.now());
    last_row_totals(m["bus"]);
    m["slaves"] = net_->slave_metrics();
    // Only a lockstep master reports (on the sim clock); one on its own wall clock does not.
    const bool reports = clock_server_ != nullptr;
    // As the run left it: a state its shutdown reports after the end ("stopped") is in events.log.
    const simclock::MasterReport& rr = run_report_;
    // A master that does not report leaves its stop, node, path origin and ticks unknown: null,
    // not 0 and -1, which read as "never stopped" and passed an expectation on them (a realtime
    // master that stopped on node_missing was judged as one that never did; found by a
    // walkthrough). An expectation on a null metric fails, saying why.
    const auto known = [reports](const nlohmann::json& v) { return reports ? v : nlohmann::json(nullptr); };
    m["master"] = {{"state", reports ? simclock::to_string(rr.state) : "unreported"},
                   {"stop_reason", reports ? simclock::to_string(rr.reason) : "unreported"},
                   {"stop_reason_code", known(static_cast<int>(rr.reason))},
                   {"missing_node", known(rr.node)},
                   {"stopped_at_s", known(master_stop_ns_ < 0 ? -1.0 : ns_to_seconds(master_stop_ns_))},
                   {"path_origin_s", known(rr.path_origin_ns < 0 ? -1.0 : ns_to_seconds(rr.path_origin_ns))},
                   {"ticks", known(tick_)},
                   {"clock", clock_server_ ? "sim" : vtime_server_ ? "virtual" : "wall"},
                   {"command", master_command_},
                   // `omnitwin twin`: the master is the user's, started by them ("not started"
                   // read as if it never ran; found by a walkthrough).
                   {"exit", master_ ? master_->describe_exit() : o_.external_master ? "external" : "not started"},
                   {"exit_code", master_ ? master_->exit_code() : -1},  // 128 + N: killed by signal N
                   {"lost", master_lost_ns_ >= 0},
                   {"lost_at_s", master_lost_ns_ < 0 ? -1.0 : ns_to_seconds(master_lost_ns_)},
                   {"lost_reason", master_lost_why_},
                   {"sigterm_at_s", sigterm_ns_ < 0 ? -1.0 : ns_to_seconds(sigterm_ns_)},
                   {"stop_signal", stop_signal_},  // "SIGTERM" (the twin's), "SIGINT from the terminal", "stop in the grants"; "" none
                   {"exited_at_s", master_exit_ns_ < 0 ? -1.0 : ns_to_seconds(master_exit_ns_)},
                   {"shutdown_s", master_exit_ns_ < 0 ? -1.0 : ns_to_seconds(master_exit_ns_ - sigterm_ns_)}};
    if (vtime_pacer_)
      m["master"]["virtual_time"] = {{"waits", vtime_server_->waits()}, {"wakes", vtime_pacer_->wakes()},
                                     {"frame_wakes", vtime_pacer_->frame_wakes()},
                                     {"now_s", ns_to_seconds(vtime_pacer_->master_now())}};
    // A master that keeps its own counters leaves them in master-stats.json; the sim-clock
    // report keeps its state and stop reason (merge_master_stats).
    const fs::path stats = fs::path(o_.out_dir) / "master-stats.json";
    if (std::ifstream f(stats); f) merge_master_stats(m["master"], nlohmann::json::parse(f, nullptr, false));
  } else {
    m["bus"] = {{"name", to_string(s_.bus.kind)}, {"frames_tx", 0}, {"frames_rx", 0}, {"dropouts", 0},
                {"dropout_rate", 0.0}, {"errors", 0}};
  }
  m["clock"] = to_string(s_.clock);
  m["sim_time_s"] = sim_s;
  m["wall_time_s"] = wall_s;
  m["real_time_factor"] = wall_s > 0 ? sim_s / wall_s : 0.0;
  m["interrupted"] = interrupted;
  m["platform"] = truth_stats_.to_json();
  m["platform"]["final_x_m"] = final_pose_[0];
  m["platform"]["final_y_m"] = final_pose_[1];
  m["platform"]["final_phi_deg"] = final_pose_[2] * 180.0 / std::numbers::pi;
  m["platform"]["path_done_s"] = path_done_ns_ < 0 ? -1.0 : ns_to_seconds(path_done_ns_);
  m["drives"] = drive_history_.to_json();
  m["platform_odometry"] = odom_stats_.to_json();
  m["axes"] = nlohmann::json::array();
  for (std::size_t i = 0; i < axis_stats_.size(); ++i) {
    nlohmann::json a = axis_stats_[i].to_json();
    if (axis_master_stats_[i].samples() > 0) a.update(axis_master_stats_[i].to_json("_at_master"));
    m["axes"].push_back(std::move(a));
  }
  m["physics"] = {{"model", model_name(s_.platform)}, {"timestep_s", s_.platform.sim.timestep},
                  {"steps", physics_steps_}, {"warnings", sim_.warning_count()}};
  return m;
}

RunResult PlatformRun::execute() {
  // Everything is built and the directory prepared (run_scenario): the records begin.
  write_run_description();
  csv_ = std::make_unique<CsvWriter>((fs::path(o_.out_dir) / "trajectory.csv").string(), trajectory_header());
  bus_csv_ = std::make_unique<CsvWriter>((fs::path(o_.out_dir) / "bus.csv").string(), bus_header());
  events_ = std::make_unique<EventLog>((fs::path(o_.out_dir) / "events.log").string());
  if (o_.progress && !o_.until_stopped) progress_ = std::make_unique<ProgressBar>(s_.duration, s_.name, true);
  if (o_.observer)
    o_.observer->on_start(RunInfo{s_.name, to_string(s_.bus.kind), to_string(s_.clock), o_.out_dir,
                                  s_.controller.period, s_.duration});
  log_event(0, "start",
            fmt::format("scenario {} bus {} clock {} model {} params {}", s_.name, to_string(s_.bus.kind),
                        to_string(s_.clock), model_name(s_.platform), s_.platform.source));

  if (on_bus()) {
    net_->open_pcap((fs::path(o_.out_dir) / fmt::format("bus-{}.pcap", net_->wire_name())).string());
    try {
      if (!o_.external_master) start_master();
    } catch (const std::exception& e) {
      error_ = e.what();
      stop_master();  // a master that started: waited for or stopped, its log named master.log
      return finish(0.0, nullptr);
    }
  }
  LockstepPacer lockstep;
  std::unique_ptr<RealtimePacer> realtime;
  if (s_.clock == ClockMode::realtime) {
    const SimTime tm = on_bus() ? master_period_ns() : seconds_to_ns(s_.controller.period);
    realtime = std::make_unique<RealtimePacer>(tm);
    pacer_ = realtime.get();
    // Lateness per second of sim time, so a long run shows when it was late (a soak's trend).
    realtime_csv_ = std::make_unique<CsvWriter>((fs::path(o_.out_dir) / "realtime.csv").string(), realtime_header());
    realtime->set_window(kNsPerSecond, [this](const LatenessWindow& w) {
      const std::array<double, 7> row{ns_to_seconds(w.start), static_cast<double>(w.ticks), static_cast<double>(w.overruns),
                                      w.mean_us, w.p50_us, w.p99_us, w.max_us};
      note(realtime_csv_->row(row), *realtime_csv_);
    });
    // A master on its own wall clock waits for its frames: answer them as they arrive.
    if (net_ && net_->wake_fd() >= 0) realtime->set_wake(net_->wake_fd(), [this](SimTime t) { net_->on_wake(t); });
  } else if (vtime_server_) {
    vtime_pacer_ = std::make_unique<VtimePacer>(
        *vtime_server_, *net_, sched_, std::chrono::milliseconds(std::llround(s_.master.watchdog * 1e3)),
        [this](std::string why, bool gone) {
          if (gone) master_lost(sched_.now(), std::move(why), true);
          else fail(std::move(why));
        },
        [this] { return master_ ? (master_->running() ? std::string("still running") : master_->describe_exit())
                                : std::string("not started"); });
    pacer_ = vtime_pacer_.get();
  } else {
    pacer_ = &lockstep;
  }
  schedule();
  const std::int64_t wall0 = monotonic_ns();
  pacer_->start();
  // Events up to and including the final control sample at `duration`. Anything thrown
  // from inside a step ends the run like a record failure: records closed, metrics written.
  try {
    sched_.run_until(end_ + 1, *pacer_, [this] { return signalled(); });
    serve_master_shutdown();
  } catch (const std::exception& e) {
    if (error_.empty()) error_ = e.what();
  }
  const double wall_s = (monotonic_ns() - wall0) * 1e-9;
  log_faults_still_active();
  if (realtime) realtime->flush_window();
  if (progress_) progress_->finish();
  stop_master();
  return finish(wall_s, realtime.get());
}

RunResult PlatformRun::finish(double wall_s, const RealtimePacer* realtime) {
  // A twin that runs until stopped ends by the signal: that is its normal end.
  const bool was_signalled = signalled();
  const bool interrupted = was_signalled && !o_.until_stopped;
  RunResult r;
  r.out_dir = o_.out_dir;
  r.interrupted = interrupted;
  r.metrics = metrics_json(wall_s, interrupted);
  if (realtime) {
    const RealtimeStats st = realtime->stats();
    r.metrics["realtime"] = {{"scheduling", st.scheduling}, {"ticks", st.ticks}, {"overruns", st.overruns},
                             {"jitter_mean_us", st.jitter_mean_us}, {"jitter_p99_us", st.jitter_p99_us},
                             {"jitter_max_us", st.jitter_max_us}};
  }
  ExpectationResult ex = evaluate_expectations(s_.expectations, r.metrics);
  const bool cut_short = interrupted || !error_.empty();
  if (cut_short) {
    // Bounds meant for the whole run say nothing about a part of it.
    ex.passed = false;
    // (An interrupted run whose master's shutdown was served names the interrupt's instant.)
    ex.failures.assign({fmt::format("{} at t = {:.3f} s: expectations not evaluated",
                                    interrupted ? "interrupted" : "failed",
                                    ns_to_seconds(interrupted ? std::min(sched_.now(), end_) : sched_.now()))});
  }
  // Any master, the user's own above all (`omnitwin twin` or master.command): one that never
  // sent a frame commanded nothing, whatever the bounds say (a master.command of `sleep 60`
  // passed; found in review).
  if (on_bus() && r.metrics["bus"].value("frames_rx", 0) == 0) {
    ex.passed = false;
    ex.failures.push_back(fmt::format("no master connected: no frame reached the twin on {} in {:.1f} s",
                                      r.metrics["bus"].value("transport", std::string("its transport")),
                                      ns_to_seconds(sched_.now())));
  }
  if (o_.external_master) r.metrics["stopped_by"] = was_signalled ? "signal" : "duration";
  if (sim_.warning_count() > 0) {
    ex.passed = false;
    ex.failures.push_back(fmt::format("MuJoCo reported {} warnings: the physics is not trustworthy", sim_.warning_count()));
  }
  const std::string end_kind = !error_.empty() ? "error" : (interrupted ? "interrupt" : "end");
  // events.log's last line now; the live observers (DDS, the web view) get the verdict only
  // once the records are closed and metrics.json written, which can still fail the run (a full
  // disk: DDS said "passed" for a run that ended with exit 3; found in review).
  note(events_->log(ns_to_seconds(sched_.now()), end_kind,
                    error_.empty() ? fmt::format("expectations {} ({} failures)", ex.passed ? "passed" : "failed",
                                                 ex.failures.size())
                                   : error_),
       *events_);
  // A record is renamed only if everything reached it; otherwise the reason joins the metrics.
  const auto close_record = [this](auto* w) {
    try {
      if (w) w->close();
    } catch (const std::exception& e) {
      if (error_.empty()) error_ = e.what();
    }
  };
  close_record(csv_.get());
  close_record(bus_csv_.get());
  close_record(realtime_csv_.get());
  close_record(events_.get());
  if (on_bus()) {
    if (std::string why = net_->close_pcap(); !why.empty() && error_.empty()) error_ = why;
  }
  if (!error_.empty()) r.metrics["error"] = error_;
  // A record that failed while it was closed leaves the run without its evidence: whatever
  // the bounds said, it is not a pass.
  if (!error_.empty() && ex.passed) {
    ex.passed = false;
    ex.failures.push_back("records not written whole: " + error_);
  }
  if (interrupted) r.metrics["interrupted_phase"] = "run";
  r.metrics["expectations"] = ex.to_json();
  r.passed = ex.passed;
  r.error = error_;
  try {
    write_json_atomic((fs::path(o_.out_dir) / "metrics.json").string(), r.metrics);
  } catch (const std::exception& e) {
    if (r.error.empty()) r.error = e.what();
  }
  // Whatever failed, the run says which records it could not write whole.
  const RecordInventory inv = take_inventory(o_.out_dir, expected_records());
  r.missing_records = inv.missing;
  r.partial_records = inv.partial;
  const bool records_whole = r.error.empty() && r.missing_records.empty() && r.partial_records.empty();
  if (!records_whole) r.passed = false;  // e.g. metrics.json itself could not be written
  if (o_.observer) {
    std::vector<std::string> failures = ex.failures;
    for (const std::string& f : r.missing_records) failures.push_back(f + " was not written");
    for (const std::string& f : r.partial_records) failures.push_back(f + " is incomplete");
    if (!r.error.empty() && ex.passed) failures.push_back("records not written whole: " + r.error);
    for (const std::string& f : failures)
      o_.observer->on_event(RunEvent{sched_.now(), RunEventKind::expectation, "expectations", "failed: " + f});
    o_.observer->on_event(
        RunEvent{sched_.now(), RunEventKind::expectation, "expectations", r.passed ? "passed" : "failed"});
    const std::string kind = !r.error.empty() ? "error" : end_kind;
    o_.observer->on_event(RunEvent{sched_.now(), run_event_kind(kind), kind,
                                   !r.error.empty() ? r.error
                                                    : fmt::format("expectations {} ({} failures)",
                                                                  r.passed ? "passed" : "failed", failures.size())});
    o_.observer->on_end(r.metrics);
  }
  r.exit_code = cut_short || !records_whole ? 3 : (r.passed ? 0 : 1);
  return r;
}

// Who masters the bus, for run.json: "none" (bus direct: the twin's own loop), "omni-master"
// (the built-in master, started by the twin), "command" (master.command, started by the twin)
// or "external" (`omnitwin twin`: a master the twin did not start).
const char* PlatformRun::master_kind() const {
  if (!on_bus()) return "none";
  if (o_.external_master) return "external";
  return s_.master.command.empty() ? "omni-master" : "command";
}

// The records this run must leave (docs/run-directory.md), video and report aside.
std::vector<std::string> PlatformRun::expected_records() const {
  std::vector<std::string> names{"run.json", "platform.xml", "trajectory.csv", "bus.csv", "events.log", "metrics.json"};
  if (on_bus()) names.push_back(fmt::format("bus-{}.pcap", net_->wire_name()));
  if (master_) names.push_back("master.log");
  if (realtime_csv_) names.push_back("realtime.csv");
  return names;
}

// Isolation: a lockstep run's frames are for its own master and twin only (a third sender
// would break the per-tick frame counts, and a concurrent run would corrupt both). A UDP bus
// in lockstep therefore gets a port of its own, chosen free when the twin opens it, and the
// well-known python-can group is swapped for the lockstep group kLockstepGroup, so not even a
// realtime run on the documented group and port can meet it. Unless the spec names a TTL the
// frames stay on the host (ttl=0), which spares a network-device send per datagram
// (docs/benchmarks.md). Realtime runs and `omnitwin twin` keep the scenario's spec.
constexpr const char* kLockstepGroup = "239.74.164.1";

std::string lockstep_can_spec(const std::string& given) {
  const can::TransportSpec t = can::parse_transport_spec(given);
  if (t.kind != can::TransportSpec::Kind::udp) return given;
  const std::string group = !t.ipv6 && t.name == can::kPythonCanGroupV4 ? kLockstepGroup : t.name;
  std::string spec = t.ipv6 ? fmt::format("udp:[{}]:0", group) : fmt::format("udp:{}:0", group);
  const std::size_t q = given.find('?');
  const std::string opts = q == std::string::npos ? std::string() : given.substr(q + 1);
  spec += opts.empty() ? "?" : "?" + opts + "&";
  if (opts.find("ttl=") == std::string::npos) return spec + "ttl=0";
  return spec.substr(0, spec.size() - 1);
}

Scenario with_lockstep_transport(const Scenario& s, bool external_master) {
  Scenario e = s;
  const bool on_can = s.bus.kind == BusKind::can || s.bus.kind == BusKind::canopen || s.bus.kind == BusKind::tml;
  if (!on_can || s.clock != ClockMode::lockstep || external_master) return e;
  e.bus.can.transport = lockstep_can_spec(s.bus.can.transport);
  return e;
}

}  // namespace

RunResult run_scenario(const Scenario& given, const RunOptions& options) {
  Scenario scenario;
  try {
    Scenario chosen = given;
    // A static master cannot live on the virtual clock; asked to, it runs on the wall clock.
    if (chosen.virtual_time_master() && chosen.master.on_static == MasterSpec::OnStatic::realtime) {
      const std::vector<std::string> words = split_command(chosen.master.command);
      if (!words.empty() && preload_obstacle(words[0]).starts_with("statically")) {
        spdlog::warn("master: {} is statically linked: it runs on the wall clock (master.on_static: realtime)", words[0]);
        chosen.clock = ClockMode::realtime;
      }
    }
    scenario = with_lockstep_transport(chosen, options.external_master);
  } catch (const std::invalid_argument& e) {
    throw RunSetupError(fmt::format("master.command: {}", e.what()));
  } catch (const can::TransportError& e) {
    throw RunSetupError(fmt::format("bus.transport: {}", e.what()));
  }
  const BusKind bus = scenario.bus.kind;
  // Building the platform (compiling the MJCF, checking its names) is part of validating
  // the input: a model that does not load is bad input, and nothing has been written yet.
  std::unique_ptr<PlatformRun> run;
  try {
    run = std::make_unique<PlatformRun>(scenario, options);
  } catch (const std::exception& e) {
    const char* key = scenario.platform.sim.mjcf.empty() ? "platform" : "platform.mjcf";
    throw RunSetupError(fmt::format("{}: {}", key, one_line(e.what())));
  }
  if (options.external_master && (bus == BusKind::direct || scenario.clock != ClockMode::realtime))
    throw RunSetupError(
        "the twin alone needs a bus (can, canopen, tml, ethercat or m3; not direct) and clock: realtime (an "
        "external master keeps its own time)");
  // Decided here, after a static master may have moved the run onto the wall clock.
  std::unique_lock<std::mutex> turn;
  if (options.realtime_turn && scenario.clock == ClockMode::realtime) turn = std::unique_lock<std::mutex>(*options.realtime_turn);
  if (bus != BusKind::direct) {
    try {
      run->build_network();
    } catch (const can::TransportError& e) {
      throw RunSetupError(fmt::format("bus.transport: {}", e.what()));
    } catch (const ethercat::TransportError& e) {
      throw RunSetupError(fmt::format("bus.transport: {}", e.what()));
    } catch (const m3::TransportError& e) {
      throw RunSetupError(fmt::format("bus.transport: {}", e.what()));
    } catch (const BusInUse& e) {
      throw RunSetupError(fmt::format("bus.transport: {}", e.what()));
    } catch (const canopen::EdsError& e) {
      throw RunSetupError(fmt::format("bus.eds: {}", e.what()));
    } catch (const std::exception& e) {
      throw RunSetupError(one_line(e.what()));
    }
    if (options.on_bus_ready) options.on_bus_ready(run->master_iface());
  }
  // One run per directory: an earlier run's records are cleared, anyone else's are refused.
  if (std::string why = prepare_run_directory(options.out_dir); !why.empty()) throw RunSetupError(why);
  RunResult result = run->execute();
  run.reset();  // its bus (and the claim on it) is let go before the next realtime run takes its turn
  return result;
}

}  // namespace omnitwin::twin
