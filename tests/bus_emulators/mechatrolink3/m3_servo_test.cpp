// Tests bus_emulators/mechatrolink3/m3_servo: the standard servo profile on the shared drive
// core, closed over a 1-DOF axis model (drive::AxisModel) stepped every 1 ms. SV_ON needs
// SENS_ON and holds CMDRDY at 0 until the drive is enabled; VELCTRL, INTERPOLATE, POSING,
// FEED and TRQCTRL move the axis as commanded and need the servo on; BRK_ON/OFF need it off;
// POS_SET shifts the reported position; monitors, SVCMD_STAT and SVCMD_IO say what happened;
// SVPRM_RD/WR and ID_RD work and refuse bad input; a following error is a device alarm that
// ALM_RD reports and ALM_CLR clears; a lost link turns the servo off; and the whole servo
// start-up sequence of seed 000 fig. 8 runs through the slave link (m3_link) in phase 3.
#include "bus_emulators/mechatrolink3/m3_servo.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/mechatrolink3/m3_servo_format.hpp"

namespace omnitwin::m3 {
namespace {

using namespace servo;

constexpr double kCpr = 10000;  // counts per revolution in these tests

ServoConfig config() {
  ServoConfig c;
  c.drive.counts_per_rev = kCpr;
  c.drive.max_speed_rad_s = 200;
  c.drive.rated_torque_nm = 1.0;
  return c;
}

// A command field of 32 bytes with the header and, for a servo command, SVCMD_CTRL with
// SEL_MON1/2/3 = APOS, FSPD, PERR (the common commands have their own fields from byte 4).
std::vector<std::uint8_t> cmd(Command c, std::vector<std::pair<std::size_t, std::int32_t>> i32 = {},
                              std::uint32_t svcmd_ctrl = sel_mon(0x0, 0x5, 0x2)) {
  std::vector<std::uint8_t> f(32, 0);
  write_header(f, CommandHeader{static_cast<std::uint8_t>(c), 0, 0});
  if (!common_format(c) && c != Command::connect) put_u32(f, kSvcmdCtrl, svcmd_ctrl);
  for (auto [at, v] : i32) put_i32(f, at, v);
  return f;
}

class M3Servo : public ::testing::Test {
 protected:
  ServoProfile servo{config()};
  drive::AxisModel axis{drive::AxisModelConfig{.inertia_kg_m2 = 1e-3, .viscous_nm_s = 1e-3, .coulomb_nm = 0.005}};
  SimTime t = 0;
  std::vector<std::uint8_t> rsp = std::vector<std::uint8_t>(32, 0);

