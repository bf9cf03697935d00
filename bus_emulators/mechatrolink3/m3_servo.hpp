// bus_emulators/mechatrolink3 — the standard servo profile (profile type 10h) on top of the
// shared drive core (bus_emulators/drive/Cia402Drive), so an M-III servo drives a MuJoCo
// wheel exactly as the EtherCAT drives do. The link (m3_link) hands it the commands its
// phase allows; this class turns them into the drive core's objects (controlword, mode,
// targets) and answers with CMD_STAT's device bits, the servo status and the monitors.
//
// Command and response fields after the 4-byte header follow the public command format of the
// standard servo profile (byte by byte in m3_servo_format.hpp, shared with our master):
//   command  bytes 4-7 SVCMD_CTRL (bit 0 CMD_PAUSE, bit 1 CMD_CANCEL, bits 16-19/20-23/24-27
//            SEL_MON1/2/3), 8-11 SVCMD_IO (reserved here), 12/16/20/24/28 the command's fields
//   response bytes 4-7 SVCMD_STAT (bit 0 CMD_PAUSE_CMP, bit 1 CMD_CANCEL_CMP, bit 8 L_CMP1,
//            bit 10 POS_RDY, bit 11 PON, bit 12 M_RDY, bit 13 SV_ON, bits 16-27 SEL_MON echo),
//            8-11 SVCMD_IO (bit 1 DEC, 2 P_OT, 3 N_OT, 9 BRK_ON, 12 DEN, 14 PSET, 15 ZPOINT,
//            19 ZSPD), 12/16 CPRM_SEL_MON1/2 (parameters 0111h/0112h, ours), 20/24/28
//            MONITOR1/2/3 (every servo command but SVPRM_RD/WR, whose fields start at 12)
//   INTERPOLATE 12 TPOS [ref] 16 VFF [ref/s] 28 TLIM [0.1 %]; POSING and EX_POSING 12 TPOS
//   16 TSPD 20 ACCR 24 DECR [ref/s²] (0: the parameter) 28 TLIM; FEED 16 TSPD 20 ACCR 24 DECR
//   28 TLIM; VELCTRL 16 VREF 20 ACCR 24 DECR (0: at once) 28 TLIM; TRQCTRL 16 TQREF [0.1 %];
//   ZRET 12 the homing method (ours: the CiA 402 number; 0 the parameter) 16 TSPD 20 ACCR
//   28 TLIM; POS_SET 12 PS_SUBCMD (bit 7 REFE) 16 POS_DATA; SVPRM_RD/WR 12 NO u16, 14 SIZE
//   (4), 15 MODE, 16 PARAMETER. TLIM 0 leaves parameter 0101h, a larger one is capped at it.
//   The common commands keep the common format, no SVCMD_STAT/IO in their answers: ID_RD 4
//   ID_CODE 5 OFFSET 6 SIZE u16 → 8… ASCII; ALM_RD 4 ALM_RD_MOD u16 (0 now, 1 history) → 8…
//   up to 12 codes u16; ALM_CLR 4 ALM_CLR_MOD u16 (1 also clears the history); CONFIG.
// CMD_PAUSE and CMD_CANCEL act on POSING, FEED, EX_POSING, ZRET and VELCTRL (the profile):
// pause decelerates the motion to a stop and holds it (PAUSE_CMP once it stands), resuming when
// the bit clears; cancel does not take the command, decelerates the motion to a stop and ends
// it there (CANCEL_CMP once it stands). STOP_MODE is not modelled: both decelerate.
// Reference units [ref] are the drive's counts; monitors: 0 APOS, 1 CPOS, 2 PERR, 3 LPOS1,
// 5 FSPD, 6 CSPD, 7 TRQ, 8 ALARM, 9 MPOS (others read 0).
//
// Rules: SV_ON needs SENS_ON first and CMDRDY stays 0 until the drive is enabled (one FSA
// step per drive period); motion commands need the servo on, BRK_ON/BRK_OFF and SENS_OFF
// need it off (else CMD_ALM condition error); a drive fault is D_ALM and servo off until
// ALM_CLR (the command, or CMD_CTRL.ALM_CLR rising: clear_alarms()); a communication alarm (stop()) is servo off at once, and SV_ON is refused (condition
// error, by the link: needs_alarm_cleared()) until ALM_CLR clears COMM_ALM; DISCONNECT (disconnect())
// is servo off and SENS_ON, POS_SET, the latch and the home forgotten. Subcommands (48-byte mode, region
// bytes 32-47: 0 SUB_CMD, 1-3 SUB_CTRL with SEL_MON4/5/6 in bits 12-15/16-19/20-23): SMON →
// monitors at 4/8/12; SVPRM_RD/WR → NO 4, SIZE 6, MODE 7, PARAMETER 8; ALM_RD → MOD 4, four
// codes from 8; ALM_CLR → MOD 4. ZRET runs the drive core's homing; ZPOINT says it
// is done. EX_POSING positions towards TPOS until the latch input (the DEC input: the
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
#include "bus_emulators/mechatrolink3/m3_servo_format.hpp"

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
  cprm_sel_mon1 = 0x0111,           // the monitor code CPRM_SEL_MON1 (response byte 12) reads, 0…F
  cprm_sel_mon2 = 0x0112,           // the monitor code CPRM_SEL_MON2 (response byte 16) reads, 0…F
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
  // ALM_CLR (the command, or a rising CMD_CTRL.ALM_CLR): a drive fault is reset in the next
  // drive period (D_ALM then clears unless the cause persists).
  void clear_alarms() override;
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
  void apply_tlim(std::span<const std::uint8_t> cmd, std::size_t at);
  bool stopped() const;
  void fill_status(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) const;
  void fill_monitors(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) const;
  std::uint16_t controlword();
  void note_alarm(std::uint16_t code);

  ServoConfig cfg_;
  drive::Cia402Drive drive_;
  bool want_on_ = false, sensor_on_ = false, paused_ = false, fault_reset_ = false;
  bool cancelled_ = false;         // the last servo command carried CMD_CANCEL
  std::uint16_t max_torque_;       // parameter 0101h [0.1 %]; a command's TLIM caps it
  std::int32_t vref_ = 0;          // VELCTRL: VREF [ref/s]
  double vel_acc_ = 0, vel_dec_ = 0;  // VELCTRL: ACCR, DECR [ref/s²] (0: at once)
  double vel_ramp_ = 0;            // VELCTRL: the velocity set-point on its ramp [ref/s]
  SimTime last_step_ = -1;         // the last drive period's time [ns]
  std::array<std::uint8_t, 2> cprm_sel_mon_{0x0, 0x5};  // parameters 0111h/0112h: APOS, FSPD
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
