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

std::string stamp(SimTime t) { return fmt::format("[{:10.4f} ms]", static_cast<double>(t) * 1e-6); }

// The master core and the platform loop, one SYNC period at a time; frames out through an
// outbox (lockstep: sent in one batch after the tick) or straight to the transport.
class Runner {
 public:
  Runner(const CoProgramConfig& pc, const omnitwin::canopen::EdsDevice& eds, std::optional<MasterConfig> platform,
         can::Transport& tr, bool hold)
      : pc_(pc),
        out_(tr, hold),
        master_(pc, eds, [this](const can::Frame& f, SimTime t) { return out_.send(f, t); }),
        platform_(platform, master_tick(pc), pc.wheel_counts_per_rev) {
    master_.set_event_callback([](SimTime t, const std::string& s, bool warning) {
      if (warning) spdlog::warn("{} {}", stamp(t), s);
      else spdlog::info("{} {}", stamp(t), s);
    });
  }

  CoMaster& master() { return master_; }
  const CoMaster& master() const { return master_; }

  void on_frame(const can::Frame& f, SimTime t) {
    ++frames_rx;
    master_.on_frame(f, t);
  }
  // One SYNC period at t: the platform's set-points, then the core's frames.
  void tick(SimTime t) {
    platform(t);
    master_.on_tick(t);
  }
  // Lockstep: the tick's frames in one batch. Refusals reach the core.
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
    const CoMasterStats& s = master_.stats();
    nlohmann::json nodes = nlohmann::json::array();
    for (int i = 0; i < 4; ++i) {
      const CoNodeView v = master_.node(i);
      nodes.push_back({{"node", v.id}, {"nmt_state", omnitwin::canopen::to_string(v.nmt)}, {"statusword", v.statusword},
                       {"emcy", v.emcy}, {"last_emcy", v.last_emcy}, {"tpdos", v.tpdos}, {"configured", v.configured},
                       {"lost", v.lost}});
    }
    return {{"phase", to_string(master_.phase())}, {"cycles", s.ticks}, {"syncs", s.syncs},
            {"sdo_done", s.sdo_done}, {"sdo_aborts", s.sdo_aborts}, {"last_sdo_abort", s.last_abort},
            {"emcy", s.emcy}, {"heartbeat_timeouts", s.heartbeat_timeouts}, {"boot_ups", s.boot_ups},
            {"recoveries", s.recoveries}, {"tpdo_rx", s.tpdo_rx}, {"nmt_sent", s.nmt_sent},
            {"send_failures", s.tx_refused}, {"nodes", nodes}};
  }

  bool failed() const { return master_.phase() == CoPhase::failed; }
  std::uint64_t frames_tx() const { return out_.frames_tx(); }
  std::uint64_t frames_rx = 0;

 private:
  WheelCounts counts() const {
    WheelCounts c{};
    for (int i = 0; i < 4; ++i) c[static_cast<std::size_t>(i)] = master_.position(i);
    return c;
  }
  void platform(SimTime t) {
    const PlatformDriver::Step st = platform_.tick(t, master_.phase() == CoPhase::running, counts());
    if (st.started) spdlog::info("{} wheel drives enabled: platform loop running", stamp(t));
    if (st.command)
      for (int i = 0; i < 4; ++i) master_.set_velocity(i, static_cast<std::int32_t>(std::llround(st.wheel_counts_per_s[static_cast<std::size_t>(i)])));
    if (st.finished) {
      master_.finish(t);
      spdlog::info("{} path done", stamp(t));
    }
  }

  const CoProgramConfig& pc_;
  CanOutbox out_;  // before the core: its send callback
  CoMaster master_;
  PlatformDriver platform_;
};

void write_stats(const std::string& path, const Runner& r) {
  nlohmann::json j = r.stats();
  j["frames_tx"] = r.frames_tx();
  j["frames_rx"] = r.frames_rx;
  write_stats_file(path, j.dump());
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
    if (!pc.platform_file.empty()) platform = load_master_config(pc.platform_file);
    else if (!pc.platform_yaml.empty()) platform = parse_master_config(pc.platform_yaml, o.config + " (platform)");
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
  std::unique_ptr<can::Transport> tr;
  try {
    tr = can::open_transport(normalize_iface(o.iface));
  } catch (const can::TransportError& e) {
    spdlog::error("--iface {}: {}", o.iface, e.what());
    return kExitUsage;
  }
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
  const int sigfd = open_signal_fd();
  int code = kExitOk;
  try {
    code = o.clock == "sim" ? run_lockstep(o.sim_clock, *runner, *tr, sigfd)
                            : run_wall_clock(std::llround(master_tick(pc) * 1e9), o.duration, *runner, *tr, sigfd);
  } catch (const LoopFailure& f) {
    spdlog::error("{}", f.message);
    code = kExitRuntime;
  } catch (const simclock::ChannelError& e) {
    spdlog::error("{}", e.what());
    code = kExitRuntime;
  }
  runner->flush();
  runner->release();
  if (runner->failed()) code = kExitRuntime;
  log_end(*runner);
  if (!o.stats.empty()) write_stats(o.stats, *runner);
  if (sigfd >= 0) ::close(sigfd);
  return code;
}

}  // namespace omnitwin::controller::canopen
