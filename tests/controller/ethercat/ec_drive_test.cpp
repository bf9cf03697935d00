// Tests controller/ethercat/ec_drive: statusword decoding and the goal → controlword table,
// then the drive layer on the master against four emulated drives (EscChain + DriveSlaves):
// goals drive the axes to operation enabled, PDO objects are written/read through the image,
// other objects through queued SDOs (requests_pending), and the `go` bit is cleared once the
// drive acknowledges a profile-position set-point; a lost segment quick-stops every axis, and
// they stay stopped when it returns; a drive's CoE emergency code reaches the Botnana word
// drive-emcy@.
#include "controller/ethercat/ec_drive.hpp"

#include <gtest/gtest.h>

#include "controller/botnana/botnana_interpreter.hpp"
#include "ec_bench.hpp"

using namespace omnitwin::controller::ethercat;
using omnitwin::botnana::PdsGoal;
using ecbench::Bench;

TEST(EcDrive, DecodesTheStatusword) {
  EXPECT_EQ(decode_statusword(0x0000), PdsState::not_ready_to_switch_on);
  EXPECT_EQ(decode_statusword(0x0250), PdsState::switch_on_disabled);
  EXPECT_EQ(decode_statusword(0x0231), PdsState::ready_to_switch_on);
  EXPECT_EQ(decode_statusword(0x0233), PdsState::switched_on);
  EXPECT_EQ(decode_statusword(0x0237), PdsState::operation_enabled);
  EXPECT_EQ(decode_statusword(0x1637), PdsState::operation_enabled);  // mode bits ignored
  EXPECT_EQ(decode_statusword(0x0217), PdsState::quick_stop_active);
  EXPECT_EQ(decode_statusword(0x021F), PdsState::fault_reaction_active);
  EXPECT_EQ(decode_statusword(0x0218), PdsState::fault);
}

TEST(EcDrive, ControlwordTowardsEachGoal) {
  EXPECT_EQ(controlword_towards(PdsState::switch_on_disabled, PdsGoal::operation_enabled), 0x0006);
  EXPECT_EQ(controlword_towards(PdsState::ready_to_switch_on, PdsGoal::operation_enabled), 0x0007);
  EXPECT_EQ(controlword_towards(PdsState::switched_on, PdsGoal::operation_enabled), 0x000F);
  EXPECT_EQ(controlword_towards(PdsState::operation_enabled, PdsGoal::operation_enabled), 0x000F);
  EXPECT_EQ(controlword_towards(PdsState::quick_stop_active, PdsGoal::operation_enabled), 0x000F);
  EXPECT_EQ(controlword_towards(PdsState::operation_enabled, PdsGoal::quick_stop_active), 0x0002);
  EXPECT_EQ(controlword_towards(PdsState::operation_enabled, PdsGoal::switched_on), 0x0007);
  EXPECT_EQ(controlword_towards(PdsState::operation_enabled, PdsGoal::ready_to_switch_on), 0x0006);
  EXPECT_EQ(controlword_towards(PdsState::operation_enabled, PdsGoal::switch_on_disabled), 0x0000);
  EXPECT_EQ(controlword_towards(PdsState::switch_on_disabled, PdsGoal::switched_on), 0x0006);
  EXPECT_EQ(controlword_towards(PdsState::quick_stop_active, PdsGoal::switched_on), 0x0000);
}

