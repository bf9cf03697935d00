// bus_emulators/ethercat/device — the firmware of an emulated EtherCAT servo slave: an ESC
// (ethercat/ec_esc) with N CiA 402 axes (drive/cia402_drive) behind it.
//
// DriveSlave is the EscApplication of one slave. From its DeviceDescription (ESI) it builds the
// SII EEPROM image and the EscConfig, the object dictionary (ESI objects; CiA 402 objects of axis
// a at index + 0x800·a bound to that axis' drive::Objects), the CoE server, and the PDO mapping
// (assignment 0x1C12/0x1C13, mappings 0x16xx/0x1Axx: writable in PRE-OP when the ESI says so,
// fixed otherwise). Two applications share this firmware (chosen by the ESI's ProfileNo):
//  * cia402 (ProfileNo 402, models/ethercat/omnitwin_drive.xml): the PDOs map drive objects
//    directly;
//  * multiaxis (ProfileNo 5001, models/ethercat/omnitwin_multiaxis.xml): the multi-axis motion
//    controller of seed 001: per axis card one 12-byte command data module and one 12-byte
//    status data module (layout in docs/protocols/ethercat-multiaxis.md), translated each cycle
//    to and from the axis' drive::Objects (controlword sequencing, modes, handshake).
//
// AL transitions the firmware checks (the ESC has already refused illegal ones):
//   INIT → PRE-OP     SM0/SM1 enabled mailboxes (SM0 master-write, SM1 master-read), ≥ 16 bytes,
//                     not overlapping; else 0x0016. The CoE reply size becomes SM1's length,
//                     and the firmware activates SM0/SM1 (PDI control 0x0807 bit 0 cleared):
//                     as in SSC, they are deactivated in INIT (from power-on and every return
//                     to INIT), so the master's mailbox accesses there get WKC 0.
//   PRE-OP → SAFE-OP  the assigned PDOs' sizes: SM2 (outputs) enabled, buffered, master-write,
//                     length = RxPDO bytes, else 0x001D; SM3 likewise for TxPDO bytes, else 0x001E
//                     (a direction with 0 bytes may be disabled). The process-data layout is
//                     fixed here.
//   SAFE-OP → OP      accepted; the Outputs SM (SM2) is activated and outputs are applied from
//                     its first complete buffer on.
//   → SAFE-OP / OP    (steps up only) refused with 0x0030 invalid DC SYNC configuration while
//                     SYNC0 is activated with a cycle the ESC refuses (DcClock::sync0_invalid).
//   → INIT / PRE-OP   CoE transfers dropped (INIT), outputs no longer applied, axes' controlwords
//   / SAFE-OP         set to 0 (the drives disable), as a real drive does when outputs stop.
// The Outputs SM (SM2) is deactivated by the firmware (PDI control 0x0807 bit 0) as the common
// slave stack (Beckhoff's SSC) does it: off in INIT and PRE-OP, on from PRE-OP → SAFE-OP (the
// master's outputs are taken, not applied, in SAFE-OP), on in OP, and OFF when a local error —
// the ESC's process-data watchdog — drops the slave to SAFE-OP + error (on_al_fallback), until
// the master acknowledges the error (on_al_error_cleared). So a master supervising by WKC alone
// sees a watchdog trip: 4 slaves × (2 + 1) = 12 in SAFE-OP and OP, one slave in SAFE-OP + error
// takes 2 away. docs/protocols/ethercat-states.md has the table, state by state.
// Emergencies: at every firmware cycle an axis whose 0x603F changed sends one CoE emergency — its
// new code (CiA 402: 0x8611 following error, 0x6320 parameter/external, …) with the error
// register 0x1001 (generic bit + the code's class bit) and the axis number (1-based) in the first
// manufacturer byte; back to 0 (the fault reset) it sends code 0x0000 "error reset". 0x1001 is
// the OR over the axes. In INIT (no mailbox) nothing is sent and the change is counted as lost.
// The firmware cycle (cycle(t), or on_sync0(t) while DC SYNC0 is active): pending CoE replies
// posted to SM1; in OP the last complete buffer of the ESI's Outputs SM (SM2) is unpacked into
// the OD entries it maps (the axes' Objects); the cycle hook runs, if one is set (a caller may
// step the drives there; the twin steps them on their own timer instead); in SAFE-OP/OP the
// TxPDO entries are packed and written to the ESI's Inputs SM (SM3) — by index, never "the
// first buffered SM", so a master configuring another SM as buffered does not divert the
// process data.
// Set-up allocates and throws EsiError on an unusable description; the cyclic path does not
// allocate and never throws.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "bus_emulators/drive/cia402_drive.hpp"
#include "bus_emulators/ethercat/device/ec_coe.hpp"
#include "bus_emulators/ethercat/device/ec_esi.hpp"
#include "bus_emulators/ethercat/device/ec_od.hpp"
#include "bus_emulators/ethercat/ec_esc.hpp"

