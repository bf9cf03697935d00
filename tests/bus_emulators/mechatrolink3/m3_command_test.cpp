// Tests bus_emulators/mechatrolink3/m3_command: the standard servo profile's command codes
// and names (fact sheet list), the CMD_CTRL and CMD_STAT bit layouts worked by hand, the
// CMD_ALM/COMM_ALM warning/alarm split, which commands each phase allows, the subcommand
// list, and the header codec.
#include "bus_emulators/mechatrolink3/m3_command.hpp"

#include <gtest/gtest.h>

#include <array>
#include <utility>
#include <vector>

namespace omnitwin::m3 {
namespace {

TEST(M3Command, CodesAndNamesOfTheFactSheet) {
  const std::vector<std::pair<int, const char*>> codes = {
      {0x00, "NOP"},      {0x03, "ID_RD"},    {0x04, "CONFIG"},     {0x05, "ALM_RD"},   {0x06, "ALM_CLR"},
      {0x0D, "SYNC_SET"}, {0x0E, "CONNECT"},  {0x0F, "DISCONNECT"}, {0x1D, "MEM_RD"},   {0x1E, "MEM_WR"},
      {0x20, "POS_SET"},  {0x21, "BRK_ON"},   {0x22, "BRK_OFF"},    {0x23, "SENS_ON"},  {0x24, "SENS_OFF"},
      {0x30, "SMON"},     {0x31, "SV_ON"},    {0x32, "SV_OFF"},     {0x34, "INTERPOLATE"}, {0x35, "POSING"},
      {0x36, "FEED"},     {0x39, "EX_POSING"}, {0x3A, "ZRET"},      {0x3C, "VELCTRL"},  {0x3D, "TRQCTRL"},
      {0x40, "SVPRM_RD"}, {0x41, "SVPRM_WR"}};
  for (const auto& [code, name] : codes) EXPECT_STREQ(to_string(static_cast<Command>(code)), name) << code;
  int known = 0;
  for (int c = 0; c < 256; ++c) known += is_known(static_cast<Command>(c)) ? 1 : 0;
  EXPECT_EQ(known, static_cast<int>(codes.size())) << "no code outside the list is known";
}

TEST(M3Command, CmdStatBitsByHand) {
  const CmdStat s{.d_alm = true, .d_war = false, .cmdrdy = true, .alm_clr_cmp = false, .rcmd_id = 2,
                  .cmd_alm = CmdAlarm::phase_error, .comm_alm = CommAlarm::wdt};
  // D_ALM bit 0, CMDRDY bit 2, RCMD_ID 2 in bits 6-7, CMD_ALM Ch in 8-11, COMM_ALM Ch in 12-15.
  EXPECT_EQ(pack(s), 0x0001 | 0x0004 | 0x0080 | 0x0C00 | 0xC000);
  const CmdStat back = unpack_stat(pack(s));
  EXPECT_TRUE(back.d_alm);
  EXPECT_FALSE(back.d_war);
  EXPECT_TRUE(back.cmdrdy);
  EXPECT_EQ(back.rcmd_id, 2);
  EXPECT_EQ(back.cmd_alm, CmdAlarm::phase_error);
  EXPECT_EQ(back.comm_alm, CommAlarm::wdt);
  EXPECT_EQ(pack(CmdStat{.d_alm = false, .d_war = true, .cmdrdy = false, .alm_clr_cmp = true}), 0x000A);
}

TEST(M3Command, CmdCtrlBitsByHand) {
  EXPECT_EQ(pack(CmdCtrl{.alm_clr = true, .cmd_id = 0}), 0x0008);
  EXPECT_EQ(pack(CmdCtrl{.alm_clr = false, .cmd_id = 3}), 0x00C0);
  EXPECT_TRUE(unpack_ctrl(0x0048).alm_clr);
  EXPECT_EQ(unpack_ctrl(0x0048).cmd_id, 1);
}

TEST(M3Command, WarningsAreBelowEightAlarmsFromEight) {
  EXPECT_FALSE(is_alarm(CmdAlarm::invalid_data_warning));
  EXPECT_TRUE(is_alarm(CmdAlarm::unsupported));
  EXPECT_TRUE(is_alarm(CmdAlarm::phase_error));
  EXPECT_FALSE(is_alarm(CommAlarm::no_sync_warning));
  EXPECT_TRUE(is_alarm(CommAlarm::fcs));
  EXPECT_TRUE(is_alarm(CommAlarm::wdt));
  EXPECT_STREQ(to_string(CommAlarm::wdt), "WDT error");
  EXPECT_STREQ(to_string(CmdAlarm::phase_error), "phase error");
}

TEST(M3Command, WhatEachPhaseAllows) {
  EXPECT_TRUE(allowed_in(Command::connect, Phase::p1));
  EXPECT_FALSE(allowed_in(Command::connect, Phase::p2));
  EXPECT_TRUE(allowed_in(Command::nop, Phase::p1));
  EXPECT_TRUE(allowed_in(Command::disconnect, Phase::p3));
  EXPECT_FALSE(allowed_in(Command::velctrl, Phase::p1));
  EXPECT_TRUE(allowed_in(Command::velctrl, Phase::p2));
  EXPECT_TRUE(allowed_in(Command::velctrl, Phase::p3));
  EXPECT_FALSE(allowed_in(Command::interpolate, Phase::p2));
  EXPECT_TRUE(allowed_in(Command::interpolate, Phase::p3));
  for (int c = 0; c < 256; ++c) EXPECT_FALSE(allowed_in(static_cast<Command>(c), Phase::p5)) << c;
}

TEST(M3Command, SubcommandsOfThe48ByteMode) {
  for (Command c : {Command::nop, Command::alm_rd, Command::alm_clr, Command::mem_rd, Command::mem_wr, Command::smon,
                    Command::svprm_rd, Command::svprm_wr})
    EXPECT_TRUE(is_subcommand(c)) << to_string(c);
  EXPECT_FALSE(is_subcommand(Command::sv_on));
  EXPECT_FALSE(is_subcommand(Command::connect));
}

TEST(M3Command, HeaderAndLittleEndianFields) {
  std::array<std::uint8_t, 8> f{};
  ASSERT_TRUE(write_header(f, CommandHeader{0x3C, 0x50, 0x1234}));
  EXPECT_EQ(f[0], 0x3C);
  EXPECT_EQ(f[1], 0x50);
  EXPECT_EQ(f[2], 0x34);
  EXPECT_EQ(f[3], 0x12);
  CommandHeader h;
  ASSERT_TRUE(read_header(f, h));
  EXPECT_EQ(h.ctrl, 0x1234);
  EXPECT_FALSE(read_header(std::span<const std::uint8_t>(f).first(3), h));
  put_i32(f, 4, -2);
  EXPECT_EQ(get_i32(f, 4), -2);
  EXPECT_EQ(f[4], 0xFE);
  EXPECT_EQ(f[7], 0xFF);
}

}  // namespace
}  // namespace omnitwin::m3
