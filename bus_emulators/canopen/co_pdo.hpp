// bus_emulators/canopen — the process data objects of one node (CiA 301 §7.2.2): RPDOs and
// TPDOs configured by their communication (0x1400+n / 0x1800+n) and mapping (0x1600+n /
// 0x1A00+n) objects, with dynamic mapping over SDO and every transmission type.
//
// The engine installs check and after-write hooks on those objects, so a master configures
// PDOs exactly as on a real device (CiA 301's procedure: COB-ID bit 31 set, sub 0 of the
// mapping 0, entries, sub 0 = n, COB-ID valid), and keeps a resolved form of each PDO —
// COB-ID, type, timers and pointers straight into the mapped entries' storage — so the cyclic
// path copies bytes and never searches the dictionary or allocates.
//
// Transmission types: RPDO 0..240 synchronous (applied at the next SYNC), 254/255 at once.
// TPDO 0 acyclic synchronous (at a SYNC, if the mapped data changed), 1..240 every n-th SYNC
// (from the SYNC whose counter equals sub 6 when the SYNC carries a counter), 252 sampled at
// SYNC and sent on a remote request, 253 sampled and sent on a remote request, 254/255
// event-driven: sent when the mapped data change (our "application event"), no sooner than
// the inhibit time (sub 3, 100 µs) after the previous one, and at the latest when the event
// timer (sub 5, ms) expires. RPDO event timer = deadline monitoring (EMCY 0x8250).
// Model choices (docs/protocols/canopen.md): mapping is byte-granular (Granularity 8), 8
// entries and 64 bits at most; mapping writes need the PDO invalid (abort 0x08000022); an
// RPDO shorter than its mapping is not processed (EMCY 0x8210), a longer one is processed
// (EMCY 0x8220); dummy entries (index 0x0002..0x0007) are accepted in RPDOs.
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::canopen {

inline constexpr int kMaxPdos = 8;  // per direction: 0x1400..0x1407 / 0x1800..0x1807
inline constexpr int kMaxMapped = 8;

// What became of a received frame that is one of the node's RPDOs.
enum class RpdoStatus : std::uint8_t {
  not_rpdo,    // not an enabled RPDO of this node (or not OPERATIONAL)
  applied,     // written to the mapped objects (or buffered for the next SYNC)
  too_short,   // shorter than the mapping: not processed (EMCY 0x8210)
  too_long,    // longer than the mapping: processed (EMCY 0x8220)
};

struct PdoStats {
  std::uint64_t rpdo_rx = 0, tpdo_tx = 0, length_errors = 0, rpdo_timeouts = 0, tx_refused = 0,
                rtr_answers = 0;
};

class PdoEngine {
 public:
  // Called with EMCY codes for length errors and RPDO deadline misses; `now`.
  using ErrorFn = void (*)(void* ctx, std::uint16_t emcy_code, SimTime now);

  PdoEngine(ObjectDictionary& od, std::uint8_t node_id);
  PdoEngine(const PdoEngine&) = delete;
  PdoEngine& operator=(const PdoEngine&) = delete;

  // Installs the hooks on every PDO object the dictionary has and resolves all PDOs. The
  // dictionary must outlive the engine. Set-up.
  void attach();
  // After the communication objects were reset to their defaults. Real-time safe.
  void resolve_all();

  // A received frame: an RPDO of this node (OPERATIONAL only) is applied or buffered; a
  // remote frame on a TPDO of type 252/253 is answered. Real-time safe.
  RpdoStatus on_frame(const can::Frame& f, SimTime now, NmtState s, const SendFn& send);
  // A SYNC (counter 0 when it carries none): buffered RPDOs are applied, synchronous TPDOs due
  // now are sent. Real-time safe.
  void on_sync(std::uint8_t counter, SimTime now, NmtState s, const SendFn& send);
  // Event-driven TPDOs (change, inhibit, event timer) and RPDO deadlines. Real-time safe.
  void on_time(SimTime now, NmtState s, const SendFn& send);
  // Entering OPERATIONAL: event-driven TPDOs send their current data once, deadlines restart.
  void on_operational(SimTime now);

  void set_error_handler(ErrorFn fn, void* ctx) { error_fn_ = fn, error_ctx_ = ctx; }
  const PdoStats& stats() const { return stats_; }
  // For tests and metrics: the resolved COB-ID (0 = invalid) and byte length of PDO n (0-based).
  std::uint32_t rpdo_cob_id(int n) const { return rx_[static_cast<std::size_t>(n)].valid ? rx_[static_cast<std::size_t>(n)].cob_id : 0; }
  std::uint32_t tpdo_cob_id(int n) const { return tx_[static_cast<std::size_t>(n)].valid ? tx_[static_cast<std::size_t>(n)].cob_id : 0; }
  int rpdo_bytes(int n) const { return rx_[static_cast<std::size_t>(n)].bytes; }
  int tpdo_bytes(int n) const { return tx_[static_cast<std::size_t>(n)].bytes; }

 private:
  struct Mapped {
    std::uint8_t* ptr = nullptr;  // nullptr: a dummy entry (RPDO) — bytes skipped
    std::uint8_t bytes = 0;
  };
  struct Pdo {
    bool present = false, valid = false, rtr_allowed = true;
    std::uint32_t cob_id = 0;
    std::uint8_t type = 255, sync_start = 0;
    SimTime inhibit_ns = 0, event_ns = 0;
    std::array<Mapped, kMaxMapped> map{};
    int n = 0, bytes = 0;
    // Changing state.
    std::array<std::uint8_t, 8> buffer{};  // RPDO: data waiting for SYNC; TPDO: sample (252) / last sent
    bool buffered = false, sent_once = false, started = false;
    int sync_count = 0;
    SimTime last_tx = -1, last_rx = -1;
    bool deadline_missed = false;
  };

  void install_hooks(int n, bool tx);
  void resolve(int n, bool tx);
  SdoAbort check_comm(int n, bool tx, std::uint8_t sub, std::span<const std::uint8_t> data) const;
  SdoAbort check_mapping(int n, bool tx, std::uint8_t sub, std::span<const std::uint8_t> data) const;
  SdoAbort check_entry(bool tx, std::uint32_t v) const;
  void gather(const Pdo& p, std::uint8_t* out) const;
  void scatter(const Pdo& p, const std::uint8_t* in) const;
  bool transmit(Pdo& p, const std::uint8_t* data, SimTime now, const SendFn& send);
  bool changed(const Pdo& p) const;
  void error(std::uint16_t code, SimTime now) {
    if (error_fn_) error_fn_(error_ctx_, code, now);
  }

  ObjectDictionary& od_;
  std::uint8_t node_id_;
  std::array<Pdo, kMaxPdos> rx_{}, tx_{};
  ErrorFn error_fn_ = nullptr;
  void* error_ctx_ = nullptr;
  PdoStats stats_;
};

}  // namespace omnitwin::canopen