TEST(EcDrive, GoalsEnableEveryAxisAndVelocityFlowsBothWays) {
  EcMasterConfig cfg;
  cfg.startup.push_back(StartupSdo{-1, 0x6060, 0, {9}});  // CSV
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  EcDrives& d = *b.drives;
  EXPECT_EQ(d.axis_count(), 4);
  EXPECT_TRUE(d.has_drive(4, 1));
  EXPECT_FALSE(d.has_drive(5, 1));
  EXPECT_FALSE(d.has_drive(1, 2));
  for (int s = 1; s <= 4; ++s) d.set_goal(s, 1, PdsGoal::operation_enabled);
  ASSERT_TRUE(b.run_until([&] { return d.all_enabled(); }, 2000));
  for (int s = 1; s <= 4; ++s) EXPECT_EQ(d.state(s, 1), PdsState::operation_enabled);
  EXPECT_EQ(b.slaves[0]->axis(0).objects().controlword & 0x008F, 0x000F);
  ASSERT_TRUE(d.write(2, 1, 0x60FF, 0, 5000));  // counts/s, PDO
  for (int k = 0; k < 300; ++k) b.step();
  EXPECT_EQ(b.slaves[1]->axis(0).objects().target_velocity, 5000);
  const auto v = d.read(2, 1, 0x606C, 0);
  ASSERT_TRUE(v.has_value());
  EXPECT_GT(*v, 4000);
  EXPECT_EQ(*v, b.slaves[1]->axis(0).objects().velocity_actual);
  const auto p = d.read(2, 1, 0x6064, 0);
  ASSERT_TRUE(p.has_value());
  EXPECT_GT(*p, 0);
  EXPECT_EQ(d.read(1, 1, 0x6041, 0), b.slaves[0]->axis(0).objects().statusword);
  EXPECT_FALSE(d.write(2, 1, 0x6064, 0, 1)) << "an input object cannot be written";
  EXPECT_EQ(d.slaves(), 4);
  EXPECT_FALSE(d.user_pdo(1, 1, omnitwin::botnana::UserPdo::wpdo1).has_value());
  d.set_user_pdo(omnitwin::botnana::UserPdo::wpdo1, {0x60B1, 0});
  const auto ref = d.user_pdo(1, 1, omnitwin::botnana::UserPdo::wpdo1);
  ASSERT_TRUE(ref.has_value());
  EXPECT_EQ(ref->index, 0x60B1);
  EXPECT_FALSE(d.user_pdo(9, 1, omnitwin::botnana::UserPdo::wpdo1).has_value());
  EXPECT_FALSE(d.last_error().empty());
}

TEST(EcDrive, ObjectsOutsideThePdoGoThroughSdo) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  EcDrives& d = *b.drives;
  ASSERT_TRUE(d.write(3, 1, 0x6083, 0, 250000));  // profile acceleration: not mapped
  EXPECT_TRUE(d.requests_pending(3));
  EXPECT_FALSE(d.requests_pending(2));
  ASSERT_TRUE(b.run_until([&] { return !d.requests_pending(3); }, 500));
  EXPECT_EQ(b.slaves[2]->axis(0).objects().profile_acceleration, 250000u);
  EXPECT_FALSE(d.read(3, 1, 0x6081, 0).has_value());  // first read queues an upload
  EXPECT_TRUE(d.requests_pending(3));
  ASSERT_TRUE(b.run_until([&] { return !d.requests_pending(3); }, 500));
  EXPECT_EQ(d.read(3, 1, 0x6081, 0), static_cast<std::int64_t>(b.slaves[2]->axis(0).objects().profile_velocity));
  EXPECT_FALSE(d.write(7, 1, 0x6083, 0, 1));
  EXPECT_NE(d.last_error().find("slave 7"), std::string::npos);
}

TEST(EcDrive, GoBitIsClearedWhenTheDriveAcknowledges) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  EcDrives& d = *b.drives;
  ASSERT_TRUE(d.write(1, 1, 0x6060, 0, 1));  // PP through the PDO
  d.write(1, 1, 0x6081, 0, 20000);
  d.write(1, 1, 0x6083, 0, 200000);
  d.write(1, 1, 0x6084, 0, 200000);
  d.set_goal(1, 1, PdsGoal::operation_enabled);
  ASSERT_TRUE(b.run_until([&] { return d.state(1, 1) == PdsState::operation_enabled && !d.requests_pending(1); }, 2000));
  ASSERT_TRUE(d.write(1, 1, 0x607A, 0, 1000));
  const auto cw = d.read(1, 1, 0x6040, 0);
  ASSERT_TRUE(cw.has_value());
  ASSERT_TRUE(d.write(1, 1, 0x6040, 0, *cw | 0x10));  // go
  EXPECT_EQ(*d.read(1, 1, 0x6040, 0) & 0x10, 0x10);
  ASSERT_TRUE(b.run_until([&] { return (*d.read(1, 1, 0x6040, 0) & 0x10) == 0; }, 200));
  EXPECT_EQ(b.slaves[0]->axis(0).objects().target_position, 1000);
  ASSERT_TRUE(b.run_until([&] { return (d.statusword(1, 1) & 0x0400) && b.slaves[0]->axis(0).objects().position_actual > 900; }, 5000));
}

