// bus_emulators/mechatrolink3 — the application layer's common part: command codes, the
// command header every command and response starts with, and the status codes a slave
// answers with. Shared by the slaves, our C1 master and the dissector.
//
// Layout of an information field (the public MECHATROLINK-III command format of the
// standard servo profile; facts/mechatrolink3.md lists the codes):
//   command:  byte 0 CMD code, byte 1 WDT, bytes 2-3 CMD_CTRL, bytes 4… command data
//   response: byte 0 RCMD (the command echoed), byte 1 RWDT, bytes 2-3 CMD_STAT, bytes 4… data
//   48-byte mode: bytes 32-47 are the subcommand region (byte 32 SUB_CMD, 33-35 SUB_CTRL or
//   SUB_STAT, 36-47 data).
// CMD_CTRL: bit 3 ALM_CLR, bits 6-7 CMD_ID. CMD_STAT: bit 0 D_ALM, bit 1 D_WAR, bit 2
// CMDRDY, bit 3 ALM_CLR_CMP, bits 6-7 RCMD_ID, bits 8-11 CMD_ALM, bits 12-15 COMM_ALM; the
// CMD_ALM and COMM_ALM codes are the profile's (values 1-7 warnings, 8-F alarms). Multi-byte
// fields are little endian. WDT/RWDT are ours (docs/protocols/mechatrolink3.md): WDT bits 4-7
// are the master's count, advanced every communication cycle; RWDT bits 4-7 echo the count
// the slave last received and bits 0-3 are the slave's own count.
// Pure codec: no sockets, no time, no allocation, no throw.
#pragma once

#include <cstdint>
#include <span>

