// bus_emulators/ethercat — one EtherCAT slave controller (ESC): its register and RAM space and
// what a passing datagram does to it.
//
// The ESC is the hardware half of a slave: addressing (position/ADP increment, node address or
// alias, broadcast, logical through FMMUs), working-counter rules, registers (information, DL,
// AL control/status, watchdogs, SII interface, FMMUs, SyncManagers, distributed clocks) and the
// SyncManager handshakes over process RAM. The firmware half (CoE, PDO mapping, drives) sits
// behind the PDI as an EscApplication (ethercat/device). No sockets, no clock: datagrams and
// time (SimTime, ns) come in, bytes go out in place.
//
// WKC rules (facts/ethercat.md): a read +1, a write +1, a read-write +1 (read) +2 (write);
// BRD ORs register bytes into the data, +1 per slave; ARMW/FRMW: the addressed slave reads (+1),
// every other slave writes (+1); logical commands count at most one read and one write per slave
// per datagram; refused accesses (mailbox full/empty, process-data SM inactive or below
// SAFE-OP, wrong direction) do not count and move no data.
//
// Layers: ec_al (AL state machine), ec_eeprom (SII), ec_sm (SyncManagers), ec_fmmu (FMMUs),
// ec_dc (clocks); register addresses in ec_registers.hpp.
//
// DL status 0x0110: bit 0 PDI operational, per port p: bit 4+p physical link, bit 9+2p
// communication established, bit 8+2p loop closed (a port without link closes automatically).
// A middle slave of a line reads 0x0A31, the end of the line 0x0611 (port 1 closed); the
// 0x0A00/0x0200 of facts/ethercat.md are the communication bits of these values.
//
// ECAT events (0x0210, ORed into every passing datagram's IRQ field under the mask 0x0200):
// bit 2 DL status changed (cleared by reading 0x0110), bit 3 AL status changed (cleared by
// reading 0x0130), bit 4 + i: SM i is a read mailbox holding a reply (i < 8).
//
// SyncManagers act on process RAM (>= 0x1000) only: one configured over the registers or past
// the end of RAM is not activated (see Esc::sm_in_process_ram). An enabled SM keeps its start,
// length and control registers: writes change only its activate byte until it is disabled
// (Esc::restore_sm_area). SYNC0 pulses: at most
// kMaxSync0PerAdvance per advance(), the rest are dropped (Stats::sync0_dropped).
//
// Model choices: all datagrams of a frame reach one ESC at the same time t (the frame's arrival);
// logical writes do not trigger register side effects (FMMUs map RAM); the AL watchdog reaction
// (OP → SAFE-OP + 0x001B, outputs zeroed) is done here rather than by the firmware, which is told
// through EscApplication::on_al_fallback; the SM0
// mailbox is read by the firmware (emptied) right after on_mailbox returns. The mailbox repeat
// (0x080E bit 1 toggled, acknowledged in 0x080F bit 1) is also done here for the firmware: the
// data the master last read from the read mailbox goes back into it; a newer reply waiting
// there is set aside and follows once the repeated one has been read (ESC Technology Section I
// §8.6). Deactivating the read mailbox (set_sm_deactivated) forgets both.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "bus_emulators/ethercat/ec_al.hpp"
#include "bus_emulators/ethercat/ec_dc.hpp"
#include "bus_emulators/ethercat/ec_eeprom.hpp"
#include "bus_emulators/ethercat/ec_fmmu.hpp"
#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/ec_sm.hpp"

