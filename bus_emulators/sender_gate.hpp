// bus_emulators — the slaves' side of a transport deciding who the master is (issue 16, item 7):
// the first sender a slaves-role transport hears is taken as the master; a frame from any other
// sender is counted, and refused when the scenario asks (bus.refuse_foreign).
//
// One gate for every transport that has senders to tell apart: a source MAC on raw Ethernet
// (EtherCAT, M-III), a socket address on UDP (EtherCAT, M-III). The address is compared as
// bytes, so the gate needs no socket types, and time is handed in, so it reads no clock. No
// allocation; real-time safe.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace omnitwin::bus_emulators {

// Holds up to kMaxAddress bytes of the master's address (a sockaddr_storage fits).
//
// A master started again sends from a new address where the address is a UDP socket's (a new
// ephemeral port). With a handover time set, a sender heard after the master has been silent
// that long becomes the master (counted in changes()); a second program sending while the
// master is active stays foreign, and a master that was only stalled takes the bus back when it
// is heard again. Times are the caller's [ns], any monotonic clock.
class SenderGate {
 public:
  static constexpr std::size_t kMaxAddress = 128;

  void set_refuse(bool refuse) { refuse_ = refuse; }
  bool refuse() const { return refuse_; }
  // silent_ns < 0: the first sender stays the master for good (the default).
  void set_handover(std::int64_t silent_ns) { handover_ns_ = silent_ns; }
  bool has_master() const { return have_master_; }
  std::uint64_t changes() const { return changes_; }  // masters taken over from a silent one

  // A frame from `sender` at now_ns: true to take it, false when it is a foreign sender's and
  // refused. The first sender becomes the master, as does a new one once the master has been
  // silent for the handover time; a foreign one adds to `foreign` (and to `refused` when
  // refused). A former master heard again was only stalled: it is the master again, the
  // handover undone and the frames taken from the other sender since counted foreign. An
  // address longer than kMaxAddress is compared on its first kMaxAddress bytes.
  bool admit(std::span<const std::uint8_t> sender, std::int64_t now_ns, std::uint64_t& foreign,
             std::uint64_t& refused) {
    const std::size_t n = std::min(sender.size(), kMaxAddress);
    const bool first = !have_master_;
    const bool same = !first && is(master_, master_len_, sender, n);
    if (!first && !same && former_len_ > 0 && is(former_, former_len_, sender, n)) {  // it was stalled
      std::swap(master_, former_);
      master_len_ = former_len_;
      former_len_ = 0;
      --changes_;
      foreign += taken_;
      last_ns_ = now_ns;
      return true;
    }
    const bool handover = !first && !same && handover_ns_ >= 0 && now_ns - last_ns_ >= handover_ns_;
    if (handover) {
      former_ = master_;
      former_len_ = master_len_;
      taken_ = 0;
      ++changes_;
    }
    if (first || handover) {
      std::copy_n(sender.begin(), n, master_.begin());
      master_len_ = n;
      have_master_ = true;
    }
    if (first || same || handover) {
      last_ns_ = now_ns;
      ++taken_;
      return true;
    }
    ++foreign;
    if (!refuse_) return true;
    ++refused;
    return false;
  }

 private:
  using Address = std::array<std::uint8_t, kMaxAddress>;
  static bool is(const Address& a, std::size_t len, std::span<const std::uint8_t> sender, std::size_t n) {
    return n == len && std::equal(sender.begin(), sender.begin() + static_cast<std::ptrdiff_t>(n), a.begin());
  }
  Address master_{}, former_{};  // former: the master before the last handover (0 long: none)
  std::size_t master_len_ = 0, former_len_ = 0;
  bool have_master_ = false;
  bool refuse_ = false;
  std::int64_t handover_ns_ = -1;
  std::int64_t last_ns_ = 0;  // the master's last frame
  std::uint64_t changes_ = 0;
  std::uint64_t taken_ = 0;   // frames taken from the master since the last handover
};

}  // namespace omnitwin::bus_emulators
