// bus_emulators/tml — the relay axis (seed 003 chapter 2, facts/tml.md "HOST bit"): the drive a
// PC is wired to over RS-232 forwards the PC's messages for other axes onto the CAN bus, and
// the answers addressed to the host (its own axis ID with the HOST bit) back over RS-232.
//
// A protocol core: messages from the host and frames from CAN in, messages to the host and
// frames to CAN out through callbacks; no sockets, no clock. The relay's own drive gets the
// messages for itself from either side (tml_drive does the addressing: axis 0 and its groups
// included, so a broadcast from the host reaches it and the CAN bus). Real-time safe.
#pragma once

#include <cstdint>
#include <functional>

#include "bus_emulators/can/can_frame.hpp"
#include "bus_emulators/tml/tml_drive.hpp"

namespace omnitwin::tml {

struct RelayStats {
  std::uint64_t to_can = 0, to_host = 0, own = 0, not_encodable = 0, ignored = 0;
};

class TmlRelay {
 public:
  using FrameSink = std::function<bool(const can::Frame&, SimTime)>;
  using HostSink = std::function<void(const Message&, SimTime)>;

  // can_protocol: tmlcan or techcan (std::invalid_argument otherwise: set-up).
  TmlRelay(TmlDrive& drive, Protocol can_protocol, FrameSink to_can, HostSink to_host);

  // A message the host sent over RS-232. RT-safe.
  void from_host(const Message& m, SimTime t);
  // A frame on the CAN bus. RT-safe.
  void from_can(const can::Frame& f, SimTime t);
  const RelayStats& stats() const { return stats_; }

 private:
  bool host_answer(const Message& m) const;

  TmlDrive& drive_;
  Protocol protocol_;
  FrameSink to_can_;
  HostSink to_host_;
  RelayStats stats_;
};

}  // namespace omnitwin::tml
