// twin layer — the twin's side of a TML network (bus `tml`): four emulated Technosoft IDM
// drives (bus_emulators/tml/tml_can_node, seed 003) with axis IDs 1..4 on the simulated CAN
// wire (can_drive_network), speaking TMLCAN (29-bit) or TechCAN (11-bit).
#pragma once

#include <array>
#include <memory>

#include "bus_emulators/tml/tml_can_node.hpp"
#include "twin/can_drive_network.hpp"

namespace omnitwin::twin {

class TmlNetwork final : public CanDriveNetwork {
 public:
  // Builds the wire and the drives, opens the transport (throws can::TransportError). Not
  // real-time safe.
  TmlNetwork(const Scenario& s, Scheduler& sched, Hooks hooks);

  nlohmann::json bus_metrics(SimTime now) const override;
  const tml::TmlCanNode& drive(int axis0) const { return *drives_[static_cast<std::size_t>(axis0)]; }

 private:
  void deliver(int axis0, const can::Frame& f, SimTime t) override;
  drive::Command drive_step(int axis0, SimTime t, const drive::Feedback& fb) override {
    return drives_[static_cast<std::size_t>(axis0)]->step(t, fb);
  }
  const drive::Cia402Drive& drive_core(int axis0) const override { return drives_[static_cast<std::size_t>(axis0)]->drive().core(); }
  void drive_power(int axis0, bool on, SimTime t) override;
  bool drive_running(int axis0) const override;
  DriveDetail drive_detail(int axis0) const override;
  std::string drive_protocol_state(int axis0) const override;
  nlohmann::json drive_json(int axis0) const override;

  const TmlSpec& spec_;
  std::array<std::unique_ptr<tml::TmlCanNode>, 4> drives_;
};

}  // namespace omnitwin::twin
