// bus_emulators/can — SocketCAN raw transport (`socketcan:vcan0`, `socketcan:can0`).
//
// A CAN_RAW socket bound to one interface, non-blocking, classic frames only (CAN FD frames
// are not enabled, so the kernel never hands us one). Error frames are received (all error
// classes) and delivered as FrameKind::error with the error class in the identifier and the
// kernel's 8 detail bytes. Own frames are not received (the kernel default).
#pragma once

#include "bus_emulators/can/transport.hpp"

namespace omnitwin::can {

class SocketCanTransport final : public Transport {
 public:
  // Throws TransportError when SocketCAN is not available (no PF_CAN: module can/can-raw not
  // loaded) or the interface does not exist.
  explicit SocketCanTransport(const std::string& ifname);
  ~SocketCanTransport() override;

  bool send(const Frame& f, std::int64_t timestamp_ns = 0) override;
  std::optional<TimedFrame> receive() override;
  int poll_fd() const override { return fd_; }
  TransportStats stats() const override { return stats_; }
  std::string spec() const override { return "socketcan:" + ifname_; }

  // Whether this kernel offers CAN_RAW sockets at all; `why` gets the reason when not.
  static bool available(std::string* why = nullptr);

 private:
  std::string ifname_;
  int fd_ = -1;
  TransportStats stats_;
};

}  // namespace omnitwin::can
