// bus_emulators/ethercat/transport — EtherCAT on raw Ethernet (`raw:IFACE`): the wire format of
// real masters and slaves, on a veth pair or a NIC.
//
// An AF_PACKET SOCK_RAW socket, non-blocking, bound to one interface with protocol 0x88A4, so
// the kernel hands it EtherCAT frames of that interface only. A classic BPF filter on the
// socket also drops, in the kernel (no wake-up, no copy), our own outgoing frames
// (pkttype OUTGOING); the same check runs again here in case the kernel refused the filter.
// Frames of another EtherCAT header type than 1 pass it and are counted in dropped_foreign
// here (they used to be dropped in the kernel, uncounted: a master's network-variable or
// mailbox-gateway frames then vanished without a trace). PACKET_IGNORE_OUTGOING (Linux
// ≥ 4.20) is set where the kernel has it, and PACKET_QDISC_BYPASS (≥ 3.14) unless turned off:
// a frame goes straight to the driver, as a real-time master wants (no queueing discipline, no
// reordering). Its price: frames sent that way skip the interface's taps, so tcpdump or
// Wireshark on the sending interface do not show them (the other end of a veth pair does, and
// so does an ec_pcap capture); RawOptions::qdisc_bypass = false keeps them visible.
//
// master: frames go out from the interface's MAC to ff:ff:ff:ff:ff:ff. slaves: each reply goes
// out with the Ethernet header of the frame it answers, bit 1 of the first source-MAC byte set
// (as a real ESC marks a frame that passed it). Frames shorter than 60 bytes are padded with
// zeros; receive() strips the Ethernet header and the padding (see ec_transport.hpp).
//
// One frame per system call each way: an EtherCAT master exchanges one frame per cycle, so
// there is nothing to batch; the frame is gathered from its header, the caller's PDU and the
// padding (sendmsg with three iovecs) and received the same way (header and PDU into separate
// buffers), so no byte is copied in user space.
//
// Opening needs CAP_NET_RAW (root); the error says so. Only Ethernet interfaces are accepted
// (not `lo`, where a frame would come back to its sender as a received broadcast).
#pragma once

#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "bus_emulators/sender_gate.hpp"

#include <array>
#include <string>

namespace omnitwin::ethercat {

struct RawOptions {
  bool qdisc_bypass = true;  // PACKET_QDISC_BYPASS where the kernel has it (see above)
};

class RawTransport final : public EcTransport {
 public:
  // Throws TransportError naming "raw:IFACE": no such interface, not Ethernet, missing
  // privilege ("needs root or CAP_NET_RAW"), or any other socket set-up failure.
  RawTransport(const std::string& ifname, Role role, RawOptions options = {});
  ~RawTransport() override;

  bool send(std::span<const std::uint8_t> pdu) override;
  int receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) override;
  int fd() const override { return fd_; }
  std::string describe() const override;
  Stats stats() const override { return stats_; }
  void set_refuse_foreign_senders(bool refuse) override { gate_.set_refuse(refuse); }
  bool wire_header(std::array<std::uint8_t, kEthHeaderSize>& out) const override {
    out = last_hdr_;
    return stats_.received > 0;
  }

  const Mac& mac() const { return mac_; }         // the interface's MAC when opened
  bool kernel_filter() const { return kernel_filter_; }  // the BPF filter is attached
  bool qdisc_bypass() const { return qdisc_bypass_; }    // PACKET_QDISC_BYPASS is on
  // The Ethernet header the next slaves-role send() uses (valid once a frame was received).
  const std::array<std::uint8_t, kEthHeaderSize>& reply_header() const { return reply_hdr_; }

 private:
  std::string ifname_;
  Role role_;
  int fd_ = -1;
  int ifindex_ = 0;
  Mac mac_{};
  bool kernel_filter_ = false;
  bool qdisc_bypass_ = false;
  bool have_peer_ = false;                                // slaves: a frame was received
  std::array<std::uint8_t, kEthHeaderSize> tx_hdr_{};     // master: broadcast from mac_
  std::array<std::uint8_t, kEthHeaderSize> reply_hdr_{};  // slaves: the marked received header
  std::array<std::uint8_t, kEthHeaderSize> last_hdr_{};   // the header of the last PDU returned
  bus_emulators::SenderGate gate_;                         // slaves: the first source MAC is the master's
  std::array<std::uint8_t, kEthHeaderSize> rx_hdr_{};     // scratch for receive()
  Stats stats_;
};

}  // namespace omnitwin::ethercat
