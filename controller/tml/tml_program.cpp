// controller/tml — the `--bus tml` program path (see tml_program.hpp).
#include "controller/tml/tml_program.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <numbers>
#include <optional>
#include <vector>

#include "bus_emulators/can/transport.hpp"
#include "controller/can_master_loop.hpp"
#include "controller/master_config.hpp"
#include "controller/platform_driver.hpp"
#include "controller/program_support.hpp"
#include "controller/tml/tml_master.hpp"

namespace omnitwin::controller::tml {

namespace {

constexpr int kExitOk = 0, kExitUsage = 2, kExitRuntime = 3;

std::string stamp(SimTime t) { return fmt::format("[{:10.4f} ms]", static_cast<double>(t) * 1e-6); }

// The TML master core and the platform loop, one tick at a time.
class Runner {
 public:
  Runner(const TmlProgramConfig& pc, std::optional<MasterConfig> platform, can::Transport& tr, bool hold)
      : pc_(pc), out_(tr, hold), master_(pc, [this](const can::Frame& f, SimTime t) { return out_.send(f, t); }),
        platform_(platform, pc.cycle, pc.wheel_counts_per_rev) {
    master_.set_event_callback([](SimTime t, const std::string& s, bool warning) {
      if (warning) spdlog::warn("{} {}", stamp(t), s);
      else spdlog::info("{} {}", stamp(t), s);
    });
  }

  const TmlMaster& master() const { return master_; }
  void on_frame(const can::Frame& f, SimTime t) {
    ++frames_rx;
    master_.on_frame(f, t);
  }
  void tick(SimTime t) {
    platform(t);
    master_.on_tick(t);
  }
  void flush() { master_.note_send_failures(out_.flush()); }
  void release() { out_.release(); }
  void shutdown(SimTime t) { master_.shutdown(t); }

  simclock::MasterReport report() const {
    simclock::MasterReport r;
    r.state = master_.report_state();
    r.reason = master_.reason();
    r.node = master_.reason_node();
    platform_.fill(r);
    return r;
  }
  nlohmann::json stats() const {
    const TmlMasterStats& s = master_.stats();
    nlohmann::json axes = nlohmann::json::array();
    for (int i = 0; i < 4; ++i) axes.push_back({{"axis", pc_.axes[static_cast<std::size_t>(i)]}, {"srl", master_.srl(i)},
                                                {"apos", master_.position(i)}});
    return {{"phase", to_string(master_.phase())}, {"cycles", s.ticks}, {"answers", s.answers},
            {"axes_lost", s.axes_lost}, {"not_tml", s.not_tml}, {"send_failures", s.tx_refused},
            {"frames_tx", frames_tx()}, {"frames_rx", frames_rx}, {"axes", axes}};
  }
  bool failed() const { return master_.phase() == TmlPhase::failed; }
  std::uint64_t frames_tx() const { return out_.frames_tx(); }
  std::uint64_t frames_rx = 0;

 private:
  WheelCounts counts() const {
    WheelCounts c{};
    for (int i = 0; i < 4; ++i) c[static_cast<std::size_t>(i)] = master_.position(i);
    return c;
  }
  void platform(SimTime t) {
    const PlatformDriver::Step st = platform_.tick(t, master_.phase() == TmlPhase::running, counts());
    if (st.started) spdlog::info("{} axes on: platform loop running", stamp(t));
    if (st.command)
      for (int i = 0; i < 4; ++i) master_.set_speed(i, st.wheel_counts_per_s[static_cast<std::size_t>(i)]);
    if (st.finished) {
      master_.finish(t);
      spdlog::info("{} path done", stamp(t));
    }
  }

  const TmlProgramConfig& pc_;
  CanOutbox out_;  // before the core: its send callback
  TmlMaster master_;
  PlatformDriver platform_;
};

void write_stats(const std::string& path, const Runner& r) { write_stats_file(path, r.stats().dump()); }

}  // namespace

int run_tml_program(const ProgramOptions& o) {
  TmlProgramConfig pc;
  std::optional<MasterConfig> platform;
  try {
    pc = load_tml_config(o.config);
    if (!pc.platform_file.empty()) platform = load_master_config(pc.platform_file);
    else if (!pc.platform_yaml.empty()) platform = parse_master_config(pc.platform_yaml, o.config + " (platform)");
  } catch (const TmlConfigError& e) {
    spdlog::error("{}", e.what());
    return kExitUsage;
  } catch (const MasterConfigError& e) {
    spdlog::error("{}", e.what());
    return kExitUsage;
  }
  if (o.print_config) {
    std::cout << dump_tml_config(pc);
    if (platform) std::cout << dump_master_config(*platform);
    return kExitOk;
  }
  std::unique_ptr<can::Transport> tr;
  try {
    tr = can::open_transport(normalize_iface(o.iface));
  } catch (const can::TransportError& e) {
    spdlog::error("--iface {}: {}", o.iface, e.what());
    return kExitUsage;
  }
  Runner runner(pc, platform, *tr, o.clock == "sim");
  spdlog::info("TML master on {} ({}, clock {}, tick {} µs, axes {} {} {} {}, host axis {})", tr->spec(),
               pc.techcan ? "TechCAN" : "TMLCAN", o.clock, std::llround(pc.cycle * 1e6), pc.axes[0], pc.axes[1], pc.axes[2],
               pc.axes[3], pc.host_axis);
  const int sigfd = open_signal_fd();
  int code = kExitOk;
  try {
    code = o.clock == "sim" ? run_lockstep(o.sim_clock, runner, *tr, sigfd)
                            : run_wall_clock(std::llround(pc.cycle * 1e9), o.duration, runner, *tr, sigfd);
  } catch (const LoopFailure& f) {
    spdlog::error("{}", f.message);
    code = kExitRuntime;
  } catch (const simclock::ChannelError& e) {
    spdlog::error("{}", e.what());
    code = kExitRuntime;
  }
  runner.flush();
  runner.release();
  if (runner.failed()) code = kExitRuntime;
  const TmlMasterStats& s = runner.master().stats();
  spdlog::info("end: phase {}, reason {}, ticks {}, answers {}, axes lost {}, frames tx {} rx {}",
               to_string(runner.master().phase()), simclock::to_string(runner.master().reason()), s.ticks, s.answers,
               s.axes_lost, runner.frames_tx(), runner.frames_rx);
  if (!o.stats.empty()) write_stats(o.stats, runner);
  if (sigfd >= 0) ::close(sigfd);
  return code;
}

}  // namespace omnitwin::controller::tml
