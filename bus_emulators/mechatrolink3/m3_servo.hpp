// bus_emulators/mechatrolink3 — the standard servo profile (profile type 10h) on top of the
// shared drive core (bus_emulators/drive/Cia402Drive), so an M-III servo drives a MuJoCo
// wheel exactly as the EtherCAT drives do. The link (m3_link) hands it the commands its
// phase allows; this class turns them into the drive core's objects (controlword, mode,
// targets) and answers with CMD_STAT's device bits, the servo status and the monitors.
//
// Command and response fields after the 4-byte header are ours, modelled on the public
// standard servo profile (docs/protocols/mechatrolink3.md has the table):
//   command  bytes 4-7 SVCMD_CTRL (bit 0 CMD_PAUSE, bit 1 CMD_CANCEL, bits 12-15/16-19/20-23
//            SEL_MON1/2/3), 8-11 SVCMD_IO (reserved), 12… per command (below)
//   response bytes 4-7 SVCMD_STAT (bit 0 CMD_PAUSE_CMP, bit 1 CMD_CANCEL_CMP, bit 10 POS_RDY,
//            bit 11 PON, bit 12 M_RDY, bit 13 SV_ON, bits 16-19/20-23/24-27 SEL_MON echo),
//            8-11 SVCMD_IO (bit 0 DEC, 1 P_OT, 2 N_OT, 9 PSET: POSING/INTERPOLATE within the
//            position window of its target, 11 ZPOINT, 12 BRK_ON),
//            12-15/16-19/20-23 MONITOR1/2/3 (motion, servo and SMON commands; SVPRM_RD/WR,
//            ID_RD and ALM_RD carry SVCMD_STAT and SVCMD_IO but their own fields from 12 on)
//   VELCTRL 16 VREF [ref/s] 20 P_TLIM u16 [0.1 %]; INTERPOLATE 16 TPOS [ref] 20 VFF [ref/s];
//   POSING 16 TPOS 20 TSPD 24 ACCR 28 DECR [ref/s²] (0: the parameter); FEED 20 TSPD 24 ACCR
//   28 DECR; TRQCTRL 16 TQREF [0.1 %]; POS_SET 12 PS_SUBCMD (bit 7 REFE) 16 POS_DATA;
//   SVPRM_RD/WR 12 NO u16, 14 SIZE (4), 15 MODE, 16 PARAMETER i32; ID_RD 12 ID_CODE 13 OFFSET
//   14 SIZE → 16… ASCII; ALM_RD 12 ALM_RD_MOD (0 now, 1 history) → 16… alarm codes u16;
//   ALM_CLR 12 ALM_CLR_MOD.
// Reference units [ref] are the drive's counts; monitors: 0 APOS, 1 CPOS, 2 PERR, 3 LPOS1,
// 5 FSPD, 6 CSPD, 7 TRQ, 8 ALARM, 9 MPOS (others read 0).
//
// Rules: SV_ON needs SENS_ON first and CMDRDY stays 0 until the drive is enabled (one FSA
// step per drive period); motion commands need the servo on, BRK_ON/BRK_OFF and SENS_OFF
// need it off (else CMD_ALM condition error); a drive fault is D_ALM and servo off until
// ALM_CLR; a communication alarm (stop()) is servo off at once, and SV_ON is refused (condition
// error, by the link: needs_alarm_cleared()) until ALM_CLR clears COMM_ALM; DISCONNECT (disconnect())
// is servo off and SENS_ON, POS_SET, the latch and the home forgotten. Subcommands (48-byte mode, region
// bytes 32-47: 0 SUB_CMD, 1-3 SUB_CTRL with SEL_MON4/5/6 in bits 12-15/16-19/20-23): SMON →
// monitors at 4/8/12; SVPRM_RD/WR → NO 4, SIZE 6, MODE 7, PARAMETER 8; ALM_RD → MOD 4, four
// codes from 8; ALM_CLR → MOD 4. ZRET 12 homing method (CiA 402 number; 0: the parameter)
// 20 TSPD 24 ACCR runs the drive core's homing; ZPOINT says it is done. EX_POSING (16 TPOS,
// 20 TSPD, 24 ACCR, 28 DECR) positions towards TPOS until the latch input (the DEC input: the
// drive core's home switch or scenario bit 2) rises, then stops at the latched position +
// parameter 0107h; LPOS1 (monitor 3) is the latched position and SVCMD_STAT bit 8 L_CMP1 says
// it latched (within one drive period). CONFIG answers normal (our parameters take effect
// when written). Not built: MEM_RD/MEM_WR (virtual memory; "unsupported").
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "bus_emulators/drive/cia402_drive.hpp"
#include "bus_emulators/mechatrolink3/m3_link.hpp"

