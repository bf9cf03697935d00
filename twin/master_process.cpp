// twin layer — the master program as a child process; see master_process.hpp.
#include "twin/master_process.hpp"
#include "twin/process_tree.hpp"
#include "controller/master_bounds.hpp"

#include "twin/canopen_network.hpp"
#include "twin/ethercat_network.hpp"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

extern char** environ;

namespace omnitwin::twin {

namespace fs = std::filesystem;

MasterProcess::MasterProcess(const std::string& program, const std::vector<std::string>& args,
                             const std::string& log_path, const std::vector<std::string>& env) {
  std::vector<std::string> argv_s{program};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : argv_s) argv.push_back(a.data());
  argv.push_back(nullptr);
  // stdout and stderr into the run directory's master.log; stdin from /dev/null.
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 1, log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  // The environment: ours, with `env`'s names replaced.
  std::vector<std::string> env_s;
  for (char** e = environ; *e; ++e) {
    const std::string_view v(*e);
    const std::string_view name = v.substr(0, v.find('='));
    bool replaced = false;
    for (const std::string& x : env) replaced = replaced || x.substr(0, x.find('=')) == name;
    if (!replaced) env_s.emplace_back(v);
  }
  env_s.insert(env_s.end(), env.begin(), env.end());
  // Who started it: our masters end when this process does (OMNITWIN_TWIN_PID, see
  // controller/program_support's watch_parent); other programs ignore the name.
  env_s.push_back(fmt::format("OMNITWIN_TWIN_PID={}", ::getpid()));
  std::vector<char*> envp;
  for (std::string& e : env_s) envp.push_back(e.data());
  envp.push_back(nullptr);
  const int rc = program.find('/') == std::string::npos
                     ? posix_spawnp(&pid_, program.c_str(), &fa, nullptr, argv.data(), envp.data())
                     : posix_spawn(&pid_, program.c_str(), &fa, nullptr, argv.data(), envp.data());
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) {
    pid_ = -1;
    throw std::runtime_error(fmt::format("cannot start the master '{}': {}", program, std::strerror(rc)));
  }
  start_guard();
}

void MasterProcess::start_guard() {
  std::string dir;
  const std::string guard =
      find_beside_executable({"omnitwin-guard", "../twin/omnitwin-guard"}, OMNITWIN_BINARY_DIR "/twin/omnitwin-guard", X_OK, dir);
  if (guard.empty()) {
    spdlog::warn("omnitwin-guard not found beside {}: a master behind a wrapper outlives a killed twin", dir);
    return;
  }
  // Who the master is: pid and start time (posix_spawn returned after its exec).
  const std::optional<ProcessEntry> self = process_entry(pid_);
  if (!self) return;  // it has ended already
  std::vector<std::string> argv_s{guard, std::to_string(::getpid()), std::to_string(pid_), std::to_string(self->start),
                                  std::to_string(kGuardGrace.count())};
  std::vector<char*> argv;
  for (std::string& a : argv_s) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  for (int fd = 0; fd < 3; ++fd) posix_spawn_file_actions_addopen(&fa, fd, "/dev/null", fd == 0 ? O_RDONLY : O_WRONLY, 0);
  if (posix_spawn(&guard_pid_, guard.c_str(), &fa, nullptr, argv.data(), environ) != 0) guard_pid_ = -1;
  posix_spawn_file_actions_destroy(&fa);
}

void MasterProcess::end_guard() {
  if (guard_pid_ <= 0) return;
  ::kill(guard_pid_, SIGKILL);
  while (waitpid(guard_pid_, nullptr, 0) < 0 && errno == EINTR) {
  }
  guard_pid_ = -1;
}

MasterProcess::~MasterProcess() {
  if (pid_ > 0 && (exit_code_ < 0 || descendants_alive())) stop(kGuardGrace);
  end_guard();
}