namespace omnitwin::ethercat {

enum class SlaveApp : std::uint8_t { cia402, multiaxis };
const char* to_string(SlaveApp a);

inline constexpr std::uint16_t kAxisOffset = 0x0800;  // CiA 402 multi-axis object offset

struct DriveSlaveConfig {
  int axes = 0;                   // axis cards fitted: 0 = the ESI's ChannelCount; 1..ChannelCount
  drive::DriveConfig drive;       // every axis
  std::uint16_t alias = 0;        // SII word 4
  std::uint32_t serial = 0;       // SII serial, 0x1018:4
  EscConfig esc;                  // ESC parameters; its sii is replaced by build_sii()
};

struct DriveSlaveStats {
  std::uint64_t cycles = 0;             // firmware cycles run
  std::uint64_t outputs_applied = 0;    // cycles in OP that unpacked outputs
  std::uint64_t mailbox_posted = 0;     // replies handed to SM1
  std::uint64_t al_refused = 0;         // AL requests refused by the firmware checks
  std::uint64_t address_errors = 0;     // multiaxis: command modules addressing no fitted card
  std::uint64_t emergencies = 0;        // CoE emergencies queued (faults and their resets)
  std::uint64_t emergencies_lost = 0;   // not sent: INIT (no mailbox) or the reply queue full
};

// ETG.1020 SyncManager synchronisation parameters, 0x1C32 (outputs, SM2) and 0x1C33 (inputs,
// SM3): the firmware keeps the live values here and the OD entries are bound to them.
//  :01 sync mode      0 free run (the firmware's own cycle), 2 DC SYNC0; SM-synchronous (1) is
//                     not supported (:04 = 0x0005) and refused with 0x06090030. Written by the
//                     master in PRE-OP, it must agree with the SYNC0 activation (0x0981) at
//                     PRE-OP → SAFE-OP, else 0x0030; never written, it follows the activation
//                     (each object on its own: a master may write only 0x1C32).
//  :02 cycle time     [ns] the SYNC0 cycle with DC, else the firmware's measured local cycle
//  :05 minimum cycle  [ns] DcClock::kMinSyncCycleNs; :03 :06 :09 shift, calc+copy, delay: 0 (the
//                     model's firmware takes no time)
//  :08 get cycle time 2 resets the error counters (then reads 0); 0/1 are kept
//  :0A SYNC0 cycle    [ns] 0x09A0 while SYNC0 is active, else 0
//  :0B SM event missed  SYNC0 pulses in OP that found no new SM2 buffer since the last one
//  :0C :0D            0 (no cycle is too short for the model)
//  :20 sync error     the last SYNC0 pulse in OP missed its SM event
struct SmSyncParams {
  std::uint16_t sync_mode = 0;
  std::uint32_t cycle_time = 0, shift_time = 0;
  std::uint16_t supported = 0x0005;
  std::uint32_t min_cycle = DcClock::kMinSyncCycleNs, calc_copy = 0;
  std::uint16_t get_cycle = 0;
  std::uint32_t delay = 0, sync0_cycle = 0;
  std::uint16_t sm_missed = 0, too_small = 0, shift_short = 0;
  std::uint8_t sync_error = 0;
};

// One PDO entry in the process image: `bits` bits at bit `offset` of the image ↔ the OD entry.
struct PdoSlot {
  std::uint32_t offset = 0;
  std::uint16_t bits = 0;
  OdEntry* entry = nullptr;       // nullptr = padding
};

class DriveSlave final : public EscApplication {
 public:
  // Throws EsiError when the description has no mailbox SMs, no process-data SMs or PDOs that
  // map absent objects, or config.axes is outside 1..ChannelCount.
  DriveSlave(const DeviceDescription& desc, const DriveSlaveConfig& config);
  DriveSlave(const DriveSlave&) = delete;
  DriveSlave& operator=(const DriveSlave&) = delete;

  Esc& esc() { return *esc_; }
  const Esc& esc() const { return *esc_; }
  int axes() const { return static_cast<int>(axes_.size()); }
  drive::Cia402Drive& axis(int i) { return *axes_.at(static_cast<std::size_t>(i)); }
  const drive::Cia402Drive& axis(int i) const { return *axes_.at(static_cast<std::size_t>(i)); }
  ObjectDictionary& od() { return od_; }
  const CoeServer& coe() const { return *coe_; }
  SlaveApp app() const { return app_; }
  const DeviceDescription& description() const { return desc_; }
  const DriveSlaveStats& stats() const { return stats_; }
  const SmSyncParams& sync_params(bool outputs) const { return outputs ? sync_out_ : sync_in_; }

