// bus_emulators/can — F2812 eCAN receive mailboxes; see ecan.hpp.
#include "bus_emulators/can/ecan.hpp"

#include <stdexcept>
#include <string>
#include <utility>

namespace omnitwin::can {
namespace {

constexpr std::uint32_t kId29 = 0x1FFFFFFFu;
constexpr std::uint32_t kStdBits = 0x7FFu << 18;  // MSGID bits 28..18

// Identifier in MSGID bit layout: a standard identifier sits in bits 28..18.
constexpr std::uint32_t msgid_bits(std::uint32_t id, bool extended) {
  return extended ? (id & kId29) : ((id & 0x7FFu) << 18);
}

}  // namespace

EcanMailboxConfig ecan_rx_mailbox(std::uint32_t id, bool extended, std::uint32_t mask, bool opc) {
  EcanMailboxConfig m;
  m.enabled = true;
  m.direction = EcanDirection::receive;
  m.id = id;
  m.extended = extended;
  m.ame = mask != 0;
  m.lam = extended ? (mask & kId29) : ecan_lam_standard(mask);
  m.opc = opc;
  return m;
}

bool ecan_id_matches(const EcanMailboxConfig& mb, const Frame& f) {
  const bool masked = mb.ame && mb.direction == EcanDirection::receive;
  if (!(masked && mb.lami) && f.extended != mb.extended) return false;
  const std::uint32_t compared = f.extended ? kId29 : kStdBits;
  const std::uint32_t care = masked ? compared & ~mb.lam : compared;
  return ((msgid_bits(f.id, f.extended) ^ msgid_bits(mb.id, mb.extended)) & care) == 0;
}

Ecan::Ecan(const std::array<EcanMailboxConfig, kMailboxes>& mailboxes) : config_(mailboxes) {
  for (int n = 0; n < kMailboxes; ++n) {
    const auto& m = config_[static_cast<std::size_t>(n)];
    if (m.id > (m.extended ? kId29 : 0x7FFu))
      throw std::invalid_argument("eCAN mailbox " + std::to_string(n) +
                                  ": identifier out of range");
  }
}

void Ecan::store(int n, const Frame& frame, std::uint64_t rx_time_ns, bool overwrite) {
  Message& m = messages_[static_cast<std::size_t>(n)];
  m.frame = frame;
  m.rx_time_ns = rx_time_ns;
  rmp_ |= bit(n);
  if (overwrite) {
    rml_ |= bit(n);
    ++stats_.overwritten;
  } else {
    ++stats_.stored;
  }
  if (config_[static_cast<std::size_t>(n)].mim && on_interrupt_) on_interrupt_(n, overwrite);
}

Ecan::RxResult Ecan::receive(const Frame& frame, std::uint64_t rx_time_ns) {
  if (frame.kind == FrameKind::error || !frame.valid()) return {RxStatus::invalid, -1};
  const bool remote = frame.kind == FrameKind::remote;
  bool blocked = false;  // a matching receive mailbox was full and protected
  for (int n = kMailboxes - 1; n >= 0; --n) {
    const auto& mb = config_[static_cast<std::size_t>(n)];
    if (!mb.enabled) continue;
    if (mb.direction == EcanDirection::transmit) {
      if (!remote || !ecan_id_matches(mb, frame)) continue;
      if (mb.aam) {
        trs_ |= bit(n);
        ++stats_.auto_answers;
        return {RxStatus::auto_answer, n};
      }
      return {RxStatus::ignored, n};
    }
    if (!ecan_id_matches(mb, frame)) continue;
    if ((rmp_ & bit(n)) == 0) {
      store(n, frame, rx_time_ns, false);
      return {RxStatus::stored, n};
    }
    if (!mb.opc) {
      store(n, frame, rx_time_ns, true);
      return {RxStatus::overwritten, n};
    }
    blocked = true;  // protected: try the next lower matching mailbox
  }
  if (blocked) {
    ++stats_.lost;
    return {RxStatus::lost, -1};
  }
  ++stats_.unmatched;
  return {RxStatus::no_match, -1};
}

void Ecan::clear_rmp(int n) {
  rmp_ &= ~bit(n);
  rml_ &= ~bit(n);
}

}  // namespace omnitwin::can