  CmdAlarm send(const std::vector<std::uint8_t>& c) {
    std::fill(rsp.begin(), rsp.end(), std::uint8_t{0});
    return servo.execute(static_cast<Command>(c[0]), c, rsp, t);
  }
  void run(double seconds) {
    for (int k = 0; k < std::lround(seconds * 1000); ++k) {
      axis.step(servo.step(t, axis.feedback()), 1e-3);
      t += 1'000'000;
    }
  }
  void servo_on() {
    ASSERT_EQ(send(cmd(Command::sens_on)), CmdAlarm::normal);
    ASSERT_EQ(send(cmd(Command::sv_on)), CmdAlarm::normal);
    run(0.01);
    ASSERT_TRUE(servo.servo_on());
  }
  std::uint32_t svcmd_stat() const { return get_u32(rsp, kSvcmdStat); }
  std::uint32_t svcmd_io() const { return get_u32(rsp, kSvcmdIoIn); }
  std::int32_t monitor(int k) const { return get_i32(rsp, kMonitor1 + 4 * static_cast<std::size_t>(k)); }
};

TEST_F(M3Servo, ServoOnNeedsTheSensorAndHoldsCmdrdyUntilTheDriveIsEnabled) {
  EXPECT_EQ(send(cmd(Command::sv_on)), CmdAlarm::condition_error) << "SENS_ON first (fig. 8)";
  EXPECT_EQ(send(cmd(Command::sens_on)), CmdAlarm::normal);
  EXPECT_NE(svcmd_stat() & (1u << 10), 0u) << "POS_RDY";
  EXPECT_EQ(send(cmd(Command::sv_on)), CmdAlarm::normal);
  EXPECT_FALSE(servo.ready()) << "CMDRDY 0 while the FSA steps";
  run(0.01);
  EXPECT_TRUE(servo.servo_on());
  EXPECT_TRUE(servo.ready());
  send(cmd(Command::smon));
  EXPECT_NE(svcmd_stat() & (1u << 13), 0u) << "SV_ON";
  EXPECT_EQ(svcmd_stat() & (0xFu << 16), 0x0u << 16);
  EXPECT_EQ((svcmd_stat() >> 20) & 0xF, 0x5u) << "SEL_MON2 echoed";
}

TEST_F(M3Servo, VelctrlTurnsTheAxisAtTheCommandedSpeed) {
  servo_on();
  // slaves.N.mode: no motion command has run yet (the drive core holding still in CSV is not
  // VELCTRL; a never-connected servo reported 9, found in review).
  EXPECT_EQ(servo.motion_mode(), 0);
  const auto vref = static_cast<std::int32_t>(kCpr);  // one revolution per second
  EXPECT_EQ(send(cmd(Command::velctrl, {{kVelVref, vref}})), CmdAlarm::normal);
  run(1.0);
  EXPECT_EQ(servo.motion_mode(), 9);
  EXPECT_NEAR(axis.velocity_rad_s(), 2 * M_PI, 0.05 * 2 * M_PI);
  send(cmd(Command::velctrl, {{kVelVref, vref}}));
  EXPECT_NEAR(monitor(1), vref, 0.05 * vref) << "FSPD";
  EXPECT_GT(monitor(0), 0.8 * kCpr) << "APOS after about a second";
  // A power cycle starts the servo afresh: no motion command has run since (9 survived it,
  // found in review).
  servo.power_cycle();
  run(0.01);
  EXPECT_EQ(servo.motion_mode(), 0);
}

TEST_F(M3Servo, MotionNeedsTheServoOnAndTheBrakeNeedsItOff) {
  EXPECT_EQ(send(cmd(Command::velctrl, {{kVelVref, 1000}})), CmdAlarm::condition_error);
  EXPECT_EQ(send(cmd(Command::posing, {{kPosTpos, 1000}, {kPosTspd, 1000}})), CmdAlarm::condition_error);
  EXPECT_EQ(send(cmd(Command::brk_off)), CmdAlarm::normal);
  servo_on();
  EXPECT_EQ(send(cmd(Command::brk_on)), CmdAlarm::condition_error);
  EXPECT_EQ(send(cmd(Command::sens_off)), CmdAlarm::condition_error);
  EXPECT_EQ(send(cmd(Command::sv_off)), CmdAlarm::normal);
  run(0.01);
  EXPECT_FALSE(servo.servo_on());
  EXPECT_EQ(send(cmd(Command::brk_on)), CmdAlarm::normal);
  run(0.002);
  send(cmd(Command::smon));
  EXPECT_NE(svcmd_io() & kIoBrkOn, 0u) << "BRK_ON in SVCMD_IO";
}

TEST_F(M3Servo, InterpolateFollowsAPositionRamp) {
  servo_on();
  for (int k = 1; k <= 1000; ++k) {
    const auto tpos = static_cast<std::int32_t>(2 * k);  // 2000 counts/s
    ASSERT_EQ(send(cmd(Command::interpolate, {{kIpTpos, tpos}, {kIpVff, 2000}})), CmdAlarm::normal);
    run(0.001);
  }
  send(cmd(Command::interpolate, {{kIpTpos, 2000}, {kIpVff, 0}}));  // the end: no more feed-forward
  run(0.2);
  send(cmd(Command::interpolate, {{kIpTpos, 2000}, {kIpVff, 0}}));
  EXPECT_NEAR(monitor(0), 2000, 20) << "APOS at the last target";
  EXPECT_LT(std::abs(monitor(2)), 20) << "PERR";
  EXPECT_NE(svcmd_io() & kIoPset, 0u) << "PSET";
  EXPECT_NE(svcmd_io() & kIoDen, 0u) << "DEN: the distribution is done";
  EXPECT_EQ(servo.motion_mode(), 8);
}

TEST_F(M3Servo, PosingReachesItsTargetAndFeedRunsWithoutOne) {
  servo_on();
  ASSERT_EQ(send(cmd(Command::posing, {{kPosTpos, 20000}, {kPosTspd, 20000}, {kPosAccr, 100000}, {kPosDecr, 100000}})), CmdAlarm::normal);
  run(2.0);
  send(cmd(Command::posing, {{kPosTpos, 20000}, {kPosTspd, 20000}, {kPosAccr, 100000}, {kPosDecr, 100000}}));
  EXPECT_NEAR(monitor(0), 20000, 15);
  EXPECT_NE(svcmd_io() & kIoPset, 0u) << "PSET";
  EXPECT_NE(svcmd_io() & kIoZspd, 0u) << "ZSPD: standing still";
  EXPECT_EQ(send(cmd(Command::posing, {{kPosTpos, 0}, {kPosTspd, 0}})), CmdAlarm::invalid_data) << "TSPD 0";
  ASSERT_EQ(send(cmd(Command::feed, {{kFeedTspd, -5000}, {kFeedAccr, 100000}})), CmdAlarm::normal);
  run(0.5);
  EXPECT_LT(axis.velocity_rad_s(), -0.9 * 2 * M_PI * 5000 / kCpr);
}

TEST_F(M3Servo, TrqctrlAppliesTheTorque) {
  servo_on();
  ASSERT_EQ(send(cmd(Command::trqctrl, {{kTrqTqref, 100}})), CmdAlarm::normal);  // 10 % of 1 Nm
  run(0.2);
  EXPECT_GT(axis.velocity_rad_s(), 1.0) << "0.1 Nm on 1e-3 kg m² accelerates";
  EXPECT_EQ(send(cmd(Command::trqctrl, {{kTrqTqref, 40000}})), CmdAlarm::invalid_data);
}

TEST_F(M3Servo, PosSetShiftsTheReportedPosition) {
  EXPECT_EQ(send(cmd(Command::pos_set, {{kPosSetData, 5000}})), CmdAlarm::condition_error) << "the sensor is off";
  servo_on();
  ASSERT_EQ(send(cmd(Command::pos_set, {{kPosSetData, 5000}})), CmdAlarm::normal);
  send(cmd(Command::smon));
  EXPECT_NEAR(monitor(0), 5000, 2);
}

TEST_F(M3Servo, ServoParametersReadWriteAndRefuseBadNumbers) {
  auto prm = [&](Command c, std::uint16_t no, std::int32_t value, std::uint8_t size = 4) {
    auto f = cmd(c, {{kPrmData, value}});
    put_u16(f, kPrmNo, no);
    f[kPrmSize] = size;
    return send(f);
  };
  EXPECT_EQ(prm(Command::svprm_wr, 0x0102, 123456), CmdAlarm::normal);
  EXPECT_EQ(servo.drive().objects().profile_acceleration, 123456u);
  EXPECT_EQ(prm(Command::svprm_rd, 0x0102, 0), CmdAlarm::normal);
  EXPECT_EQ(get_i32(rsp, kPrmData), 123456);
  EXPECT_EQ(get_u16(rsp, kPrmNo), 0x0102) << "NO echoed";
  EXPECT_EQ(prm(Command::svprm_rd, 0x0110, 0), CmdAlarm::normal);
  EXPECT_EQ(get_i32(rsp, kPrmData), 10000);
  EXPECT_EQ(prm(Command::svprm_wr, 0x0110, 1), CmdAlarm::invalid_data) << "read only";
  EXPECT_EQ(prm(Command::svprm_rd, 0x7777, 0), CmdAlarm::invalid_data);
  EXPECT_EQ(prm(Command::svprm_rd, 0x0102, 0, 2), CmdAlarm::invalid_data) << "SIZE 2";
  EXPECT_EQ(prm(Command::svprm_wr, 0x0101, 70000), CmdAlarm::invalid_data);
}

// SVPRM_RD/WR use bytes 12… for their own fields, but bytes 4-11 are SVCMD_STAT and SVCMD_IO
// as in every servo response: a master must not read "servo off". ID_RD and ALM_RD are common
// commands: their fields start at byte 4 (the public common format), with no servo status.
TEST_F(M3Servo, ParameterReadsCarryTheServoStatusAndCommonCommandsTheirOwnFields) {
  servo_on();
  send(cmd(Command::smon));
  const std::uint32_t stat = svcmd_stat(), io = svcmd_io();
  ASSERT_NE(stat & kSvOn, 0u) << "SV_ON";
  auto rd = cmd(Command::svprm_rd);
  put_u16(rd, kPrmNo, 0x0106);
  rd[kPrmSize] = 4;
  ASSERT_EQ(send(rd), CmdAlarm::normal);
  EXPECT_EQ(svcmd_stat(), stat) << "SVPRM_RD";
  EXPECT_EQ(svcmd_io(), io);
  EXPECT_EQ(get_u16(rsp, kPrmNo), 0x0106) << "the parameter's own fields stay";
  EXPECT_EQ(get_u32(rsp, kPrmData), servo.drive().objects().position_window);
  auto id = cmd(Command::id_rd);
  put_u16(id, kIdSize, 4);
  ASSERT_EQ(send(id), CmdAlarm::normal);
  EXPECT_EQ(get_u16(rsp, kIdSize), 4) << "ID_RD echoes its fields at 4…7";
  EXPECT_EQ(std::string(rsp.begin() + kIdData, rsp.begin() + kIdData + 4), "OMNI");
  ASSERT_EQ(send(cmd(Command::alm_rd)), CmdAlarm::normal);
  EXPECT_EQ(get_u16(rsp, kAlmMode), 0) << "ALM_RD_MOD echoed";
  EXPECT_EQ(get_u16(rsp, kAlmData), 0) << "no alarm";
}

TEST_F(M3Servo, IdReadGivesTheDeviceName) {
  auto f = cmd(Command::id_rd);
  put_u16(f, kIdSize, 8);
  ASSERT_EQ(send(f), CmdAlarm::normal);
  EXPECT_EQ(std::string(rsp.begin() + kIdData, rsp.begin() + kIdData + 8), "OMNITWIN");
  f[kIdOffset] = 9;
  ASSERT_EQ(send(f), CmdAlarm::normal);
  EXPECT_EQ(std::string(rsp.begin() + kIdData, rsp.begin() + kIdData + 8), "M3-SERVO");
  put_u16(f, kIdSize, 25);
  EXPECT_EQ(send(f), CmdAlarm::invalid_data) << "more than the 24 bytes a 32-byte answer holds";
  put_u16(f, kIdSize, 8);
  f[kIdCode] = 5;  // an ID code we do not have
  EXPECT_EQ(send(f), CmdAlarm::invalid_data);
}

TEST_F(M3Servo, AFollowingErrorIsADeviceAlarmThatAlmClrClears) {
  servo_on();
  auto prm = cmd(Command::svprm_wr, {{kPrmData, 50}});
  put_u16(prm, kPrmNo, 0x0100);  // following error window 50 counts
  prm[kPrmSize] = 4;
  ASSERT_EQ(send(prm), CmdAlarm::normal);
  send(cmd(Command::interpolate, {{kIpTpos, 50000}}));  // a jump the axis cannot follow
  run(0.1);
  EXPECT_TRUE(servo.device_alarm());
  EXPECT_FALSE(servo.servo_on());
  auto rd = cmd(Command::alm_rd);
  ASSERT_EQ(send(rd), CmdAlarm::normal);
  EXPECT_EQ(get_u16(rsp, kAlmData), 0x0D00) << "position deviation overflow";
  EXPECT_EQ(send(cmd(Command::sv_on)), CmdAlarm::condition_error) << "not while the alarm stands";
  ASSERT_EQ(send(cmd(Command::alm_clr)), CmdAlarm::normal);
  run(0.01);
  EXPECT_FALSE(servo.device_alarm());
  put_u16(rd, kAlmMode, 1);  // history
  send(rd);
  EXPECT_EQ(get_u16(rsp, kAlmData), 0x0D00);
  auto clr = cmd(Command::alm_clr);
  put_u16(clr, kAlmMode, 1);  // clear the history
  ASSERT_EQ(send(clr), CmdAlarm::normal);
  send(rd);
  EXPECT_EQ(get_u16(rsp, kAlmData), 0) << "history cleared";
  put_u16(clr, kAlmMode, 2);
  EXPECT_EQ(send(clr), CmdAlarm::invalid_data);
}

TEST_F(M3Servo, ALostLinkTurnsTheServoOffAndUnbuiltCommandsSaySo) {
  servo_on();
  send(cmd(Command::velctrl, {{kVelVref, 10000}}));
  run(0.2);
  servo.stop(t);
  run(0.01);
  EXPECT_FALSE(servo.servo_on());
  EXPECT_EQ(send(cmd(Command::mem_rd)), CmdAlarm::unsupported) << "no virtual memory modelled";
  EXPECT_EQ(send(cmd(Command::config)), CmdAlarm::normal) << "parameters take effect when written";
}

TEST_F(M3Servo, ZeroReturnHomesTheAxisAndSetsZpoint) {
  EXPECT_EQ(send(cmd(Command::zret)), CmdAlarm::condition_error) << "servo off";
  servo_on();
  send(cmd(Command::velctrl, {{kVelVref, 5000}}));
  run(0.5);  // somewhere away from zero
  auto z = cmd(Command::zret, {{kZretTspd, 2000}});
  z[kZretMode] = 37;  // CiA 402 method 37: the current position is home
  ASSERT_EQ(send(z), CmdAlarm::normal);
  run(0.2);
  EXPECT_TRUE(servo.drive().homed());
  send(z);
  EXPECT_NE(svcmd_io() & kIoZpoint, 0u) << "ZPOINT";
  EXPECT_LT(std::abs(monitor(0)), 20) << "APOS at the new origin";
  EXPECT_EQ(send(cmd(Command::zret, {{kZretTspd, -1}})), CmdAlarm::invalid_data);
}

// EX_POSING: towards TPOS until the latch input (here the drive core's modelled home switch
// at 1 rad) rises, then to the latched position + parameter 0107h.
TEST(M3ServoLatch, ExternalPositioningStopsAtTheLatchPlusTheDistance) {
  ServoConfig c = config();
  c.drive.switches.home = 1.0;  // rad on the load shaft: 1591.5 counts at 10000 counts/rev
  ServoProfile servo(c);
  drive::AxisModel axis;
  SimTime t = 0;
  std::vector<std::uint8_t> rsp(32, 0);
  auto send = [&](const std::vector<std::uint8_t>& f) { return servo.execute(static_cast<Command>(f[0]), f, rsp, t); };
  auto run = [&](double s) {
    for (int k = 0; k < std::lround(s * 1000); ++k, t += 1'000'000) axis.step(servo.step(t, axis.feedback()), 1e-3);
  };
  auto prm = cmd(Command::svprm_wr, {{kPrmData, 500}});
  put_u16(prm, kPrmNo, 0x0107);
  prm[kPrmSize] = 4;
  ASSERT_EQ(send(prm), CmdAlarm::normal);
  send(cmd(Command::sens_on));
  send(cmd(Command::sv_on));
  run(0.01);
  const auto ex = cmd(Command::ex_posing, {{kPosTpos, 20000}, {kPosTspd, 5000}, {kPosAccr, 50000}, {kPosDecr, 50000}},
                      sel_mon(0x3, 0x0));  // MONITOR1 LPOS1, MONITOR2 APOS
  ASSERT_EQ(send(ex), CmdAlarm::normal);
  for (int k = 0; k < 3000; ++k) {  // the master repeats it every cycle
    send(ex);
    run(0.001);
  }
  send(ex);
  const std::int32_t lpos = get_i32(rsp, kMonitor1), apos = get_i32(rsp, kMonitor2);
  EXPECT_NE(get_u32(rsp, kSvcmdStat) & kLCmp1, 0u) << "L_CMP1";
  EXPECT_NEAR(lpos, 10000 / (2 * M_PI), 10) << "latched where the switch is (within a drive period)";
  EXPECT_NEAR(apos, lpos + 500, 12) << "stopped at the latch + 0107h, not at TPOS";
  EXPECT_NE(get_u32(rsp, kSvcmdIoIn) & kIoPset, 0u) << "PSET";
}

TEST_F(M3Servo, SubcommandsReadMonitorsParametersAndAlarms) {
  std::array<std::uint8_t, 16> sub{}, out{};
  sub[0] = static_cast<std::uint8_t>(Command::svprm_wr);
  put_u16(sub, 4, 0x0103);
  sub[6] = 4;
  put_i32(sub, 8, 77777);
  EXPECT_EQ(servo.execute_sub(Command::svprm_wr, sub, out), CmdAlarm::normal);
  EXPECT_EQ(servo.drive().objects().profile_deceleration, 77777u);
  out.fill(0);
  sub[0] = static_cast<std::uint8_t>(Command::svprm_rd);
  EXPECT_EQ(servo.execute_sub(Command::svprm_rd, sub, out), CmdAlarm::normal);
  EXPECT_EQ(get_i32(out, 8), 77777);
  servo_on();
  send(cmd(Command::velctrl, {{kVelVref, 5000}}));
  run(0.3);
  const std::int32_t fspd = servo.monitor(5);
  std::array<std::uint8_t, 16> smon{};
  smon[0] = static_cast<std::uint8_t>(Command::smon);
  smon[3] = 0x05;  // SUB_CTRL (bytes 1-3): bits 12-15 SEL_MON4 = 0 (APOS), bits 16-19 SEL_MON5 = 5 (FSPD)
  out.fill(0);
  EXPECT_EQ(servo.execute_sub(Command::smon, smon, out), CmdAlarm::normal);
  EXPECT_GT(get_i32(out, 4), 0) << "APOS";
  EXPECT_EQ(get_i32(out, 8), fspd) << "FSPD";
  EXPECT_GT(fspd, 1000);
  std::array<std::uint8_t, 16> alm{};
  out.fill(0);
  EXPECT_EQ(servo.execute_sub(Command::alm_rd, alm, out), CmdAlarm::normal);
  EXPECT_EQ(get_u16(out, 8), 0) << "no alarm";
  EXPECT_EQ(servo.execute_sub(Command::mem_rd, alm, out), CmdAlarm::unsupported);
}

// One servo behind its slave link at station 03h, driven one communication cycle at a time as
// a master would drive it.
struct LinkRig {
  LinkRig() = default;
  LinkRig(const LinkRig&) = delete;  // the link's callback holds `this`
  LinkRig& operator=(const LinkRig&) = delete;

