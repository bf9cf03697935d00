// bus_emulators/canopen — the EMCY producer (CiA 301 §7.2.7) with the error register 0x1001
// and the pre-defined error field 0x1003.
//
// An error that occurs is one EMCY write [error code (LE16), error register, 5 bytes
// manufacturer-specific] on the COB-ID of 0x1014, no sooner than the inhibit time 0x1015
// [100 µs] after the previous one (later ones wait in a small queue, dropped and counted when
// it is full). It enters 0x1003 as the newest entry (sub 1), older ones move down; the error
// register gets the error's class bit (generic bit 0 always). When the last active error is
// cleared, an "error reset or no error" EMCY (code 0x0000) is sent. EMCYs are sent only in
// PRE-OPERATIONAL and OPERATIONAL (CiA 301): in STOPPED (and INITIALISING) errors that occur or
// end are recorded in 0x1001/0x1003 but not sent, and on the way back the master is brought up
// to date — one EMCY per active error, or the "error reset" when none is left (our choice; as
// CANopenNode, whose EMCYs wait for PRE-OPERATIONAL). The node owns the dictionary; the
// producer reads 0x1014/0x1015 and writes 0x1001/0x1003 through it.
// Real-time safe: no allocation after construction.
#pragma once

#include <array>
#include <cstdint>

#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::canopen {

// Error register 0x1001 bits.
namespace error_register {
inline constexpr std::uint8_t generic = 0x01, current = 0x02, voltage = 0x04, temperature = 0x08,
                              communication = 0x10, device_profile = 0x20, manufacturer = 0x80;
}

// Error codes used by our devices (CiA 301 table 21, CiA 402).
namespace emcy_code {
inline constexpr std::uint16_t reset = 0x0000, generic = 0x1000, communication = 0x8100,
                               can_overrun = 0x8110, error_passive = 0x8120, life_guard = 0x8130,
                               bus_off_recovered = 0x8140, pdo_length = 0x8210, pdo_length_exceeded = 0x8220,
                               following_error = 0x8611;
}
// The error register bit an error code belongs to.
std::uint8_t register_bit_of(std::uint16_t code);

class EmcyProducer {
 public:
  static constexpr int kActive = 8, kQueue = 8;

  // Installs the dictionary's hooks: 0x1003:0 takes only 0, which deletes the history; 0x1014
  // takes a new identifier only while the EMCY is invalid (bit 31 set), 11-bit and not 0
  // (both: else 0x06090030). Set-up.
  EmcyProducer(ObjectDictionary& od, std::uint8_t node_id);

  // Error `code` occurred at now: one EMCY (inhibit time permitting) and an 0x1003 entry.
  // A code already active is not signalled again. Returns false when the queue was full.
  bool raise(std::uint16_t code, SimTime now, const SendFn& send, std::array<std::uint8_t, 5> mfr = {});
  // Error `code` is gone; the last one sends the reset EMCY. Returns whether it was active.
  bool clear(std::uint16_t code, SimTime now, const SendFn& send);
  // NMT reset node: every error gone with the application, nothing sent (a node in
  // INITIALISING sends nothing before its boot-up message). Real-time safe.
  void forget_all();
  // Sends queued EMCYs whose inhibit time has passed. Real-time safe.
  void on_time(SimTime now, const SendFn& send);
  // NMT reset communication: forget the queue and the inhibit timer (errors stay active).
  void reset_communication();
  // The node's NMT state after each transition: leaving PRE-OPERATIONAL/OPERATIONAL drops the
  // queued EMCYs; coming back after an error occurred or ended (or was dropped) sends the
  // active errors, or the reset EMCY when none is left. Real-time safe.
  void set_nmt_state(NmtState s, SimTime now, const SendFn& send);

  std::uint8_t error_register() const;
  int active_count() const { return active_n_; }
  // Whether error `code` is active (raised, not cleared). Real-time safe.
  bool active(std::uint16_t code) const;
  std::uint64_t sent() const { return sent_; }
  std::uint64_t dropped() const { return dropped_; }

 private:
  struct Pending {
    std::uint16_t code = 0;
    std::uint8_t reg = 0;
    std::array<std::uint8_t, 5> mfr{};
  };
  Pending* find_active(std::uint16_t code);
  void enqueue(const Pending& p, SimTime now, const SendFn& send);
  void emit(const Pending& p, SimTime now, const SendFn& send);
  void update_register();
  void push_history(std::uint16_t code, std::array<std::uint8_t, 5> mfr);

  ObjectDictionary& od_;
  std::uint8_t node_id_;
  std::array<Pending, kActive> active_{};  // the active errors (reg unused)
  int active_n_ = 0;
  std::array<Pending, kQueue> queue_{};
  int queue_n_ = 0;
  SimTime last_sent_ = -1;
  bool may_send_ = true;  // PRE-OPERATIONAL or OPERATIONAL
  bool missed_ = false;   // an EMCY was not sent in another NMT state
  std::uint64_t sent_ = 0, dropped_ = 0;
};

}  // namespace omnitwin::canopen
