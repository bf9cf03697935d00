// bus_emulators/mechatrolink3 — command codes and header codec; see m3_command.hpp.
#include "bus_emulators/mechatrolink3/m3_command.hpp"

#include <cstring>

namespace omnitwin::m3 {

const char* to_string(Command c) {
  switch (c) {
    case Command::nop: return "NOP";
    case Command::id_rd: return "ID_RD";
    case Command::config: return "CONFIG";
    case Command::alm_rd: return "ALM_RD";
    case Command::alm_clr: return "ALM_CLR";
    case Command::sync_set: return "SYNC_SET";
    case Command::connect: return "CONNECT";
    case Command::disconnect: return "DISCONNECT";
    case Command::mem_rd: return "MEM_RD";
    case Command::mem_wr: return "MEM_WR";
    case Command::pos_set: return "POS_SET";
    case Command::brk_on: return "BRK_ON";
    case Command::brk_off: return "BRK_OFF";
    case Command::sens_on: return "SENS_ON";
    case Command::sens_off: return "SENS_OFF";
    case Command::smon: return "SMON";
    case Command::sv_on: return "SV_ON";
    case Command::sv_off: return "SV_OFF";
    case Command::interpolate: return "INTERPOLATE";
    case Command::posing: return "POSING";
    case Command::feed: return "FEED";
    case Command::ex_posing: return "EX_POSING";
    case Command::zret: return "ZRET";
    case Command::velctrl: return "VELCTRL";
    case Command::trqctrl: return "TRQCTRL";
    case Command::svprm_rd: return "SVPRM_RD";
    case Command::svprm_wr: return "SVPRM_WR";
  }
  return "?";
}

bool is_known(Command c) noexcept { return std::strcmp(to_string(c), "?") != 0; }

bool is_subcommand(Command c) noexcept {
  switch (c) {
    case Command::nop:
    case Command::alm_rd:
    case Command::alm_clr:
    case Command::mem_rd:
    case Command::mem_wr:
    case Command::smon:
    case Command::svprm_rd:
    case Command::svprm_wr: return true;
    default: return false;
  }
}

bool common_format(Command c) noexcept {
  return c == Command::id_rd || c == Command::config || c == Command::alm_rd || c == Command::alm_clr ||
         c == Command::mem_rd || c == Command::mem_wr;
}

bool combines(Command main, Command sub) noexcept {
  if (sub == Command::nop) return true;
  if (!is_subcommand(sub)) return false;
  const auto code = static_cast<std::uint8_t>(main);
  return main == Command::nop || main == Command::id_rd || code >= 0x20;
}

std::uint32_t pack_sub_stat(bool ready, CmdAlarm alarm) noexcept {
  return (ready ? 0x4u : 0u) | ((static_cast<std::uint32_t>(alarm) & 0xF) << 8);
}

CmdAlarm sub_alarm(std::uint32_t sub_stat) noexcept { return static_cast<CmdAlarm>((sub_stat >> 8) & 0xF); }

const char* to_string(CmdAlarm a) {
  switch (a) {
    case CmdAlarm::normal: return "normal";
    case CmdAlarm::invalid_data_warning: return "invalid data (warning)";
    case CmdAlarm::unsupported: return "unsupported command";
    case CmdAlarm::invalid_data: return "invalid data";
    case CmdAlarm::condition_error: return "command execution condition error";
    case CmdAlarm::subcommand_combination: return "subcommand combination error";
    case CmdAlarm::phase_error: return "phase error";
  }
  return "?";
}

const char* to_string(CommAlarm a) {
  switch (a) {
    case CommAlarm::normal: return "normal";
    case CommAlarm::fcs_warning: return "FCS error (warning)";
    case CommAlarm::no_command_warning: return "command data not received (warning)";
    case CommAlarm::no_sync_warning: return "synchronous frame not received (warning)";
    case CommAlarm::fcs: return "FCS error";
    case CommAlarm::no_command: return "command data not received";
    case CommAlarm::no_sync: return "synchronous frame not received";
    case CommAlarm::sync_interval: return "synchronization interval error";
    case CommAlarm::wdt: return "WDT error";
  }
  return "?";
}

bool is_alarm(CmdAlarm a) noexcept { return static_cast<std::uint8_t>(a) >= 0x8; }
bool is_alarm(CommAlarm a) noexcept { return static_cast<std::uint8_t>(a) >= 0x8; }

std::uint16_t pack(const CmdCtrl& c) noexcept {
  return static_cast<std::uint16_t>((c.alm_clr ? 0x0008 : 0) | ((c.cmd_id & 0x3) << 6));
}

CmdCtrl unpack_ctrl(std::uint16_t v) noexcept {
  return CmdCtrl{(v & 0x0008) != 0, static_cast<std::uint8_t>((v >> 6) & 0x3)};
}

std::uint16_t pack(const CmdStat& s) noexcept {
  return static_cast<std::uint16_t>((s.d_alm ? 0x1 : 0) | (s.d_war ? 0x2 : 0) | (s.cmdrdy ? 0x4 : 0) |
                                    (s.alm_clr_cmp ? 0x8 : 0) | ((s.rcmd_id & 0x3) << 6) |
                                    ((static_cast<unsigned>(s.cmd_alm) & 0xF) << 8) |
                                    ((static_cast<unsigned>(s.comm_alm) & 0xF) << 12));
}

CmdStat unpack_stat(std::uint16_t v) noexcept {
  CmdStat s;
  s.d_alm = (v & 0x1) != 0;
  s.d_war = (v & 0x2) != 0;
  s.cmdrdy = (v & 0x4) != 0;
  s.alm_clr_cmp = (v & 0x8) != 0;
  s.rcmd_id = static_cast<std::uint8_t>((v >> 6) & 0x3);
  s.cmd_alm = static_cast<CmdAlarm>((v >> 8) & 0xF);
  s.comm_alm = static_cast<CommAlarm>((v >> 12) & 0xF);
  return s;
}

std::uint16_t get_u16(std::span<const std::uint8_t> f, std::size_t at) noexcept {
  return static_cast<std::uint16_t>(f[at] | (f[at + 1] << 8));
}

std::int32_t get_i32(std::span<const std::uint8_t> f, std::size_t at) noexcept {
  const std::uint32_t v = static_cast<std::uint32_t>(f[at]) | (static_cast<std::uint32_t>(f[at + 1]) << 8) |
                          (static_cast<std::uint32_t>(f[at + 2]) << 16) | (static_cast<std::uint32_t>(f[at + 3]) << 24);
  return static_cast<std::int32_t>(v);
}

std::uint32_t get_u32(std::span<const std::uint8_t> f, std::size_t at) noexcept {
  return static_cast<std::uint32_t>(get_i32(f, at));
}

void put_u32(std::span<std::uint8_t> f, std::size_t at, std::uint32_t v) noexcept {
  put_i32(f, at, static_cast<std::int32_t>(v));
}

void put_u16(std::span<std::uint8_t> f, std::size_t at, std::uint16_t v) noexcept {
  f[at] = static_cast<std::uint8_t>(v);
  f[at + 1] = static_cast<std::uint8_t>(v >> 8);
}

void put_i32(std::span<std::uint8_t> f, std::size_t at, std::int32_t v) noexcept {
  const auto u = static_cast<std::uint32_t>(v);
  for (std::size_t i = 0; i < 4; ++i) f[at + i] = static_cast<std::uint8_t>(u >> (8 * i));
}

bool read_header(std::span<const std::uint8_t> field, CommandHeader& out) noexcept {
  if (field.size() < kCommandHeader) return false;
  out = CommandHeader{field[0], field[1], get_u16(field, 2)};
  return true;
}

bool write_header(std::span<std::uint8_t> field, const CommandHeader& h) noexcept {
  if (field.size() < kCommandHeader) return false;
  field[0] = h.code;
  field[1] = h.wdt;
  put_u16(field, 2, h.ctrl);
  return true;
}

bool allowed_in(Command c, Phase p) noexcept {
  if (p == Phase::p5) return false;
  switch (c) {
    case Command::nop:
    case Command::disconnect: return true;
    case Command::connect: return p == Phase::p1;
    case Command::interpolate: return p == Phase::p3;
    default: return p == Phase::p2 || p == Phase::p3;
  }
}

}  // namespace omnitwin::m3
