// Test and benchmark support (not a test file): the shipped CiA 402 drive's EDS, and a drive
// node built from it on one node of a simulated CAN bus. Shared by the CANopen master's test
// network (tests/controller/canopen/co_network.hpp, also its fuzz target) and the CAN scaling
// benchmark, which put several such drives on one wire.
#pragma once

#include <memory>
#include <string>

#include "bus_emulators/can/can_bus.hpp"
#include "bus_emulators/canopen/co_drive.hpp"
#include "bus_emulators/canopen/co_eds.hpp"

namespace omnitwin::canopen::testing {

// models/canopen/omnitwin_drive.eds, loaded once.
inline const EdsDevice& shipped_eds() {
  static const EdsDevice eds = load_eds(std::string(OMNITWIN_SOURCE_DIR) + "/models/canopen/omnitwin_drive.eds");
  return eds;
}

// A drive with node ID `node` that sends as bus node `node` of `bus` (10,000 counts per
// revolution); the caller delivers the bus's frames to it and powers it on.
inline std::unique_ptr<DriveNode> drive_on_bus(can::CanBus& bus, int node) {
  drive::DriveConfig dc;
  dc.counts_per_rev = 10000;
  return std::make_unique<DriveNode>(shipped_eds(), static_cast<std::uint8_t>(node), dc,
                                     [&bus, node](const can::Frame& f, SimTime t) {
                                       return bus.submit(node, f, t) == can::SubmitStatus::queued;
                                     });
}

}  // namespace omnitwin::canopen::testing
