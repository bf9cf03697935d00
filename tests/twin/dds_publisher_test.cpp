// Tests of the DDS publisher (twin/dds/dds_publisher.hpp) with C API readers in the same
// process, on loopback, on a domain of this test process alone: every state topic carries
// the exact values offered (pose, yaw quaternion, body-frame twist, wheel names, sim-time
// stamps), cmd_vel is skipped while the command is unknown, 1 kHz offered at 100 Hz
// publishes every 10th sample, a late reader still gets the run's events, a full ring drops
// (and counts) instead of blocking, set-up errors throw DdsError, and two publishers on two
// domains in one process stay apart; the test domains of two processes never meet.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <stdlib.h>
#include <sys/file.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <vector>

#include "tests/support/temp_dir.hpp"
#include "tests/twin/dds_test_support.hpp"
#include "twin/dds/dds_messages.hpp"
#include "twin/dds/dds_publisher.hpp"

namespace omnitwin::twin {
namespace {

using ddstest::make_sample;
using ddstest::test_domain;
using ddstest::TestReader;

namespace fs = std::filesystem;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

DdsSettings loopback_settings(int domain, double rate_hz = 1000) {
  DdsSettings s;
  s.domain = domain;
  s.interface = "lo";
  s.rate_hz = rate_hz;
  return s;
}

RunInfo run_info(const std::string& scenario) {
  return RunInfo{scenario, "can", "lockstep", "/tmp/run", 0.001, 2.0};
}

TEST(DdsPublisher, PlatformStateCarriesTheExactValuesOffered) {
  DdsPublisher pub(loopback_settings(test_domain()));
  TestReader reader(test_domain(), "state");
  ASSERT_TRUE(reader.wait_matched());
  pub.start(run_info("exact"));
  for (std::uint64_t i = 0; i < 5; ++i) EXPECT_TRUE(pub.offer(make_sample(i)));
  pub.finish();
  std::vector<omnitwin_msg_dds__PlatformState_> got;
  reader.take<omnitwin_msg_dds__PlatformState_>(5, [&](const auto& m) { got.push_back(m); });
  ASSERT_EQ(got.size(), 5u);
  for (std::uint64_t i = 0; i < 5; ++i) {
    const StateSample s = make_sample(i);
    const auto& m = got[i];
    EXPECT_EQ(m.t_ns, s.t_ns);
    EXPECT_EQ(m.seq, i);
    EXPECT_EQ(m.x, s.x);
    EXPECT_EQ(m.y, s.y);
    EXPECT_EQ(m.phi, s.phi);
    EXPECT_EQ(m.vx, s.vx);
    EXPECT_EQ(m.vy, s.vy);
    EXPECT_EQ(m.wz, s.wz);
    EXPECT_EQ(m.ref_x, s.ref_x);
    EXPECT_EQ(m.ref_y, s.ref_y);
    EXPECT_EQ(m.ref_phi, s.ref_phi);
    EXPECT_EQ(m.cmd_vx, s.cmd_vx);
    EXPECT_EQ(m.cmd_vy, s.cmd_vy);
    EXPECT_EQ(m.cmd_wz, s.cmd_wz);
    for (std::size_t w = 0; w < 4; ++w) {
      EXPECT_EQ(m.wheel_angle[w], s.wheel_angle[w]);
      EXPECT_EQ(m.wheel_speed[w], s.wheel_speed[w]);
      EXPECT_EQ(m.wheel_cmd[w], s.wheel_cmd[w]);
      EXPECT_EQ(m.wheel_torque[w], s.wheel_torque[w]);
    }
    EXPECT_EQ(m.active_faults, s.active_faults);
  }
  EXPECT_EQ(pub.stats().published, 5u);
}

TEST(DdsPublisher, OdometryIsRosShapedWithYawQuaternionAndBodyTwist) {
  DdsPublisher pub(loopback_settings(test_domain()));
  TestReader reader(test_domain(), "odom");
  ASSERT_TRUE(reader.wait_matched());
  pub.start(run_info("odom"));
  StateSample s = make_sample(3);
  s.t_ns = 2'500'000'123;  // 2 s + 500000123 ns
  s.phi = 0.5;             // world twist (1, 0) seen from a frame turned by 0.5 rad
  s.vx = 1.0, s.vy = 0.0;
  pub.offer(s);
  pub.finish();
  int n = reader.take<nav_msgs_msg_dds__Odometry_>(1, [&](const nav_msgs_msg_dds__Odometry_& m) {
    EXPECT_EQ(m.header.stamp.sec, 2);
    EXPECT_EQ(m.header.stamp.nanosec, 500000123u);
    EXPECT_STREQ(m.header.frame_id, "world");
    EXPECT_STREQ(m.child_frame_id, "base_link");
    EXPECT_EQ(m.pose.pose.position.x, s.x);
    EXPECT_EQ(m.pose.pose.position.y, s.y);
    EXPECT_EQ(m.pose.pose.position.z, 0.0);
    EXPECT_EQ(m.pose.pose.orientation.x, 0.0);
    EXPECT_EQ(m.pose.pose.orientation.y, 0.0);
    EXPECT_DOUBLE_EQ(m.pose.pose.orientation.z, std::sin(0.25));
    EXPECT_DOUBLE_EQ(m.pose.pose.orientation.w, std::cos(0.25));
    EXPECT_DOUBLE_EQ(m.twist.twist.linear.x, std::cos(0.5));
    EXPECT_DOUBLE_EQ(m.twist.twist.linear.y, -std::sin(0.5));
    EXPECT_EQ(m.twist.twist.angular.z, s.wz);
    for (double c : m.pose.covariance) EXPECT_EQ(c, 0.0);
  });
  EXPECT_EQ(n, 1);
}

TEST(DdsPublisher, JointStatesNameTheWheelsAndStampSimTime) {
  DdsPublisher pub(loopback_settings(test_domain()));
  TestReader reader(test_domain(), "joint_states");
  ASSERT_TRUE(reader.wait_matched());
  pub.start(run_info("joints"));
  const StateSample s = make_sample(7);
  pub.offer(s);
  pub.finish();
  int n = reader.take<sensor_msgs_msg_dds__JointState_>(1, [&](const sensor_msgs_msg_dds__JointState_& m) {
    EXPECT_EQ(ddsmsg::to_ns(m.header.stamp), s.t_ns);
    ASSERT_EQ(m.name._length, 4u);
    ASSERT_EQ(m.position._length, 4u);
    ASSERT_EQ(m.velocity._length, 4u);
    ASSERT_EQ(m.effort._length, 4u);
    for (std::uint32_t w = 0; w < 4; ++w) {
      EXPECT_EQ(std::string(m.name._buffer[w]), "wheel" + std::to_string(w + 1));
      EXPECT_EQ(m.position._buffer[w], s.wheel_angle[w]);
      EXPECT_EQ(m.velocity._buffer[w], s.wheel_speed[w]);
      EXPECT_EQ(m.effort._buffer[w], s.wheel_torque[w]);
    }
  });
  EXPECT_EQ(n, 1);
}

// /clock as ROS 2 reads it with use_sim_time: rt/clock, rosgraph_msgs/Clock, the sample's
// simulated time split into seconds and nanoseconds.
TEST(DdsPublisher, ClockCarriesTheSimulatedTimeOnRos2Clock) {
  const std::optional<TopicInfo> topic = find_topic("clock");
  ASSERT_TRUE(topic.has_value());
  EXPECT_EQ(topic->name, "rt/clock");
  EXPECT_EQ(topic->type_name, "rosgraph_msgs::msg::dds_::Clock_");
  EXPECT_EQ(topic->label(), "clock");
  DdsPublisher pub(loopback_settings(test_domain()));
  TestReader reader(test_domain(), "clock");
  ASSERT_TRUE(reader.wait_matched());
  pub.start(run_info("clock"));
  StateSample s = make_sample(3);
  s.t_ns = 12'000'000'250;  // 12 s 250 ns
  pub.offer(s);
  pub.finish();
  const int n = reader.take<rosgraph_msgs_msg_dds__Clock_>(1, [&](const rosgraph_msgs_msg_dds__Clock_& m) {
    EXPECT_EQ(m.clock.sec, 12);
    EXPECT_EQ(m.clock.nanosec, 250u);
  });
  EXPECT_EQ(n, 1);
}

TEST(DdsPublisher, DrivesAndBusStatisticsFollowTheSample) {
  DdsPublisher pub(loopback_settings(test_domain()));
  TestReader drives(test_domain(), "drives"), bus(test_domain(), "bus");
  ASSERT_TRUE(drives.wait_matched() && bus.wait_matched());
  pub.start(run_info("drives"));
  const StateSample s = make_sample(11);
  pub.offer(s);
  pub.finish();
  EXPECT_EQ(drives.take<omnitwin_msg_dds__DriveStates_>(1, [&](const omnitwin_msg_dds__DriveStates_& m) {
    EXPECT_EQ(m.seq, 11u);
    for (std::size_t w = 0; w < 4; ++w) {
      EXPECT_EQ(m.drives[w].node, w + 1);
      EXPECT_STREQ(m.drives[w].state_name, w == 2 ? "fault" : "running");
      EXPECT_EQ(m.drives[w].state, w == 2 ? 4 : 2);
      EXPECT_EQ(m.drives[w].command_rad_s, s.drives[w].command_rad_s);
      EXPECT_EQ(m.drives[w].setpoint_rad_s, s.drives[w].setpoint_rad_s);
      EXPECT_EQ(m.drives[w].dac_code, s.drives[w].dac_code);
      EXPECT_EQ(m.drives[w].encoder_count, s.drives[w].encoder_count);
    }
  }), 1);
  EXPECT_EQ(bus.take<omnitwin_msg_dds__BusStatistics_>(1, [&](const omnitwin_msg_dds__BusStatistics_& m) {
    EXPECT_STREQ(m.bus, "can");
    EXPECT_TRUE(m.has_frames);
    EXPECT_EQ(m.frames_tx, 110u);
    EXPECT_EQ(m.frames_rx, 99u);
    EXPECT_EQ(m.dropouts, 3u);
    EXPECT_EQ(m.errors, 2u);
    EXPECT_EQ(m.load, s.bus.load);
  }), 1);
}

TEST(DdsPublisher, CmdVelIsTheBodyFrameCommandAndSkippedWhenUnknown) {
  DdsPublisher pub(loopback_settings(test_domain()));
  TestReader reader(test_domain(), "cmd_vel");
  ASSERT_TRUE(reader.wait_matched());
  pub.start(run_info("cmd"));
  StateSample known = make_sample(0), unknown = make_sample(1);
  known.phi = -1.0, known.cmd_vx = 0.0, known.cmd_vy = 2.0, known.cmd_wz = 0.3;
  unknown.cmd_vx = unknown.cmd_vy = unknown.cmd_wz = kNaN;
  pub.offer(known);
  pub.offer(unknown);
  pub.finish();
  std::vector<geometry_msgs_msg_dds__Twist_> got;
  reader.take<geometry_msgs_msg_dds__Twist_>(2, [&](const auto& m) { got.push_back(m); }, 0.2);
  ASSERT_EQ(got.size(), 1u);  // the unknown command is not published
  EXPECT_DOUBLE_EQ(got[0].linear.x, 2.0 * std::sin(-1.0));
  EXPECT_DOUBLE_EQ(got[0].linear.y, 2.0 * std::cos(-1.0));
  EXPECT_EQ(got[0].angular.z, 0.3);
  EXPECT_EQ(pub.stats().published, 2u);
}

TEST(DdsPublisher, OneKilohertzAtOneHundredHertzPublishesEveryTenthSample) {
  DdsPublisher pub(loopback_settings(test_domain(), 100));
  TestReader reader(test_domain(), "state");
  ASSERT_TRUE(reader.wait_matched());
  pub.start(run_info("rate"));
  for (std::uint64_t i = 0; i < 100; ++i) pub.offer(make_sample(i));
  pub.finish();
  std::vector<std::uint64_t> seqs;
  reader.take<omnitwin_msg_dds__PlatformState_>(10, [&](const auto& m) { seqs.push_back(m.seq); });
  EXPECT_EQ(seqs, (std::vector<std::uint64_t>{0, 10, 20, 30, 40, 50, 60, 70, 80, 90}));
  const DdsPublisher::Stats st = pub.stats();
  EXPECT_EQ(st.offered, 100u);
  EXPECT_EQ(st.skipped, 90u);
  EXPECT_EQ(st.published, 10u);
  EXPECT_EQ(st.dropped, 0u);
}

TEST(RateDecimator, AnOfferPeriodThatDoesNotDivideKeepsTheAverageRate) {
  RateDecimator d(100);  // 10 ms
  int taken = 0;
  for (std::int64_t t = 0; t < 3'000'000'000; t += 3'000'000) taken += d.take(t);
  EXPECT_NEAR(taken, 300, 1);  // 3 s at 100 Hz
}

TEST(RateDecimator, RoundingJitterDoesNotSkipASample) {
  RateDecimator d(100);
  EXPECT_TRUE(d.take(0));
  EXPECT_FALSE(d.take(5'000'000));
  EXPECT_TRUE(d.take(9'999'999));    // 10 ms less 1 ns of rounding
  EXPECT_TRUE(d.take(20'000'001));
  EXPECT_TRUE(d.take(5'000'000));    // time went back (a new run): the grid restarts
  EXPECT_FALSE(d.take(6'000'000));
}

TEST(DdsPublisher, LateReaderGetsTheRunEventsThenTheEnd) {
  DdsPublisher pub(loopback_settings(test_domain()));
  pub.start(run_info("late"));
  pub.event(RunEvent{1'000'000, RunEventKind::fault, "fault", "node 2 power loss"});
  pub.event(RunEvent{2'000'000, RunEventKind::info, "master", "recovered"});
  ASSERT_TRUE(ddstest::wait_until([&] { return pub.stats().events == 3; }));
  TestReader reader(test_domain(), "events");  // joins after the events went out
  std::vector<std::string> got;
  reader.take<omnitwin_msg_dds__RunEvent_>(3, [&](const omnitwin_msg_dds__RunEvent_& m) {
    got.push_back(std::string(m.kind_name) + "|" + m.source + "|" + m.text + "|" + m.scenario);
  });
  ASSERT_EQ(got.size(), 3u);
  EXPECT_EQ(got[0].rfind("start|twin|scenario=late bus=can clock=lockstep", 0), 0u) << got[0];
  EXPECT_EQ(got[1], "fault|fault|node 2 power loss|late");
  EXPECT_EQ(got[2], "info|master|recovered|late");
  pub.finish();
  int ends = reader.take<omnitwin_msg_dds__RunEvent_>(1, [&](const omnitwin_msg_dds__RunEvent_& m) {
    EXPECT_STREQ(m.kind_name, "end");
    EXPECT_EQ(m.kind, static_cast<std::uint8_t>(RunEventKind::end));
  });
  EXPECT_EQ(ends, 1);
}

// The source timestamps of what `reader` holds, in the order taken, with each sample's text
// from `name` (the event's kind, or "" for a state).
template <class T>
std::vector<std::pair<dds_time_t, std::string>> stamps(dds_entity_t reader, std::string (*name)(const T&)) {
  std::vector<std::pair<dds_time_t, std::string>> out;
  ddstest::wait_until([&] {
    void* samples[64] = {nullptr};
    dds_sample_info_t infos[64];
    const dds_return_t n = dds_take(reader, samples, infos, 64, 64);
    for (dds_return_t i = 0; i < n; ++i)
      if (infos[i].valid_data) out.emplace_back(infos[i].source_timestamp, name(*static_cast<const T*>(samples[i])));
    if (n > 0) dds_return_loan(reader, samples, n);
    return false;
  }, 0.5);
  return out;
}

// Events go out after every sample offered before them, so a reader gets the run's end after
// its last state: the publishing thread sent all queued events before the states still in the
// ring, and the end came 20–100 states early (found in review). Samples offered before start()
// wait in the ring; the event queued after them must follow them on the wire (the writers'
// source timestamps), the start event precede them.
TEST(DdsPublisher, EventsGoOutAfterTheSamplesOfferedBeforeThem) {
  const int domain = test_domain(3);
  DdsPublisher pub(loopback_settings(domain));
  TestReader states(domain, "state"), events(domain, "events");
  ASSERT_TRUE(states.wait_matched());
  ASSERT_TRUE(events.wait_matched());
  for (std::uint64_t i = 0; i < 50; ++i) ASSERT_TRUE(pub.offer(make_sample(i)));
  pub.event(RunEvent{49'000'000, RunEventKind::info, "master", "after 50 states"});
  pub.start(run_info("order"));
  pub.finish();
  const auto st = stamps<omnitwin_msg_dds__PlatformState_>(
      states.get(), +[](const omnitwin_msg_dds__PlatformState_&) { return std::string(); });
  const auto ev = stamps<omnitwin_msg_dds__RunEvent_>(
      events.get(), +[](const omnitwin_msg_dds__RunEvent_& m) { return std::string(m.kind_name); });
  ASSERT_EQ(st.size(), 50u);
  ASSERT_EQ(ev.size(), 3u);
  EXPECT_EQ(ev[0].second, "start");
  EXPECT_EQ(ev[1].second, "info");
  EXPECT_EQ(ev[2].second, "end");
  EXPECT_LE(ev[0].first, st.front().first) << "the start event precedes the first state";
  EXPECT_GE(ev[1].first, st.back().first) << "an event went out before states offered before it";
  EXPECT_GE(ev[2].first, st.back().first);
}

// outputs.dds.wait_for_readers counts readers of any state topic: a ROS 2 node reads rt/clock,
// not our platform_state, and only that one counted (found in review).
TEST(DdsPublisher, AReaderOfTheClockAloneCountsForWaitForReaders) {
  const int domain = test_domain(4);
  DdsPublisher pub(loopback_settings(domain));
  EXPECT_EQ(pub.wait_for_readers(1, 0.0), 0);
  TestReader clock(domain, "clock");
  EXPECT_EQ(pub.wait_for_readers(1, 5.0), 1);
}

// A configuration file whose path holds a comma: Cyclone splits its configuration string at
// commas, so the path was cut there and the file not found (found in review).
TEST(DdsPublisher, AConfigFileWhosePathHoldsACommaIsRead) {
  omnitwin::testing::TempDir dir("omnitwin-dds");
  fs::create_directories(dir / "com,ma");
  fs::copy_file(ddstest::loopback_config(), dir / "com,ma/loopback.xml");
  DdsSettings s = loopback_settings(test_domain(5));
  s.interface.clear();
  s.config_file = (dir / "com,ma/loopback.xml").string();
  DdsPublisher pub(s);
  EXPECT_EQ(pub.endpoint().config_file, s.config_file);
}

TEST(DdsPublisher, AnEndEventGivenByTheRunIsNotRepeated) {
  DdsPublisher pub(loopback_settings(test_domain()));
  pub.start(run_info("end"));
  pub.event(RunEvent{5, RunEventKind::end, "scenario", "done"});
  pub.finish();
  pub.finish();  // idempotent
  EXPECT_EQ(pub.stats().events, 2u);  // start + the run's end
}

TEST(DdsPublisher, AFullRingDropsAndCountsInsteadOfBlocking) {
  DdsSettings s = loopback_settings(test_domain());
  s.queue_capacity = 8;
  DdsPublisher pub(s);
  int accepted = 0;
  for (std::uint64_t i = 0; i < 20; ++i) accepted += pub.offer(make_sample(i));  // no consumer yet
  EXPECT_EQ(accepted, 8);
  EXPECT_EQ(pub.stats().dropped, 12u);
  pub.start(run_info("full"));
  pub.finish();
  const DdsPublisher::Stats st = pub.stats();
  EXPECT_EQ(st.offered, 20u);
  EXPECT_EQ(st.published, 8u);
  EXPECT_EQ(st.dropped, 12u);
}

TEST(DdsPublisher, SetUpErrorsThrowDdsErrorNamingTheCause) {
  DdsSettings bad_if = loopback_settings(test_domain());
  bad_if.interface = "omnitwin-nx0";
  try {
    DdsPublisher p(bad_if);
    ADD_FAILURE() << "no DdsError for a missing interface";
  } catch (const DdsError& e) {
    EXPECT_NE(std::string(e.what()).find("'omnitwin-nx0' does not exist"), std::string::npos) << e.what();
  }
  DdsSettings bad_domain = loopback_settings(233);
  EXPECT_THROW(DdsPublisher{bad_domain}, DdsError);
  DdsSettings bad_rate = loopback_settings(test_domain(), 0);
  EXPECT_THROW(DdsPublisher{bad_rate}, DdsError);
  DdsSettings missing = loopback_settings(test_domain());
  missing.config_file = "/nonexistent/cyclonedds.xml";
  EXPECT_THROW(DdsPublisher{missing}, DdsError);
}

TEST(DdsPublisher, AMalformedConfigFileIsADdsError) {
  omnitwin::testing::TempDir dir("omnitwin-dds");
  std::ofstream(dir / "bad.xml") << "<CycloneDDS><Domain id=\"any\"><NoSuchElement/></Domain></CycloneDDS>\n";
  DdsSettings s = loopback_settings(test_domain());
  s.config_file = (dir / "bad.xml").string();
  EXPECT_THROW(DdsPublisher{s}, DdsError);
}

TEST(DdsPublisher, DomainAndInterfaceComeFromTheEnvironmentWhenNotSet) {
  ::setenv("OMNITWIN_DDS_DOMAIN", std::to_string(test_domain()).c_str(), 1);
  ::setenv("OMNITWIN_DDS_INTERFACE", "lo", 1);
  {
    DdsPublisher pub(DdsSettings{});
    EXPECT_EQ(pub.endpoint().domain, test_domain());
    EXPECT_EQ(pub.endpoint().interface, "lo");
  }
  ::setenv("OMNITWIN_DDS_DOMAIN", "seven", 1);
  EXPECT_THROW(DdsPublisher{DdsSettings{}}, DdsError);
  ::unsetenv("OMNITWIN_DDS_DOMAIN");
  ::unsetenv("OMNITWIN_DDS_INTERFACE");
}

TEST(DdsPublisher, TwoPublishersOnTwoDomainsInOneProcessStayApart) {
  DdsPublisher a(loopback_settings(test_domain(0)));
  DdsSettings sb = loopback_settings(test_domain(1));
  sb.config_file = ddstest::loopback_config();
  DdsPublisher b(sb);
  TestReader ra(test_domain(0), "state"), rb(test_domain(1), "state");
  ASSERT_TRUE(ra.wait_matched() && rb.wait_matched());
  a.start(run_info("a"));
  b.start(run_info("b"));
  a.offer(make_sample(1));
  b.offer(make_sample(2));
  a.finish();
  b.finish();
  std::vector<std::uint64_t> sa, sb_seen;
  ra.take<omnitwin_msg_dds__PlatformState_>(2, [&](const auto& m) { sa.push_back(m.seq); }, 0.2);
  rb.take<omnitwin_msg_dds__PlatformState_>(2, [&](const auto& m) { sb_seen.push_back(m.seq); }, 0.2);
  EXPECT_EQ(sa, std::vector<std::uint64_t>{1});
  EXPECT_EQ(sb_seen, std::vector<std::uint64_t>{2});
}

// The test domains: a process keeps its ids, and no other process (parallel ctest) can take
// one of them while this one lives, because it cannot lock the id's file; pid mod 230 gave
// two processes one domain in CI.
TEST(DdsTestDomain, AnotherProcessCannotTakeADomainThisOneOwns) {
  const int mine0 = test_domain(0), mine1 = test_domain(1);
  EXPECT_NE(mine0, mine1);
  EXPECT_EQ(test_domain(0), mine0);
  for (int id : {mine0, mine1}) {
    EXPECT_GE(id, 1);
    EXPECT_LE(id, 232);
    // What another process's owned_dds_domain does: a new open of the file, a try-lock.
    const std::string path = std::string(omnitwin::testing::kDdsDomainLockDir) + "/" + std::to_string(id);
    const int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
    ASSERT_GE(fd, 0) << path;
    EXPECT_NE(::flock(fd, LOCK_EX | LOCK_NB), 0) << "domain " << id << " is free to others";
    ::close(fd);
  }
}

}  // namespace
}  // namespace omnitwin::twin