namespace omnitwin::ethercat {

inline constexpr int kMaxFmmus = 16;
inline constexpr SimTime kNoEscEvent = std::numeric_limits<SimTime>::max();  // next_event_time(): nothing scheduled
inline constexpr int kMaxSyncManagers = 16;
inline constexpr int kMaxSync0PerAdvance = 1000;  // SYNC0 pulses delivered per Esc::advance()
inline constexpr std::uint32_t kProcessRam = 0x1000;  // process RAM starts here (registers below)

struct EscConfig {
  std::uint8_t type = 0x11, revision = 0;
  std::uint16_t build = 0;
  std::uint8_t fmmus = 8, sync_managers = 8, ram_kib = 8;  // process RAM from 0x1000
  std::uint16_t features = 0x0004 | 0x0008;                 // DC supported, 64-bit DC
  std::uint8_t port_descriptor = 0x0F;                      // ports 0 and 1: MII
  std::vector<std::uint16_t> sii;                           // EEPROM image, words
  double oscillator_drift = 0;          // local clock = (1 + drift) × sim time + offset
  std::int64_t power_on_time_ns = 0;    // local time at sim time 0 (and after a power cycle)
  std::int64_t forward_delay_ns = 600;  // frame processing + forwarding per slave
  std::int64_t eeprom_busy_ns = 0;      // busy bit time after an EEPROM command (0: none)
};

class EscApplication {  // the slave firmware behind the PDI (ethercat/device implements it)
 public:
  virtual ~EscApplication() = default;
  // The master asked for a legal AL transition from → to; return none to accept, else the code
  // (the ESC then sets the error bit and stays). Checks of SM/FMMU configuration are the firmware's.
  virtual AlStatusCode on_al_request(AlState from, AlState to, SimTime t) = 0;
  // SM0 became full: one whole mailbox write (SM0 length bytes). Answer later/now via Esc::post_mailbox.
  virtual void on_mailbox(std::span<const std::uint8_t> mailbox, SimTime t) = 0;
  // The master completed a write of the SM2 (outputs) buffer.
  virtual void on_outputs(std::span<const std::uint8_t> outputs, SimTime t) = 0;
  virtual void on_sync0(SimTime /*t*/) {}  // a SYNC0 pulse (DC active)
  // The AL state fell from `from` to `to` with the error bit and `code` without a master request
  // (the process-data watchdog, or Esc::set_al_error). The firmware reacts as on a requested
  // step down (stops applying outputs, deactivates its output SM).
  virtual void on_al_fallback(AlState /*from*/, AlState /*to*/, AlStatusCode /*code*/, SimTime /*t*/) {}
  // The master acknowledged the error bit (0x0120 bit 4) while in `state`; the error is cleared.
  virtual void on_al_error_cleared(AlState /*state*/, SimTime /*t*/) {}
  virtual void on_sync1(SimTime /*t*/) {}  // a SYNC1 pulse (SYNC1 active)
};

class Esc {
 public:
  struct Stats {
    std::uint64_t datagrams = 0;  // datagrams that passed this ESC
    std::uint64_t addressed = 0;  // … of which touched it (WKC candidates)
    std::uint64_t refused = 0;    // accesses refused by a SyncManager
    std::uint64_t malformed = 0;  // unknown commands
    std::uint64_t sync0_dropped = 0;  // SYNC0 pulses beyond kMaxSync0PerAdvance in one advance()
  };

  Esc(EscConfig config, EscApplication* app);

  // One datagram passing this slave at time t: addressing, read/write of registers and RAM,
  // FMMU mapping, WKC rules, ADP increment for position addressing. Runs advance(t) first.
  // RT-safe, no throw.
  void process(Datagram& d, SimTime t) noexcept;
  void advance(SimTime t) noexcept;  // watchdogs, DC SYNC0 pulses up to t
  // When advance() next has something to do (SYNC0 pulse, watchdog expiry); kNoEscEvent if
  // nothing. For the owner's event scheduler. RT-safe.
  SimTime next_event_time() const noexcept;
  // The frame that carried a latch (write to 0x0900) came back through port `port` at t:
  // latches that port's receive time (the chain calls this). RT-safe.
  void latch_port(int port, SimTime t) noexcept;
  bool latch_pending() const { return latch_pending_; }
  void end_of_frame() { latch_pending_ = false; }

