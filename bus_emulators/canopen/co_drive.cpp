// bus_emulators/canopen — a CiA 402 drive as a CANopen node (see co_drive.hpp).
#include "bus_emulators/canopen/co_drive.hpp"

#include "bus_emulators/ethercat/device/cia402_od.hpp"

namespace omnitwin::canopen {

namespace {

// The EDS's dictionary with the drive's objects bound in.
ObjectDictionary build(const EdsDevice& eds, std::uint8_t node_id, drive::Cia402Drive& d) {
  ObjectDictionary od;
  add_to_od(eds, node_id, od);
  ethercat::bind_cia402_objects(od, d);
  return od;
}

bool enabled(drive::State s) {
  return s == drive::State::operation_enabled || s == drive::State::quick_stop_active;
}
bool faulted(drive::State s) { return s == drive::State::fault_reaction_active || s == drive::State::fault; }

}  // namespace

DriveNode::DriveNode(const EdsDevice& eds, std::uint8_t node_id, const drive::DriveConfig& drive_config, SendFn send)
    : drive_(drive_config),
      od_(build(eds, node_id, drive_)),
      node_(od_, node_id, std::move(send),
            NodeHooks{nullptr, [this](NmtTransition tr, SimTime t) { on_nmt(tr, t); },
                      [this](std::uint16_t code, SimTime t) { on_comm_error(code, t); }}) {}

void DriveNode::power_on(SimTime now) {
  powered_ = true;
  node_.power_on(now);  // reset node: the application reset (on_nmt) powers the drive core on
}

void DriveNode::on_nmt(NmtTransition tr, SimTime now) {
  switch (tr) {
    case NmtTransition::reset_node:
      drive_.power_cycle();
      comm_fault_pending_ = false;
      last_state_ = drive_.state();
      raised_code_ = 0;
      return;
    case NmtTransition::stop:
    case NmtTransition::enter_pre_operational:
    case NmtTransition::reset_communication:
      // The master left us while the wheels were powered: fault (0x6007 = 1).
      if (enabled(drive_.state())) on_comm_error(0x8100, now);
      return;
    default:
      return;
  }
}

void DriveNode::on_comm_error(std::uint16_t code, SimTime /*now*/) {
  if (!enabled(drive_.state()) || comm_fault_pending_) return;  // one fault per loss
  drive_.raise_fault(code);
  comm_fault_pending_ = true;
  ++stats_.comm_faults;
}

drive::Command DriveNode::step(SimTime now, const drive::Feedback& fb) {
  if (!powered_) return drive::Command{};
  node_.on_time(now);
  const drive::Command c = drive_.step(now, fb);
  ++stats_.steps;
  const drive::State s = drive_.state();
  if (!enabled(s)) comm_fault_pending_ = false;
  // A fault signals its 0x603F code once; the fault reset clears it (the "no error" EMCY).
  if (faulted(s) && !faulted(last_state_)) {
    raised_code_ = drive_.objects().error_code != 0 ? drive_.objects().error_code : emcy_code::generic;
    node_.raise_error(raised_code_, now);
    ++stats_.faults;
  } else if (!faulted(s) && faulted(last_state_) && raised_code_ != 0) {
    node_.clear_error(raised_code_, now);
    raised_code_ = 0;
  }
  last_state_ = s;
  return c;
}

}  // namespace omnitwin::canopen
