// bus_emulators/mechatrolink3/transport — M-III on raw Ethernet (`raw:IFACE`), on a veth pair or
// a NIC: the Ethernet encapsulation of docs/protocols/mechatrolink3.md, the same bytes
// m3::encapsulate() writes and the captures (m3_pcap) record.
//
// An AF_PACKET SOCK_RAW socket, non-blocking, bound to one interface with protocol 0x88B5, so
// the kernel hands it M-III frames of that interface only. A classic BPF filter on the socket
// also drops, in the kernel (no wake-up, no copy), our own outgoing frames (pkttype OUTGOING)
// and other EtherTypes; the same checks run again here, where they are counted, in case the
// kernel refused the filter or RawOptions::kernel_filter turned it off (the socket then takes
// every EtherType). PACKET_IGNORE_OUTGOING (Linux ≥ 4.20) is set where the kernel has it, and
// PACKET_QDISC_BYPASS (≥ 3.14) unless turned off: a frame goes straight to the driver (no
// queueing discipline, no reordering). Its price: frames sent that way skip the sending
// interface's taps, so tcpdump on it does not show them (the other end of a veth pair does, and
// so does an m3_pcap capture); RawOptions::qdisc_bypass = false keeps them visible. The socket
// also asks for promiscuous mode (best effort): frames go to station MACs
// (02:4D:33:00:00:<address>), not to the interface's own, and a NIC would filter them out.
//
// Both roles send alike: each frame goes out with the station MACs of its own destination and
// source bytes, EtherType 0x88B5, zero padding to 60 bytes. Unlike m3::encapsulate() the frame
// is not decoded first: a frame with a bad FCS (a corruption fault) goes out as it is, since the
// receiving station checks the FCS, not the transport. receive() strips the Ethernet header and
// the padding and hands out the frame, its FCS unchecked (see m3_transport.hpp).
//
// One frame per system call each way, gathered from its header, the caller's frame and the
// padding (sendmsg with three iovecs) and received the same way (header and frame into separate
// buffers), so no byte is copied in user space.
//
// Opening needs CAP_NET_RAW (root); the error says so. Only Ethernet interfaces are accepted
// (not `lo`, where a frame would come back to its sender as a received frame).
#pragma once

#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"
#include "bus_emulators/sender_gate.hpp"

#include <array>
#include <string>

namespace omnitwin::m3 {

struct RawOptions {
  bool qdisc_bypass = true;   // PACKET_QDISC_BYPASS where the kernel has it (see above)
  bool kernel_filter = true;  // off: no BPF filter and the socket bound to every EtherType,
                              // so all the interface's frames reach receive()'s own checks
                              // (its tests; diagnosis). Costs a wake-up per foreign frame.
};

class RawTransport final : public M3Transport {
 public:
  // Throws TransportError naming "raw:IFACE": no such interface, not Ethernet, missing
  // privilege ("needs root or CAP_NET_RAW"), or any other socket set-up failure.
  RawTransport(const std::string& ifname, Role role, RawOptions options = {});
  ~RawTransport() override;

  bool send(std::span<const std::uint8_t> frame) override;
  void set_refuse_foreign_senders(bool refuse) override { gate_.set_refuse(refuse); }
  int receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) override;
  int fd() const override { return fd_; }
  std::string spec() const override { return "raw:" + ifname_; }
  std::string describe() const override;
  Stats stats() const override { return stats_; }
  std::int64_t last_age_ns() const override { return last_age_ns_; }

  const Mac& mac() const { return mac_; }                // the interface's MAC when opened
  bool kernel_filter() const { return kernel_filter_; }  // the BPF filter is attached
  bool qdisc_bypass() const { return qdisc_bypass_; }    // PACKET_QDISC_BYPASS is on
  bool promiscuous() const { return promiscuous_; }      // promiscuous membership is held

 private:
  void set_options(const RawOptions& options);  // best effort: ignore outgoing, bypass, promisc
  void attach_filter();                        // the kernel filter (best effort)
  // Why the frame just received into rx_hdr_ and buf is dropped (its stats field), or null.
  // `pkttype` is the sockaddr_ll's, n the Ethernet frame's real length; ok: size is the frame's.
  std::uint64_t* drop_reason(unsigned pkttype, std::size_t n, std::span<const std::uint8_t> buf, std::size_t& size);

  std::string ifname_;
  Role role_;
  int fd_ = -1;
  int ifindex_ = 0;
  Mac mac_{};
  bool kernel_filter_ = false;
  bool qdisc_bypass_ = false;
  bool promiscuous_ = false;
  std::array<std::uint8_t, kEthHeaderSize> tx_hdr_{};  // scratch for send()
  std::array<std::uint8_t, kEthHeaderSize> rx_hdr_{};  // scratch for receive()
  // Slaves: the first source MAC received is the master's; frames from another are foreign.
  bus_emulators::SenderGate gate_;  // slaves: the first source MAC is the master's
  Stats stats_;
  detail::ReceiveStamp stamp_;
  std::int64_t last_age_ns_ = -1;
};

}  // namespace omnitwin::m3