  // PDI side (the application):
  bool post_mailbox(std::span<const std::uint8_t> reply);  // into SM1; false while SM1 is still full
  std::span<const std::uint8_t> outputs() const;           // the last complete SM2 buffer (empty: none yet)
  void write_inputs(std::span<const std::uint8_t> inputs); // the SM3 buffer the next read sees
  std::span<const std::uint8_t> outputs(int sm) const;     // same, for ECAT-write buffered SM `sm`
  bool write_inputs(int sm, std::span<const std::uint8_t> inputs);  // ECAT-read buffered SM `sm`
  const SyncManager& sm(int i) const { return sms_[static_cast<std::size_t>(i)].reg; }
  const SmUnit& sm_unit(int i) const { return sms_[static_cast<std::size_t>(i)]; }
  const Fmmu& fmmu(int i) const { return fmmus_[static_cast<std::size_t>(i)]; }
  AlState al_state() const { return state_; }
  AlStatusCode al_status_code() const { return code_; }
  bool al_error() const { return error_; }
  // Firmware-detected error (e.g. sync): the error bit, `code`, and a fall to `fall_to` when
  // that is below the current state (the application's on_al_fallback is then called).
  void set_al_error(AlState fall_to, AlStatusCode code, SimTime t = 0);
  // PDI control 0x0807 + 8·sm bit 0: the firmware deactivates (true) or reactivates SM `sm`.
  // A deactivated SM refuses every ECAT access to its area (no WKC) and, if it triggers the
  // watchdog, no longer arms it; reactivation starts its buffers afresh (no complete buffer).
  void set_sm_deactivated(int sm, bool deactivated);
  std::uint16_t station_address() const { return read16(0x0010); }
  std::uint16_t alias() const { return read16(0x0012); }
  std::uint8_t read8(std::uint16_t reg) const;
  std::uint16_t read16(std::uint16_t reg) const;
  std::uint32_t read32(std::uint16_t reg) const;
  std::uint64_t read64(std::uint16_t reg) const;
  std::span<const std::uint8_t> memory() const { return mem_; }  // registers + RAM, PDI view
  void power_cycle(SimTime t);           // back to power-on state (INIT, address 0, SMs off)
  void set_port_link(int port, bool up); // DL status 0x0110 (the chain sets it)
  bool port_link(int port) const { return links_[static_cast<std::size_t>(port & 3)]; }
  std::int64_t local_time(SimTime t) const { return dc_.local(t); }   // DC local clock [ns]
  std::int64_t system_time(SimTime t) const { return dc_.system(t); } // local + offset (0x0920)
  const DcClock& dc() const { return dc_; }
  // Fault injection: the oscillator's drift changes at t (local time stays continuous; the DC
  // loop, if driven, pulls the system time back). Kept across power cycles.
  void set_oscillator_drift(double drift, SimTime t);
  const SiiEeprom& eeprom() const { return sii_; }
  const EscConfig& config() const { return cfg_; }
  const Stats& stats() const { return stats_; }
  bool dc_supported() const { return (cfg_.features & 0x0004) != 0; }

 private:
  struct Access { bool read = false, write = false; };
  void handle(Datagram& d, SimTime t);  // addressing, access, WKC of one datagram
  Access physical(std::uint16_t ado, std::uint8_t* data, std::uint16_t n, bool rd, bool wr, bool or_read, SimTime t);
  void logical(Datagram& d, SimTime t, bool& did_read, bool& did_write);
  bool writable(std::uint32_t a) const;
  bool sm_in_process_ram(const SyncManager& r) const;  // see ec_esc.cpp
  std::uint8_t mem_at(std::uint32_t a) const { return a < mem_.size() ? mem_[a] : 0; }
  void refresh_for_read(std::uint32_t a, std::uint32_t n, SimTime t);
  void after_write(std::uint32_t a, std::uint32_t n, const std::uint8_t* st_in, SimTime t);
  void sm_event(int i, SmEvent e, SimTime t);
  void fill_mailbox(int i, std::span<const std::uint8_t> data);  // SM i's buffer, marked full
  void mailbox_read(int i);
  void repeat_mailbox(int i);
  void al_control_written(SimTime t);
  void enter_state(AlState s, SimTime t);
  void raise_event(std::uint16_t bits, bool on);  // ECAT event request 0x0210
  void update_al_registers();
  void update_dl_status();
  void update_sm_registers(int i);
  void restore_sm_area(int i);  // SM i's start/length/control registers from its state
  void reload_from_sii();
  void init_registers();
  int find_sm(bool mailbox, bool ecat_writes) const;
  void watchdog_check(SimTime t);
  void deliver_sync1(SimTime t) noexcept;

  EscConfig cfg_;
  EscApplication* app_;
  std::vector<std::uint8_t> mem_;
  std::vector<std::uint8_t> last_read_;  // the read-mailbox data the master last read (repeat)
  std::size_t last_read_len_ = 0;
  std::vector<std::uint8_t> parked_;     // a newer reply a repeat request set aside
  std::size_t parked_len_ = 0;
  int parked_sm_ = -1;                   // … and its SM (-1: none)
  std::array<SmUnit, kMaxSyncManagers> sms_{};
  std::array<Fmmu, kMaxFmmus> fmmus_{};
  SiiEeprom sii_;
  DcClock dc_;
  AlState state_ = AlState::init;
  AlStatusCode code_ = AlStatusCode::none;
  bool error_ = false;
  std::array<bool, 4> links_{true, false, false, false};
  bool latch_pending_ = false;
  SimTime wd_last_ = 0;
  bool wd_expired_ = false;
  SimTime now_ = 0;
  Stats stats_;
};

}  // namespace omnitwin::ethercat