namespace omnitwin::m3 {

// Main command codes of the standard servo profile (common commands 00h-1Fh, servo 20h-).
enum class Command : std::uint8_t {
  nop = 0x00, id_rd = 0x03, config = 0x04, alm_rd = 0x05, alm_clr = 0x06, sync_set = 0x0D,
  connect = 0x0E, disconnect = 0x0F, mem_rd = 0x1D, mem_wr = 0x1E, pos_set = 0x20, brk_on = 0x21,
  brk_off = 0x22, sens_on = 0x23, sens_off = 0x24, smon = 0x30, sv_on = 0x31, sv_off = 0x32,
  interpolate = 0x34, posing = 0x35, feed = 0x36, ex_posing = 0x39, zret = 0x3A, velctrl = 0x3C,
  trqctrl = 0x3D, svprm_rd = 0x40, svprm_wr = 0x41,
};
const char* to_string(Command);  // "NOP", "VELCTRL", …; "?" for codes the profile lacks
bool is_known(Command) noexcept;
// Subcommands the 48-byte mode allows (NOP, ALM_RD, ALM_CLR, MEM_RD, MEM_WR, SMON, SVPRM_RD/WR).
bool is_subcommand(Command) noexcept;
// Whether subcommand `sub` may go with main command `main` (profile: the common commands
// other than NOP and ID_RD take only the NOP subcommand; NOP, ID_RD and the servo commands
// take every subcommand). Real-time safe.
bool combines(Command main, Command sub) noexcept;
// The common commands that keep the common format: their fields start at byte 4 and their
// answers carry no servo status (ID_RD, CONFIG, ALM_RD, ALM_CLR, MEM_RD, MEM_WR). Real-time safe.
bool common_format(Command c) noexcept;


// CMD_STAT.CMD_ALM: how the slave judged the command (profile codes).
enum class CmdAlarm : std::uint8_t {
  normal = 0x0,
  invalid_data_warning = 0x1,   // executed with the value clamped
  unsupported = 0x8,            // unknown command: not executed
  invalid_data = 0x9,           // not executed
  condition_error = 0xA,        // execution condition not met (e.g. SV_ON with the sensor off)
  subcommand_combination = 0xB, // this subcommand cannot go with this main command
  phase_error = 0xC,            // the command is not allowed in the current phase
};
// CMD_STAT.COMM_ALM: the communication's health (profile codes).
enum class CommAlarm : std::uint8_t {
  normal = 0x0,
  fcs_warning = 0x1, no_command_warning = 0x2, no_sync_warning = 0x3,  // once
  fcs = 0x8, no_command = 0x9, no_sync = 0xA,                          // twice in a row
  sync_interval = 0xB, wdt = 0xC,                                      // at once
};
const char* to_string(CmdAlarm);
const char* to_string(CommAlarm);
bool is_alarm(CmdAlarm) noexcept;   // 8h-Fh: not a warning
bool is_alarm(CommAlarm) noexcept;

// SUB_STAT (response bytes 33-35, 24 bits; ours after CMD_STAT): bit 2 SBCMDRDY, bits 8-11
// SUBCMD_ALM (CmdAlarm codes).
std::uint32_t pack_sub_stat(bool ready, CmdAlarm alarm) noexcept;
CmdAlarm sub_alarm(std::uint32_t sub_stat) noexcept;

struct CmdCtrl {
  bool alm_clr = false;
  std::uint8_t cmd_id = 0;  // 0 … 3
};
struct CmdStat {
  bool d_alm = false, d_war = false, cmdrdy = true, alm_clr_cmp = false;
  std::uint8_t rcmd_id = 0;  // 0 … 3
  CmdAlarm cmd_alm = CmdAlarm::normal;
  CommAlarm comm_alm = CommAlarm::normal;
};
std::uint16_t pack(const CmdCtrl&) noexcept;
CmdCtrl unpack_ctrl(std::uint16_t) noexcept;
std::uint16_t pack(const CmdStat&) noexcept;
CmdStat unpack_stat(std::uint16_t) noexcept;

// The header bytes 0-3 of a command or response.
inline constexpr std::size_t kCommandHeader = 4, kSubcommandOffset = 32;
struct CommandHeader {
  std::uint8_t code = 0;  // CMD or RCMD (a raw byte: unknown codes must be answerable)
  std::uint8_t wdt = 0;   // WDT or RWDT
  std::uint16_t ctrl = 0; // CMD_CTRL or CMD_STAT
};
// Reads the header; false if the field is shorter than 4 bytes. Real-time safe.
bool read_header(std::span<const std::uint8_t> field, CommandHeader& out) noexcept;
// Writes the header into the first 4 bytes; false if the field is shorter. Real-time safe.
bool write_header(std::span<std::uint8_t> field, const CommandHeader& h) noexcept;

// Little-endian field access inside an information field (callers check the size).
std::uint16_t get_u16(std::span<const std::uint8_t> f, std::size_t at) noexcept;
std::int32_t get_i32(std::span<const std::uint8_t> f, std::size_t at) noexcept;
std::uint32_t get_u32(std::span<const std::uint8_t> f, std::size_t at) noexcept;
void put_u16(std::span<std::uint8_t> f, std::size_t at, std::uint16_t v) noexcept;
void put_i32(std::span<std::uint8_t> f, std::size_t at, std::int32_t v) noexcept;
void put_u32(std::span<std::uint8_t> f, std::size_t at, std::uint32_t v) noexcept;

// Communication phases of a slave (seed 000 fig. 7): 1 waiting for CONNECT, 2 asynchronous
// commands only, 3 synchronous (all commands; cyclic mode only), 5 powered off.
enum class Phase : std::uint8_t { p1 = 1, p2 = 2, p3 = 3, p5 = 5 };
// Whether `c` may be executed in phase p: NOP and DISCONNECT in phases 1-3; CONNECT in phase 1
// only (ours: a connected slave is released by DISCONNECT first, as the start-up sequence of
// seed 000 fig. 8 does); INTERPOLATE in phase 3 only; every other command in phases 2 and 3.
// Nothing in phase 5 (no power). Real-time safe.
bool allowed_in(Command c, Phase p) noexcept;

}  // namespace omnitwin::m3