  // Bytes of the assigned RxPDOs / TxPDOs with the current 0x1C12/0x1C13 and mappings.
  std::size_t output_bytes() const;
  std::size_t input_bytes() const;
  // The layout fixed at the last PRE-OP → SAFE-OP (the construction defaults before).
  std::span<const PdoSlot> rx_layout() const { return rx_; }
  std::span<const PdoSlot> tx_layout() const { return tx_; }
  // SM2/SM3 indices (from the ESI).
  int output_sm() const { return sm_out_; }
  int input_sm() const { return sm_in_; }

  // The firmware cycle at t (see the header comment). While DC SYNC0 is active it only posts
  // mailbox replies: the process-data part runs on the SYNC0 pulses. RT-safe.
  void cycle(SimTime t) noexcept;
  bool sync0_driven() const;      // 0x0981 has cyclic unit and SYNC0 active, and the ESC accepted the cycle
  // Power loss and return at t: the ESC to its power-on state, the axes to theirs, the object
  // dictionary (PDO assignment and mapping included) to the ESI defaults, CoE transfers and
  // replies dropped. Set-up path (no allocation, but not meant for every cycle).
  void power_cycle(SimTime t);
  // Called by every firmware cycle at its time t, after the outputs were unpacked into the axes'
  // objects and before the inputs are packed: where the twin steps the drives (axis(i).step with
  // physics feedback), so that a SYNC0-driven cycle steps them at the pulse. Empty: nothing is
  // called (the caller steps the drives itself). Set-up call; the hook must be RT-safe.
  using CycleHook = std::function<void(SimTime t)>;
  void set_cycle_hook(CycleHook hook) { hook_ = std::move(hook); }

  // EscApplication.
  AlStatusCode on_al_request(AlState from, AlState to, SimTime t) override;
  void on_mailbox(std::span<const std::uint8_t> mailbox, SimTime t) override;
  void on_outputs(std::span<const std::uint8_t> outputs, SimTime t) override;
  void on_sync0(SimTime t) override;
  void on_al_fallback(AlState from, AlState to, AlStatusCode code, SimTime t) override;
  void on_al_error_cleared(AlState state, SimTime t) override;

 private:
  void build_od();
  void bind_cia402_axis(int a);
  void bind_multiaxis_axis(int a);
  void install_pdo_checks();
  void bind_sync_params(std::uint16_t index, SmSyncParams& p);
  void set_factor_objects();
  void update_sync_params(SimTime t) noexcept;
  void follow_sync_mode(bool dc) noexcept;
  void signal_emergencies() noexcept;
  SdoAbort check_mapping(const OdObject& o, std::uint8_t sub, std::span<const std::uint8_t> data) const;
  SdoAbort check_assign(const OdObject& o, std::uint8_t sub, std::span<const std::uint8_t> data) const;
  std::size_t assigned_bits(bool rx) const;
  bool build_layout(bool rx, std::vector<PdoSlot>& out) const;
  void firmware(SimTime t) noexcept;
  void pack_inputs() noexcept;
  void pump_mailbox() noexcept;
  void outputs_stopped() noexcept;
  void close_mailbox(bool closed);
  void multiaxis_commands() noexcept;
  void multiaxis_status() noexcept;
  OdState od_state() const;

  DeviceDescription desc_;
  DriveSlaveConfig cfg_;
  SlaveApp app_ = SlaveApp::cia402;
  int sm_mbx_out_ = 0, sm_mbx_in_ = 1, sm_out_ = 2, sm_in_ = 3;
  std::vector<std::unique_ptr<drive::Cia402Drive>> axes_;
  ObjectDictionary od_;
  std::unique_ptr<CoeServer> coe_;
  std::unique_ptr<Esc> esc_;
  std::vector<PdoSlot> rx_, tx_;
  std::vector<std::uint8_t> in_image_;
  bool outputs_valid_ = false;    // OP and outputs being applied
  // multiaxis per-card state
  struct Card {
    std::uint8_t handshake = 0;   // last acknowledged handshake bit
    std::uint8_t work_mode = 0;   // active work mode
    std::uint16_t prev_control = 0;
    bool address_error = false;
    int card = -1;                // card addressed by this slot's command module (-1: none)
    bool mode_pending = false;
  };
  std::vector<Card> cards_;
  // multiaxis: per slot its command module's entries (subs 1-4), then its status module's.
  std::vector<std::array<OdEntry*, 8>> modules_;
  CycleHook hook_;
  DriveSlaveStats stats_;
  SmSyncParams sync_out_, sync_in_;
  bool sync_mode_written_out_ = false;  // the master wrote 0x1C32:01 since power-on
  bool sync_mode_written_in_ = false;   // … 0x1C33:01
  bool outputs_fresh_ = false;      // a complete SM2 buffer since the last firmware cycle
  SimTime last_cycle_ = -1;
  std::vector<std::uint16_t> emcy_code_;  // per axis: the 0x603F last signalled
};

}  // namespace omnitwin::ethercat
