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

// The TML master core and the platform loop, one tick at a time: each wheel's speed goes into
// its axis's CSPD once every axis is on.
class Runner : public CanRunner<Runner, TmlMaster> {
 public:
  static constexpr const char* kStarted = "axes on";
  Runner(const TmlProgramConfig& pc, std::optional<MasterConfig> platform, can::Transport& tr, bool hold)
      : CanRunner(tr, hold, PlatformDriver(platform, pc.cycle, pc.wheel_counts_per_rev), pc), pc_(pc) {}

  bool drives_ready() const { return master().phase() == TmlPhase::running; }
  void command(int i, double counts_per_s) { core().set_speed(i, counts_per_s); }
  bool failed() const { return master().phase() == TmlPhase::failed; }

  nlohmann::json stats() const {
    const TmlMaster& m = master();
    const TmlMasterStats& s = m.stats();
    nlohmann::json axes = nlohmann::json::array();
    for (int i = 0; i < 4; ++i) axes.push_back({{"axis", pc_.axes[static_cast<std::size_t>(i)]}, {"srl", m.srl(i)},
                                                {"apos", m.position(i)}});
    return {{"phase", to_string(m.phase())}, {"cycles", s.ticks}, {"answers", s.answers},
            {"axes_lost", s.axes_lost}, {"setup_resends", s.setup_resends}, {"not_tml", s.not_tml}, {"send_failures", s.tx_refused},
            {"frames_tx", frames_tx()}, {"frames_rx", frames_rx}, {"axes", axes}};
  }

 private:
  const TmlProgramConfig& pc_;
};

bool write_stats(const std::string& path, const Runner& r) { return write_stats_file(path, r.stats().dump()); }

}  // namespace

int run_tml_program(const ProgramOptions& o) {
  TmlProgramConfig pc;
  std::optional<MasterConfig> platform;
  try {
    pc = load_tml_config(o.config);
    platform = load_platform_section(pc.platform_file, pc.platform_yaml, o.config);
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
  const std::unique_ptr<can::Transport> tr = open_can_iface(o.iface);
  if (!tr) return kExitUsage;
  Runner runner(pc, platform, *tr, o.clock == "sim");
  spdlog::info("TML master on {} ({}, clock {}, tick {} µs, axes {} {} {} {}, host axis {})", tr->spec(),
               pc.techcan ? "TechCAN" : "TMLCAN", o.clock, std::llround(pc.cycle * 1e6), pc.axes[0], pc.axes[1], pc.axes[2],
               pc.axes[3], pc.host_axis);
  int code = run_can_master(o, runner, *tr, std::llround(pc.cycle * 1e9));
  const TmlMasterStats& s = runner.master().stats();
  spdlog::info("end: phase {}, reason {}, ticks {}, answers {}, axes lost {}, frames tx {} rx {}",
               to_string(runner.master().phase()), simclock::to_string(runner.master().reason()), s.ticks, s.answers,
               s.axes_lost, runner.frames_tx(), runner.frames_rx);
  if (!o.stats.empty() && !write_stats(o.stats, runner)) code = kExitRuntime;
  return code;
}

}  // namespace omnitwin::controller::tml
