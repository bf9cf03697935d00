// bus_emulators/tml — one emulated Technosoft IDM drive as a protocol core (seed 003; facts/tml.md;
// docs/protocols/tml.md "The drive"): TML messages and time in, TML messages out through a
// callback. No sockets, no clock, no link framing: the serial link (tml_serial's
// SerialDriveLink, driven by tml_pty) and the CAN node (tml_can_node) wrap it, as
// canopen::DriveNode wraps the same shared drive core for CANopen.
//
// What it does: addressing (axis ID, axis 0, group ID mask, broadcast, HOST bit), the TML
// registers and variables the seed's examples use and those a motion needs, assignments,
// GiveMeData → TakeData, GiveMeData2 → TakeData2, unsolicited TakeData2 on masked status bit
// changes (type C), AXISON/AXISOFF/UPD/STOP/FAULTR, speed mode and position mode mapped onto the
// CiA 402 drive core (drive::Cia402Drive, which drives the wheel), GROUPID/ADDGRID/REMGRID, and
// TechCAN synchronisation (SYNC latches the drive time, SETSYNC n makes the drive the master).
//
// Units (TML "internal units", IU; our choices, docs/protocols/tml.md): positions in encoder
// counts (the drive core's counts); speeds in counts per sampling period and accelerations in
// counts per sampling period², both 32-bit fixed point 16.16 (high word integer part, as the
// seed's PVT example encodes −10 IU as 0xFFF60000); the sampling period is DriveSetup's
// sample_period_s (1 ms by default). Drive time in ms (32-bit, wraps).
//
// Every opcode and address the seed does not give is OUR CHOICE, marked so below and in the
// docs. The seed does not say which MER bit an unknown instruction sets, so unknown opcodes
// and addresses are only counted.
#pragma once

#include <cstdint>
#include <functional>

#include "bus_emulators/drive/cia402_drive.hpp"
#include "bus_emulators/tml/tml_message.hpp"

