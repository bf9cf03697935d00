// bus_emulators/drive — the CiA 402 power drive state machine (FSA): controlword command
// decoding, the transitions 0–16 and the state bits of the statusword (facts/cia402.md).
// Pure computation: no time, no I/O; the axis (cia402_drive) feeds it the controlword and the
// events it detects (a fault, a finished stop) once per drive period.
//
// State machine (Fsa::apply, one flat switch over the states; "cmd" = decoded controlword):
//   not_ready_to_switch_on  power on, self test. Legal: 0 (auto, the first period) → 1 (auto)
//                           → switch_on_disabled.
//   switch_on_disabled      Legal: 2 shutdown → ready_to_switch_on; 13 error → fault_reaction_active.
//   ready_to_switch_on      Legal: 3 switch on → switched_on (3+4 in one period for enable
//                           operation); 7 disable voltage / quick stop → switch_on_disabled; 13.
//   switched_on             Legal: 4 enable operation → operation_enabled; 6 shutdown →
//                           ready_to_switch_on; 10 disable voltage / quick stop →
//                           switch_on_disabled; 13.
//   operation_enabled       Legal: 5 disable operation → switched_on; 8 shutdown →
//                           ready_to_switch_on; 9 disable voltage → switch_on_disabled;
//                           11 quick stop → quick_stop_active; 13.
//   quick_stop_active       Legal: 12 disable voltage, or the stop finished with quick stop
//                           option 1–4 (option 0: at once) → switch_on_disabled; 16 enable
//                           operation with option 5–8 → operation_enabled; 13.
//   fault_reaction_active   Legal: 14 (auto) the fault reaction finished (option 0: at once) → fault.
//   fault                   Legal: 15 fault reset (rising edge of controlword bit 7) →
//                           switch_on_disabled.
// Commands carry bit 7 = 0; while bit 7 is 1 no other command is taken.
#pragma once

#include <cstdint>

namespace omnitwin::drive {

// The FSA states; legal transitions and commands per state in the file comment above.
enum class State : std::uint8_t {
  not_ready_to_switch_on,
  switch_on_disabled,
  ready_to_switch_on,
  switched_on,
  operation_enabled,
  quick_stop_active,
  fault_reaction_active,
  fault,
};
const char* to_string(State);

// Controlword 0x6040 bits.
namespace cw {
inline constexpr std::uint16_t switch_on = 1u << 0, enable_voltage = 1u << 1, quick_stop = 1u << 2,
                               enable_operation = 1u << 3, new_set_point = 1u << 4,
                               start_homing = 1u << 4, change_immediately = 1u << 5,
                               relative = 1u << 6, fault_reset = 1u << 7, halt = 1u << 8,
                               change_on_set_point = 1u << 9;
// The usual command words (bits 7,3,2,1,0 per the fact sheet).
inline constexpr std::uint16_t kShutdown = 0x0006, kSwitchOn = 0x0007, kEnableOperation = 0x000F,
                               kDisableVoltage = 0x0000, kQuickStop = 0x0002,
                               kDisableOperation = 0x0007, kFaultReset = 0x0080;
}  // namespace cw

// Statusword 0x6041 bits.
namespace sw {
inline constexpr std::uint16_t ready_to_switch_on = 1u << 0, switched_on = 1u << 1,
                               operation_enabled = 1u << 2, fault = 1u << 3,
                               voltage_enabled = 1u << 4, quick_stop = 1u << 5,
                               switch_on_disabled = 1u << 6, warning = 1u << 7, remote = 1u << 9,
                               target_reached = 1u << 10, internal_limit = 1u << 11,
                               set_point_ack = 1u << 12, speed_zero = 1u << 12,
                               homing_attained = 1u << 12, following_error = 1u << 13,
                               homing_error = 1u << 13;
}  // namespace sw

// A decoded controlword command (bit 7 edge semantics are the Fsa's).
enum class FsaCommand : std::uint8_t {
  none,              // bit 7 set: no state command (a fault reset only on its rising edge)
  shutdown,          // 0-110
  switch_on,         // 00111 (= disable operation in operation_enabled)
  enable_operation,  // 01111
  disable_voltage,   // 0--0-
  quick_stop,        // 0-01-
};
const char* to_string(FsaCommand);
FsaCommand decode_controlword(std::uint16_t controlword) noexcept;

// Decodes the state from statusword bits 6,5,3,2,1,0 (fact sheet table); unknown patterns
// decode as not_ready_to_switch_on.
State decode_statusword(std::uint16_t statusword) noexcept;

// The state bits 0–6 of the statusword: bits 0,1,2,3,5,6 per the decoding table (bit 5, a
// don't-care in some states, is 0 there), bit 4 voltage enabled in every state but
// not_ready_to_switch_on (mains always present in the model). Golden values with bit 9
// remote: 0x0250 SOD, 0x0231 RTSO, 0x0233 SO, 0x0237 OE, 0x0217 QSA, 0x021F FRA, 0x0218 fault.
std::uint16_t state_bits(State s) noexcept;

// True while the power stage drives the motor (OE, QSA, FRA): torque possible, brake released.
bool power_stage_on(State s) noexcept;

// Transitions are reported by their fact-sheet numbers 0..16; this value means none.
inline constexpr std::uint8_t kNoTransition = 255;

// What the axis detected this period.
struct FsaEvents {
  bool fault = false;             // an error occurred (13)
  bool stop_finished = false;     // the quick stop / fault reaction deceleration is done
};

class Fsa {
 public:
  Fsa() = default;
  State state() const noexcept { return state_; }
  // One drive period: decodes the controlword (fault reset on the rising edge of bit 7),
  // applies up to three chained transitions (0+1, 3+4, 11+12 with quick stop option 0, 13+14
  // with fault reaction option 0). Returns the last one taken (kNoTransition when none). `qs_option` = 0x605A, `fr_option` = 0x605E.
  std::uint8_t step(std::uint16_t controlword, const FsaEvents& ev, std::int16_t qs_option,
                    std::int16_t fr_option) noexcept;
  // Every transition number taken in the last step, in order (at most three).
  const std::uint8_t* last_transitions(int& count) const noexcept {
    count = n_last_;
    return last_;
  }
  void reset() noexcept;  // power on: not_ready_to_switch_on
  void force(State s) noexcept { state_ = s; }  // tests only

 private:
  // One transition from state_ (or kNoTransition). `reset_edge`: bit 7 rose this period.
  std::uint8_t apply(FsaCommand cmd, bool reset_edge, const FsaEvents& ev, std::int16_t qs_option,
                     std::int16_t fr_option) noexcept;
  State state_ = State::not_ready_to_switch_on;
  bool unpowered_fault_ = false;  // transition 13 came from a state with the power stage off
  bool prev_reset_bit_ = true;  // a controlword with bit 7 already set at power-on is no edge
  std::uint8_t last_[3] = {255, 255, 255};
  int n_last_ = 0;
};

}  // namespace omnitwin::drive