TEST(EcDrive, HomingAttainedSetsTheHomedRecord) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  EcDrives& d = *b.drives;
  EXPECT_EQ(d.homed(1, 1), false);
  EXPECT_FALSE(d.homed(9, 1).has_value());
  ASSERT_TRUE(d.write(1, 1, 0x6060, 0, 6));   // HM through the PDO
  ASSERT_TRUE(d.write(1, 1, 0x6098, 0, 37));  // method 37: the current position is home (SDO)
  d.set_goal(1, 1, PdsGoal::operation_enabled);
  ASSERT_TRUE(b.run_until([&] { return d.state(1, 1) == PdsState::operation_enabled && !d.requests_pending(1); }, 2000));
  EXPECT_EQ(d.homed(1, 1), false);
  ASSERT_TRUE(d.write(1, 1, 0x6040, 0, *d.read(1, 1, 0x6040, 0) | 0x10));  // start homing
  ASSERT_TRUE(b.run_until([&] { return d.homed(1, 1) == true; }, 3000)) << std::hex << d.statusword(1, 1);
  EXPECT_EQ(d.homed(2, 1), false);
  d.set_homed(1, 1, false);
  EXPECT_EQ(d.homed(1, 1), false);
}

TEST(EcDrive, LostSegmentQuickStopsEveryAxisAndTheyStayStoppedWhenItReturns) {
  EcMasterConfig cfg;
  cfg.startup.push_back(StartupSdo{-1, 0x6060, 0, {9}});  // CSV
  cfg.segment_loss_cycles = 3;
  cfg.segment_loss_ns = 0;  // the cycle count alone (1 ms cycles)
  cfg.probe_every_ns = 10'000'000;
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  EcDrives& d = *b.drives;
  for (int s = 1; s <= 4; ++s) d.set_goal(s, 1, PdsGoal::operation_enabled);
  ASSERT_TRUE(b.run_until([&] { return d.all_enabled(); }, 2000));
  for (int s = 1; s <= 4; ++s) ASSERT_TRUE(d.write(s, 1, 0x60FF, 0, 5000));
  for (int k = 0; k < 100; ++k) b.step();
  EXPECT_FALSE(d.stopped());
  b.drop_next = 100;
  for (int k = 0; k < 10; ++k) b.step();
  ASSERT_TRUE(b.master->segment_lost());
  EXPECT_TRUE(d.stopped());
  const auto target = b.master->find_entry(1, 0x60FF, 0);
  ASSERT_TRUE(target.has_value());
  EXPECT_EQ(b.master->read_entry(*target, true), 0) << "the velocity set-point that goes out when it returns";
  ASSERT_TRUE(b.run_until([&] { return b.master->operational(); }, 20000));
  for (int k = 0; k < 300; ++k) b.step();
  for (int s = 0; s < 4; ++s) {
    EXPECT_NE(d.state(s + 1, 1), PdsState::operation_enabled) << "slave " << s + 1;
    EXPECT_EQ(b.slaves[s]->axis(0).objects().target_velocity, 0);
    EXPECT_EQ(b.slaves[s]->axis(0).objects().velocity_actual, 0);
  }
  d.set_goal(1, 1, PdsGoal::operation_enabled);
  EXPECT_FALSE(d.stopped()) << "a new goal lifts the stop";
}

TEST(EcDrive, TheLastEmergencyOfADriveIsWhatDriveEmcyFetches) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  std::string out;
  omnitwin::botnana::Interpreter in(*b.drives, [&](std::string_view s) { out += s; });
  ASSERT_TRUE(in.evaluate("1 3 drive-emcy@ .").ok);
  EXPECT_EQ(out, "-1 ");  // none received yet
  b.slaves[2]->axis(0).raise_fault(omnitwin::drive::kErrorFollowing);
  ASSERT_TRUE(b.run_until([&] { return b.master->stats().emergencies >= 1; }, 100));
  out.clear();
  ASSERT_TRUE(in.evaluate("1 3 drive-emcy@ . 1 2 drive-emcy@ . 1 3 drive-fault? .").ok);
  EXPECT_EQ(out, "34321 -1 -1 ");  // 0x8611 on slave 3; slave 2 sent nothing; fault flag true
  EXPECT_FALSE(in.evaluate("1 9 drive-emcy@").ok);
}

