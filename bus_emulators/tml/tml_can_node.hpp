// bus_emulators/tml — an emulated Technosoft IDM drive on a CAN bus (seed 003 chapters 4 and 5;
// docs/protocols/tml.md "The drive"): the TmlDrive protocol core behind the TMLCAN (29-bit) or
// TechCAN (11-bit) codec of tml_can. Frames and time in, frames out through a callback; no
// sockets, no clock. Shaped like canopen::DriveNode so the twin runs it the same way: every bus
// frame goes to on_frame(), step() runs once per drive period.
//
// Frames that are not this protocol's are ignored and counted: a TechCAN node shares its bus
// with CANopen nodes (their COB-IDs lie outside TechCAN's ranges), and 29-bit frames; a TMLCAN
// node ignores 11-bit frames. Answers of other drives (TakeData, TakeData2, PONG) are ignored.
// Set-up throws; on_frame/step are real-time safe (no allocation).
#pragma once

#include <cstdint>
#include <functional>

#include "bus_emulators/can/can_frame.hpp"
#include "bus_emulators/tml/tml_can.hpp"
#include "bus_emulators/tml/tml_drive.hpp"

namespace omnitwin::tml {

struct CanNodeStats {
  std::uint64_t frames_in = 0;       // every frame seen
  std::uint64_t delivered = 0;       // decoded and handed to the drive
  std::uint64_t foreign = 0;         // not this protocol (CANopen, the other frame format)
  std::uint64_t others_answers = 0;  // TakeData / TakeData2 / PONG of other drives
  std::uint64_t malformed = 0;       // this protocol's range, but not a valid TML frame
  std::uint64_t frames_out = 0;
  std::uint64_t encode_errors = 0;   // a message this protocol cannot carry
  std::uint64_t send_refused = 0;    // the frame sink returned false
};

class TmlCanNode {
 public:
  using FrameSink = std::function<bool(const can::Frame&, SimTime)>;
  // setup.protocol must be tmlcan or techcan (std::invalid_argument otherwise; TmlDrive's
  // checks apply too).
  TmlCanNode(const DriveSetup& setup, FrameSink out);
  TmlCanNode(const TmlCanNode&) = delete;
  TmlCanNode& operator=(const TmlCanNode&) = delete;

  // Power on at t / power lost (silent until power_on). RT-safe.
  void power_on(SimTime t) { drive_.power_on(t); }
  void power_off() { drive_.power_off(); }
  // Every frame on the bus at t. RT-safe.
  void on_frame(const can::Frame& f, SimTime t);
  // One drive period (see TmlDrive::step). RT-safe.
  drive::Command step(SimTime t, const drive::Feedback& fb) { return drive_.step(t, fb); }

  TmlDrive& drive() { return drive_; }
  const TmlDrive& drive() const { return drive_; }
  const CanNodeStats& stats() const { return stats_; }

 private:
  void send(const Message& m, SimTime t);
  void on_techcan(const can::Frame& f, SimTime t);
  void on_tmlcan(const can::Frame& f, SimTime t);

  FrameSink out_;
  TmlDrive drive_;
  CanNodeStats stats_;
};

}  // namespace omnitwin::tml
