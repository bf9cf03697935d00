// bus_emulators/mechatrolink3 — a slave station's communication core: what its ASIC and
// communication firmware do before a command reaches the profile (servo, I/O). It answers
// the C1 master's link services (detection, the TR_DLY echo, cycle notification,
// communication start), runs the communication phases of seed 000 fig. 7 with CONNECT,
// SYNC_SET and DISCONNECT, refuses commands the phase does not allow (CMD_ALM phase error)
// and codes it does not know (unsupported), keeps the watchdog (WDT) and counts FCS errors,
// missing commands and missing sync frames into COMM_ALM as the profile does (from phase 2
// on; in phase 1 FCS errors are only counted in the stats): a warning the first time, an
// alarm the second time in a row, a WDT error at once; an alarm drops phase 3 to phase 2 and
// tells the application to stop (servo off), and until ALM_CLR clears it the commands the
// profile names (Profile::needs_alarm_cleared: a servo's SV_ON) are refused with CMD_ALM Ah.
// ALM_CLR clears COMM_ALM in phases 2 and 3 only.
//
// A powered slave answers every command frame addressed to it: CYC_NOTIFY and COMM_START are
// taken note of, and a slave that comes back after them (power returned) learns the
// transmission cycle from the interval of two SYNC frames, so the master can reconnect it.
//
// Shaped like the other protocol cores: frames and simulated time in, response frames out
// through a callback, no sockets, no clock, no allocation on the cyclic path. Fixed
// configuration (LinkConfig) apart from changing state. The profile is an interface the
// application implements (m3_servo, m3_io).
//
// Phases and what is legal in each (one flat switch over named transitions, transition()):
//   P5 powered off   -> power_on                    -> P1
//   P1 no connection -> CONNECT accepted             -> P2 (any mode)
//   P2 asynchronous  -> SYNC_SET (synchronous mode)  -> P3 ; DISCONNECT -> P1 (communication
//                       goes on: the slave waits for CONNECT again)
//   P3 synchronous   -> communication alarm          -> P2 ; DISCONNECT -> P1
//   any              -> power_off                    -> P5
// In P1 only NOP, CONNECT and DISCONNECT execute; INTERPOLATE needs P3 (allowed_in()), and so
// do the profile's own synchronous commands (Profile::synchronous_only()).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>

#include "bus_emulators/mechatrolink3/m3_command.hpp"
#include "bus_emulators/mechatrolink3/m3_frame.hpp"
#include "bus_emulators/mechatrolink3/m3_wire.hpp"

namespace omnitwin::m3 {

// What CONNECT negotiates (command bytes 4-7: VER, COM_MOD, COM_TIM, PROFILE_TYPE).
struct Connection {
  bool synchronous = true;     // COM_MOD bit 1 SYNCMODE
  bool subcommand = false;     // COM_MOD bit 7 SUBCMD (48-byte mode only)
  std::uint8_t com_tim = 1;    // communication cycle = transmission cycle × COM_TIM
  std::uint8_t profile = 0x10; // PROFILE_TYPE
  std::size_t data_bytes = 32; // the length the CONNECT frame came with
};
inline constexpr std::uint8_t kServoProfileVersion = 0x30;
inline constexpr std::uint8_t kComModSync = 0x02, kComModSubcommand = 0x80;
// COM_MOD bits 2-3 DTMODE (only 00b, single transfer, is built) and the reserved bits 0, 4-6.
inline constexpr std::uint8_t kComModDtMode = 0x0C, kComModReserved = 0x71;
// The communication cycle (transmission cycle × COM_TIM) a slave accepts: 0.125 ms … 32 ms,
// a typical servo's range (facts/mechatrolink3.md).
inline constexpr SimTime kMinCommCycleNs = 125'000, kMaxCommCycleNs = 32'000'000;

// The profile above the link (a servo, an I/O station). Called from the cyclic path: must
// not block or allocate.
class Profile {
 public:
  virtual ~Profile() = default;
  virtual std::uint8_t profile_type() const = 0;                 // 10h servo, 30h I/O
  virtual bool accepts_length(std::size_t data_bytes) const = 0;  // e.g. 32 and 48 for a servo
  // A profile command that is synchronous (phase 3 only, as INTERPOLATE): e.g. I/O DATA_RWS.
  virtual bool synchronous_only(Command) const { return false; }
  // A command refused (CMD_ALM Ah) while COMM_ALM holds an alarm, until ALM_CLR clears it: a
  // communication alarm is the device's alarm too (e.g. a servo's SV_ON).
  virtual bool needs_alarm_cleared(Command) const { return false; }
  // Executes a command allowed in the current phase (not NOP, CONNECT, DISCONNECT, SYNC_SET,
  // which the link handles). cmd is the whole information field; rsp (same length) arrives
  // with its header written and the rest zero; `t` is when the command arrived [ns].
  virtual CmdAlarm execute(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp,
                           SimTime t) = 0;
  // A subcommand of the 48-byte mode (allowed with this main command): sub and rsp are the
  // 16-byte regions (byte 0 SUB_CMD / SUB_RCMD, 1-3 SUB_CTRL / SUB_STAT written by the link).
  virtual CmdAlarm execute_sub(Command, std::span<const std::uint8_t>, std::span<std::uint8_t>) {
    return CmdAlarm::unsupported;
  }
  // ALM_CLR for the device: the command ALM_CLR, or CMD_CTRL.ALM_CLR rising. The link clears
  // COMM_ALM itself; a profile resets its device alarm (D_ALM) here.
  virtual void clear_alarms() {}
  // A communication alarm stopped cyclic operation: servo off.
  virtual void stop(SimTime t) = 0;
  // DISCONNECT ended the connection: after it the slave's state is unknown to the master, which
  // starts again with CONNECT (seed 000 fig. 8). At least what stop() does; a profile also
  // forgets what the connection set up (a servo: encoder, POS_SET, home).
  virtual void disconnect(SimTime t) { stop(t); }
  virtual bool device_alarm() const { return false; }    // CMD_STAT.D_ALM
  virtual bool device_warning() const { return false; }  // CMD_STAT.D_WAR
  virtual bool ready() const { return true; }            // CMD_STAT.CMDRDY
};

struct LinkConfig {
  std::uint8_t address = kFirstSlave;
  SimTime response_ns = 2'000;   // command's last bit → response's first bit
  std::uint32_t vendor_id = 0;   // in DETECT_RPL (ours: vendor u32, device code u16, profile u8, 0)
  std::uint16_t device_code = 0;
};

// Counters a test, the twin's metrics and the report read.
struct LinkStats {
  std::uint64_t commands = 0, responses = 0, fcs_errors = 0, bad_frames = 0, not_for_me = 0;
  std::uint64_t missed_commands = 0, missed_syncs = 0, wdt_errors = 0, phase_errors = 0, unsupported = 0;
  // Profile commands not executed because their length is not the connection's (CMD_ALM 9h).
  std::uint64_t length_errors = 0;
  std::uint64_t comm_alarms = 0;  // COMM_ALM alarms (8h-Ch) raised
  std::uint64_t repeated = 0;     // retries of the last command answered from its stored response
};

class SlaveLink {
 public:
  // emit(frame, t_send): a frame this station sends, starting at t_send [ns].
  using Emit = std::function<void(std::span<const std::uint8_t>, SimTime)>;
  SlaveLink(const LinkConfig& config, Profile& profile, Emit emit);

