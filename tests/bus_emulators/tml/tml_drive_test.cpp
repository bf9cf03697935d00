// Tests bus_emulators/tml/tml_drive: the emulated IDM drive as a protocol core — addressing
// (axis, axis 0, groups with GROUPID/ADDGRID/REMGRID, broadcast, HOST bit), register reads and
// writes, GiveMeData → TakeData byte-exact against the seed's serial vectors, a group
// GiveMeData2 answered by each member, TakeData2 on a masked SRL change, speed mode and
// position mode run on the shared drive core against an axis model, AXISOFF, following error
// → MER + TakeData2, unknown opcodes/addresses counted, TechCAN SYNC/SETSYNC/set master time.
#include "bus_emulators/tml/tml_drive.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/tml/tml_serial.hpp"

namespace omnitwin::tml {
namespace {

constexpr SimTime kMs = 1'000'000;
using Bytes = std::vector<std::uint8_t>;

Bytes bytes_of(const Message& m) {
  const Packet p = encode_packet(m);
  return {p.bytes.begin(), p.bytes.begin() + p.size};
}

DriveSetup setup_for(std::uint8_t axis, Protocol p = Protocol::tmlcan, std::uint8_t host = 255) {
  DriveSetup s;
  s.axis = axis, s.protocol = p, s.host_axis = host;
  return s;
}

// One drive, the messages it sends, and an axis model as its wheel.
struct Rig {
  std::vector<Message> sent;
  TmlDrive d;
  drive::AxisModel wheel;
  SimTime now = 0;
  explicit Rig(const DriveSetup& s) : d(s, [this](const Message& m, SimTime) { sent.push_back(m); }) { d.power_on(0); }
  void in(const Message& m) { d.on_message(m, now); }
  void set16(std::uint16_t addr, std::uint16_t v) { in(*assign16(axis_id_code(d.axis()), addr, v)); }
  void set32(std::uint16_t addr, std::uint32_t v) { in(*assign32(axis_id_code(d.axis()), addr, v)); }
  void cmd(std::uint16_t opcode) { in(instruction(axis_id_code(d.axis()), opcode)); }
  std::uint32_t get(std::uint16_t addr, bool wide = false) {
    std::uint32_t v = 0;
    EXPECT_TRUE(d.read(addr, wide, v)) << addr;
    return v;
  }
  // n drive periods of 1 ms with the wheel in the loop (or a blocked wheel).
  drive::Command run(int n, bool blocked = false) {
    drive::Command c;
    for (int i = 0; i < n; ++i) {
      c = d.step(now, blocked ? drive::Feedback{} : wheel.feedback());
      if (!blocked) wheel.step(c, 0.001);
      now += kMs;
    }
    return c;
  }
};

std::uint16_t kpp_of(Rig& r) { return static_cast<std::uint16_t>(r.get(reg::kpp)); }

TEST(TmlDrive, AddressingAxisAxisZeroGroupsBroadcastHost) {
  Rig r(setup_for(5));
  r.in(*assign16(axis_id_code(5), reg::kpp, 1));
  EXPECT_EQ(kpp_of(r), 1);
  r.in(*assign16(axis_id_code(6), reg::kpp, 2));  // another axis
  EXPECT_EQ(kpp_of(r), 1);
  r.in(*assign16(axis_id_code(0), reg::kpp, 3));  // axis 0: every drive
  EXPECT_EQ(kpp_of(r), 3);
  r.in(*assign16(group_id_code(group_mask(1)), reg::kpp, 4));  // default group 1
  EXPECT_EQ(kpp_of(r), 4);
  r.in(*assign16(group_id_code(group_mask(2)), reg::kpp, 5));  // not a member
  EXPECT_EQ(kpp_of(r), 4);
  r.in(*assign16(group_id_code(0), reg::kpp, 6));  // broadcast
  EXPECT_EQ(kpp_of(r), 6);
  r.in(*assign16(axis_id_code(5, true), reg::kpp, 7));  // HOST bit: for the host, not executed
  EXPECT_EQ(kpp_of(r), 6);
  EXPECT_EQ(r.d.stats().for_host, 1u);
  EXPECT_EQ(r.d.stats().not_for_us, 2u);
  EXPECT_EQ(r.d.stats().handled, 4u);  // axis 5, axis 0, group 1, broadcast
}

TEST(TmlDrive, GroupIdAddGridRemGridChangeMembership) {
  Rig r(setup_for(5));
  r.in(instruction(axis_id_code(5), instr::groupid, 3));  // group 3 only
  EXPECT_EQ(r.d.groups(), 0x04);
  r.in(instruction(axis_id_code(5), instr::addgrid, 2));
  r.in(instruction(axis_id_code(5), instr::addgrid, 8));
  EXPECT_EQ(r.d.groups(), 0x86);
  r.in(instruction(axis_id_code(5), instr::remgrid, 3));
  EXPECT_EQ(r.d.groups(), 0x82);
  r.in(*assign16(group_id_code(group_mask(1)), reg::kpp, 9));  // no longer in group 1
  EXPECT_NE(kpp_of(r), 9);
  r.in(*assign16(group_id_code(group_mask(8) | group_mask(5)), reg::kpp, 10));  // any bit matches
  EXPECT_EQ(kpp_of(r), 10);
  EXPECT_EQ(r.get(reg::aar), 0x8205u);  // AAR: group ID high byte, axis ID low byte
  r.in(instruction(axis_id_code(5), instr::addgrid, 9));  // no group 9
  EXPECT_EQ(r.d.stats().refused, 1u);
  EXPECT_EQ(r.d.groups(), 0x82);
}

TEST(TmlDrive, RegisterWritesAndReads) {
  Rig r(setup_for(5));
  r.set16(reg::kpp, 0x1234);
  r.set32(reg::cpos, 0xFFFFFC18);  // −1000
  r.set32(reg::cspd, 0x00028000);  // 2.5 IU
  r.set32(reg::cacc, 0x00001000);
  r.set16(reg::srl_mask, 0x0400);
  r.set16(reg::srh_mask, 0x8000);
  r.set16(reg::mer_mask, 0x0008);
  r.set16(reg::masterid, 0x0031);
  r.set16(reg::errmax, 500);
  EXPECT_EQ(r.get(reg::kpp), 0x1234u);
  EXPECT_EQ(r.get(reg::cpos, true), 0xFFFFFC18u);
  EXPECT_EQ(r.get(reg::cpos), 0xFC18u);       // 16-bit read: the low word
  EXPECT_EQ(r.get(reg::cpos + 1), 0xFFFFu);   // and the high word at the next address
  EXPECT_EQ(r.get(reg::cspd, true), 0x00028000u);
  EXPECT_EQ(r.get(reg::cacc, true), 0x00001000u);
  EXPECT_EQ(r.get(reg::srl_mask), 0x0400u);
  EXPECT_EQ(r.get(reg::srh_mask), 0x8000u);
  EXPECT_EQ(r.get(reg::mer_mask), 0x0008u);
  EXPECT_EQ(r.get(reg::masterid), 0x0031u);
  EXPECT_EQ(r.d.core().objects().following_error_window, 500u);
  EXPECT_EQ(r.get(reg::errmax), 500u);
  // Power-on status: axis off, nothing moving (SRL.10 = 1), no fault, no error.
  EXPECT_EQ(r.get(reg::srl), 0x0400u);
  EXPECT_EQ(r.get(reg::srh), 0u);
  EXPECT_EQ(r.get(reg::mer), 0u);
  EXPECT_EQ(r.get(reg::srl, true), 0x00000400u);  // SR32 = SRH:SRL
  EXPECT_EQ(r.get(reg::poserr), 0u);
  // Read-only variables refuse writes (counted), the value stays.
  r.set32(reg::apos, 77);
  r.set16(reg::srl, 0xFFFF);
  EXPECT_EQ(r.d.stats().unknown_addresses, 2u);
  EXPECT_EQ(r.get(reg::srl), 0x0400u);
}

TEST(TmlDrive, GiveMeDataAnswersTakeDataByteExactSeedVector) {
  Rig r(setup_for(255, Protocol::rs232));
  Message req;
  ASSERT_EQ(decode_packet(Bytes{0x08, 0x0F, 0xF0, 0xB0, 0x04, 0x0F, 0xF1, 0x02, 0x5E, 0x1B}, req), PacketStatus::ok);
  r.in(req);
  ASSERT_EQ(r.sent.size(), 1u);
  EXPECT_EQ(bytes_of(r.sent[0]), (Bytes{0x0A, 0x0F, 0xF1, 0xB4, 0x04, 0x0F, 0xF0, 0x02, 0x5E, 0x01, 0x20, 0x42}));
  // After the seed's KPP = 5 the answer carries 5.
  Message set;
  ASSERT_EQ(decode_packet(Bytes{0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x05, 0x88}, set), PacketStatus::ok);
  r.in(set);
  r.in(req);
  ASSERT_EQ(r.sent.size(), 2u);
  EXPECT_EQ(r.sent[1], take_data(0x0FF1, 0x0FF0, reg::kpp, 5, false));
  EXPECT_EQ(r.d.stats().answers_sent, 2u);
  // 32-bit request: SR32.
  r.in(give_me_data(0x0FF0, 0x0FF1, reg::srl, true));
  EXPECT_EQ(r.sent.back(), take_data(0x0FF1, 0x0FF0, reg::srl, 0x00000400, true));
}

TEST(TmlDrive, GroupGiveMeData2AnsweredByEachMember) {
  Rig a(setup_for(5)), b(setup_for(7)), c(setup_for(9));
  c.d.on_message(instruction(axis_id_code(9), instr::groupid, 2), 0);  // leaves group 1
  const Message req = give_me_data2(group_id_code(group_mask(1)), axis_id_code(3), reg::poserr, false);
  for (Rig* r : {&a, &b, &c}) r->in(req);
  ASSERT_EQ(a.sent.size(), 1u);
  ASSERT_EQ(b.sent.size(), 1u);
  EXPECT_TRUE(c.sent.empty());
  EXPECT_EQ(a.sent[0], take_data2(0x0030, 5, reg::poserr, 0, false));
  EXPECT_EQ(b.sent[0], take_data2(0x0030, 7, reg::poserr, 0, false));
  // GiveMeData (not 2) to a group is refused: one axis only.
  a.in(give_me_data(group_id_code(1), axis_id_code(3), reg::kpp, false));
  EXPECT_EQ(a.sent.size(), 1u);
  EXPECT_EQ(a.d.stats().refused, 1u);
}

TEST(TmlDrive, UnknownOpcodeAndAddressCountedAndIgnored) {
  Rig r(setup_for(5));
  r.in(instruction(axis_id_code(5), 0x7777));
  EXPECT_EQ(r.d.stats().unknown_opcodes, 1u);
  r.in(give_me_data(axis_id_code(5), axis_id_code(3), 0x0250, false));
  r.in(*assign16(axis_id_code(5), 0x0251, 1));
  EXPECT_EQ(r.d.stats().unknown_addresses, 2u);
  EXPECT_TRUE(r.sent.empty());
  EXPECT_EQ(r.get(reg::mer), 0u);  // the seed names no MER bit for it
}

TEST(TmlDrive, SpeedModeMovesTheCoreVelocitySetPoint) {
  Rig r(setup_for(5));
  r.in(bitset_instruction(axis_id_code(r.d.axis()), bitset_data::mode_sp));
  r.set32(reg::cspd, 2 << 16);  // 2 counts/sample = 2000 counts/s
  r.set32(reg::cacc, 1 << 12);  // 1/16 count/sample² = 62500 counts/s²
  r.cmd(instr::axison);
  r.run(5);
  EXPECT_EQ(r.d.core().state(), drive::State::operation_enabled);
  EXPECT_EQ(r.d.srl() & bits::srl_axis_on, bits::srl_axis_on);
  EXPECT_EQ(r.d.core().objects().target_velocity, 0);  // CSPD waits for UPD
  r.cmd(instr::upd);
  r.run(200);
  EXPECT_EQ(r.d.core().mode(), drive::Mode::pv);
  EXPECT_EQ(r.d.core().objects().target_velocity, 2000);
  EXPECT_EQ(r.d.core().objects().profile_acceleration, 62500u);
  const double k = r.d.core().counts_per_load_rad();
  EXPECT_NEAR(r.wheel.velocity_rad_s() * k, 2000.0, 60.0);
  EXPECT_NEAR(static_cast<double>(static_cast<std::int32_t>(r.get(reg::aspd, true))), 2 << 16, 0.03 * (2 << 16));
  // STOP ramps down to standstill.
  r.cmd(instr::stop);
  r.run(200);
  EXPECT_NEAR(r.wheel.velocity_rad_s() * k, 0.0, 20.0);
}

TEST(TmlDrive, PositionModeReachesTargetAndSetsMotionComplete) {
  Rig r(setup_for(255, Protocol::rs232));
  r.set16(reg::srl_mask, 0x0400);
  r.in(bitset_instruction(axis_id_code(r.d.axis()), bitset_data::mode_pp));
  r.in(bitset_instruction(axis_id_code(r.d.axis()), bitset_data::cpa));
  r.cmd(instr::axison);
  r.run(5);
  ASSERT_EQ(r.d.core().state(), drive::State::operation_enabled);
  r.sent.clear();
  r.set32(reg::cpos, 5000);
  r.set32(reg::cspd, 10 << 16);  // 10000 counts/s
  r.set32(reg::cacc, 1 << 16);   // 1e6 counts/s²
  r.cmd(instr::upd);
  r.run(20);
  EXPECT_EQ(r.d.srl() & bits::srl_motion_complete, 0);  // moving
  ASSERT_EQ(r.sent.size(), 1u);  // SRL.10 1 → 0
  EXPECT_EQ(r.sent[0], take_data2(0x0FF1, 255, reg::srl, 0x00008000, true));
  r.run(1500);
  EXPECT_NEAR(static_cast<std::int32_t>(r.get(reg::apos, true)), 5000, 10);
  EXPECT_EQ(r.d.srl(), bits::srl_axis_on | bits::srl_motion_complete);
  ASSERT_EQ(r.sent.size(), 2u);  // SRL.10 0 → 1: the seed's "motion complete" TakeData2
  // The seed's vector with SRH = 0 instead of 0x0201: checksum 0x7C − 0x02 − 0x01 = 0x79.
  EXPECT_EQ(bytes_of(r.sent[1]), (Bytes{0x0A, 0x0F, 0xF1, 0xD5, 0xFF, 0x09, 0x0E, 0x84, 0x00, 0x00, 0x00, 0x79}));
  // Relative: 1000 more.
  r.in(bitset_instruction(axis_id_code(r.d.axis()), bitset_data::cpr));
  r.set32(reg::cpos, 1000);
  r.cmd(instr::upd);
  r.run(1000);
  EXPECT_NEAR(static_cast<std::int32_t>(r.get(reg::apos, true)), 6000, 10);
  EXPECT_EQ(r.d.stats().take_data2_sent, 4u);
}

// Found in review: SRL.10 followed the core's target-reached bit, which fell again when the
// position crossed the window's edge at the end of a move: 1 → 0 → 1 → 0 → 1, and a host saw
// a new motion start (seed ch. 3 example 3). It is latched now: cleared by UPD, set once.
TEST(TmlDrive, MotionCompleteIsSetOnceAtTheEndOfAPositionMove) {
  Rig r(setup_for(5, Protocol::rs232, 3));
  r.run(10);
  r.cmd(instr::axison);
  r.run(100);
  r.set16(reg::srl_mask, 0x0400);
  r.set32(reg::cpos, 5000);
  r.set32(reg::cspd, 0x00050000);  // 5 counts/sample; the default CACC
  r.cmd(instr::upd);
  r.run(4000);
  ASSERT_EQ(r.sent.size(), 2u);  // SRL.10 1 → 0 when the move starts, 0 → 1 when it ends
  EXPECT_EQ(r.sent[0], take_data2(master_id(3), 5, reg::srl, 0x00008000, true));
  EXPECT_EQ(r.sent[1], take_data2(master_id(3), 5, reg::srl, 0x00008400, true));
  EXPECT_NEAR(static_cast<std::int32_t>(r.get(reg::apos, true)), 5000, 10);
  // The next UPD starts a new motion: SRL.10 falls again, then rises once.
  r.set32(reg::cpos, 0);
  r.cmd(instr::upd);
  r.run(4000);
  ASSERT_EQ(r.sent.size(), 4u);
  EXPECT_EQ(r.sent[2], take_data2(master_id(3), 5, reg::srl, 0x00008000, true));
  EXPECT_EQ(r.sent[3], take_data2(master_id(3), 5, reg::srl, 0x00008400, true));
}

TEST(TmlDrive, AxisOffSwitchesThePowerStageOff) {
  Rig r(setup_for(5));
  r.cmd(instr::axison);
  EXPECT_TRUE(r.run(5).power);
  EXPECT_EQ(r.d.srl() & bits::srl_axis_on, bits::srl_axis_on);
  r.cmd(instr::axisoff);
  const drive::Command c = r.run(3);
  EXPECT_FALSE(c.power);
  EXPECT_EQ(r.d.srl() & bits::srl_axis_on, 0);
  EXPECT_NE(r.d.core().state(), drive::State::operation_enabled);
  r.cmd(instr::axison);
  EXPECT_TRUE(r.run(5).power);
}

TEST(TmlDrive, FollowingErrorSetsMerStopsAndSendsTakeData2) {
  Rig r(setup_for(2, Protocol::techcan, 3));
  r.set16(reg::mer_mask, bits::mer_control_error);
  r.set16(reg::errmax, 100);
  r.set16(reg::terrmax, 5);
  r.in(bitset_instruction(axis_id_code(r.d.axis()), bitset_data::mode_pp));
  r.cmd(instr::axison);
  r.run(5, true);
  r.set32(reg::cpos, 100000);
  r.set32(reg::cspd, 20 << 16);
  r.cmd(instr::upd);
  r.run(100, true);  // the wheel is blocked: the demand runs away from it
  EXPECT_EQ(r.d.mer(), bits::mer_control_error);
  EXPECT_EQ(r.d.srh() & bits::srh_fault, bits::srh_fault);
  EXPECT_EQ(r.d.srl() & bits::srl_axis_on, 0);
  ASSERT_FALSE(r.sent.empty());
  EXPECT_EQ(r.sent.back(), take_data2(master_id(3), 2, reg::mer, 0x0008, false));  // seed ch. 5 ex. 5
  const drive::Command c = r.run(1, true);
  EXPECT_FALSE(c.power);
  EXPECT_EQ(c.velocity_rad_s, 0.0);
  // FAULTR clears it (MER falls: another TakeData2), AXISON enables again.
  r.sent.clear();
  r.cmd(instr::faultr);
  r.run(3, true);
  EXPECT_EQ(r.d.mer(), 0);
  ASSERT_EQ(r.sent.size(), 1u);
  EXPECT_EQ(r.sent[0], take_data2(master_id(3), 2, reg::mer, 0, false));
  r.cmd(instr::axison);
  EXPECT_TRUE(r.run(5, true).power);
}

TEST(TmlDrive, Rs485SendsNoTypeCAndRefusesGroupRequests) {
  Rig r(setup_for(1, Protocol::rs485));
  r.set16(reg::srl_mask, 0xFFFF);
  r.cmd(instr::axison);
  r.run(5);
  EXPECT_EQ(r.d.stats().take_data2_sent, 0u);
  r.in(give_me_data2(group_id_code(1), axis_id_code(255), reg::kpp, false));
  EXPECT_TRUE(r.sent.empty());
  r.in(give_me_data(axis_id_code(1), axis_id_code(255), reg::kpp, false));  // RS-485 golden addressing
  ASSERT_EQ(r.sent.size(), 1u);
  EXPECT_EQ(r.sent[0], take_data(0x0FF0, 0x0010, reg::kpp, 0x0120, false));
}

// Found in review: every drive on an RS-485 line hears axis 0 (seed ch. 2), so a request to
// axis 0 had every drive answer at once and the answers collided (seed ch. 3).
TEST(TmlDrive, Rs485DriveDoesNotAnswerARequestToAxisZero) {
  Rig r(setup_for(1, Protocol::rs485));
  r.in(give_me_data(axis_id_code(0), axis_id_code(255), reg::kpp, false));
  r.in(give_me_data2(axis_id_code(0), axis_id_code(255), reg::kpp, false));
  EXPECT_TRUE(r.sent.empty());
  EXPECT_EQ(r.d.stats().refused, 2u);
  r.in(*assign16(axis_id_code(0), reg::kpp, 3));  // a type A message to axis 0 still executes
  EXPECT_EQ(kpp_of(r), 3);
  // Point to point (RS-232) the one drive answers axis 0 with its own axis.
  Rig p(setup_for(1, Protocol::rs232));
  p.in(give_me_data(axis_id_code(0), host_id_code(1), reg::kpp, false));
  ASSERT_EQ(p.sent.size(), 1u);
  EXPECT_EQ(p.sent[0], take_data(host_id_code(1), axis_id_code(1), reg::kpp, 0x0120, false));
}

// Found in review: ID codes with bits 15–13 or 3–1 set (zero by chapter 2) were executed: id_of()
// of 0x2050 and 0x005E is 5.
TEST(TmlDrive, MessagesWithMalformedIdCodesAreDropped) {
  Rig r(setup_for(5, Protocol::rs232, 3));
  r.in(*assign16(0x2050, reg::kpp, 77));
  r.in(*assign16(0x005E, reg::kpp, 78));
  r.in(give_me_data(0x0052, host_id_code(3), reg::kpp, false));
  EXPECT_EQ(kpp_of(r), 0x0120);
  EXPECT_TRUE(r.sent.empty());
  EXPECT_EQ(r.d.stats().invalid_id_codes, 3u);
  EXPECT_EQ(r.d.stats().handled, 0u);
}

TEST(TmlDrive, TechCanSyncSetSyncAndMasterTime) {
  Rig master(setup_for(1, Protocol::techcan)), slave(setup_for(2, Protocol::techcan));
  slave.d.power_on(7 * kMs);  // powered 7 ms later: its clock lags by 7 ms
  master.cmd(instr::setsync);  // no data word: refused
  EXPECT_EQ(master.d.stats().refused, 1u);
  master.in(instruction(axis_id_code(1), instr::setsync, 20));
  EXPECT_TRUE(master.d.sync_master());
  EXPECT_EQ(master.get(reg::sync_period), 20u);
  slave.now = 7 * kMs;
  master.now = 0;
  // Both step on the same timeline; the master's messages reach the slave.
  for (SimTime t = 7 * kMs; t < 70 * kMs; t += kMs) {
    master.now = t;
    master.d.step(t, drive::Feedback{});
    for (const Message& m : master.sent) slave.d.on_message(m, t);
    master.sent.clear();
    slave.d.step(t, drive::Feedback{});
  }
  EXPECT_EQ(master.d.stats().syncs_sent, 3u);  // at 20, 40, 60 ms
  EXPECT_EQ(slave.d.stats().syncs_received, 3u);
  EXPECT_EQ(slave.d.drive_time_ms(70 * kMs), master.d.drive_time_ms(70 * kMs));
  EXPECT_EQ(slave.d.drive_time_ms(70 * kMs), 70u);
  // A SYNC alone latches the time; a master time then moves the clock by the difference.
  Rig lone(setup_for(3, Protocol::techcan));
  lone.now = 1000 * kMs;
  lone.in(sync_message());
  EXPECT_EQ(lone.get(reg::sync_time, true), 1000u);
  lone.in(set_master_time(0x0246C46F));
  EXPECT_EQ(lone.d.drive_time_ms(1000 * kMs), 0x0246C46Fu);
  EXPECT_EQ(lone.d.drive_time_ms(1005 * kMs), 0x0246C46Fu + 5);
  // SETSYNC is a CAN service: refused on RS-232.
  Rig serial(setup_for(4, Protocol::rs232));
  serial.in(instruction(axis_id_code(4), instr::setsync, 20));
  EXPECT_FALSE(serial.d.sync_master());
}

TEST(TmlDrive, SetUpErrorsAndPowerOff) {
  EXPECT_THROW(TmlDrive(setup_for(0), nullptr), std::invalid_argument);
  EXPECT_THROW(TmlDrive(setup_for(40, Protocol::techcan), nullptr), std::invalid_argument);
  Rig r(setup_for(5));
  r.d.power_off();
  r.in(*assign16(axis_id_code(5), reg::kpp, 1));
  EXPECT_EQ(r.d.stats().handled, 0u);
  EXPECT_FALSE(r.run(1).power);
}

}  // namespace
}  // namespace omnitwin::tml