namespace {
// Steps the bench with the interpreter's tasks until none runs (or max steps); whether none does.
bool run_tasks(Bench& b, omnitwin::botnana::Interpreter& in, int max_steps) {
  return b.run_until([&] { return in.step_tasks() == 0; }, max_steps);
}
}  // namespace

// Found in review: -1 went out to 0x6081 (UNSIGNED32) as 4294967295, 257 to 0x6060 (INTEGER8)
// as mode 1, 2^32 + 1000 to 0x607A as 1000. A value that does not fit the object's type is
// refused, naming the value and the range, and nothing goes out (neither SDO nor image).
TEST(EcDrive, AValueThatDoesNotFitTheObjectsTypeIsRefusedAndNothingGoesOut) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  EcDrives& d = *b.drives;
  EXPECT_FALSE(d.write(1, 1, 0x6081, 0, -1));  // UNSIGNED32, SDO
  EXPECT_NE(d.last_error().find("-1"), std::string::npos) << d.last_error();
  EXPECT_NE(d.last_error().find("0..4294967295"), std::string::npos) << d.last_error();
  EXPECT_FALSE(d.requests_pending(1)) << "nothing queued";
  ASSERT_TRUE(d.write(1, 1, 0x6060, 0, 3));    // INTEGER8 in the image
  EXPECT_FALSE(d.write(1, 1, 0x6060, 0, 257));
  EXPECT_NE(d.last_error().find("-128..127"), std::string::npos) << d.last_error();
  EXPECT_EQ(d.read(1, 1, 0x6060, 0), 3) << "the image keeps the last good value";
  EXPECT_FALSE(d.write(1, 1, 0x607A, 0, 4294968296LL));  // INTEGER32 in the image
  EXPECT_FALSE(d.write(1, 1, 0x607A, 0, 2147483648LL));
  EXPECT_TRUE(d.write(1, 1, 0x607A, 0, -2147483648LL));
  EXPECT_FALSE(d.write(1, 1, 0x6040, 0, 65536));       // the controlword: UNSIGNED16
  EXPECT_TRUE(d.write(1, 1, 0x6081, 0, 4294967295LL));
  std::string out;
  omnitwin::botnana::Interpreter in(d, [&](std::string_view s) { out += s; });
  const auto s = in.evaluate("257 1 2 op-mode!");
  ASSERT_FALSE(s.ok);
  EXPECT_EQ(s.word, "op-mode!");
  EXPECT_NE(s.message.find("257"), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("-128..127"), std::string::npos) << s.message;
}

// Found in review: homing method 99 was aborted by the drive, and until-no-requests returned as
// if it had been set. The seed: until-no-requests waits until the command is actually set in
// the drive; an abort fails the task, naming the object and the abort code.
TEST(EcDrive, AnSdoDownloadTheDriveAbortsFailsUntilNoRequestsNamingTheObjectAndTheCode) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  std::string out;
  omnitwin::botnana::Interpreter in(*b.drives, [&](std::string_view s) { out += s; });
  ASSERT_TRUE(in.evaluate("deploy 99 1 1 homing-method! until-no-requests .\" carried on\" ;deploy").ok);
  ASSERT_TRUE(run_tasks(b, in, 500));
  EXPECT_EQ(out.find("carried on"), std::string::npos) << out;
  const auto& e = in.last_task_error();
  ASSERT_FALSE(e.ok);
  EXPECT_EQ(e.word, "until-no-requests");
  EXPECT_NE(e.message.find("0x6098"), std::string::npos) << e.message;
  EXPECT_NE(e.message.find("0x06090030"), std::string::npos) << e.message;
  // The failure was reported once: a later good request waits and succeeds.
  out.clear();
  ASSERT_TRUE(in.evaluate("deploy 37 1 1 homing-method! until-no-requests .\" set\" ;deploy").ok);
  ASSERT_TRUE(run_tasks(b, in, 500));
  EXPECT_EQ(out, "set");
  EXPECT_EQ(b.slaves[0]->axis(0).objects().homing_method, 37);
}

