// bus_emulators/can — receive side of the TI TMS320F2812 eCAN module in eCAN mode (the
// master node's controller in seed 002, §4-1-1): 32 mailboxes, each with its own identifier
// (MSGID, standard or extended), local acceptance mask (LAMn, used when MSGID.AME is set,
// LAMn.LAMI = accept both formats), overwrite protection (CANOPC), receive-message-pending
// (CANRMP) and receive-message-lost (CANRML) flags, and a per-mailbox interrupt mask (CANMIM).
//
// Reception follows SPRU074: the message controller looks for a matching identifier starting
// at mailbox 31 and going down. A matching receive mailbox whose RMP is clear takes the frame
// and sets RMP. If its RMP is already set: with OPC clear the old message is overwritten and
// RML is set; with OPC set the search goes on to the next lower matching mailbox, and if none
// takes it the frame is lost without notification. A remote frame that matches a transmit
// mailbox with auto-answer (AAM) sets that mailbox's TRS; a transmit mailbox without AAM
// swallows it; either way the search stops. Data frames only go to receive mailboxes.
//
// Frames come in from the bus core; nothing here touches sockets or a clock (a timestamp, if
// wanted, is passed in by the caller in ns). Fixed mailbox configuration set at construction;
// flags and stored messages are the state. No allocation after construction; every member
// function is real-time safe unless noted.
#pragma once

#include <array>
#include <cstdint>
#include <functional>

#include "bus_emulators/can/can_frame.hpp"

namespace omnitwin::can {

enum class EcanDirection : std::uint8_t { transmit, receive };  // CANMD[n]: 1 = receive

struct EcanMailboxConfig {
  bool enabled = false;                               // CANME[n]
  EcanDirection direction = EcanDirection::receive;   // CANMD[n]
  std::uint32_t id = 0;       // identifier, right-aligned: 11-bit if !extended, else 29-bit
  bool extended = false;      // MSGID.IDE
  bool ame = false;           // MSGID.AME: use the local acceptance mask (receive mailboxes)
  // LAMn[28:0] in MSGID bit layout (a standard identifier occupies bits 28..18; see
  // ecan_lam_standard()). 1 = don't care, 0 = the received bit must equal the MSGID bit.
  std::uint32_t lam = 0;
  bool lami = false;          // LAMn.31: 1 = accept standard and extended frames
  bool opc = false;           // CANOPC[n]: protect an unread message from being overwritten
  bool mim = true;            // CANMIM[n]: mailbox interrupt enabled
  bool aam = false;           // MSGCTRL.AAM: transmit mailbox answers matching remote frames
};

// LAM bits for an 11-bit mask written in standard-identifier terms (bit 10..0 -> 28..18).
constexpr std::uint32_t ecan_lam_standard(std::uint32_t mask11) { return (mask11 & 0x7FFu) << 18; }

// Convenience for set-up code: an enabled receive mailbox; `mask` (same alignment as `id`,
// 1 = don't care) enables AME when non-zero.
EcanMailboxConfig ecan_rx_mailbox(std::uint32_t id, bool extended = false, std::uint32_t mask = 0,
                                  bool opc = false);

// Does this mailbox's identifier/mask accept the frame? Ignores direction, enable and RMP.
// Masks apply only to receive mailboxes with AME set; otherwise identifier and IDE must be
// equal. Standard frames compare MSGID bits 28..18 only. Real-time safe.
bool ecan_id_matches(const EcanMailboxConfig& mailbox, const Frame& frame);

class Ecan {
 public:
  static constexpr int kMailboxes = 32;

  enum class RxStatus : std::uint8_t {
    stored,        // went into an empty receive mailbox; RMP set
    overwritten,   // replaced an unread message (OPC clear); RMP stays set, RML set
    lost,          // every matching receive mailbox was full and protected (OPC)
    no_match,      // no enabled mailbox matched: not stored (the node still ACKs on the bus)
    auto_answer,   // matched a transmit mailbox with AAM: its TRS is set
    ignored,       // remote frame matched a transmit mailbox without AAM: not received
    invalid,       // error frame or identifier/DLC out of range
  };

  struct RxResult {
    RxStatus status = RxStatus::no_match;
    int mailbox = -1;  // the mailbox that took (or swallowed) the frame; -1 if none
  };

  struct Message {
    Frame frame;                   // as received: with a mask, the received identifier
    std::uint64_t rx_time_ns = 0;  // caller-supplied receive time [ns]; 0 if unused
  };

  struct Stats {
    std::uint64_t stored = 0;       // frames written into an empty mailbox
    std::uint64_t overwritten = 0;  // frames that overwrote an unread one (RML events)
    std::uint64_t lost = 0;         // frames lost behind overwrite protection
    std::uint64_t unmatched = 0;    // frames no mailbox wanted
    std::uint64_t auto_answers = 0; // remote frames that set a TRS
  };

  // Mailbox interrupt: called with the mailbox number after a frame is stored into it or
  // overwrites it (`overwritten` = RML was set), if that mailbox's MIM bit is set. Set up
  // once, before frames flow; must not re-enter receive() on this object.
  using InterruptHandler = std::function<void(int mailbox, bool overwritten)>;

  // Throws std::invalid_argument for a mailbox identifier out of range for its format
  // (set-up code only).
  explicit Ecan(const std::array<EcanMailboxConfig, kMailboxes>& mailboxes);

  // One frame completed on the bus; see the file comment for the rules. Real-time safe.
  RxResult receive(const Frame& frame, std::uint64_t rx_time_ns = 0);

  // The last message written into mailbox n (0..31); meaningful while RMP[n] is set.
  // Real-time safe.
  const Message& read(int n) const { return messages_[static_cast<std::size_t>(n)]; }

  // The CPU writes 1 to RMP[n] after reading: clears RMP[n] and RML[n]. Real-time safe.
  void clear_rmp(int n);
  // The CPU (or a completed transmission) clears TRS[n]. Real-time safe.
  void clear_trs(int n) { trs_ &= ~bit(n); }

  std::uint32_t rmp() const { return rmp_; }  // CANRMP, bit n = mailbox n
  std::uint32_t rml() const { return rml_; }  // CANRML
  std::uint32_t trs() const { return trs_; }  // CANTRS (only auto-answer sets it here)
  bool pending(int n) const { return (rmp_ & bit(n)) != 0; }
  bool lost(int n) const { return (rml_ & bit(n)) != 0; }

  void set_interrupt_handler(InterruptHandler handler) { on_interrupt_ = std::move(handler); }

  const Stats& stats() const { return stats_; }
  const EcanMailboxConfig& mailbox(int n) const { return config_[static_cast<std::size_t>(n)]; }

 private:
  static constexpr std::uint32_t bit(int n) { return 1u << static_cast<unsigned>(n); }
  void store(int n, const Frame& frame, std::uint64_t rx_time_ns, bool overwrite);

  std::array<EcanMailboxConfig, kMailboxes> config_;
  std::array<Message, kMailboxes> messages_{};
  std::uint32_t rmp_ = 0;
  std::uint32_t rml_ = 0;
  std::uint32_t trs_ = 0;
  Stats stats_;
  InterruptHandler on_interrupt_;
};

}  // namespace omnitwin::can
