// bus_emulators/canopen — a CiA 402 single-axis servo drive as a CANopen node: the object
// dictionary of its EDS, the node's CiA 301 services (co_node) and the shared drive core
// (drive/cia402_drive), whose 0x6000 objects are bound into the dictionary so that SDO and
// PDO access read and write the drive's own variables.
//
// The drive runs its period on the owner's timer (step()): node timers first, then one drive
// step; a fault of the drive raises an EMCY with its 0x603F error code, and its reset clears
// it. Communication errors while the drive is enabled (the master's heartbeat lost, life
// guarding, bus-off) fault the drive, as CiA 402's abort connection option code 0x6007 = 1
// ("fault signal") asks: the wheels must not run on without their master. Leaving OPERATIONAL
// while the drive is enabled does the same.
// Set-up allocates; on_frame/step are real-time safe.
#pragma once

#include <cstdint>

#include "bus_emulators/canopen/co_eds.hpp"
#include "bus_emulators/canopen/co_node.hpp"
#include "bus_emulators/drive/cia402_drive.hpp"

namespace omnitwin::canopen {

struct DriveNodeStats {
  std::uint64_t faults = 0, comm_faults = 0, steps = 0;
};

class DriveNode {
 public:
  // Builds the dictionary from `eds` for `node_id`, binds the drive's objects and wires the
  // node. Throws std::invalid_argument for a bad node ID (set-up).
  DriveNode(const EdsDevice& eds, std::uint8_t node_id, const drive::DriveConfig& drive_config, SendFn send);
  DriveNode(const DriveNode&) = delete;
  DriveNode& operator=(const DriveNode&) = delete;

  // Power on: drive and node back to their power-on state, boot-up message. Real-time safe
  // apart from nothing (no allocation).
  void power_on(SimTime now);
  // Power lost: the node falls silent until power_on (the owner stops calling it).
  void power_off() { powered_ = false; }
  bool powered() const { return powered_; }

  // Every frame on the bus. Real-time safe.
  void on_frame(const can::Frame& f, SimTime now) {
    if (powered_) node_.on_frame(f, now);
  }
  // One drive period at now: node timers, the drive core's step, EMCY on faults. Returns the
  // command to the physics (power off: no power). Real-time safe.
  drive::Command step(SimTime now, const drive::Feedback& fb);
  // The controller recovered from bus-off. Real-time safe.
  void on_bus_off_recovered(SimTime now) {
    if (powered_) node_.on_bus_off_recovered(now);
  }

  Node& node() { return node_; }
  const Node& node() const { return node_; }
  drive::Cia402Drive& drive() { return drive_; }
  const drive::Cia402Drive& drive() const { return drive_; }
  const DriveNodeStats& stats() const { return stats_; }

 private:
  void on_nmt(NmtTransition tr, SimTime now);
  void on_comm_error(std::uint16_t code, SimTime now);

  drive::Cia402Drive drive_;  // before the dictionary: its objects are bound into it
  ObjectDictionary od_;       // before the node: the PDOs resolve pointers into bound storage
  Node node_;
  bool powered_ = false;
  drive::State last_state_ = drive::State::not_ready_to_switch_on;
  std::uint16_t raised_code_ = 0;  // the 0x603F code signalled by EMCY (0 = none)
  bool comm_fault_pending_ = false;  // a communication fault was raised; the drive has not left enabled yet
  DriveNodeStats stats_;
};

}  // namespace omnitwin::canopen