namespace omnitwin::tml {

using SimTime = std::int64_t;  // [ns] on the simulated timeline

enum class Protocol : std::uint8_t { rs232, rs485, tmlcan, techcan };
const char* to_string(Protocol p);

// ---- Registers and variables (addresses; 16-bit unless marked 32) ------------------------------
namespace reg {
// From the seed (facts/tml.md).
inline constexpr std::uint16_t kpp = 0x025E;     // position loop proportional gain (stored only)
inline constexpr std::uint16_t poserr = 0x022A;  // following error [counts], read-only, saturated
inline constexpr std::uint16_t srl = 0x090E;     // status register low; 32-bit access = SR32
inline constexpr std::uint16_t srh = 0x090F;     // status register high (tml_message's inference)
inline constexpr std::uint16_t mer = 0x08FC;     // motion error register
// From Technosoft's public TML_lib_light (APOS, CPOS, CSPD, CACC); ASPD as recalled, unverified.
inline constexpr std::uint16_t apos = 0x0228;    // 32: actual position [counts], read-only
inline constexpr std::uint16_t aspd = 0x022C;    // 32: actual speed [16.16 counts/sample], read-only
inline constexpr std::uint16_t cpos = 0x029E;    // 32: command position [counts]
inline constexpr std::uint16_t cspd = 0x02A0;    // 32: command speed [16.16 counts/sample]
inline constexpr std::uint16_t cacc = 0x02A2;    // 32: command acceleration [16.16 counts/sample²]
// OUR CHOICE — invented, in a block the seed leaves unused (0x0300–0x030F; TML_lib_light names
// DER2 0x0305 and MCR 0x0309 there: documented overlap).
inline constexpr std::uint16_t tpos = 0x0300;       // 32: position demand [counts], read-only
inline constexpr std::uint16_t errmax = 0x0302;     // following error limit [counts]
inline constexpr std::uint16_t terrmax = 0x0303;    // following error time [samples]
inline constexpr std::uint16_t masterid = 0x0304;   // destination ID code of unsolicited TakeData2
inline constexpr std::uint16_t srl_mask = 0x0305;   // SRL bits whose change sends TakeData2
inline constexpr std::uint16_t srh_mask = 0x0306;   // SRH bits whose change sends TakeData2
inline constexpr std::uint16_t mer_mask = 0x0307;   // MER bits whose change sends TakeData2
inline constexpr std::uint16_t aar = 0x0308;        // axis ID (bits 7–0), group ID (15–8), read-only
inline constexpr std::uint16_t time = 0x030A;       // 32: drive time [ms], read-only
inline constexpr std::uint16_t sync_time = 0x030C;  // 32: drive time latched by the last SYNC [ms]
inline constexpr std::uint16_t sync_period = 0x030E;  // SETSYNC period [ms] (0: not sync master)
}  // namespace reg

// Status and error bits.
namespace bits {
inline constexpr std::uint16_t srl_motion_complete = 1u << 10;  // seed: SRL.10, SRL_MASK 0x0400
inline constexpr std::uint16_t srl_axis_on = 1u << 15;          // seed example SRL = 0x8400; vendor docs
inline constexpr std::uint16_t srh_fault = 1u << 15;            // OUR CHOICE (vendor docs as recalled)
inline constexpr std::uint16_t mer_control_error = 1u << 3;     // seed ex. 5: control error → MER 0x0008
}  // namespace bits

// ---- Instructions -------------------------------------------------------------------------------
// Binary codes from Technosoft's public TML_lib_light (BSD-3, facts only): AXISON, AXISOFF, UPD,
// STOP, SETSYNC, FAULTR (its RESET_FAULT) and the bit-set instruction 0x5909 that carries MODE PP,
// MODE SP, TUM1, CPA and CPR as a 32-bit AND/OR mask (docs/protocols/tml.md "Instructions").
// GROUPID/ADDGRID/REMGRID are OUR CHOICE (invented; the operand is a group number).
namespace instr {
inline constexpr std::uint16_t axisoff = 0x0002;   // power stage off
inline constexpr std::uint16_t axison = 0x0102;    // power stage on
inline constexpr std::uint16_t upd = 0x0108;       // apply the command set-points
inline constexpr std::uint16_t stop = 0x01C4;      // stop the motion at CACC
inline constexpr std::uint16_t faultr = 0x1C04;    // fault reset
inline constexpr std::uint16_t setsync = 0x1404;   // data 1 = period [ms], 0 = stop
inline constexpr std::uint16_t bitset = 0x5909;    // data 1–2 = 32-bit mask (low word first): MODE, TUM, CPA/CPR
inline constexpr std::uint16_t groupid = 0x0610;   // data 1 = group number 1–8 (0: none) (invented)
inline constexpr std::uint16_t addgrid = 0x0611;   // data 1 = group number 1–8 (invented)
inline constexpr std::uint16_t remgrid = 0x0612;   // data 1 = group number 1–8 (invented)
}  // namespace instr
// The masks of the bit-set instruction (TML_lib_light's values).
namespace bitset_data {
inline constexpr std::uint32_t mode_pp = 0xBFC18701;  // MODE PP: position profile
inline constexpr std::uint32_t mode_sp = 0xBBC18301;  // MODE SP: speed profile
inline constexpr std::uint32_t tum1 = 0xFFFF4000;     // TUM1: target update mode 1 (accepted, no effect here)
inline constexpr std::uint32_t cpa = 0xFFFF2000;      // CPOS absolute
inline constexpr std::uint32_t cpr = 0xDFFF0000;      // CPOS relative
}  // namespace bitset_data

// The bit-set instruction with its 32-bit mask (low word first, as every 32-bit TML datum). RT-safe.
Message bitset_instruction(std::uint16_t dest, std::uint32_t mask);
// A one-word instruction (and GROUPID/ADDGRID/REMGRID/SETSYNC with their data word). RT-safe.
Message instruction(std::uint16_t dest, std::uint16_t opcode);
Message instruction(std::uint16_t dest, std::uint16_t opcode, std::uint16_t data);

// ---- Configuration -----------------------------------------------------------------------------
struct DriveSetup {
  std::uint8_t axis = 255;         // 1–255 (TechCAN 1–31)
  std::uint8_t groups = 1;         // group ID mask (default group 1)
  std::uint8_t host_axis = 255;    // MASTERID = host_axis · 16 + 1
  Protocol protocol = Protocol::rs232;
  double sample_period_s = 0.001;  // the IU time base of speeds and accelerations
  drive::DriveConfig drive{};      // the shared drive core (counts_per_rev = counts per motor rev)
};

struct DriveStats {
  std::uint64_t handled = 0;          // messages for this drive that were executed
  std::uint64_t not_for_us = 0;       // other axes/groups, answers of other drives
  std::uint64_t for_host = 0;         // HOST bit set: for the host (a relay would forward them)
  std::uint64_t answers_sent = 0;     // TakeData / TakeData2 answering a request
  std::uint64_t take_data2_sent = 0;  // unsolicited TakeData2 (type C)
  std::uint64_t unknown_opcodes = 0;
  std::uint64_t unknown_addresses = 0;  // reads/writes of addresses we do not model, read-only writes
  std::uint64_t refused = 0;          // well-formed but not allowed (e.g. GiveMeData to a group)
  std::uint64_t invalid_id_codes = 0;  // ID code bits 15–13 or 3–1 set: dropped
  std::uint64_t syncs_sent = 0;       // as SETSYNC master
  std::uint64_t syncs_received = 0;
  std::uint64_t steps = 0;
};

// The drive. Power states: off (messages and steps ignored) → power_on → on → power_off.
// Motion requests (AXISON/AXISOFF, UPD, STOP, FAULTR) are applied to the drive core's
// controlword in the next step(): AXISON walks switch-on-disabled → ready → operation enabled;
// position mode raises the new-set-point bit until the core acknowledges it.
class TmlDrive {
 public:
  using Send = std::function<void(const Message&, SimTime)>;
  // Throws std::invalid_argument for an axis outside 1–255 (TechCAN 1–31) or a bad sample period.
  TmlDrive(const DriveSetup& setup, Send send);
  TmlDrive(const TmlDrive&) = delete;
  TmlDrive& operator=(const TmlDrive&) = delete;
  // Set-up only: the link adapter that carries this drive's messages.
  void set_sender(Send send) { send_ = std::move(send); }