// Seed 004: drive-nsl@ / drive-psl@ give the limits the master read back from the drive at
// boot. Found in review: the first use failed ("not available"), the upload only queued then.
TEST(EcDrive, TheSoftwareLimitsAreReadBackAtStartUpSoTheWordsAnswerAtOnce) {
  EcMasterConfig cfg;
  cfg.read_back = {{0x607D, 1}, {0x607D, 2}};
  Bench b(2, cfg);
  b.slaves[1]->axis(0).objects().sw_limit_min = -50000;
  b.slaves[1]->axis(0).objects().sw_limit_max = 70000;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  std::string out;
  omnitwin::botnana::Interpreter in(*b.drives, [&](std::string_view s) { out += s; });
  const auto s = in.evaluate("1 2 drive-nsl@ . 1 2 drive-psl@ .");
  ASSERT_TRUE(s.ok) << s.to_string();
  EXPECT_EQ(out, "-50000 70000 ");
  EXPECT_FALSE(b.drives->requests_pending(2)) << "answered from the start-up read-back";
}

// A drive without 0x607D: the start-up upload is aborted (the slave still reaches OP) and the
// word says that the drive has no such object.
TEST(EcDrive, ADriveWithoutSoftwareLimitsReachesOpAndTheWordSaysSo) {
  EcMasterConfig cfg;
  cfg.read_back = {{0x607D, 1}, {0x607D, 7}};  // sub 7 does not exist
  Bench b(1, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  omnitwin::botnana::Interpreter in(*b.drives);
  ASSERT_TRUE(in.evaluate("1 1 drive-nsl@ drop").ok);
  EXPECT_FALSE(b.drives->read(1, 1, 0x607D, 7).has_value());
  EXPECT_NE(b.drives->last_error().find("has no object 0x607D:07"), std::string::npos) << b.drives->last_error();
  EXPECT_FALSE(b.drives->requests_pending(1)) << "no second upload of an object the drive lacks";
}

// Seed 004: +drive-homed / -drive-homed / drive-homed? are "a record the master provides".
// Found in review: drive-homed? read only the interpreter's list, not the master's record
// (which homing attained sets).
TEST(EcDrive, DriveHomedAsksTheMastersHomedRecord) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  EcDrives& d = *b.drives;
  std::string out;
  omnitwin::botnana::Interpreter in(d, [&](std::string_view s) { out += s; });
  ASSERT_TRUE(in.evaluate("deploy hm 1 1 op-mode! 37 1 1 homing-method! until-no-requests "
                          "1 1 drive-on 1 1 until-drive-on 1 1 go 1 1 until-target-reached ;deploy").ok);
  ASSERT_TRUE(run_tasks(b, in, 5000));
  ASSERT_TRUE(in.last_task_error().ok) << in.last_task_error().to_string();
  ASSERT_EQ(d.homed(1, 1), true);
  ASSERT_TRUE(in.evaluate("1 1 drive-homed? . 1 2 drive-homed? .").ok);
  EXPECT_EQ(out, "-1 0 ");
  ASSERT_TRUE(in.evaluate("1 1 -drive-homed 1 2 +drive-homed").ok);
  EXPECT_EQ(d.homed(1, 1), false);
  EXPECT_EQ(d.homed(2, 1), true);
}

// Seed 004: drive-cw! sets the controlword directly. Found in review: after drive-on the
// master's goal overlaid bits 0-3 and 7, so 6 drive-cw! (shutdown) was silently ignored.
// drive-cw! takes the controlword back from the goal until the next goal word.
TEST(EcDrive, DriveCwTakesTheControlwordBackFromTheGoal) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.step();
  EcDrives& d = *b.drives;
  omnitwin::botnana::Interpreter in(d);
  ASSERT_TRUE(in.evaluate("1 1 drive-on").ok);
  ASSERT_TRUE(b.run_until([&] { return d.state(1, 1) == PdsState::operation_enabled; }, 2000));
  ASSERT_TRUE(in.evaluate("6 1 1 drive-cw!").ok);
  ASSERT_TRUE(b.run_until([&] { return d.state(1, 1) == PdsState::ready_to_switch_on; }, 200))
      << to_string(*d.state(1, 1));
  EXPECT_EQ(b.slaves[0]->axis(0).objects().controlword, 0x0006);
  ASSERT_TRUE(in.evaluate("1 1 go").ok);  // a bit word keeps the written word
  for (int k = 0; k < 20; ++k) b.step();
  EXPECT_EQ(d.state(1, 1), PdsState::ready_to_switch_on);
  ASSERT_TRUE(in.evaluate("1 1 drive-on").ok);  // a goal word takes it over again
  ASSERT_TRUE(b.run_until([&] { return d.state(1, 1) == PdsState::operation_enabled; }, 2000));
}
