// bus_emulators/ethercat — the EtherCAT application-layer (AL) state machine of one slave.
//
// A pure decision function: given the current state, the error flag and a write to AL control
// (0x0120), it says which transition the master asked for and what the ESC does. The Esc asks
// the slave firmware (EscApplication::on_al_request) for legal transitions and applies the
// result; keeping the table here makes it testable without an ESC.
//
// States and legal transitions (AlState):
//   INIT    → PRE-OP, BOOT
//   PRE-OP  → INIT, SAFE-OP
//   SAFE-OP → INIT, PRE-OP, OP
//   OP      → INIT, PRE-OP, SAFE-OP
//   BOOT    → INIT
//   any state → itself (accepted, nothing to do)
// Everything else (e.g. INIT → OP, PRE-OP → OP, PRE-OP → BOOT) is refused with 0x0011 invalid
// state change; a requested value outside {1, 2, 3, 4, 8} with 0x0012 unknown state. A refused
// request sets the error flag (AL status bit 4) and the state stays.
// While the error flag is set, a request without the acknowledge bit (0x0120 bit 4) is ignored,
// except a request for INIT, which acknowledges the error as the bit does (the slave stack's
// "error acknowledge with 0xX1 is allowed"). With either, the flag and the code are cleared and
// the request is then evaluated.
#pragma once

#include <cstdint>

namespace omnitwin::ethercat {

enum class AlState : std::uint8_t { init = 1, preop = 2, boot = 3, safeop = 4, op = 8 };

enum class AlStatusCode : std::uint16_t {
  none = 0,
  unspecified = 0x0001,
  no_memory = 0x0002,
  invalid_state_change = 0x0011,
  unknown_state = 0x0012,
  bootstrap_not_supported = 0x0013,
  no_valid_firmware = 0x0014,
  invalid_mailbox_config_boot = 0x0015,
  invalid_mailbox_config = 0x0016,
  invalid_sm_config = 0x0017,
  no_valid_inputs = 0x0018,
  no_valid_outputs = 0x0019,
  synchronization_error = 0x001A,
  watchdog = 0x001B,
  invalid_sync_manager_types = 0x001C,
  invalid_output_config = 0x001D,
  invalid_input_config = 0x001E,
  invalid_watchdog_config = 0x001F,
  cold_start_needed = 0x0020,
  init_needed = 0x0021,
  preop_needed = 0x0022,
  safeop_needed = 0x0023,
  invalid_dc_sync_config = 0x0030,
  invalid_dc_latch_config = 0x0031,
  pll_error = 0x0032,
  dc_sync_io_error = 0x0033,
  dc_sync_timeout = 0x0034,
  dc_invalid_sync_cycle_time = 0x0035,
  dc_sync0_cycle_time = 0x0036,
  dc_sync1_cycle_time = 0x0037,
};

const char* to_string(AlState);       // "INIT", "PRE-OP", "BOOT", "SAFE-OP", "OP"
const char* to_string(AlStatusCode);  // "invalid state change", …; "?" for unlisted codes

// Rank for "lower/higher" comparisons: INIT 0, PRE-OP 1, BOOT 1, SAFE-OP 2, OP 3.
int al_rank(AlState) noexcept;
bool al_state_valid(std::uint8_t v) noexcept;  // v in {1, 2, 3, 4, 8}

// What one AL control write asks for (after the error/acknowledge rules).
enum class AlTransition : std::uint8_t {
  ignored,        // error pending and no acknowledge: nothing changes
  stay,           // request for the current state: accepted, nothing to ask the firmware
  legal,          // a legal transition current → target: ask the firmware
  invalid,        // refused: invalid state change (0x0011)
  unknown_state,  // refused: unknown requested state (0x0012)
};

struct AlDecision {
  AlTransition transition = AlTransition::ignored;
  AlState target = AlState::init;  // meaningful for stay/legal
  bool clear_error = false;        // the acknowledge bit cleared the error flag and code
};

// One AL control write. Pure; real-time safe.
AlDecision al_decide(AlState current, bool error, std::uint16_t control) noexcept;

// True when from → to is one of the legal transitions listed above (from == to included).
bool al_transition_legal(AlState from, AlState to) noexcept;

}  // namespace omnitwin::ethercat
