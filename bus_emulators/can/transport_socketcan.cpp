// bus_emulators/can — SocketCAN raw transport; see transport_socketcan.hpp.
#include "bus_emulators/can/transport_socketcan.hpp"

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <linux/sockios.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace omnitwin::can {

namespace {

std::string err(const std::string& ifname, const char* what) {
  return "socketcan:" + ifname + ": " + what + ": " + std::strerror(errno);
}

}  // namespace

bool SocketCanTransport::available(std::string* why) {
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) {
    if (why) *why = std::string("no SocketCAN in this kernel (socket(PF_CAN, SOCK_RAW, CAN_RAW): ") + std::strerror(errno) + ")";
    return false;
  }
  ::close(fd);
  return true;
}

SocketCanTransport::SocketCanTransport(const std::string& ifname) : ifname_(ifname) {
  if (ifname_.empty() || ifname_.size() >= IFNAMSIZ) throw TransportError("socketcan: bad interface name '" + ifname_ + "'");
  fd_ = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd_ < 0) throw TransportError(err(ifname_, "socket(PF_CAN) (is the 'can_raw' module available?)"));
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, ifname_.c_str(), IFNAMSIZ - 1);
  if (::ioctl(fd_, SIOCGIFINDEX, &ifr) != 0) {
    const std::string m = err(ifname_, "no such interface");
    ::close(fd_);
    throw TransportError(m);
  }
  const can_err_mask_t errmask = CAN_ERR_MASK;
  ::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &errmask, sizeof errmask);  // best effort
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    const std::string m = err(ifname_, "bind");
    ::close(fd_);
    throw TransportError(m);
  }
}

SocketCanTransport::~SocketCanTransport() {
  if (fd_ >= 0) ::close(fd_);
}

bool SocketCanTransport::send(const Frame& f, std::int64_t /*timestamp_ns*/) {
  if (!f.valid()) {
    ++stats_.invalid_tx;
    return false;
  }
  can_frame cf{};
  switch (f.kind) {
    case FrameKind::data:
      cf.can_id = f.id | (f.extended ? CAN_EFF_FLAG : 0u);
      break;
    case FrameKind::remote:
      cf.can_id = f.id | CAN_RTR_FLAG | (f.extended ? CAN_EFF_FLAG : 0u);
      break;
    case FrameKind::error:
      cf.can_id = (f.id & CAN_ERR_MASK) | CAN_ERR_FLAG;
      break;
  }
  cf.can_dlc = f.dlc;
  if (f.kind != FrameKind::remote) std::copy_n(f.data.begin(), std::min<int>(f.dlc, 8), cf.data);
  for (;;) {
    const ssize_t n = ::write(fd_, &cf, sizeof cf);
    if (n == static_cast<ssize_t>(sizeof cf)) {
      ++stats_.frames_tx;
      return true;
    }
    if (n < 0 && errno == EINTR) continue;
    ++stats_.send_errors;  // ENOBUFS (tx queue full), ENETDOWN, …
    return false;
  }
}

std::optional<TimedFrame> SocketCanTransport::receive() {
  for (int budget = 256; budget > 0; --budget) {
    can_frame cf{};
    const ssize_t n = ::read(fd_, &cf, sizeof cf);
    if (n < 0) {
      if (errno == EINTR) continue;
      if (errno != EAGAIN && errno != EWOULDBLOCK) ++stats_.rx_errors;
      return std::nullopt;
    }
    if (n != static_cast<ssize_t>(sizeof cf)) {
      ++stats_.malformed_rx;
      continue;
    }
    Frame f;
    if (cf.can_id & CAN_ERR_FLAG) {
      f.kind = FrameKind::error;
      f.id = cf.can_id & CAN_ERR_MASK;
    } else {
      f.extended = (cf.can_id & CAN_EFF_FLAG) != 0;
      f.kind = (cf.can_id & CAN_RTR_FLAG) ? FrameKind::remote : FrameKind::data;
      f.id = cf.can_id & (f.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
      if (!f.extended && (cf.can_id & CAN_EFF_MASK & ~CAN_SFF_MASK)) {
        ++stats_.bad_id_rx;  // standard frame with bits above 11 set
        continue;
      }
    }
    if (cf.can_dlc > 8) {
      ++stats_.wrong_dlc_rx;
      continue;
    }
    f.dlc = cf.can_dlc;
    if (f.kind != FrameKind::remote) std::copy_n(cf.data, f.dlc, f.data.begin());
    std::int64_t ts = 0;
    timeval tv{};
    if (::ioctl(fd_, SIOCGSTAMP, &tv) == 0) ts = std::int64_t{tv.tv_sec} * 1'000'000'000 + std::int64_t{tv.tv_usec} * 1000;
    ++stats_.frames_rx;
    return TimedFrame{f, ts};
  }
  return std::nullopt;
}

}  // namespace omnitwin::can
