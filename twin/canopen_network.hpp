// twin layer — the twin's side of a CANopen network (bus `canopen`): four emulated CiA 402
// drives, each a CANopen node (bus_emulators/canopen/co_drive) built from the drives' EDS, on
// the simulated CAN wire (can_drive_network: the wire, transport, capture and CAN faults).
// Not real-time safe at set-up; the per-event paths are.
#pragma once

#include <array>
#include <memory>
#include <string>

#include "bus_emulators/canopen/co_drive.hpp"
#include "bus_emulators/canopen/co_eds.hpp"
#include "twin/can_drive_network.hpp"

namespace omnitwin::twin {

// The EDS a scenario's canopen bus uses (absolute path).
std::string canopen_eds_path(const CanopenSpec& c);
// The wire's share the four-drive configuration needs: per SYNC the SYNC, four RPDO1 and four
// TPDO1 (6 bytes), TPDO2 at most every 10 SYNCs, five heartbeats per heartbeat period; with
// the stuffing of all-zero data (nominal) and the worst case. nominal > 1: it does not fit.
struct LoadBudget {
  double nominal = 0, worst = 0;
};
LoadBudget canopen_load_budget(const Scenario& s);

class CanopenNetwork final : public CanDriveNetwork {
 public:
  // Loads the EDS, builds the wire and the drives, opens the transport (throws
  // can::TransportError, canopen::EdsError, std::runtime_error). Not real-time safe.
  CanopenNetwork(const Scenario& s, Scheduler& sched, Hooks hooks);

  // Not after an NMT stop to all nodes seen on the wire, until an NMT start.
  bool master_must_talk() const override { return !bus_stopped_; }
  void open_pcap(const std::string& path) override;
  nlohmann::json bus_metrics(SimTime now) const override;

  const canopen::DriveNode& drive(int axis0) const { return *drives_[static_cast<std::size_t>(axis0)]; }

 private:
  void deliver(int axis0, const can::Frame& f, SimTime t) override { drives_[static_cast<std::size_t>(axis0)]->on_frame(f, t); }
  drive::Command drive_step(int axis0, SimTime t, const drive::Feedback& fb) override {
    return drives_[static_cast<std::size_t>(axis0)]->step(t, fb);
  }
  const drive::Cia402Drive& drive_core(int axis0) const override { return drives_[static_cast<std::size_t>(axis0)]->drive(); }
  void drive_power(int axis0, bool on, SimTime t) override;
  void drive_bus_off_recovered(int axis0, SimTime t) override {
    drives_[static_cast<std::size_t>(axis0)]->on_bus_off_recovered(t);  // EMCY 0x8140, error behaviour
  }
  bool drive_running(int axis0) const override;
  DriveDetail drive_detail(int axis0) const override;
  std::string drive_protocol_state(int axis0) const override;
  void on_master_frame(const can::Frame& f, SimTime end) override;
  nlohmann::json drive_json(int axis0) const override;

  const CanopenSpec& spec_;
  canopen::EdsDevice eds_;
  std::array<std::unique_ptr<canopen::DriveNode>, 4> drives_;
  bool bus_stopped_ = false;
  LoadBudget budget_;
};

}  // namespace omnitwin::twin