  // A frame fully received at t [ns] (bytes as the line delivered them, FCS included).
  // Real-time safe.
  void on_frame(std::span<const std::uint8_t> bytes, SimTime t);
  // Time passes to t [ns]: in phase 3, a missing SYNC is noticed here (1.5 transmission cycles
  // after the last one, then every cycle); a missing command when the next communication
  // cycle's SYNC comes. Real-time safe.
  void advance(SimTime t);
  void power_on(SimTime t);
  void power_off(SimTime t);

  Phase phase() const { return s_.phase; }
  const Connection& connection() const { return s_.conn; }
  CommAlarm comm_alarm() const { return s_.comm_alm; }
  CmdAlarm cmd_alarm() const { return s_.cmd_alm; }
  SimTime transmission_cycle_ns() const { return s_.cycle_ns; }
  bool communication_started() const { return s_.started; }
  const LinkStats& stats() const { return s_.stats; }  // since the last power-on
  std::uint8_t address() const { return cfg_.address; }

 private:
  enum class Transition : std::uint8_t { power_on, connect, sync_set, disconnect, comm_alarm, power_off };
  void transition(Transition tr, SimTime t);
  void on_link_service(const FrameView& f, SimTime t);
  void on_command(const FrameView& f, SimTime t);
  CmdAlarm run_link_command(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, SimTime t);
  void run_subcommand(Command main, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp);
  CmdAlarm connect(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, SimTime t);
  void check_watchdog(std::uint8_t wdt, SimTime t);
  void on_sync(SimTime t);
  void raise(CommAlarm a, SimTime t);
  void count_miss(bool sync, SimTime t);
  void reply(FrameType type, std::span<const std::uint8_t> data, std::uint8_t sequence, SimTime t);

  LinkConfig cfg_;
  Profile& profile_;
  Emit emit_;
  // Changing state; power-on resets all of it (State{}).
  struct State {
    Phase phase = Phase::p5;
    Connection conn;
    SimTime cycle_ns = 0;             // transmission cycle (CYC_NOTIFY), 0: not told
    bool started = false;             // COMM_START seen (noted; commands are answered anyway)
    CommAlarm comm_alm = CommAlarm::normal;
    CmdAlarm cmd_alm = CmdAlarm::normal;
    SimTime last_sync = -1, last_command = -1, next_check = -1;
    int sync_misses = 0, command_misses = 0, fcs_in_row = 0;
    std::uint8_t last_wdt = 0, own_count = 0;
    bool wdt_seen = false;
    bool alm_clr_bit = false;         // CMD_CTRL.ALM_CLR of the last command (a clear on its rising edge)
    int last_sequence = -1;           // of the command last executed (it is in cmd_, its response in rsp_)
    bool cycle_open = false;          // phase 3: a communication cycle was opened by a SYNC
    bool commanded = false;           // and a command has come in it
    std::uint32_t syncs = 0;          // SYNCs since phase 3 (COM_TIM of them per communication cycle)
    std::size_t last_length = 0;
    LinkStats stats;
  } s_;
  std::array<std::uint8_t, kMaxFrame> out_{};
  std::array<std::uint8_t, kMaxData> cmd_{}, rsp_{};
};

}  // namespace omnitwin::m3