void MasterProcess::reap(int status) {
  exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

bool MasterProcess::running() {
  if (pid_ <= 0 || exit_code_ >= 0) return false;
  int status = 0;
  const pid_t r = waitpid(pid_, &status, WNOHANG);
  if (r == pid_) reap(status);
  return exit_code_ < 0;
}

bool MasterProcess::descendants_alive() const {
  if (pid_ <= 0) return false;
  const std::vector<ProcessEntry> all = process_table();
  // A process it started that was orphaned (its parent ended first) is still one of them.
  for (const ProcessEntry& p : all)
    for (const ProcessEntry& s : signalled_)
      if (p.state != 'Z' && same_process(p, s)) return true;
  // Once it is reaped its pid may be another process's: only those signalled count then.
  return exit_code_ < 0 && !descendants_of(pid_, all).empty();
}

void MasterProcess::signal_all(int sig) {
  const std::vector<ProcessEntry> all = process_table();
  if (exit_code_ < 0)
    for (const ProcessEntry& p : descendants_of(pid_, all))
      if (std::none_of(signalled_.begin(), signalled_.end(), [&](const ProcessEntry& s) { return same_process(p, s); }))
        signalled_.push_back(p);
  if (exit_code_ < 0) ::kill(pid_, sig);
  // Only a process that is still the one it started (its pid may have been taken again).
  for (const ProcessEntry& s : signalled_)
    if (std::any_of(all.begin(), all.end(), [&](const ProcessEntry& p) { return same_process(p, s); })) ::kill(s.pid, sig);
}

bool MasterProcess::wait(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (running()) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

void MasterProcess::terminate() {
  if (!running() && !descendants_alive()) return;
  signal_all(SIGTERM);
  signal_all(SIGCONT);  // a stopped master (SIGSTOP, a debugger) acts on SIGTERM only when continued
}

void MasterProcess::stop(std::chrono::milliseconds grace) {
  if (!running() && !descendants_alive()) return;
  terminate();
  // The program, then what it started, within the grace.
  const auto deadline = std::chrono::steady_clock::now() + grace;
  const bool program_ended = wait(grace);
  while (descendants_alive() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  if (program_ended && !descendants_alive()) return;
  signal_all(SIGKILL);
  if (program_ended) return;
  int status = 0;
  while (waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
  }
  reap(status);
}

std::string MasterProcess::describe_exit() const {
  if (exit_code_ < 0) return "running";
  if (exit_code_ >= 128) return fmt::format("killed by signal {}", exit_code_ - 128);
  return fmt::format("exit {}", exit_code_);
}

std::string log_tail(const std::string& path, int max_lines) {
  constexpr std::streamoff kTail = 4096;
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return "";
  const std::streamoff size = in.tellg();
  in.seekg(std::max<std::streamoff>(0, size - kTail));
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // Walk back over the lines, keeping the non-empty ones (a partial first line included).
  std::vector<std::string> lines;
  std::size_t end = text.size();
  while (end > 0 && static_cast<int>(lines.size()) < max_lines) {
    const std::size_t nl = text.rfind('\n', end - 1);
    const std::size_t begin = nl == std::string::npos ? 0 : nl + 1;
    std::string line = text.substr(begin, end - begin);
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (!line.empty()) lines.insert(lines.begin(), std::move(line));
    end = nl == std::string::npos ? 0 : nl;
  }
  std::string out;
  for (const std::string& l : lines) out += (out.empty() ? "" : " | ") + l;
  return out;
}

std::string find_master_program(const std::string& configured) {
  if (!configured.empty()) {
    if (access(configured.c_str(), X_OK) != 0)
      throw std::runtime_error(fmt::format("bus.master: '{}' is not an executable program", configured));
    return configured;
  }
  // Build tree (build/twin/omnitwin → build/controller/omni-master), an install beside it,
  // then this build's own (for test and benchmark programs elsewhere in the build tree).
  std::string dir;
  const std::string found = find_beside_executable({"../controller/omni-master", "omni-master"},
                                                   OMNITWIN_BINARY_DIR "/controller/omni-master", X_OK, dir);
  if (!found.empty()) return found;
  throw std::runtime_error(fmt::format(
      "bus: the master program omni-master was not found beside {} (build it, or set bus.master)", dir));
}

std::string find_beside_executable(const std::vector<std::string>& beside, const std::string& in_build, int mode,
                                   std::string& folder) {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  const fs::path dir = ec ? fs::current_path() : self.parent_path();
  folder = dir.string();
  std::vector<fs::path> candidates;
  for (const std::string& b : beside) candidates.push_back(dir / b);
  candidates.emplace_back(in_build);
  for (const fs::path& p : candidates)
    if (access(p.c_str(), mode) == 0) return p.lexically_normal().string();
  return "";
}

namespace {

controller::SegmentSpec segment_spec(const PathSegment& g) {
  using K = controller::SegmentSpec::Kind;
  controller::SegmentSpec c;
  switch (g.kind) {
    case PathSegment::Kind::line: c.kind = K::line; break;
    case PathSegment::Kind::arc: c.kind = K::arc; break;
    case PathSegment::Kind::rotate: c.kind = K::rotate; break;
    case PathSegment::Kind::dwell: c.kind = K::dwell; break;
    case PathSegment::Kind::square: c.kind = K::square; break;
    case PathSegment::Kind::circle: c.kind = K::circle; break;
    case PathSegment::Kind::figure_eight: c.kind = K::figure_eight; break;
  }
  c.duration = g.duration, c.dx = g.dx, c.dy = g.dy, c.dphi_deg = g.dphi_deg, c.cx = g.cx, c.cy = g.cy;
  c.sweep_deg = g.sweep_deg, c.side = g.side, c.radius = g.radius, c.ccw = g.ccw;
  return c;
}

}  // namespace

controller::MasterConfig master_config(const Scenario& s) {
  controller::MasterConfig m;
  const ControllerSpec& c = s.controller;
  m.loop.period = c.period;
  for (int i = 0; i < 3; ++i) m.loop.kp[i] = c.kp[i], m.loop.ki[i] = c.ki[i];
  m.loop.feedforward = c.feedforward;
  m.loop.max_speed = c.max_speed;
  m.loop.max_yaw_rate = c.max_yaw_rate;
  m.loop.L = s.platform.geometry.L;
  m.loop.r = s.platform.geometry.r;
  m.loop.counts_per_rev = s.platform.counts_per_rev();
  m.path.x = s.path.x0, m.path.y = s.path.y0, m.path.phi_deg = s.path.phi0_deg;
  for (const PathSegment& g : s.path.segments) m.path.segments.push_back(segment_spec(g));
  m.settle = s.settle;
  m.detect_every = s.bus.can.detect_every;
  // Real time: the twin may still be starting when the master first looks for its slaves.
  m.startup_timeout = s.clock == ClockMode::realtime ? 3.0 : 1.0;
  return m;
}

std::string master_config_yaml(const Scenario& s) {
  return fmt::format("# omni-master configuration written by omnitwin for scenario {}\n", s.name) +
         controller::dump_master_config(master_config(s));
}

std::string ethercat_platform_yaml(const Scenario& s) {
  controller::MasterConfig m = master_config(s);
  // The platform loop's odometry counts what the drives report: position actual values.
  m.loop.counts_per_rev = s.bus.ethercat.counts_per_rev;
  return fmt::format("# platform loop of omni-master --bus ethercat, written by omnitwin for scenario {}\n", s.name) +
         controller::dump_master_config(m);
}

std::string ethercat_master_config_yaml(const Scenario& s, const std::string& platform_file) {
  const EthercatSpec& e = s.bus.ethercat;
  const bool csv = e.mode == "csv";
  std::string out = fmt::format("# omni-master --bus ethercat configuration written by omnitwin for scenario {}\n", s.name);
  const int extra = ethercat_extra_slaves(e);
  if (extra == 0) {
    out += fmt::format("esi: {}\n", ethercat_esi_path(e));
  } else {  // the wheels' drives, then seed 001's multi-axis slaves behind them
    out += fmt::format("esi:\n  - {}\n  - {}\n", ethercat_esi_path(e), ethercat_multiaxis_esi_path());
  }
  out += fmt::format("cycle: {}\n", s.controller.period);
  out += fmt::format("dc: {}\n", e.dc ? "true" : "false");
  out += fmt::format("expected_slaves: {}\n", 4 + extra);
  // Every wheel drive in the wheels' cyclic mode (0x6060 modes of operation: 9 CSV, 8 CSP).
  out += "startup:\n";
  if (extra == 0) {
    out += fmt::format("  - slave: all\n    index: 0x6060\n    sub: 0\n    size: 1\n    value: {}\n", csv ? 9 : 8);
  } else {  // not the multi-axis slaves: their cards have modes of their own
    for (int i = 1; i <= 4; ++i)
      out += fmt::format("  - slave: {}\n    index: 0x6060\n    sub: 0\n    size: 1\n    value: {}\n", i, csv ? 9 : 8);
  }
  out += "wheels:\n";
  for (int i = 1; i <= 4; ++i) out += fmt::format("  - slave: {}\n    channel: 1\n", i);
  out += fmt::format("wheel_mode: {}\n", e.mode);
  out += fmt::format("wheel_counts_per_rev: {}\n", e.counts_per_rev);
  out += fmt::format("platform: {}\n", platform_file);
  return out;
}

std::string m3_platform_yaml(const Scenario& s) {
  controller::MasterConfig m = master_config(s);
  // The platform loop's odometry counts what the servos report: APOS in reference units.
  m.loop.counts_per_rev = s.bus.m3.counts_per_rev;
  return fmt::format("# platform loop of omni-master --bus m3, written by omnitwin for scenario {}\n", s.name) +
         controller::dump_master_config(m);
}

std::string m3_master_config_yaml(const Scenario& s, const std::string& platform_file) {
  const M3Spec& m = s.bus.m3;
  std::string out = fmt::format("# omni-master --bus m3 configuration written by omnitwin for scenario {}\n", s.name);
  out += fmt::format("cycle: {}\nretry_slots: {}\n", m.cycle, m.retry_slots);
  if (m.communication == "event") out += "communication: event\n";  // 64-byte data
  else out += fmt::format("data_bytes: {}\n", m.data_bytes);
  out += "wheels: [0x03, 0x04, 0x05, 0x06]\n";
  if (m.stations > 4) out += fmt::format("extra_axes: {}\n", m.stations - 4);
  const bool realtime = s.clock == ClockMode::realtime;
  out += fmt::format("response_us: {}\nmargin_us: {}\n", m.response_us, m.margin(realtime));
  // Detection and delay measurement wait per station; across processes in realtime the
  // transport's round trip, not the wire's microseconds, sets how long an answer takes.
  if (realtime) out += "detect_timeout_ms: 5\n";
  // The servos must be on before the path starts (and a realtime master may start before the twin).
  out += fmt::format("startup_timeout: {}\n", std::max(1.0, m.startup + (realtime ? controller::kRealtimeStartupGrace : 0.0)));
  out += fmt::format("wheel_command: {}\nwheel_counts_per_rev: {}\n", m.mode, m.counts_per_rev);
  out += fmt::format("platform: {}\n", platform_file);
  return out;
}

std::string canopen_platform_yaml(const Scenario& s) {
  controller::MasterConfig m = master_config(s);
  // The platform loop's odometry counts what the drives report: position actual values.
  m.loop.counts_per_rev = s.bus.canopen.counts_per_rev;
  return fmt::format("# platform loop of omni-master --bus canopen, written by omnitwin for scenario {}\n", s.name) +
         controller::dump_master_config(m);
}

std::string canopen_master_config_yaml(const Scenario& s, const std::string& platform_file) {
  const CanopenSpec& c = s.bus.canopen;
  std::string out = fmt::format("# omni-master --bus canopen configuration written by omnitwin for scenario {}\n", s.name);
  out += fmt::format("eds: {}\n", canopen_eds_path(c));
  out += fmt::format("cycle: {}\n", c.cycle);
  if (c.sync_producer == "drive") out += fmt::format("sync_producer: 1\ntick: {}\n", s.controller.period);
  out += "nodes: [1, 2, 3, 4]\n";
  out += fmt::format("master_heartbeat_ms: {}\nnode_heartbeat_ms: {}\nheartbeat_timeout_ms: {}\n", c.heartbeat_ms,
                     c.heartbeat_ms, 3 * c.heartbeat_ms);
  out += fmt::format("wheel_mode: {}\nwheel_counts_per_rev: {}\n", c.mode, c.counts_per_rev);
  // A realtime master may start before the twin's nodes are up.
  out += fmt::format("startup_timeout: {}\n", std::max(1.0, c.startup + (s.clock == ClockMode::realtime ? controller::kRealtimeStartupGrace : 0.0)));
  out += fmt::format("platform: {}\n", platform_file);
  return out;
}

std::string tml_platform_yaml(const Scenario& s) {
  controller::MasterConfig m = master_config(s);
  // The platform loop's odometry counts what the drives report: APOS in encoder counts.
  m.loop.counts_per_rev = s.bus.tml.counts_per_rev;
  return fmt::format("# platform loop of omni-master --bus tml, written by omnitwin for scenario {}\n", s.name) +
         controller::dump_master_config(m);
}

std::string tml_master_config_yaml(const Scenario& s, const std::string& platform_file) {
  const TmlSpec& t = s.bus.tml;
  std::string out = fmt::format("# omni-master --bus tml configuration written by omnitwin for scenario {}\n", s.name);
  out += fmt::format("protocol: {}\ncycle: {}\naxes: [1, 2, 3, 4]\n", t.protocol, t.cycle);
  out += fmt::format("sample_period: {}\nwheel_counts_per_rev: {}\n", t.drive_period, t.counts_per_rev);
  out += fmt::format("startup_timeout: {}\n", std::max(1.0, t.startup + (s.clock == ClockMode::realtime ? controller::kRealtimeStartupGrace : 0.0)));
  out += fmt::format("platform: {}\n", platform_file);
  return out;
}

}  // namespace omnitwin::twin
