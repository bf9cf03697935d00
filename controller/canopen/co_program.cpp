// controller/canopen — the `--bus canopen` program path (see co_program.hpp).
#include "controller/canopen/co_program.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <poll.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <vector>

#include "bus_emulators/can/transport.hpp"
#include "bus_emulators/canopen/co_eds.hpp"
#include "controller/canopen/co_config.hpp"
#include "controller/canopen/co_master.hpp"
#include "controller/can_master_loop.hpp"
#include "controller/master_config.hpp"
#include "controller/platform_driver.hpp"
#include "controller/program_support.hpp"
#include "controller/sim_clock.hpp"

namespace omnitwin::controller::canopen {

namespace {

constexpr int kExitOk = 0, kExitUsage = 2, kExitRuntime = 3;

// The CANopen master core and the platform loop, one SYNC period at a time: the wheels' speeds
// go into RPDO1 once every drive is operation enabled.
class Runner : public CanRunner<Runner, CoMaster> {
 public:
  static constexpr const char* kStarted = "wheel drives enabled";
  Runner(const CoProgramConfig& pc, const omnitwin::canopen::EdsDevice& eds, std::optional<MasterConfig> platform,
         can::Transport& tr, bool hold)
      : CanRunner(tr, hold, PlatformDriver(platform, master_tick(pc), pc.wheel_counts_per_rev), pc, eds) {}

  bool drives_ready() const { return master().phase() == CoPhase::running; }
  void command(int i, double counts_per_s) { core().set_velocity(i, static_cast<std::int32_t>(std::llround(counts_per_s))); }
  bool failed() const { return master().phase() == CoPhase::failed; }

  nlohmann::json stats() const {
    const CoMaster& m = master();
    const CoMasterStats& s = m.stats();
    nlohmann::json nodes = nlohmann::json::array();
    for (int i = 0; i < 4; ++i) {
      const CoNodeView v = m.node(i);
      nodes.push_back({{"node", v.id}, {"nmt_state", omnitwin::canopen::to_string(v.nmt)}, {"statusword", v.statusword},
                       {"emcy", v.emcy}, {"last_emcy", v.last_emcy}, {"tpdos", v.tpdos}, {"configured", v.configured},
                       {"lost", v.lost}});
    }
    return {{"phase", to_string(m.phase())}, {"reason", simclock::to_string(m.reason())}, {"reason_node", m.reason_node()},
            {"cycles", s.ticks}, {"syncs", s.syncs}, {"sdo_done", s.sdo_done}, {"sdo_aborts", s.sdo_aborts},
            {"last_sdo_abort", fmt::format("0x{:08X}", s.last_abort)},
            {"emcy", s.emcy}, {"heartbeat_timeouts", s.heartbeat_timeouts}, {"boot_ups", s.boot_ups},
            {"recoveries", s.recoveries}, {"tpdo_rx", s.tpdo_rx}, {"nmt_sent", s.nmt_sent},
            {"send_failures", s.tx_refused}, {"nodes", nodes}};
  }
};

bool write_stats(const std::string& path, const Runner& r) {
  nlohmann::json j = r.stats();
  j["frames_tx"] = r.frames_tx();
  j["frames_rx"] = r.frames_rx;
  return write_stats_file(path, j.dump());
}

void log_end(const Runner& r) {
  const CoMaster& m = r.master();
  const CoMasterStats& s = m.stats();
  spdlog::info("end: phase {}, reason {}{}, ticks {}, SYNCs {}, SDO transfers {} (aborted {}), EMCY {}, heartbeat timeouts {}, "
               "recoveries {}, frames tx {} rx {}",
               to_string(m.phase()), simclock::to_string(m.reason()),
               m.reason_node() ? fmt::format(" (node {})", m.reason_node()) : "", s.ticks, s.syncs, s.sdo_done, s.sdo_aborts,
               s.emcy, s.heartbeat_timeouts, s.recoveries, r.frames_tx(), r.frames_rx);
}

}  // namespace

int run_canopen_program(const ProgramOptions& o) {
  CoProgramConfig pc;
  std::optional<MasterConfig> platform;
  std::optional<omnitwin::canopen::EdsDevice> eds;
  try {
    pc = load_co_config(o.config);
    platform = load_platform_section(pc.platform_file, pc.platform_yaml, o.config);
    eds = omnitwin::canopen::load_eds(pc.eds);
  } catch (const CoConfigError& e) {
    spdlog::error("{}", e.what());
    return kExitUsage;
  } catch (const MasterConfigError& e) {
    spdlog::error("{}", e.what());
    return kExitUsage;
  } catch (const omnitwin::canopen::EdsError& e) {
    spdlog::error("{}", e.what());
    return kExitUsage;
  }
  if (o.print_config) {
    std::cout << dump_co_config(pc);
    if (platform) std::cout << dump_master_config(*platform);
    return kExitOk;
  }
  const std::unique_ptr<can::Transport> tr = open_can_iface(o.iface);
  if (!tr) return kExitUsage;
  std::unique_ptr<Runner> runner;
  try {
    runner = std::make_unique<Runner>(pc, *eds, platform, *tr, o.clock == "sim");
  } catch (const std::runtime_error& e) {  // the EDS lacks what the master maps
    spdlog::error("{}", e.what());
    return kExitUsage;
  }
  spdlog::info("CANopen master on {} (clock {}, SYNC every {} µs from {}, tick {} µs, nodes {} {} {} {}, {})", tr->spec(),
               o.clock, std::llround(pc.cycle * 1e6),
               pc.sync_producer ? fmt::format("node {}", pc.sync_producer) : std::string("the master"),
               std::llround(master_tick(pc) * 1e6), pc.nodes[0], pc.nodes[1], pc.nodes[2], pc.nodes[3],
               pc.mode == WheelMode::csv ? "CSV" : "PV");
  int code = run_can_master(o, *runner, *tr, std::llround(master_tick(pc) * 1e9));
  log_end(*runner);
  if (!o.stats.empty() && !write_stats(o.stats, *runner)) code = kExitRuntime;
  return code;
}

}  // namespace omnitwin::controller::canopen
