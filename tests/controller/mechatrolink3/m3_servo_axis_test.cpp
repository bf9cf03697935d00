// Tests controller/mechatrolink3/m3_servo_axis on responses written by hand: each start-up
// step of seed 000 fig. 8 writes its command and moves on only when the response echoes it
// with CMD_ALM normal, a stale (not fresh) response moves nothing, SVPRM_WR goes through
// every configured parameter, SV_ON waits for CMDRDY and SV_ON, a CMD_ALM alarm fails the
// axis naming the command (but CONNECT refused with a phase error, i.e. already connected,
// disconnects first), and the running axis writes its set-point.
#include "controller/mechatrolink3/m3_servo_axis.hpp"

#include <gtest/gtest.h>

#include <array>
#include <string>
#include <vector>

#include "bus_emulators/mechatrolink3/m3_servo_format.hpp"

namespace omnitwin::m3 {
namespace {

using namespace servo;

// The response a slave gives to `cmd` (RCMD echoed) with this CMD_STAT and SVCMD_STAT.
std::array<std::uint8_t, 32> answer(std::span<const std::uint8_t> cmd, CmdStat st = {}, std::uint32_t svstat = 0) {
  std::array<std::uint8_t, 32> r{};
  write_header(r, CommandHeader{cmd[0], 0, pack(st)});
  put_u32(r, kSvcmdStat, svstat);
  return r;
}

TEST(M3ServoAxis, WalksFigure8AndRunsTheSetPoint) {
  std::vector<std::string> log;
  ServoAxis axis("axis 1", ServoAxisConfig{.params = {{0x0102, 5000}, {0x0103, 6000}}},
                 [&](SimTime, const std::string& s) { log.push_back(s); });
  std::array<std::uint8_t, 32> cmd{}, rsp{};
  axis.on_interrupt(rsp, false, cmd, 0);
  EXPECT_EQ(cmd[0], static_cast<std::uint8_t>(Command::disconnect));
  auto next = [&](CmdStat st = {}, std::uint32_t svstat = 0) {
    rsp = answer(cmd, st, svstat);
    axis.on_interrupt(rsp, true, cmd, 0);
    return static_cast<Command>(cmd[0]);
  };
  EXPECT_EQ(next(), Command::connect);
  EXPECT_EQ(cmd[4], 0x30);
  EXPECT_EQ(cmd[7], 0x10);
  axis.on_interrupt(rsp, false, cmd, 0);
  EXPECT_EQ(static_cast<Command>(cmd[0]), Command::connect) << "a stale response moves nothing";
  EXPECT_EQ(next(), Command::sync_set);
  EXPECT_EQ(next(), Command::id_rd);
  EXPECT_EQ(get_u16(cmd, kIdSize), 16) << "ID_RD in the common format: SIZE at byte 6";
  EXPECT_EQ(next(), Command::svprm_wr);
  EXPECT_EQ(get_u16(cmd, kPrmNo), 0x0102);
  EXPECT_EQ(next(), Command::svprm_wr);
  EXPECT_EQ(get_u16(cmd, kPrmNo), 0x0103);
  EXPECT_EQ(get_i32(cmd, kPrmData), 6000);
  EXPECT_EQ(next(), Command::sens_on);
  EXPECT_EQ(next(), Command::sv_on);
  EXPECT_EQ(next(CmdStat{.cmdrdy = false}), Command::sv_on) << "CMDRDY 0: still switching on";
  EXPECT_EQ(next(CmdStat{}, 0), Command::sv_on) << "SV_ON not yet in SVCMD_STAT";
  axis.set_velocity(1234);
  EXPECT_EQ(next(CmdStat{}, 1u << 13), Command::velctrl);
  EXPECT_EQ(axis.step(), AxisStep::running);
  EXPECT_EQ(get_i32(cmd, kVelVref), 1234);
  EXPECT_EQ(get_u32(cmd, kSvcmdCtrl), sel_mon(0x0, 0x5)) << "SEL_MON1 APOS, SEL_MON2 FSPD (bits 16-23)";
  axis.shutdown(0);
  EXPECT_EQ(next(CmdStat{}, 1u << 13), Command::velctrl) << "zero speed first";
  EXPECT_EQ(get_i32(cmd, kVelVref), 0);
  EXPECT_EQ(next(CmdStat{}, 1u << 13), Command::sv_off);
  EXPECT_EQ(next(), Command::disconnect);
  next();
  EXPECT_EQ(axis.step(), AxisStep::released);
  EXPECT_NE(std::find(log.begin(), log.end(), "axis 1: SENS_ON"), log.end());
}

// The end of the run in the middle of the start-up: an axis not connected yet is only
// disconnected, one connected goes to SV_OFF at once; an alarm in the answers does not stop
// the shut-down (a slave that refuses SV_OFF is still disconnected).
TEST(M3ServoAxis, AShutDownDuringStartUpSwitchesOffAndDisconnectsWhateverTheAnswers) {
  std::array<std::uint8_t, 32> cmd{}, rsp{};
  ServoAxis fresh("axis 1", ServoAxisConfig{});
  fresh.on_interrupt(rsp, false, cmd, 0);
  rsp = answer(cmd);
  fresh.on_interrupt(rsp, true, cmd, 0);  // DISCONNECT accepted → CONNECT
  fresh.shutdown(0);
  rsp = answer(cmd);
  fresh.on_interrupt(rsp, true, cmd, 0);  // the answer to CONNECT: not yet the DISCONNECT's
  EXPECT_EQ(static_cast<Command>(cmd[0]), Command::disconnect);
  rsp = answer(cmd);
  fresh.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(fresh.step(), AxisStep::released);

  ServoAxis axis("axis 2", ServoAxisConfig{});
  axis.on_interrupt(rsp, false, cmd, 0);
  for (int i = 0; i < 3; ++i) {  // DISCONNECT, CONNECT, SYNC_SET → ID_RD
    rsp = answer(cmd);
    axis.on_interrupt(rsp, true, cmd, 0);
  }
  ASSERT_EQ(axis.step(), AxisStep::id_rd);
  axis.shutdown(0);
  rsp = answer(cmd);
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(static_cast<Command>(cmd[0]), Command::sv_off);
  rsp = answer(cmd, CmdStat{.cmd_alm = CmdAlarm::phase_error});
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(static_cast<Command>(cmd[0]), Command::disconnect) << axis.why();
  rsp = answer(cmd);
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(axis.step(), AxisStep::released);
  EXPECT_EQ(axis.recoveries(), 0) << "a phase error while shutting down is no reason to reconnect";
}

TEST(M3ServoAxis, ACommandAlarmDuringStartUpFailsTheAxis) {
  ServoAxis axis("axis 3", ServoAxisConfig{});
  std::array<std::uint8_t, 32> cmd{}, rsp{};
  axis.on_interrupt(rsp, false, cmd, 0);
  rsp = answer(cmd);
  axis.on_interrupt(rsp, true, cmd, 0);  // DISCONNECT accepted → CONNECT
  rsp = answer(cmd, CmdStat{.cmd_alm = CmdAlarm::invalid_data});
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(axis.step(), AxisStep::failed);
  EXPECT_NE(axis.why().find("CONNECT"), std::string::npos) << axis.why();
  EXPECT_NE(axis.why().find("invalid data"), std::string::npos) << axis.why();
}

// An earlier CONNECT took effect but both its answer and the retry's were lost: the slave is
// in phase 2 and refuses the next CONNECT with a phase error. The axis disconnects and
// connects again instead of failing.
TEST(M3ServoAxis, ConnectRefusedAsAlreadyConnectedDisconnectsFirst) {
  ServoAxis axis("axis 2", ServoAxisConfig{});
  std::array<std::uint8_t, 32> cmd{}, rsp{};
  axis.on_interrupt(rsp, false, cmd, 0);
  rsp = answer(cmd);
  axis.on_interrupt(rsp, true, cmd, 0);  // DISCONNECT accepted → CONNECT
  ASSERT_EQ(static_cast<Command>(cmd[0]), Command::connect);
  rsp = answer(cmd, CmdStat{.cmd_alm = CmdAlarm::phase_error});
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(axis.step(), AxisStep::disconnect);
  EXPECT_EQ(static_cast<Command>(cmd[0]), Command::disconnect);
  rsp = answer(cmd);
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(static_cast<Command>(cmd[0]), Command::connect);
  rsp = answer(cmd);
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(static_cast<Command>(cmd[0]), Command::sync_set);
}

// A communication alarm during start-up (a WDT error while the axis reads the ID): the slave
// refuses SV_ON until the alarm is cleared, so the axis clears it first (ALM_CLR with
// CMD_CTRL.ALM_CLR), sets phase 3 again and goes on, rather than sending SV_ON and failing.
TEST(M3ServoAxis, ACommunicationAlarmDuringStartUpIsClearedBeforeSvOn) {
  ServoAxis axis("axis 4", ServoAxisConfig{});
  std::array<std::uint8_t, 32> cmd{}, rsp{};
  axis.on_interrupt(rsp, false, cmd, 0);
  auto next = [&](CmdStat st = {}, std::uint32_t svstat = 0) {
    rsp = answer(cmd, st, svstat);
    axis.on_interrupt(rsp, true, cmd, 0);
    return static_cast<Command>(cmd[0]);
  };
  ASSERT_EQ(next(), Command::connect);
  ASSERT_EQ(next(), Command::sync_set);
  ASSERT_EQ(next(), Command::id_rd);
  EXPECT_EQ(next(CmdStat{.comm_alm = CommAlarm::wdt}), Command::alm_clr) << "SV_ON would be refused";
  EXPECT_TRUE(unpack_ctrl(get_u16(cmd, 2)).alm_clr);
  EXPECT_EQ(next(), Command::sync_set);
  EXPECT_EQ(next(), Command::sens_on);
  EXPECT_EQ(next(), Command::sv_on);
  next(CmdStat{}, 1u << 13);
  EXPECT_EQ(axis.step(), AxisStep::running) << axis.why();
  EXPECT_EQ(axis.recoveries(), 1);
}

// The start-up rule above is for start-up only: a running axis whose response carries a
// communication alarm with the servo still on stays running (its recovery, which takes it out
// of running and so stops the platform as a lost axis, starts when the servo goes off).
TEST(M3ServoAxis, ARunningAxisRecoversWhenTheServoGoesOffNotOnTheAlarmAlone) {
  ServoAxis axis("axis 2", ServoAxisConfig{});
  std::array<std::uint8_t, 32> cmd{}, rsp{};
  axis.on_interrupt(rsp, false, cmd, 0);
  for (int i = 0; i < 6; ++i) {
    rsp = answer(cmd, CmdStat{}, 1u << 13);
    axis.on_interrupt(rsp, true, cmd, 0);
  }
  ASSERT_EQ(axis.step(), AxisStep::running) << axis.why();
  rsp = answer(cmd, CmdStat{.comm_alm = CommAlarm::no_sync}, 1u << 13);
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(axis.step(), AxisStep::running) << axis.why();
  EXPECT_EQ(axis.recoveries(), 0);
  rsp = answer(cmd, CmdStat{.comm_alm = CommAlarm::no_sync}, 0);
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(axis.step(), AxisStep::alm_clr);
  EXPECT_EQ(axis.recoveries(), 1);
}

TEST(M3ServoAxis, PositionModeSendsInterpolate) {
  ServoAxis axis("axis 1", ServoAxisConfig{.com_tim = 1, .position_mode = true, .params = {}});
  std::array<std::uint8_t, 32> cmd{}, rsp{};
  axis.on_interrupt(rsp, false, cmd, 0);
  for (int i = 0; i < 6; ++i) {
    rsp = answer(cmd, CmdStat{}, 1u << 13);
    axis.on_interrupt(rsp, true, cmd, 0);
  }
  axis.set_position(777, 11);
  rsp = answer(cmd, CmdStat{}, 1u << 13);
  axis.on_interrupt(rsp, true, cmd, 0);
  EXPECT_EQ(static_cast<Command>(cmd[0]), Command::interpolate);
  EXPECT_EQ(get_i32(cmd, kIpTpos), 777) << "TPOS at byte 12, as the public command format";
  EXPECT_EQ(get_i32(cmd, kIpVff), 11) << "VFF at byte 16";
}

// INTERPOLATE after a recovery: the servo lost power while running to target 100000 and was
// switched on again where it stood (APOS 98826). Its first INTERPOLATE holds it there, not
// at the target it had before (a 1174-count step back, and a stopped platform that moved);
// after hold() the target follows the next response's APOS too.
TEST(M3ServoAxis, InterpolateTargetsFollowTheServoWhenItIsSwitchedOnAgainAndWhenHeld) {
  ServoAxis axis("axis 4", ServoAxisConfig{.com_tim = 1, .position_mode = true, .params = {}});
  std::array<std::uint8_t, 32> cmd{}, rsp{};
  auto next = [&](std::int32_t apos, CmdStat st = {}, std::uint32_t svstat = 1u << 13) {
    rsp = answer(cmd, st, svstat);
    put_i32(rsp, kMonitor1, apos);
    axis.on_interrupt(rsp, true, cmd, 0);
    return static_cast<Command>(cmd[0]);
  };
  axis.on_interrupt(rsp, false, cmd, 0);
  for (int i = 0; i < 10 && axis.step() != AxisStep::running; ++i) next(5000);
  ASSERT_EQ(axis.step(), AxisStep::running) << axis.why();
  EXPECT_EQ(get_i32(cmd, kIpTpos), 5000) << "the first INTERPOLATE holds the servo where it is";
  axis.set_position(100000, 2000);
  EXPECT_EQ(next(99000), Command::interpolate);
  EXPECT_EQ(get_i32(cmd, kIpTpos), 100000);
  ASSERT_EQ(next(0, CmdStat{.cmd_alm = CmdAlarm::phase_error}, 0), Command::disconnect) << "power lost: recovering";
  for (int i = 0; i < 10 && axis.step() != AxisStep::running; ++i) next(98826);
  ASSERT_EQ(axis.step(), AxisStep::running) << axis.why();
  EXPECT_EQ(static_cast<Command>(cmd[0]), Command::interpolate);
  EXPECT_EQ(get_i32(cmd, kIpTpos), 98826) << "switched on again: held where it stands, not driven to 100000";
  EXPECT_EQ(get_i32(cmd, kIpVff), 0) << "no feed-forward";
  axis.set_position(120000, 2000);
  next(98900);
  axis.hold();
  EXPECT_EQ(next(99100), Command::interpolate);
  EXPECT_EQ(get_i32(cmd, kIpTpos), 99100) << "held at the APOS of the next response";
  EXPECT_EQ(get_i32(cmd, kIpVff), 0);
}

}  // namespace
}  // namespace omnitwin::m3
