// bus_emulators/ethercat/transport — EtherCAT over UDP (`udp:HOST[:PORT]`, port 0x88A4 = 34980
// by default): the UDP payload is the PDU (EtherCAT header and datagrams, unchanged), as the
// EtherCAT standard carries it in UDP/IP.
//
// slaves: one socket bound to HOST:PORT (HOST may be a wildcard such as 0.0.0.0 or ::); each
// reply goes to the sender of the last PDU received. master: one socket bound to an ephemeral
// port of the same address family, sending to HOST:PORT; it accepts replies from any sender
// (nobody else knows the ephemeral port). HOST may be numeric (IPv4, IPv6 in brackets) or a
// name, resolved once when opening.
//
// One datagram per system call each way (one frame per cycle: nothing to batch). Datagrams too
// short to be a PDU, or whose EtherCAT header declares more bytes than arrived, are dropped and
// counted in dropped_malformed; other EtherCAT frame types in dropped_foreign.
#pragma once

#include "bus_emulators/ethercat/transport/ec_transport.hpp"

#include <sys/socket.h>

#include <string>

namespace omnitwin::ethercat {

class UdpTransport final : public EcTransport {
 public:
  // Throws TransportError naming the spec (unknown host, port in use, …).
  UdpTransport(const TransportSpec& spec, Role role);
  ~UdpTransport() override;

  bool send(std::span<const std::uint8_t> pdu) override;
  int receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) override;
  int fd() const override { return fd_; }
  std::string describe() const override;
  Stats stats() const override { return stats_; }

  std::uint16_t local_port() const { return local_port_; }  // the port this socket is bound to

 private:
  TransportSpec spec_;
  Role role_;
  int fd_ = -1;
  sockaddr_storage peer_{};  // master: HOST:PORT; slaves: the last sender
  socklen_t peer_len_ = 0;
  bool have_peer_ = false;
  std::uint16_t local_port_ = 0;
  Stats stats_;
};

}  // namespace omnitwin::ethercat
