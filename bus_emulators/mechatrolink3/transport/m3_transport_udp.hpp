// bus_emulators/mechatrolink3/transport — M-III over UDP (`udp:HOST[:PORT]`, port 0x88B5 = 34997
// by default): one frame per datagram, exactly the frame (header, information field, FCS), no
// padding. The emulation's choice (docs/protocols/mechatrolink3.md, "Encapsulations"): the
// M-III data link is not IP, but UDP lets the master and the slaves run in separate processes
// without privileges, as EtherCAT over UDP does for the EtherCAT bus.
//
// slaves: one socket bound to HOST:PORT (HOST may be a wildcard such as 0.0.0.0 or ::; PORT 0
// binds a free port, which local_port() and spec() name); each response goes to the sender of
// the last frame received. master: one socket bound to an ephemeral port of the same address
// family, sending to HOST:PORT; it accepts frames from any sender (nobody else knows the
// ephemeral port). HOST may be numeric (IPv4, IPv6 in brackets) or a name, resolved once when
// opening.
//
// One datagram per system call each way. Datagrams that cannot be a frame (see
// m3_transport.hpp) are dropped and counted in dropped_malformed; bytes after the frame are
// trimmed; a bad FCS is the receiving station's business and passes.
#pragma once

#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"

#include <sys/socket.h>

#include <string>

namespace omnitwin::m3 {

class UdpTransport final : public M3Transport {
 public:
  // Throws TransportError naming the spec (unknown host, port in use, a master to port 0, …).
  UdpTransport(const TransportSpec& spec, Role role);
  ~UdpTransport() override;

  bool send(std::span<const std::uint8_t> frame) override;
  int receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) override;
  int fd() const override { return fd_; }
  std::string spec() const override;  // slaves: the bound port; master: the slaves' port
  std::string describe() const override;
  Stats stats() const override { return stats_; }

  std::uint16_t local_port() const { return local_port_; }  // the port this socket is bound to

 private:
  int resolve();                 // fills peer_ from spec_; returns the address family
  void bind_socket(int family);  // slaves: HOST:PORT; master: an ephemeral port
  [[noreturn]] void fail(const std::string& what);  // closes fd_, throws naming the spec

  TransportSpec spec_;
  Role role_;
  int fd_ = -1;
  sockaddr_storage peer_{};  // master: HOST:PORT; slaves: the last sender
  socklen_t peer_len_ = 0;
  bool have_peer_ = false;
  std::uint16_t local_port_ = 0;
  Stats stats_;
};

}  // namespace omnitwin::m3
