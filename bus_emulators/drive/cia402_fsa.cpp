// bus_emulators/drive — the CiA 402 power drive state machine (see cia402_fsa.hpp).
#include "bus_emulators/drive/cia402_fsa.hpp"

namespace omnitwin::drive {

const char* to_string(State s) {
  switch (s) {
    case State::not_ready_to_switch_on: return "not ready to switch on";
    case State::switch_on_disabled: return "switch on disabled";
    case State::ready_to_switch_on: return "ready to switch on";
    case State::switched_on: return "switched on";
    case State::operation_enabled: return "operation enabled";
    case State::quick_stop_active: return "quick stop active";
    case State::fault_reaction_active: return "fault reaction active";
    case State::fault: return "fault";
  }
  return "?";
}

const char* to_string(FsaCommand c) {
  switch (c) {
    case FsaCommand::none: return "none";
    case FsaCommand::shutdown: return "shutdown";
    case FsaCommand::switch_on: return "switch on";
    case FsaCommand::enable_operation: return "enable operation";
    case FsaCommand::disable_voltage: return "disable voltage";
    case FsaCommand::quick_stop: return "quick stop";
  }
  return "?";
}

FsaCommand decode_controlword(std::uint16_t c) noexcept {
  if (c & cw::fault_reset) return FsaCommand::none;                 // 1----
  if (!(c & cw::enable_voltage)) return FsaCommand::disable_voltage;  // 0--0-
  if (!(c & cw::quick_stop)) return FsaCommand::quick_stop;           // 0-01-
  if (!(c & cw::switch_on)) return FsaCommand::shutdown;              // 0-110
  if (!(c & cw::enable_operation)) return FsaCommand::switch_on;      // 00111
  return FsaCommand::enable_operation;                                // 01111
}

State decode_statusword(std::uint16_t s) noexcept {
  // Bits 6,5,3,2,1,0 per the fact sheet's table; '-' positions masked out.
  const std::uint16_t b = s & 0x6F;
  if ((b & 0x4F) == 0x00) return State::not_ready_to_switch_on;  // 0-0000
  if ((b & 0x4F) == 0x40) return State::switch_on_disabled;      // 1-0000
  if (b == 0x21) return State::ready_to_switch_on;               // 010001
  if (b == 0x23) return State::switched_on;                      // 010011
  if (b == 0x27) return State::operation_enabled;                // 010111
  if (b == 0x07) return State::quick_stop_active;                // 000111
  if ((b & 0x4F) == 0x0F) return State::fault_reaction_active;   // 0-1111
  if ((b & 0x4F) == 0x08) return State::fault;                   // 0-1000
  return State::not_ready_to_switch_on;
}

std::uint16_t state_bits(State s) noexcept {
  switch (s) {
    case State::not_ready_to_switch_on: return 0x0000;
    case State::switch_on_disabled: return 0x0050;
    case State::ready_to_switch_on: return 0x0031;
    case State::switched_on: return 0x0033;
    case State::operation_enabled: return 0x0037;
    case State::quick_stop_active: return 0x0017;
    case State::fault_reaction_active: return 0x001F;
    case State::fault: return 0x0018;
  }
  return 0;
}

bool power_stage_on(State s) noexcept {
  return s == State::operation_enabled || s == State::quick_stop_active ||
         s == State::fault_reaction_active;
}

void Fsa::reset() noexcept {
  state_ = State::not_ready_to_switch_on;
  unpowered_fault_ = false;
  prev_reset_bit_ = true;
  n_last_ = 0;
}

std::uint8_t Fsa::step(std::uint16_t controlword, const FsaEvents& ev, std::int16_t qs_option,
                       std::int16_t fr_option) noexcept {
  const bool bit7 = (controlword & cw::fault_reset) != 0;
  bool reset_edge = bit7 && !prev_reset_bit_;
  prev_reset_bit_ = bit7;
  const FsaCommand cmd = decode_controlword(controlword);
  n_last_ = 0;
  FsaEvents e = ev;
  std::uint8_t last = kNoTransition;
  if (state_ == State::not_ready_to_switch_on) last_[n_last_++] = 0;  // self test done
  for (int i = 0; i < 3 && n_last_ < 3; ++i) {
    const std::uint8_t t = apply(cmd, reset_edge, e, qs_option, fr_option);
    if (t == kNoTransition) break;
    last_[n_last_++] = t;
    last = t;
    e.fault = false;  // one error, one transition 13
    reset_edge = false;
    // Only these chain within one period: 3+4 (switch on + enable operation), 11+12 (quick
    // stop option 0), 13+14 (fault reaction option 0).
    const bool chain = (t == 3 && cmd == FsaCommand::enable_operation) ||
                       (t == 11 && qs_option == 0) || (t == 13 && (fr_option == 0 || unpowered_fault_));
    if (!chain) break;
  }
  return last;
}

std::uint8_t Fsa::apply(FsaCommand cmd, bool reset_edge, const FsaEvents& ev,
                        std::int16_t qs_option, std::int16_t fr_option) noexcept {
  if (ev.fault && state_ != State::fault && state_ != State::fault_reaction_active &&
      state_ != State::not_ready_to_switch_on) {
    // With the power stage off there is no motion to stop: the reaction is complete at once
    // (13 and 14 in one period), so the power stage is never switched on for a reaction (a
    // fault in SWITCHED ON released the brake for a period; found by a protocol review).
    unpowered_fault_ = !power_stage_on(state_);
    state_ = State::fault_reaction_active;
    return 13;
  }
  switch (state_) {
    case State::not_ready_to_switch_on:
      // 0 (self test done) and 1 (auto) in the first period: the model has no self test.
      state_ = State::switch_on_disabled;
      return 1;
    case State::switch_on_disabled:
      if (cmd == FsaCommand::shutdown) { state_ = State::ready_to_switch_on; return 2; }
      return kNoTransition;
    case State::ready_to_switch_on:
      if (cmd == FsaCommand::switch_on || cmd == FsaCommand::enable_operation) {
        state_ = State::switched_on;
        return 3;
      }
      if (cmd == FsaCommand::disable_voltage || cmd == FsaCommand::quick_stop) {
        state_ = State::switch_on_disabled;
        return 7;
      }
      return kNoTransition;
    case State::switched_on:
      if (cmd == FsaCommand::enable_operation) { state_ = State::operation_enabled; return 4; }
      if (cmd == FsaCommand::shutdown) { state_ = State::ready_to_switch_on; return 6; }
      if (cmd == FsaCommand::disable_voltage || cmd == FsaCommand::quick_stop) {
        state_ = State::switch_on_disabled;
        return 10;
      }
      return kNoTransition;
    case State::operation_enabled:
      if (cmd == FsaCommand::switch_on) { state_ = State::switched_on; return 5; }
      if (cmd == FsaCommand::shutdown) { state_ = State::ready_to_switch_on; return 8; }
      if (cmd == FsaCommand::disable_voltage) { state_ = State::switch_on_disabled; return 9; }
      if (cmd == FsaCommand::quick_stop) { state_ = State::quick_stop_active; return 11; }
      return kNoTransition;
    case State::quick_stop_active: {
      const bool holds = qs_option >= 5 && qs_option <= 8;
      if (cmd == FsaCommand::disable_voltage) { state_ = State::switch_on_disabled; return 12; }
      if (!holds && (qs_option == 0 || ev.stop_finished)) {
        state_ = State::switch_on_disabled;
        return 12;
      }
      if (holds && cmd == FsaCommand::enable_operation) {
        state_ = State::operation_enabled;
        return 16;
      }
      return kNoTransition;
    }
    case State::fault_reaction_active:
      if (fr_option == 0 || ev.stop_finished || unpowered_fault_) {
        state_ = State::fault;
        unpowered_fault_ = false;
        return 14;
      }
      return kNoTransition;
    case State::fault:
      if (reset_edge) { state_ = State::switch_on_disabled; return 15; }
      return kNoTransition;
  }
  return kNoTransition;
}

}  // namespace omnitwin::drive
