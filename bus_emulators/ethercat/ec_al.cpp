// bus_emulators/ethercat — AL state machine decisions (see ec_al.hpp).
#include "bus_emulators/ethercat/ec_al.hpp"

namespace omnitwin::ethercat {

const char* to_string(AlState s) {
  switch (s) {
    case AlState::init: return "INIT";
    case AlState::preop: return "PRE-OP";
    case AlState::boot: return "BOOT";
    case AlState::safeop: return "SAFE-OP";
    case AlState::op: return "OP";
  }
  return "?";
}

const char* to_string(AlStatusCode c) {
  switch (c) {
    case AlStatusCode::none: return "no error";
    case AlStatusCode::unspecified: return "unspecified error";
    case AlStatusCode::no_memory: return "no memory";
    case AlStatusCode::invalid_state_change: return "invalid requested state change";
    case AlStatusCode::unknown_state: return "unknown requested state";
    case AlStatusCode::bootstrap_not_supported: return "bootstrap not supported";
    case AlStatusCode::no_valid_firmware: return "no valid firmware";
    case AlStatusCode::invalid_mailbox_config_boot: return "invalid mailbox configuration (BOOT)";
    case AlStatusCode::invalid_mailbox_config: return "invalid mailbox configuration";
    case AlStatusCode::invalid_sm_config: return "invalid sync manager configuration";
    case AlStatusCode::no_valid_inputs: return "no valid inputs available";
    case AlStatusCode::no_valid_outputs: return "no valid outputs";
    case AlStatusCode::synchronization_error: return "synchronization error";
    case AlStatusCode::watchdog: return "sync manager watchdog";
    case AlStatusCode::invalid_sync_manager_types: return "invalid sync manager types";
    case AlStatusCode::invalid_output_config: return "invalid output configuration";
    case AlStatusCode::invalid_input_config: return "invalid input configuration";
    case AlStatusCode::invalid_watchdog_config: return "invalid watchdog configuration";
    case AlStatusCode::cold_start_needed: return "slave needs cold start";
    case AlStatusCode::init_needed: return "slave needs INIT";
    case AlStatusCode::preop_needed: return "slave needs PRE-OP";
    case AlStatusCode::safeop_needed: return "slave needs SAFE-OP";
    case AlStatusCode::invalid_dc_sync_config: return "invalid DC sync configuration";
    case AlStatusCode::invalid_dc_latch_config: return "invalid DC latch configuration";
    case AlStatusCode::pll_error: return "PLL error";
    case AlStatusCode::dc_sync_io_error: return "DC sync IO error";
    case AlStatusCode::dc_sync_timeout: return "DC sync timeout";
    case AlStatusCode::dc_invalid_sync_cycle_time: return "DC invalid sync cycle time";
    case AlStatusCode::dc_sync0_cycle_time: return "DC SYNC0 cycle time";
    case AlStatusCode::dc_sync1_cycle_time: return "DC SYNC1 cycle time";
  }
  return "?";
}

int al_rank(AlState s) noexcept {
  switch (s) {
    case AlState::init: return 0;
    case AlState::preop: return 1;
    case AlState::boot: return 1;
    case AlState::safeop: return 2;
    case AlState::op: return 3;
  }
  return 0;
}

bool al_state_valid(std::uint8_t v) noexcept { return v == 1 || v == 2 || v == 3 || v == 4 || v == 8; }

namespace {

// The named transitions: (from << 4) | to.
enum class Named : std::uint8_t {
  init_preop = 0x12, init_boot = 0x13,
  preop_init = 0x21, preop_safeop = 0x24,
  boot_init = 0x31,
  safeop_init = 0x41, safeop_preop = 0x42, safeop_op = 0x48,
  op_init = 0x81, op_preop = 0x82, op_safeop = 0x84,
};

}  // namespace

bool al_transition_legal(AlState from, AlState to) noexcept {
  if (from == to) return true;
  const auto key = static_cast<Named>((static_cast<unsigned>(from) << 4) | static_cast<unsigned>(to));
  switch (key) {
    case Named::init_preop:
    case Named::init_boot:
    case Named::preop_init:
    case Named::preop_safeop:
    case Named::boot_init:
    case Named::safeop_init:
    case Named::safeop_preop:
    case Named::safeop_op:
    case Named::op_init:
    case Named::op_preop:
    case Named::op_safeop:
      return true;
  }
  return false;  // INIT→SAFE-OP, INIT→OP, PRE-OP→OP, PRE-OP→BOOT, SAFE-OP→BOOT, OP→BOOT, BOOT→…
}

AlDecision al_decide(AlState current, bool error, std::uint16_t control) noexcept {
  AlDecision d;
  const bool ack = (control & 0x10) != 0;
  const auto req = static_cast<std::uint8_t>(control & 0x0F);
  if (error && !ack && req != static_cast<std::uint8_t>(AlState::init)) {
    d.transition = AlTransition::ignored;
    return d;
  }
  // A request for INIT acknowledges the error too (Beckhoff's slave stack: "Error Acknowledge
  // with 0xX1 is allowed"), so a master that writes 0x0001 finds INIT without the flag, as on
  // real slaves (it kept the flag and the old code; found by a protocol review).
  d.clear_error = error && (ack || req == static_cast<std::uint8_t>(AlState::init));
  if (!al_state_valid(req)) {
    d.transition = AlTransition::unknown_state;
    return d;
  }
  d.target = static_cast<AlState>(req);
  if (d.target == current) {
    d.transition = AlTransition::stay;
  } else if (al_transition_legal(current, d.target)) {
    d.transition = AlTransition::legal;
  } else {
    d.transition = AlTransition::invalid;
  }
  return d;
}

}  // namespace omnitwin::ethercat