  // One frame of `type` to `dst` at the rig's time.
  void frame(FrameType type, std::vector<std::uint8_t> d, std::uint8_t dst) {
    std::vector<std::uint8_t> b(kMaxFrame);
    b.resize(encode(FrameSpec{.dst = dst, .type = type, .data = d}, b));
    link.on_frame(b, t);
  }
  // One 1 ms cycle: SYNC, the command with the next WDT count (`advance` false repeats the last
  // one: a WDT error in phase 3), the drive's periods; the response's data in `last`, its
  // CMD_STAT returned.
  CmdStat exchange(std::vector<std::uint8_t> c, bool advance = true) {
    frame(FrameType::sync, std::vector<std::uint8_t>(8, 0), kBroadcast);
    if (advance) wdt = static_cast<std::uint8_t>(wdt + 0x10);
    c[1] = wdt;
    frame(FrameType::cyclic_command, c, 0x03);
    axis.step(servo.step(t, axis.feedback()), 1e-3);
    t += 1'000'000;
    link.advance(t);
    FrameView v;
    EXPECT_EQ(decode(sent.back(), v), FrameStatus::ok);
    EXPECT_EQ(v.data[0], c[0]) << "RCMD";
    last.assign(v.data.begin(), v.data.end());
    return unpack_stat(get_u16(v.data, 2));
  }
  // Power on and a 1 ms cycle notified.
  void start() {
    link.power_on(0);
    std::vector<std::uint8_t> notify(16, 0);
    put_i32(notify, 0, 1'000'000);
    frame(FrameType::cycle_notify, notify, kBroadcast);
  }
  // CONNECT (profile version, synchronous, 1 cycle, profile 10h) and SYNC_SET, both answered
  // normally.
  void connect() {
    auto con = cmd(Command::connect);
    con[4] = kServoProfileVersion;
    con[5] = kComModSync;
    con[6] = 1;
    con[7] = 0x10;
    EXPECT_EQ(exchange(con).cmd_alm, CmdAlarm::normal);
    EXPECT_EQ(exchange(cmd(Command::sync_set)).cmd_alm, CmdAlarm::normal);
  }

