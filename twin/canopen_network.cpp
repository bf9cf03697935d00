// twin layer — the twin's side of a CANopen network; see canopen_network.hpp.
#include "twin/canopen_network.hpp"

#include <fmt/format.h>

#include <filesystem>

#include "bus_emulators/can/can_bits.hpp"

namespace omnitwin::twin {

namespace {

// NMT to all nodes: 0x000 [cs 00].
bool is_nmt_all(const can::Frame& f, std::uint8_t cs) {
  return f.id == 0 && !f.extended && f.kind == can::FrameKind::data && f.dlc == 2 && f.data[0] == cs && f.data[1] == 0;
}

CanDriveSetup setup_of(const Scenario& s) {
  return CanDriveSetup{"canopen", s.bus.canopen.drive_period, s.bus.canopen.drift, s.bus.canopen.counts_per_rev};
}

}  // namespace

LoadBudget canopen_load_budget(const Scenario& s) {
  const CanopenSpec& c = s.bus.canopen;
  LoadBudget out;
  for (const bool worst : {false, true}) {
    // A frame's bits: all-zero data (the stuffing a run mostly sees) or the worst case.
    auto bits = [worst](std::uint32_t id, int bytes) {
      if (worst) return static_cast<double>(can::worst_case_frame_bits(false, bytes));
      return static_cast<double>(can::frame_bits_with_intermission(canopen::frame11(id, static_cast<std::uint8_t>(bytes))));
    };
    const double per_s = 1.0 / c.cycle;
    // RPDO1 every SYNC from a master producing SYNC, every control period otherwise.
    const double rpdo_per_s = c.sync_producer == "drive" ? 1.0 / s.controller.period : per_s;
    double b = per_s * (bits(0x80, 0) + 4 * bits(0x181, 6)) + rpdo_per_s * 4 * bits(0x201, 6);  // SYNC, TPDO1, RPDO1
    b += 4 * bits(0x281, 6) * per_s / 10;                                          // TPDO2, inhibit 10 SYNCs
    b += 5 * bits(0x701, 1) * 1000.0 / c.heartbeat_ms;                             // four drives and the master
    (worst ? out.worst : out.nominal) = b / static_cast<double>(s.bus.can.bit_rate);
  }
  return out;
}

std::string canopen_eds_path(const CanopenSpec& c) {
  if (!c.eds.empty()) return std::filesystem::absolute(c.eds).lexically_normal().string();
  return std::string(OMNITWIN_SOURCE_DIR) + "/models/canopen/omnitwin_drive.eds";
}

CanopenNetwork::CanopenNetwork(const Scenario& s, Scheduler& sched, Hooks hooks)
    : CanDriveNetwork(s, sched, std::move(hooks), setup_of(s)),
      spec_(s.bus.canopen),
      eds_(canopen::load_eds(canopen_eds_path(s.bus.canopen))) {
  for (int i = 0; i < 4; ++i) {
    drive::DriveConfig dc;
    dc.counts_per_rev = spec_.counts_per_rev;
    dc.gear_ratio = 1.0;
    dc.period_s = spec_.drive_period;
    dc.max_speed_rad_s = s.platform.motor.speed_limit;
    dc.rated_torque_nm = s.platform.motor.torque_limit;
    drives_[static_cast<std::size_t>(i)] = std::make_unique<canopen::DriveNode>(
        eds_, static_cast<std::uint8_t>(i + 1), dc, [this, i](const can::Frame& f, SimTime at) { return submit(i, f, at); });
  }
  budget_ = canopen_load_budget(s);
  start();  // power on at t = 0: each node's boot-up message goes onto the wire
}

void CanopenNetwork::drive_power(int axis0, bool on, SimTime t) {
  canopen::DriveNode& d = *drives_[static_cast<std::size_t>(axis0)];
  if (on) d.power_on(t);
  else d.power_off();
}

bool CanopenNetwork::drive_running(int axis0) const {
  const canopen::DriveNode& d = *drives_[static_cast<std::size_t>(axis0)];
  return d.node().state() == canopen::NmtState::operational && d.drive().state() == drive::State::operation_enabled;
}

BusNetwork::DriveDetail CanopenNetwork::drive_detail(int axis0) const {
  if (!powered(axis0)) return {"off", ""};
  const canopen::DriveNode& d = *drives_[static_cast<std::size_t>(axis0)];
  return {canopen::to_string(d.node().state()), drive::to_string(d.drive().state())};
}

std::string CanopenNetwork::drive_protocol_state(int axis0) const {
  return fmt::format("NMT {}", powered(axis0) ? canopen::to_string(drives_[static_cast<std::size_t>(axis0)]->node().state()) : "off");
}

void CanopenNetwork::on_master_frame(const can::Frame& f, SimTime end) {
  if (is_nmt_all(f, 0x01)) {
    note_master_start(end);
    bus_stopped_ = false;
  }
  if (is_nmt_all(f, 0x02)) bus_stopped_ = true;
}

void CanopenNetwork::open_pcap(const std::string& path) {
  // The run's records are open now: the configuration's budget goes into events.log.
  hooks().log(0, "bus", fmt::format("load budget {:.1f} % of {} bit/s at a {} ms SYNC ({:.1f} % with worst-case bit "
                                    "stuffing){}",
                                    100 * budget_.nominal, scenario().bus.can.bit_rate, spec_.cycle * 1e3, 100 * budget_.worst,
                                    budget_.nominal > 1 ? ": the configuration does not fit the wire" : ""));
  CanDriveNetwork::open_pcap(path);
}

nlohmann::json CanopenNetwork::drive_json(int axis0) const {
  const canopen::DriveNode& d = *drives_[static_cast<std::size_t>(axis0)];
  const canopen::Node& node = d.node();
  const canopen::PdoStats& p = node.pdo().stats();
  return {{"nmt_state", powered(axis0) ? canopen::to_string(node.state()) : "off"},
          {"emcy", node.emcy().sent()},
          {"sdo_requests", node.sdo().stats().requests},
          {"sdo_aborts", node.sdo().stats().aborts_sent},
          {"rpdo_rx", p.rpdo_rx},
          {"tpdo_tx", p.tpdo_tx},
          {"rpdo_per_s", now() > 0 ? static_cast<double>(p.rpdo_rx) * 1e9 / static_cast<double>(now()) : 0.0},
          {"tpdo_per_s", now() > 0 ? static_cast<double>(p.tpdo_tx) * 1e9 / static_cast<double>(now()) : 0.0},
          {"pdo_length_errors", p.length_errors},
          {"syncs", node.stats().syncs},
          {"heartbeats", node.error_control().heartbeats_sent()},
          {"faults", d.stats().faults},
          {"comm_faults", d.stats().comm_faults}};
}

nlohmann::json CanopenNetwork::bus_metrics(SimTime now) const {
  nlohmann::json j = wire_metrics(now);
  std::uint64_t emcy = 0, aborts = 0;
  for (const auto& d : drives_) emcy += d->node().emcy().sent(), aborts += d->node().sdo().stats().aborts_sent;
  j["eds"] = canopen_eds_path(spec_);
  j["emcy"] = emcy;
  j["sdo_aborts"] = aborts;
  j["load_budget"] = budget_.nominal;
  j["load_budget_worst"] = budget_.worst;
  return j;
}

}  // namespace omnitwin::twin
