// controller/mechatrolink3 — one M-III servo axis as the master application sees it: the
// servo start-up sequence of seed 000 fig. 8, then a motion command every cycle, then the
// shut-down. It runs at the C1 master's cyclic interrupt: it reads the slave's last response
// (C1Master::response) and writes the next command (C1Master::command).
//
// Sequence (one flat switch over named steps, on_interrupt()):
//   disconnect  DISCONNECT: the slave's state is unknown after power-up        → connect
//   connect     CONNECT (VER 30h, synchronous, COM_TIM, profile 10h)           → sync_set
//   sync_set    SYNC_SET: phase 3                                              → id_rd
//   id_rd       ID_RD: the device name (logged)                                → params
//   params      SVPRM_WR of each configured parameter, one per step            → sens_on
//   sens_on     SENS_ON: the encoder position                                  → sv_on
//   sv_on       SV_ON until the response says SV_ON with CMDRDY                → running
//   running     VELCTRL (velocity set-point) or INTERPOLATE (position)         → sv_off
//   sv_off      SV_OFF (shutdown() asked for it)                               → release
//   release     DISCONNECT                                                     → released
//   failed      a command answered with a CMD_ALM alarm during start-up: why() says
//   alm_clr     ALM_CLR (and CMD_CTRL.ALM_CLR) after the servo went off while running, or after
//               a communication alarm during start-up                       → sync_set
// Recovery after start-up began: a CMD_ALM phase error (the slave lost power, its connection
// or phase 3) goes back to disconnect (it works in every phase); a servo that went off (a communication or device
// alarm: SVCMD_STAT.SV_ON clear), or a COMM_ALM alarm before it runs (the slave refuses SV_ON
// until ALM_CLR), goes to alm_clr; both then skip ID_RD and the parameters and count in
// recoveries().
// A step moves on when the response echoes its command with CMD_ALM normal (and, for SV_ON,
// CMDRDY and SVCMD_STAT.SV_ON); a response that is not fresh leaves the step where it is.
// Shut-down (shutdown()): a running axis first has one command at zero speed answered (INTERPOLATE:
// its target held where the servo is), then SV_OFF and DISCONNECT; an axis in start-up goes to
// SV_OFF at once, one not connected yet to DISCONNECT; the answers move on whatever their CMD_ALM.
// INTERPOLATE targets follow the servo's APOS (its latest fresh response) when the axis enters
// running (at start-up and after a recovery) and after hold(), so a servo switched on again, or
// held, stays where it is instead of driving to a target of many cycles before.
// Real-time safe after construction, except the log callback it is given.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "bus_emulators/mechatrolink3/m3_command.hpp"
#include "bus_emulators/mechatrolink3/m3_frame.hpp"

namespace omnitwin::m3 {

enum class AxisStep : std::uint8_t {
  disconnect, connect, sync_set, id_rd, params, sens_on, sv_on, running, sv_off, release, released, failed, alm_clr
};
const char* to_string(AxisStep);

struct ServoAxisConfig {
  std::uint8_t com_tim = 1;
  bool synchronous = true;     // false: event-driven (no SYNC_SET: phase 2 throughout)
  bool position_mode = false;  // INTERPOLATE instead of VELCTRL
  std::vector<std::pair<std::uint16_t, std::int32_t>> params;  // SVPRM_WR (number, value)
};

class ServoAxis {
 public:
  using Log = std::function<void(SimTime, const std::string&)>;
  ServoAxis(std::string name, ServoAxisConfig config, Log log = {});

  // At the cyclic interrupt: `rsp` is the last response (fresh: it came this cycle), `cmd`
  // is where the next command goes. Real-time safe (except logging on a step change).
  void on_interrupt(std::span<const std::uint8_t> rsp, bool fresh, std::span<std::uint8_t> cmd, SimTime t);
  void set_velocity(std::int32_t ref_per_s) { velocity_ = ref_per_s; }
  void set_position(std::int32_t ref, std::int32_t vff_ref_per_s) { position_ = ref; vff_ = vff_ref_per_s; }
  // Zero speed; the INTERPOLATE target becomes the APOS of the next fresh response (the wheel
  // held where it is, not where a response of many cycles ago said it was).
  void hold() { velocity_ = 0, vff_ = 0, anchor_ = true; }
  // The end of the run: zero speed, then SV_OFF and DISCONNECT (see above) until released().
  void shutdown(SimTime t);

  AxisStep step() const { return step_; }
  const std::string& why() const { return why_; }
  const std::string& device() const { return device_; }
  std::int32_t position() const { return apos_; }      // APOS of the last response [ref]
  std::int32_t velocity() const { return fspd_; }      // FSPD [ref/s]
  CmdStat status() const { return stat_; }
  int recoveries() const { return recoveries_; }

 private:
  void write(std::span<std::uint8_t> cmd) const;
  bool accepted(Command c, std::span<const std::uint8_t> rsp, SimTime t);
  bool recover(std::span<const std::uint8_t> rsp, SimTime t);
  void go(AxisStep next, SimTime t);

  std::string name_;
  ServoAxisConfig cfg_;
  Log log_;
  AxisStep step_ = AxisStep::disconnect;
  std::size_t param_ = 0;
  bool stopping_ = false, recovering_ = false;
  bool stop_written_ = false;  // shutting down: the zero-speed command was written
  bool anchor_ = false;        // the INTERPOLATE target follows the next fresh APOS
  int recoveries_ = 0;
  std::int32_t velocity_ = 0, position_ = 0, vff_ = 0, apos_ = 0, fspd_ = 0;
  CmdStat stat_;
  std::string why_, device_;
};

}  // namespace omnitwin::m3