  ServoProfile servo{config()};
  drive::AxisModel axis;
  std::vector<std::vector<std::uint8_t>> sent;
  SlaveLink link{LinkConfig{.address = 0x03}, servo,
                 [this](std::span<const std::uint8_t> f, SimTime) { sent.emplace_back(f.begin(), f.end()); }};
  SimTime t = 0;
  std::uint8_t wdt = 0;
  std::vector<std::uint8_t> last;  // the last response's data
};

// Seed 000 fig. 8 through the slave link: DISCONNECT, CONNECT, ID_RD, SVPRM_WR, SENS_ON,
// SV_ON, a motion command, SV_OFF, DISCONNECT; every response normal, phase 3 in between.
TEST(M3ServoOverTheLink, TheServoStartUpSequenceOfFigure8) {
  LinkRig r;
  ServoProfile& servo = r.servo;
  const drive::AxisModel& axis = r.axis;
  const SlaveLink& link = r.link;
  auto exchange = [&](std::vector<std::uint8_t> c) { return r.exchange(std::move(c)); };
  r.start();
  r.frame(FrameType::comm_start, std::vector<std::uint8_t>(8, 0), kBroadcast);
  EXPECT_EQ(exchange(cmd(Command::disconnect)).cmd_alm, CmdAlarm::normal);
  auto con = cmd(Command::connect);
  con[4] = kServoProfileVersion;
  con[5] = kComModSync;
  con[6] = 1;
  con[7] = 0x10;
  con[8] = con[9] = con[10] = con[11] = 0;
  EXPECT_EQ(exchange(con).cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(exchange(cmd(Command::sync_set)).cmd_alm, CmdAlarm::normal);
  ASSERT_EQ(link.phase(), Phase::p3);
  auto id = cmd(Command::id_rd);
  put_u16(id, kIdSize, 4);
  EXPECT_EQ(exchange(id).cmd_alm, CmdAlarm::normal);
  auto prm = cmd(Command::svprm_wr, {{kPrmData, 500000}});
  put_u16(prm, kPrmNo, 0x0102);
  prm[kPrmSize] = 4;
  EXPECT_EQ(exchange(prm).cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(exchange(cmd(Command::sens_on)).cmd_alm, CmdAlarm::normal);
  CmdStat st = exchange(cmd(Command::sv_on));
  EXPECT_FALSE(st.cmdrdy) << "SV_ON in progress";
  for (int k = 0; k < 10 && !st.cmdrdy; ++k) st = exchange(cmd(Command::nop));
  EXPECT_TRUE(st.cmdrdy);
  EXPECT_TRUE(servo.servo_on());
  for (int k = 0; k < 300; ++k) ASSERT_EQ(exchange(cmd(Command::velctrl, {{kVelVref, 5000}})).cmd_alm, CmdAlarm::normal);
  EXPECT_GT(axis.velocity_rad_s(), 2.5);
  EXPECT_EQ(exchange(cmd(Command::sv_off)).cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(exchange(cmd(Command::disconnect)).cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(link.phase(), Phase::p1);
  EXPECT_FALSE(servo.servo_on());
  EXPECT_EQ(link.comm_alarm(), CommAlarm::normal) << "no missed command or sync on the way";
}

// After DISCONNECT the slave's state is unknown (seed 000 fig. 8): a reconnected servo starts
// from CONNECT → SENS_ON → SV_ON again. The encoder is off, POS_SET's offset and the home
// (ZPOINT) gone, and SV_ON without SENS_ON is a condition error.
TEST(M3ServoOverTheLink, DisconnectForgetsTheEncoderAndThePositionSoSvOnNeedsSensOnAgain) {
  LinkRig r;
  const ServoProfile& servo = r.servo;
  const std::vector<std::uint8_t>& last = r.last;
  auto exchange = [&](std::vector<std::uint8_t> c) { return r.exchange(std::move(c)).cmd_alm; };
  auto connect = [&] { r.connect(); };
  r.start();
  connect();
  ASSERT_EQ(exchange(cmd(Command::sens_on)), CmdAlarm::normal);
  ASSERT_EQ(exchange(cmd(Command::sv_on)), CmdAlarm::normal);
  for (int k = 0; k < 10; ++k) exchange(cmd(Command::nop));
  ASSERT_TRUE(servo.servo_on());
  auto zret = cmd(Command::zret, {{kZretTspd, 2000}});
  zret[kZretMode] = 37;  // CiA 402 method 37: the current position is home
  for (int k = 0; k < 200; ++k) ASSERT_EQ(exchange(zret), CmdAlarm::normal);
  ASSERT_NE(get_u32(last, kSvcmdIoIn) & kIoZpoint, 0u) << "ZPOINT";
  ASSERT_EQ(exchange(cmd(Command::sv_off)), CmdAlarm::normal);
  ASSERT_EQ(exchange(cmd(Command::pos_set, {{kPosSetData, 123456}})), CmdAlarm::normal);
  ASSERT_EQ(exchange(cmd(Command::disconnect)), CmdAlarm::normal);
  EXPECT_FALSE(servo.position_ready());
  connect();
  ASSERT_EQ(exchange(cmd(Command::smon)), CmdAlarm::normal);
  EXPECT_EQ(get_u32(last, kSvcmdStat) & kPosRdy, 0u) << "POS_RDY off";
  EXPECT_LT(std::abs(get_i32(last, kMonitor1)), 20) << "APOS without the old POS_SET offset";
  EXPECT_EQ(get_u32(last, kSvcmdIoIn) & kIoZpoint, 0u) << "no ZPOINT: the home is forgotten";
  EXPECT_EQ(exchange(cmd(Command::sv_on)), CmdAlarm::condition_error) << "SV_ON needs SENS_ON first";
  for (int k = 0; k < 10; ++k) exchange(cmd(Command::nop));
  EXPECT_FALSE(servo.servo_on());
  EXPECT_EQ(exchange(cmd(Command::sens_on)), CmdAlarm::normal);
  EXPECT_EQ(exchange(cmd(Command::sv_on)), CmdAlarm::normal);
}

// A communication alarm (here a WDT error: the master's count did not advance) turns the servo
// off and holds COMM_ALM until the master clears it (profile: a communication alarm is a servo
// alarm, cleared by ALM_CLR or CMD_CTRL.ALM_CLR). Until then SV_ON is refused with CMD_ALM Ah
// and the servo stays off; after ALM_CLR and SYNC_SET it switches on again.
TEST(M3ServoOverTheLink, AfterAWatchdogAlarmSvOnIsRefusedUntilAlmClr) {
  LinkRig r;
  const ServoProfile& servo = r.servo;
  const SlaveLink& link = r.link;
  auto exchange = [&](std::vector<std::uint8_t> c, bool advance = true) { return r.exchange(std::move(c), advance); };
  r.start();
  r.connect();
  ASSERT_EQ(exchange(cmd(Command::sens_on)).cmd_alm, CmdAlarm::normal);
  ASSERT_EQ(exchange(cmd(Command::sv_on)).cmd_alm, CmdAlarm::normal);
  for (int k = 0; k < 10; ++k) exchange(cmd(Command::nop));
  ASSERT_TRUE(servo.servo_on());
  // The WDT error: servo off, phase 2, COMM_ALM Ch held.
  EXPECT_EQ(exchange(cmd(Command::nop), false).comm_alm, CommAlarm::wdt);
  for (int k = 0; k < 10; ++k) exchange(cmd(Command::nop));
  ASSERT_FALSE(servo.servo_on());
  ASSERT_EQ(link.phase(), Phase::p2);
  // SV_ON without ALM_CLR: refused, the servo stays off, the alarm stays.
  const CmdStat refused = exchange(cmd(Command::sv_on));
  EXPECT_EQ(refused.cmd_alm, CmdAlarm::condition_error);
  EXPECT_EQ(refused.comm_alm, CommAlarm::wdt);
  for (int k = 0; k < 10; ++k) exchange(cmd(Command::nop));
  EXPECT_FALSE(servo.servo_on()) << "SV_ON turned the servo on with a communication alarm standing";
  // ALM_CLR, SYNC_SET, SV_ON: on again.
  const CmdStat cleared = exchange(cmd(Command::alm_clr));
  EXPECT_EQ(cleared.cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(cleared.comm_alm, CommAlarm::normal);
  ASSERT_EQ(exchange(cmd(Command::sync_set)).cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(exchange(cmd(Command::sv_on)).cmd_alm, CmdAlarm::normal);
  for (int k = 0; k < 10; ++k) exchange(cmd(Command::nop));
  EXPECT_TRUE(servo.servo_on());
}

// The public command format, byte by byte (Σ-7 MECHATROLINK-III standard servo profile):
// INTERPOLATE's TPOS at 12 and VFF at 16, SEL_MON1/2/3 in SVCMD_CTRL bits 16-27 and echoed in
// SVCMD_STAT, CPRM_SEL_MON1/2 at 12/16 and MONITOR1/2/3 at 20/24/28 of the response. Written
// as literal bytes, so a shifted field fails here even if every constant moved with it.
TEST_F(M3Servo, FieldsSitWhereThePublicCommandFormatPutsThem) {
  servo_on();
  std::vector<std::uint8_t> f(32, 0);
  f[0] = 0x34;                        // INTERPOLATE
  f[6] = 0x50;                        // SVCMD_CTRL bits 16-23: SEL_MON1 0 (APOS), SEL_MON2 5 (FSPD)
  f[7] = 0x09;                        // bits 24-27: SEL_MON3 9 (MPOS)
  f[12] = 0xE8, f[13] = 0x03;         // TPOS 1000
  f[16] = 0x10, f[17] = 0x27;         // VFF 10000 [ref/s]
  ASSERT_EQ(send(f), CmdAlarm::normal);
  EXPECT_EQ(servo.drive().objects().velocity_offset, 10000) << "VFF taken from byte 16";
  f[16] = f[17] = 0;                  // VFF 0: the axis settles at TPOS
  for (int k = 0; k < 300; ++k) {
    ASSERT_EQ(send(f), CmdAlarm::normal);
    run(0.001);
  }
  EXPECT_EQ(rsp[6], 0x50) << "SEL_MON1/2 echoed in SVCMD_STAT bits 16-23";
  EXPECT_EQ(rsp[7], 0x09) << "SEL_MON3 echoed in bits 24-27";
  EXPECT_NE(rsp[5] & 0x20, 0) << "SV_ON: SVCMD_STAT bit 13";
  const std::int32_t apos = rsp[20] | rsp[21] << 8 | rsp[22] << 16 | rsp[23] << 24;
  EXPECT_NEAR(apos, 1000, 20) << "MONITOR1 (APOS) at byte 20";
  const std::int32_t mpos = rsp[28] | rsp[29] << 8 | rsp[30] << 16 | rsp[31] << 24;
  EXPECT_EQ(mpos, 1000) << "MONITOR3 (MPOS, the target) at byte 28";
  const std::int32_t cprm1 = rsp[12] | rsp[13] << 8 | rsp[14] << 16 | rsp[15] << 24;
  EXPECT_EQ(cprm1, apos) << "CPRM_SEL_MON1 at byte 12: APOS by default (parameter 0111h)";
  EXPECT_NE(rsp[9] & 0x40, 0) << "PSET: SVCMD_IO bit 14";
}

// CMD_PAUSE stops a POSING on its deceleration and holds; PAUSE_CMP says when it stands; the
// POSING goes on to its target once the bit clears. CMD_CANCEL stops it too, but ends it there
// (CANCEL_CMP): the target is dropped.
TEST_F(M3Servo, PauseHoldsAPosingAndCancelEndsIt) {
  servo_on();
  const std::vector<std::pair<std::size_t, std::int32_t>> to{
      {kPosTpos, 40000}, {kPosTspd, 20000}, {kPosAccr, 100000}, {kPosDecr, 100000}};
  ASSERT_EQ(send(cmd(Command::posing, to)), CmdAlarm::normal);
  run(0.5);
  const auto paused = cmd(Command::posing, to, sel_mon(0x0, 0x5, 0x2) | kCmdPause);
  ASSERT_EQ(send(paused), CmdAlarm::normal);
  EXPECT_EQ(svcmd_stat() & kPauseCmp, 0u) << "still decelerating";
  for (int k = 0; k < 400; ++k) send(paused), run(0.001);
  EXPECT_NE(svcmd_stat() & kPauseCmp, 0u) << "PAUSE_CMP once it stands";
  const std::int32_t held = monitor(0);
  EXPECT_LT(held, 30000) << "stopped short of the target";
  for (int k = 0; k < 300; ++k) send(paused), run(0.001);
  send(paused);
  EXPECT_NEAR(monitor(0), held, 5) << "held while paused";
  for (int k = 0; k < 3000; ++k) send(cmd(Command::posing, to)), run(0.001);
  EXPECT_EQ(svcmd_stat() & kPauseCmp, 0u);
  EXPECT_NEAR(monitor(0), 40000, 15) << "on to the target after the pause";
  // CANCEL on the way back to 0: it stops and stays.
  const std::vector<std::pair<std::size_t, std::int32_t>> back{
      {kPosTpos, 0}, {kPosTspd, 20000}, {kPosAccr, 100000}, {kPosDecr, 100000}};
  send(cmd(Command::posing, back));
  run(0.5);
  const auto cancel = cmd(Command::posing, back, sel_mon(0x0, 0x5, 0x2) | kCmdCancel);
  for (int k = 0; k < 600; ++k) send(cancel), run(0.001);
  EXPECT_NE(svcmd_stat() & kCancelCmp, 0u) << "CANCEL_CMP once it stands";
  const std::int32_t left = monitor(0);
  EXPECT_GT(left, 10000) << "the cancelled POSING did not reach its target";
  for (int k = 0; k < 500; ++k) send(cmd(Command::smon)), run(0.001);
  EXPECT_NEAR(monitor(0), left, 5) << "ended: no motion after the cancel";
  EXPECT_EQ(svcmd_stat() & kCancelCmp, 0u) << "SMON carries no CMD_CANCEL";
}

// VELCTRL's ACCR/DECR ramp VREF (0: at once, as before); CMD_PAUSE on VELCTRL decelerates to
// a stop (the drive core's CSV has no halt of its own) and resumes when it clears.
TEST_F(M3Servo, VelctrlRampsAtItsAccelerationAndPausesToAStop) {
  servo_on();
  const std::vector<std::pair<std::size_t, std::int32_t>> v{{kVelVref, 10000}, {kVelAccr, 20000}, {kVelDecr, 40000}};
  send(cmd(Command::velctrl, v));
  run(0.25);
  EXPECT_NEAR(axis.velocity_rad_s() / (2 * M_PI) * kCpr, 5000, 600) << "half way up the 0.5 s ramp";
  run(0.5);
  EXPECT_NEAR(axis.velocity_rad_s() / (2 * M_PI) * kCpr, 10000, 500);
  const auto paused = cmd(Command::velctrl, v, sel_mon(0x0, 0x5, 0x2) | kCmdPause);
  send(paused);
  EXPECT_EQ(svcmd_stat() & kPauseCmp, 0u);
  run(0.125);
  EXPECT_NEAR(axis.velocity_rad_s() / (2 * M_PI) * kCpr, 5000, 600) << "half way down the 0.25 s ramp";
  for (int k = 0; k < 200; ++k) send(paused), run(0.001);
  EXPECT_NE(svcmd_stat() & kPauseCmp, 0u) << "PAUSE_CMP at standstill";
  EXPECT_LT(std::abs(axis.velocity_rad_s()), 0.05);
  send(cmd(Command::velctrl, v));
  run(0.8);
  EXPECT_NEAR(axis.velocity_rad_s() / (2 * M_PI) * kCpr, 10000, 500) << "resumed";
}

// TLIM caps the torque for the command that carries it, below the parameter (0101h), and 0
// leaves the parameter's; it never rewrites the parameter.
TEST_F(M3Servo, TlimCapsTheTorqueOfItsCommandOnly) {
  servo_on();
  send(cmd(Command::velctrl, {{kVelVref, 10000}, {kVelTlim, 100}}));
  EXPECT_EQ(servo.drive().objects().max_torque, 100);
  send(cmd(Command::velctrl, {{kVelVref, 10000}}));
  EXPECT_EQ(servo.drive().objects().max_torque, 3000) << "0: the parameter's";
  send(cmd(Command::velctrl, {{kVelVref, 10000}, {kVelTlim, 60000}}));
  EXPECT_EQ(servo.drive().objects().max_torque, 3000) << "above the parameter: capped at it";
  auto rd = cmd(Command::svprm_rd);
  put_u16(rd, kPrmNo, 0x0101);
  rd[kPrmSize] = 4;
  send(rd);
  EXPECT_EQ(get_u32(rsp, kPrmData), 3000u) << "the parameter is untouched";
}

// CMD_CTRL.ALM_CLR resets a device alarm too, not only COMM_ALM (the profile: D_ALM returns
// to 0 when ALM_CLR is executed or CMD_CTRL.ALM_CLR is set), on its rising edge; ALM_CLR_CMP
// says when the clear is complete, i.e. once D_ALM is 0 (found by a protocol review: the bit
// used to say "complete" while D_ALM stayed 1).
TEST(M3ServoOverTheLink, CmdCtrlAlmClrClearsADeviceAlarmAndSaysWhenItIsDone) {
  LinkRig r;
  const ServoProfile& servo = r.servo;
  auto exchange = [&](std::vector<std::uint8_t> c) { return r.exchange(std::move(c)); };
  r.start();
  r.connect();
  auto prm = cmd(Command::svprm_wr, {{kPrmData, 50}});
  put_u16(prm, kPrmNo, 0x0100);  // following error window 50 counts
  prm[kPrmSize] = 4;
  ASSERT_EQ(exchange(prm).cmd_alm, CmdAlarm::normal);
  ASSERT_EQ(exchange(cmd(Command::sens_on)).cmd_alm, CmdAlarm::normal);
  ASSERT_EQ(exchange(cmd(Command::sv_on)).cmd_alm, CmdAlarm::normal);
  for (int k = 0; k < 10; ++k) exchange(cmd(Command::nop));
  ASSERT_TRUE(servo.servo_on());
  for (int k = 0; k < 100 && !servo.device_alarm(); ++k) exchange(cmd(Command::interpolate, {{kIpTpos, 50000}}));
  ASSERT_TRUE(servo.device_alarm());
  CmdStat st = exchange(cmd(Command::nop));
  ASSERT_TRUE(st.d_alm);
  // The fault reaction (a stop) ends in Fault; a clear is possible only there (CiA 402).
  for (int k = 0; k < 2000 && servo.drive().state() != drive::State::fault; ++k) st = exchange(cmd(Command::nop));
  ASSERT_EQ(servo.drive().state(), drive::State::fault);
  auto clear = cmd(Command::nop);
  put_u16(clear, 2, pack(CmdCtrl{.alm_clr = true, .cmd_id = 0}));
  st = exchange(clear);
  EXPECT_FALSE(st.alm_clr_cmp) << "not complete while D_ALM is 1";
  for (int k = 0; k < 5 && st.d_alm; ++k) st = exchange(clear);
  EXPECT_FALSE(st.d_alm) << "CMD_CTRL.ALM_CLR reset the drive's fault";
  EXPECT_TRUE(st.alm_clr_cmp);
  EXPECT_FALSE(servo.device_alarm());
  st = exchange(cmd(Command::nop));
  EXPECT_FALSE(st.alm_clr_cmp) << "the bit dropped: nothing to report";
}

}  // namespace
}  // namespace omnitwin::m3
