// bus_emulators — the slaves' side of a transport deciding who the master is (issue 16, item 7):
// the first sender a slaves-role transport hears is taken as the master; a frame from any other
// sender is counted, and refused when the scenario asks (bus.refuse_foreign).
//
// One gate for every transport that has senders to tell apart: a source MAC on raw Ethernet
// (EtherCAT, M-III), a socket address on UDP (EtherCAT, M-III). The address is compared as
// bytes, so the gate needs no socket types. No allocation; real-time safe.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace omnitwin::bus_emulators {

// Holds up to kMaxAddress bytes of the master's address (a sockaddr_storage fits).
class SenderGate {
 public:
  static constexpr std::size_t kMaxAddress = 128;

  void set_refuse(bool refuse) { refuse_ = refuse; }
  bool refuse() const { return refuse_; }
  bool has_master() const { return have_master_; }

  // A frame from `sender`: true to take it, false when it is a foreign sender's and refused.
  // The first sender becomes the master; a foreign one adds to `foreign` (and to `refused`
  // when refused). An address longer than kMaxAddress is compared on its first kMaxAddress
  // bytes.
  bool admit(std::span<const std::uint8_t> sender, std::uint64_t& foreign, std::uint64_t& refused) {
    const std::size_t n = std::min(sender.size(), kMaxAddress);
    if (!have_master_) {
      std::copy_n(sender.begin(), n, master_.begin());
      master_len_ = n;
      have_master_ = true;
      return true;
    }
    if (n == master_len_ && std::equal(sender.begin(), sender.begin() + static_cast<std::ptrdiff_t>(n), master_.begin()))
      return true;
    ++foreign;
    if (!refuse_) return true;
    ++refused;
    return false;
  }

 private:
  std::array<std::uint8_t, kMaxAddress> master_{};
  std::size_t master_len_ = 0;
  bool have_master_ = false;
  bool refuse_ = false;
};

}  // namespace omnitwin::bus_emulators