namespace omnitwin::m3 {

struct ServoConfig {
  drive::DriveConfig drive;
  std::string id = "OMNITWIN M3-SERVO";  // ID_RD, at most 32 characters
};

// Servo parameter numbers (SVPRM_RD/WR; ours), each a drive core object.
enum class ServoParam : std::uint16_t {
  following_error_window = 0x0100,  // [ref]
  max_torque = 0x0101,              // [0.1 %]
  acceleration = 0x0102,            // [ref/s²]
  deceleration = 0x0103,            // [ref/s²]
  quick_stop_deceleration = 0x0104, // [ref/s²]
  max_velocity = 0x0105,            // [ref/s]
  position_window = 0x0106,         // [ref]
  ex_posing_distance = 0x0107,      // EX_POSING: travel after the latch [ref] (signed)
  counts_per_rev = 0x0110,          // read only
};

class ServoProfile final : public Profile {
 public:
  explicit ServoProfile(const ServoConfig& config);

  std::uint8_t profile_type() const override { return 0x10; }
  bool accepts_length(std::size_t n) const override { return n == 32 || n == 48; }
  // SV_ON: a communication alarm is a servo alarm (profile), cleared by ALM_CLR before it.
  bool needs_alarm_cleared(Command c) const override { return c == Command::sv_on; }
  CmdAlarm execute(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, SimTime t) override;
  CmdAlarm execute_sub(Command c, std::span<const std::uint8_t> sub, std::span<std::uint8_t> rsp) override;
  void stop(SimTime t) override;
  // Servo off, and the encoder (SENS_ON), POS_SET's offset, the target, CMD_PAUSE, the latch
  // and the home (ZPOINT) forgotten: a reconnected servo needs SENS_ON before SV_ON again.
  void disconnect(SimTime t) override;
  bool device_alarm() const override;
  bool device_warning() const override { return false; }
  bool ready() const override;

  // One drive period at t [ns]: the controlword from the servo state, then the drive core.
  // Real-time safe.
  drive::Command step(SimTime t, const drive::Feedback& fb);
  // Power cycle: the drive back to power-on, servo off, sensor off, no alarms.
  void power_cycle();

  drive::Cia402Drive& drive() { return drive_; }
  const drive::Cia402Drive& drive() const { return drive_; }
  bool servo_on() const;
  // The CiA 402 mode (0x6061 numbering) of the last motion command that ran: 9 VELCTRL, 8
  // INTERPOLATE, 1 POSING/EX_POSING, 3 FEED, 10 TRQCTRL, 6 ZRET; 0 while none has run since
  // power-on (the drive core then holds still in CSV, which is no motion command).
  std::int8_t motion_mode() const { return motion_mode_; }
  bool position_ready() const { return sensor_on_; }
  // The monitor value for code `sel` (see the header). Real-time safe.
  std::int32_t monitor(std::uint8_t sel) const;

 private:
  enum class Motion : std::uint8_t { none, velctrl, interpolate, posing, feed, trqctrl, zret, ex_posing };
  CmdAlarm run(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp);
  CmdAlarm motion(Command c, std::span<const std::uint8_t> cmd);
  CmdAlarm posing(std::span<const std::uint8_t> cmd, bool feed);
  CmdAlarm zero_return(std::span<const std::uint8_t> cmd);
  void watch_latch();
  CmdAlarm parameter(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, std::size_t at);
  CmdAlarm alarm_read(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, std::size_t at,
                      std::size_t codes, std::size_t count) const;
  CmdAlarm id_read(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) const;
  void fill_status(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) const;
  void fill_monitors(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) const;
  std::uint16_t controlword();
  void note_alarm(std::uint16_t code);

  ServoConfig cfg_;
  drive::Cia402Drive drive_;
  bool want_on_ = false, sensor_on_ = false, paused_ = false, fault_reset_ = false;
  Motion motion_ = Motion::none;
  std::int8_t motion_mode_ = 0;    // see motion_mode()
  bool new_set_point_ = false;     // POSING/FEED: pulse controlword bit 4 once
  std::int32_t user_offset_ = 0;   // POS_SET: reported = drive position + offset [ref]
  std::int32_t target_ = 0;        // the last TPOS [ref], for CPOS/PERR
  std::array<std::uint16_t, 8> history_{};  // alarm history, newest first
  std::uint16_t last_error_ = 0;
  std::int32_t ex_distance_ = 0;   // parameter 0107h [ref]
  std::int32_t latch_pos_ = 0;     // LPOS1: where the latch input rose [ref]
  std::int32_t tpos_requested_ = 0;  // the TPOS of the EX_POSING in progress [ref]
  bool latched_ = false, prev_dec_ = false;
  bool home_lost_ = false;         // DISCONNECT since the drive homed: no ZPOINT until it homes again
};

// The M-III alarm code the servo reports for a drive core error code (ours: following error
// 8611h → D00h "position deviation overflow", others → F00h).
std::uint16_t servo_alarm_code(std::uint16_t drive_error) noexcept;

}  // namespace omnitwin::m3