  // Power on at t: registers and drive core to their power-on values, groups and axis from the
  // setup, drive time 0. Power off: silent until power_on. RT-safe.
  void power_on(SimTime t);
  void power_off() { powered_ = false; }
  bool powered() const { return powered_; }

  // Whether a message with this destination ID code is for this drive (axis, axis 0, a group it
  // belongs to, broadcast; HOST bit clear). RT-safe.
  bool accepts(std::uint16_t id_code) const;
  // One received message at t (any destination: addressing is done here; an ID code with bits
  // 15–13 or 3–1 set is dropped and counted). RT-safe.
  void on_message(const Message& m, SimTime t);
  // One drive period at t: motion requests → controlword, the drive core's step, status
  // registers, type C TakeData2, SETSYNC master. Returns the command to the physics. RT-safe.
  drive::Command step(SimTime t, const drive::Feedback& fb);

  // Register/variable access as the bus sees it (16-bit: low word). false: not modelled. RT-safe.
  bool read(std::uint16_t address, bool wide, std::uint32_t& value) const;
  bool write(std::uint16_t address, bool wide, std::uint32_t value);

  std::uint8_t axis() const { return axis_; }
  std::uint8_t groups() const { return groups_; }
  std::uint16_t srl() const { return srl_; }
  std::uint16_t srh() const { return srh_; }
  std::uint16_t mer() const { return mer_; }
  std::uint32_t drive_time_ms(SimTime t) const;
  bool sync_master() const { return sync_period_ms_ != 0; }
  const DriveSetup& setup() const { return setup_; }
  const DriveStats& stats() const { return stats_; }
  drive::Cia402Drive& core() { return core_; }
  const drive::Cia402Drive& core() const { return core_; }

  // Unit conversions (IU ↔ the drive core's SI-like units). RT-safe.
  double speed_iu_to_counts_s(std::int32_t iu) const;
  double acc_iu_to_counts_s2(std::int32_t iu) const;
  std::int32_t counts_s_to_speed_iu(double counts_s) const;

 private:
  enum class Motion : std::uint8_t { speed, position };
  void execute(const Message& m, SimTime t);
  void answer_request(const Message& m, const Classified& c, SimTime t);
  std::uint8_t run_instruction(const Message& m);  // an InstrResult (done, unknown, refused)
  bool read_word(std::uint16_t address, std::uint16_t& w) const;
  bool write_word(std::uint16_t address, std::uint16_t w);
  void on_sync(SimTime t);
  void on_master_time(std::uint32_t master_ms);
  void emit(const Message& m, SimTime t);
  std::uint16_t next_controlword();
  void apply_update();
  void update_status();
  void send_masked_changes(std::uint16_t old_srl, std::uint16_t old_srh, std::uint16_t old_mer, SimTime t);
  void run_sync_master(SimTime t);

  DriveSetup setup_;
  Send send_;
  drive::Cia402Drive core_;
  bool powered_ = false;
  std::uint8_t axis_ = 255, groups_ = 1;
  // Variables.
  std::uint16_t kpp_ = 0, masterid_ = 0, srl_mask_ = 0, srh_mask_ = 0, mer_mask_ = 0;
  std::int32_t cpos_ = 0, cspd_ = 0, cacc_ = 0;
  std::uint16_t srl_ = 0, srh_ = 0, mer_ = 0;
  // Motion requests.
  Motion motion_ = Motion::position;
  bool relative_ = false, want_on_ = false, halt_ = false, fault_reset_ = false;
  bool update_pending_ = false, set_point_high_ = false;
  bool motion_complete_ = true;  // SRL.10, latched: cleared by UPD, set when the target is first reached
  // Time.
  SimTime t0_ = 0, now_ = 0;  // power-on time; time of the last message or step
  std::int64_t time_offset_ms_ = 0;
  std::uint32_t sync_latch_ms_ = 0;
  std::uint16_t sync_period_ms_ = 0;
  SimTime next_sync_t_ = 0;
  DriveStats stats_;
};

}  // namespace omnitwin::tml
