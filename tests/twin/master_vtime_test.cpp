// Tests of lockstep for masters we did not write (twin/master_vtime, twin/vtime/):
//  - the channel's codec: round trip, golden bytes, every rejection;
//  - the preload library on a probe program (tests/twin/vtime/vt_probe.c, plain libc) against a
//    scripted twin end: each intercepted call's return value, errno and simulated time as the
//    kernel would give them on the simulated clock (clocks, sleeps, the poll/select/epoll
//    families, every receive with SO_RCVTIMEO and MSG_DONTWAIT, relative, periodic and absolute
//    timerfds, timed and clock waits on condition variables), the busy-poll rule on receives
//    and on clock reads alone, two threads, and a fork (refused);
//  - regressions found in review, one probe mode each (thread ids reused, wake-ups by the
//    process itself, signal handlers, overflowing timeouts, timerfd flags, MSG_WAITALL, …);
//  - the command line: omni-master --clock wall under the library through `omnitwin run
//    --master-cmd` reruns byte for byte and moves the platform as its --clock sim run does; the
//    same on bus can; a master's own shutdown after the run's SIGTERM is served (virtual clock
//    and realtime); the bad masters (exits early, crashes, never waits, ignores SIGTERM,
//    static, forks) each give exit 3, a message that says what happened, and records.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <poll.h>

#include <map>
#include <sstream>
#include <thread>

#include "tests/twin/cli_support.hpp"
#include "twin/master_process.hpp"
#include "twin/master_vtime.hpp"

namespace {

using namespace omnitwin::twin;
using namespace omnitwin::twin::cli;
namespace vt = omnitwin::vtime;

constexpr long long kMono = 1000'000'000'000LL;  // the library's CLOCK_MONOTONIC at t = 0

// ---- codec --------------------------------------------------------------------------------

TEST(VtimeCodec, RoundTripsEveryField) {
  vt::Record r;
  r.type = vt::Type::wait;
  r.wake_on_frame = 1;
  r.pid = 1234;
  r.ppid = 99;
  r.seq = 0x0102030405060708ULL;
  r.now = 10'000'000;
  r.deadline = 20'000'000;
  r.frames = 77;
  r.code = 5;
  const auto b = vt::encode(r);
  const auto d = vt::decode(b.data(), b.size());
  ASSERT_TRUE(d.has_value());
  EXPECT_EQ(vt::encode(*d), b);
  EXPECT_EQ(d->seq, r.seq);
  EXPECT_EQ(d->deadline, r.deadline);
  EXPECT_EQ(d->wake_on_frame, 1);
}

TEST(VtimeCodec, GoldenWakeBytes) {
  vt::Record r;
  r.type = vt::Type::wake;
  r.seq = 1;
  r.now = 1'000'000;  // 1 ms
  r.frames = 2;
  const auto b = vt::encode(r);
  const std::uint8_t head[] = {0x4f, 0x56, 0x54, 0x4d, 0x01, 0x00, 0x04, 0x00};  // "OVTM", v1, wake
  EXPECT_EQ(0, std::memcmp(b.data(), head, sizeof head));
  EXPECT_EQ(b[16], 1);
  EXPECT_EQ(b[24], 0x40);  // 1'000'000 = 0x0F4240
  EXPECT_EQ(b[25], 0x42);
  EXPECT_EQ(b[26], 0x0f);
  EXPECT_EQ(b[40], 2);
  EXPECT_EQ(b[32 + 7], 0x7f);  // the default deadline: never (INT64_MAX)
}

TEST(VtimeCodec, RejectsWhatItCannotReencode) {
  vt::Record r;
  r.type = vt::Type::end;
  const auto good = vt::encode(r);
  EXPECT_FALSE(vt::decode(good.data(), 63));
  auto b = good;
  b[0] ^= 1;  // magic
  EXPECT_FALSE(vt::decode(b.data(), b.size()));
  b = good;
  b[4] = 2;  // version
  EXPECT_FALSE(vt::decode(b.data(), b.size()));
  b = good;
  b[6] = 7;  // type
  EXPECT_FALSE(vt::decode(b.data(), b.size()));
  b = good;
  b[7] = 2;  // wake_on_frame
  EXPECT_FALSE(vt::decode(b.data(), b.size()));
  b = good;
  b[60] = 1;  // padding
  EXPECT_FALSE(vt::decode(b.data(), b.size()));
}

TEST(VtimeCommand, KnowsWhatThePreloadCannotReach) {
  EXPECT_EQ(preload_obstacle(OMNITWIN_BINARY_DIR "/tests/vt_probe"), "");
  EXPECT_TRUE(preload_obstacle(OMNITWIN_BINARY_DIR "/tests/vt_probe_static").starts_with("statically linked"));
  EXPECT_EQ(preload_obstacle("no-such-program-anywhere"), "not found on PATH");
  EXPECT_TRUE(preload_obstacle(OMNITWIN_SOURCE_DIR "/scripts/bootstrap").starts_with("not an ELF"));
}

// ---- the library on the probe, against a scripted twin --------------------------------------

// A twin end that wakes every wait at its deadline (no bus, no frames).
struct ScriptedTwin {
  VtimeServer server;
  SimTime now = 0;
  std::vector<vt::Record> waits;

  VtimeServer::Status serve() {
    for (;;) {
      vt::Record w;
      const VtimeServer::Status st = server.next_wait(w, std::chrono::seconds(5), now);
      if (st != VtimeServer::Status::ok) return st;
      waits.push_back(w);
      if (w.deadline == vt::kNever) return VtimeServer::Status::protocol;  // would wait for ever
      now = w.deadline;
      server.wake(w.seq, now, 0);
    }
  }
};

std::map<std::string, long long> probe_values(const std::string& text, std::vector<std::string>* order = nullptr) {
  std::map<std::string, long long> v;
  std::istringstream in(text);
  std::string name;
  long long value = 0;
  while (in >> name >> value) {
    v[name] = value;
    if (order) order->push_back(name);
  }
  return v;
}

class VtimeProbe : public ::testing::Test {
 protected:
  std::string probe() const { return OMNITWIN_BINARY_DIR "/tests/vt_probe"; }

  // The probe in `mode` against a scripted twin, to its end: its values, its output, how the
  // channel ended and the exit code (-1: still running after 5 s, then stopped).
  struct Run {
    std::map<std::string, long long> v;
    std::string text;
    VtimeServer::Status status = VtimeServer::Status::ok;
    int exit = -1;
  };
  Run run_mode(const std::string& mode) {
    ScriptedTwin twin;
    const std::string log = (dir_.path() / (mode + ".log")).string();
    MasterProcess p(probe(), {mode}, log, twin.server.environment(find_vtime_library(), "udp:127.0.0.1:9"));
    Run r;
    if (twin.server.accept(std::chrono::seconds(10), 0) == VtimeServer::Status::ok) r.status = twin.serve();
    if (p.wait(std::chrono::seconds(5))) r.exit = p.exit_code();
    r.text = read_bytes(log);
    r.v = probe_values(r.text);
    return r;
  }

  TempDir dir_{"omnitwin-vtime"};
};

TEST_F(VtimeProbe, EveryInterceptedCallAnswersAsTheKernelWouldOnSimulatedTime) {
  ScriptedTwin twin;
  const std::string log = (dir_.path() / "probe.log").string();
  MasterProcess p(probe(), {"calls"}, log, twin.server.environment(find_vtime_library(), "udp:127.0.0.1:9"));
  ASSERT_EQ(twin.server.accept(std::chrono::seconds(10), 0), VtimeServer::Status::ok);
  EXPECT_EQ(twin.serve(), VtimeServer::Status::closed) << read_bytes(log);
  ASSERT_TRUE(p.wait(std::chrono::seconds(10))) << read_bytes(log);
  EXPECT_EQ(p.exit_code(), 0) << read_bytes(log);
  std::vector<std::string> order;
  auto v = probe_values(read_bytes(log), &order);
  const std::string text = read_bytes(log);
  // Clocks at t = 0.
  EXPECT_EQ(v["mono"], kMono) << text;
  EXPECT_EQ(v["boot"], kMono);
  EXPECT_EQ(v["real_s"], 1767225600);
  EXPECT_EQ(v["tod_s"], 1767225600);
  EXPECT_EQ(v["time"], 1767225600);
  // Sleeps: exactly their length; an absolute deadline in the past returns at once.
  EXPECT_EQ(v["nanosleep_rc"], 0);
  EXPECT_EQ(v["after_nanosleep"], kMono + 1'500'000);
  EXPECT_EQ(v["abs_rc"], 0);
  EXPECT_EQ(v["after_abs"], kMono + 10'000'000);
  EXPECT_EQ(v["past_rc"], 0);
  EXPECT_EQ(v["after_past"], kMono + 10'000'000);
  EXPECT_EQ(v["bad_rc"], EINVAL);  // clock_nanosleep returns the error
  EXPECT_EQ(v["bad_nanosleep_rc"], -1);  // nanosleep sets errno
  EXPECT_EQ(v["bad_nanosleep_errno"], EINVAL);
  EXPECT_EQ(v["after_usleep"], kMono + 10'250'000);
  EXPECT_EQ(v["sleep_rc"], 0);
  const long long t1 = kMono + 1'010'250'000;
  EXPECT_EQ(v["after_sleep"], t1);
  // Descriptor waits time out after their timeout, returning 0 (select zeroes its timeval).
  EXPECT_EQ(v["poll_rc"], 0);
  EXPECT_EQ(v["after_poll"], t1 + 7'000'000);
  EXPECT_EQ(v["select_rc"], 0);
  EXPECT_EQ(v["select_tv"], 0);
  EXPECT_EQ(v["after_select"], t1 + 10'000'000);
  EXPECT_EQ(v["ppoll_rc"], 0);
  EXPECT_EQ(v["after_ppoll"], t1 + 12'000'000);
  EXPECT_EQ(v["epoll_rc"], 0);
  EXPECT_EQ(v["after_epoll"], t1 + 14'000'000);
  // SO_RCVTIMEO: -1 with EAGAIN after the timeout (as the kernel holds it: in whole jiffies).
  EXPECT_EQ(v["recv_rc"], -1);
  EXPECT_EQ(v["recv_errno"], EAGAIN);
  EXPECT_GE(v["rcvtimeo_ns"], 5'000'000);
  const long long t2 = t1 + 14'000'000 + v["rcvtimeo_ns"];
  EXPECT_EQ(v["after_recv"], t2);
  // The busy-poll rule: the 64th call in a row that finds nothing lets 1 µs pass.
  EXPECT_EQ(v["dontwait_rc"], -1);
  EXPECT_EQ(v["dontwait_errno"], EAGAIN);
  EXPECT_EQ(v["after_spin"], t2 + 1'000);
  // A datagram already there is taken at once.
  EXPECT_EQ(v["self_rc"], 1);
  EXPECT_EQ(v["after_self"], t2 + 1'000);
  // A periodic timerfd: one expiration per read, each a period apart.
  EXPECT_EQ(v["timerfd_settime_rc"], 0);
  EXPECT_EQ(v["timerfd_read_rc"], 8);
  EXPECT_EQ(v["timerfd_n"], 1);
  EXPECT_EQ(v["after_timerfd"], t2 + 1'000 + 3'000'000);
  EXPECT_EQ(v["timerfd_left"], 1'000'000);
  // A condition variable nobody signals times out at its deadline.
  EXPECT_EQ(v["cond_rc"], ETIMEDOUT);
  const long long t3 = t2 + 1'000 + 7'000'000;
  EXPECT_EQ(v["after_cond"], t3);
  // Two threads on 3 ms and 5 ms periods, in time order; joined when both are done.
  const std::vector<std::pair<std::string, long long>> ticks{
      {"tick3000", t3 + 3'000'000}, {"tick5000", t3 + 5'000'000}, {"tick3000", t3 + 6'000'000},
      {"tick3000", t3 + 9'000'000}, {"tick5000", t3 + 10'000'000}, {"tick5000", t3 + 15'000'000}};
  std::vector<std::pair<std::string, long long>> seen;
  std::istringstream in(text);
  std::string name;
  long long value = 0;
  while (in >> name >> value)
    if (name.starts_with("tick")) seen.emplace_back(name, value);
  EXPECT_EQ(seen, ticks) << text;
  EXPECT_EQ(v["after_join"], t3 + 15'000'000);
  // The other variants: C11's clock; recvfrom, recvmsg and read on the socket time out after
  // its SO_RCVTIMEO each; pselect and epoll_pwait time out; an empty non-blocking timerfd is
  // EAGAIN; an absolute timerfd fires at its instant; a spin on clock reads alone advances
  // 1 µs per 64 reads; pthread_cond_clockwait times out on its clock.
  const long long t4 = t3 + 15'000'000;
  const long long rt = v["rcvtimeo_ns"];
  EXPECT_EQ(v["timespec_get_s"], 1767225600 + (t4 - kMono) / 1'000'000'000);
  EXPECT_EQ(v["recvfrom_rc"], -1);
  EXPECT_EQ(v["recvfrom_errno"], EAGAIN);
  EXPECT_EQ(v["after_recvfrom"], t4 + rt);
  EXPECT_EQ(v["recvmsg_rc"], -1);
  EXPECT_EQ(v["recvmsg_errno"], EAGAIN);
  EXPECT_EQ(v["after_recvmsg"], t4 + 2 * rt);
  EXPECT_EQ(v["read_rc"], -1);
  EXPECT_EQ(v["read_errno"], EAGAIN);
  const long long t5 = t4 + 3 * rt;
  EXPECT_EQ(v["after_read"], t5);
  EXPECT_EQ(v["pselect_rc"], 0);
  EXPECT_EQ(v["after_pselect"], t5 + 3'000'000);
  EXPECT_EQ(v["epoll_pwait_rc"], 0);
  EXPECT_EQ(v["after_epoll_pwait"], t5 + 7'000'000);
  EXPECT_EQ(v["timerfd_empty_rc"], -1);
  EXPECT_EQ(v["timerfd_empty_errno"], EAGAIN);
  EXPECT_EQ(v["timerfd_poll_rc"], 1);
  EXPECT_EQ(v["timerfd_abs_read_rc"], 8);
  EXPECT_EQ(v["after_timerfd_abs"], t5 + 9'000'000);
  EXPECT_EQ(v["after_spin_clock"], t5 + 11'000'000);
  EXPECT_EQ(v["clockwait_rc"], ETIMEDOUT);
  EXPECT_EQ(v["after_clockwait"], t5 + 12'000'000);
}

TEST_F(VtimeProbe, ReRunsAreIdenticalWaitForWait) {
  std::vector<std::vector<vt::Record>> runs;
  for (int i = 0; i < 2; ++i) {
    ScriptedTwin twin;
    MasterProcess p(probe(), {"calls"}, (dir_.path() / "p.log").string(),
                    twin.server.environment(find_vtime_library(), "udp:127.0.0.1:9"));
    ASSERT_EQ(twin.server.accept(std::chrono::seconds(10), 0), VtimeServer::Status::ok);
    twin.serve();
    p.wait(std::chrono::seconds(10));
    runs.push_back(twin.waits);
  }
  ASSERT_EQ(runs[0].size(), runs[1].size());
  for (std::size_t i = 0; i < runs[0].size(); ++i) EXPECT_EQ(vt::encode(runs[0][i]), vt::encode(runs[1][i])) << i;
}

TEST_F(VtimeProbe, AForkedChildIsRefusedAndEnds) {
  ScriptedTwin twin;
  const std::string log = (dir_.path() / "fork.log").string();
  MasterProcess p(probe(), {"fork"}, log, twin.server.environment(find_vtime_library(), "udp:127.0.0.1:9"));
  ASSERT_EQ(twin.server.accept(std::chrono::seconds(10), 0), VtimeServer::Status::ok);
  EXPECT_EQ(twin.serve(), VtimeServer::Status::second_process);
  EXPECT_GT(twin.server.other_pid(), 0);
  EXPECT_NE(twin.server.other_pid(), p.pid());
  // The child says so once the Refuse reaches it: give it up to 2 s (before the stop, which
  // ends what the master started, the child with it).
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  while (!contains(read_bytes(log), "the twin refused process") && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_TRUE(contains(read_bytes(log), "the twin refused process")) << read_bytes(log);
  p.stop(std::chrono::milliseconds(500));
  EXPECT_FALSE(p.descendants_alive());  // nothing the master started is left behind
}

// ---- regressions: each found in review, each failed on the library before its fix ----------

// glibc reuses the id of a thread that was joined: a join on the new thread must wait for it,
// not take the old one's end for its own (it blocked in the kernel and held time still).
TEST_F(VtimeProbe, JoinWaitsForANewThreadThatReusesAnEndedThreadsId) {
  const Run r = run_mode("join-reuse");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_GE(r.v.at("join_reused"), 1) << "glibc did not reuse an id: the test proves nothing\n" << r.text;
  std::istringstream in(r.text);
  std::string name;
  long long value = 0;
  int joins = 0;
  while (in >> name >> value)
    if (name == "join_took") {
      EXPECT_EQ(value, 1'000'000) << r.text;
      ++joins;
    }
  EXPECT_EQ(joins, 4) << r.text;
}

// A pipe or eventfd written by one thread wakes the thread that polls it at once, not when the
// writer's next sleep (200 ms) has passed.
TEST_F(VtimeProbe, AWriteByAnotherThreadWakesItsWaiterWithoutTimeMoving) {
  const Run r = run_mode("self-wake");
  ASSERT_EQ(r.exit, 0) << r.text;
  std::istringstream in(r.text);
  std::string name;
  long long value = 0;
  std::vector<long long> rc, after;
  while (in >> name >> value) {
    if (name == "wake_rc") rc.push_back(value);
    if (name == "wake_after") after.push_back(value);
  }
  EXPECT_EQ(rc, (std::vector<long long>{1, 1})) << r.text;        // the pipe, the eventfd
  EXPECT_EQ(after, (std::vector<long long>{1'000'000, 1'000'000})) << r.text;
}

// Reruns of it stay identical wait for wait (the library checks its own descriptors before it
// asks the twin to move time).
TEST_F(VtimeProbe, SelfWakesRerunIdenticallyWaitForWait) {
  std::vector<std::vector<vt::Record>> runs;
  for (int i = 0; i < 2; ++i) {
    ScriptedTwin twin;
    MasterProcess p(probe(), {"self-wake"}, (dir_.path() / "w.log").string(),
                    twin.server.environment(find_vtime_library(), "udp:127.0.0.1:9"));
    ASSERT_EQ(twin.server.accept(std::chrono::seconds(10), 0), VtimeServer::Status::ok);
    twin.serve();
    p.wait(std::chrono::seconds(5));
    runs.push_back(twin.waits);
  }
  ASSERT_EQ(runs[0].size(), runs[1].size());
  for (std::size_t i = 0; i < runs[0].size(); ++i) EXPECT_EQ(vt::encode(runs[0][i]), vt::encode(runs[1][i])) << i;
}

// A signal handler that reads the clock (async-signal-safe) while the interrupted code holds
// the library's lock: it gets the simulated time, and nothing deadlocks (on the old library
// 10 runs in 10 hung).
TEST_F(VtimeProbe, ASignalHandlerThatReadsTheClockDoesNotDeadlock) {
  const Run r = run_mode("signal-clock");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.status, VtimeServer::Status::closed);
  EXPECT_GT(r.v.at("alarm_runs"), 0) << "no signal came: the test proves nothing";
  EXPECT_EQ(r.v.at("alarm_off_clock"), 0);
}

// TFD_TIMER_ABSTIME on a CLOCK_REALTIME timerfd: the instant is on the realtime clock.
TEST_F(VtimeProbe, AnAbsoluteRealtimeTimerfdFiresAtItsInstant) {
  const Run r = run_mode("timerfd-realtime");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("rt_settime_rc"), 0);
  EXPECT_EQ(r.v.at("rt_left"), 2'000'000) << r.text;
  EXPECT_EQ(r.v.at("rt_poll_rc"), 1) << r.text;
  EXPECT_EQ(r.v.at("rt_after"), 2'000'000) << r.text;
}

// A timeout that ends at the instant a descriptor becomes ready reports the descriptor.
TEST_F(VtimeProbe, ReadinessAtTheTimeoutsInstantIsReportedAsReady) {
  const Run r = run_mode("tie");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("tie_poll_rc"), 1) << r.text;
  EXPECT_EQ(r.v.at("tie_poll_revents"), POLLIN);
  EXPECT_EQ(r.v.at("tie_poll_at"), 2'000'000);
  EXPECT_EQ(r.v.at("tie_select_rc"), 1) << r.text;
  EXPECT_EQ(r.v.at("tie_select_set"), 1);
  EXPECT_EQ(r.v.at("tie_epoll_rc"), 1) << r.text;
  EXPECT_EQ(r.v.at("tie_epoll_at"), 6'000'000);
}

// usleep(0), nanosleep({0, 0}) and an absolute sleep in the past return at once and count as
// calls that found nothing (the busy-poll rule): a thread yielding with them lets time move.
TEST_F(VtimeProbe, ZeroAndPastSleepsCountTowardTheBusyPollRule) {
  const Run r = run_mode("yield-zero");
  ASSERT_EQ(r.exit, 0) << r.text;
  for (const std::string k : {"usleep0", "nanosleep0", "past_abs"}) {
    EXPECT_EQ(r.v.at(k + "_flag"), 1) << k << "\n" << r.text;
    EXPECT_GE(r.v.at(k + "_at"), 1'000'000) << k;
    EXPECT_LE(r.v.at(k + "_at"), 1'001'000) << k;  // at most one quantum after the flag
  }
}

// select leaves the time not slept in its timeval, as Linux does.
TEST_F(VtimeProbe, SelectWritesTheTimeLeftIntoItsTimeval) {
  const Run r = run_mode("select-remaining");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("selrem_rc"), 1);
  EXPECT_EQ(r.v.at("selrem_left_us"), 70'000) << r.text;
}

// Timeouts beyond 2^63 ns (nanosleep({LONG_MAX, 0}), 584 years…) wait for ever instead of
// overflowing into the past or into a fraction of a second (8 kinds: the sleeps, ppoll, pselect,
// select, a condition variable, a timerfd).
TEST_F(VtimeProbe, TimeoutsTooLargeForNanosecondsWaitForEver) {
  const Run r = run_mode("forever");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("forever_returned"), 0) << r.text;
}

// recv(MSG_WAITALL) on a blocking stream socket: the whole length, or what came by SO_RCVTIMEO.
TEST_F(VtimeProbe, WaitallReceivesTheWholeLength) {
  const Run r = run_mode("waitall");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("waitall_rc"), 4) << r.text;
  EXPECT_EQ(r.v.at("waitall_ok"), 1);
  EXPECT_EQ(r.v.at("waitall_at"), 1'000'000) << r.text;
  EXPECT_EQ(r.v.at("waitall_part_rc"), 2) << r.text;  // "ef" at 2 ms, then the timeout
  EXPECT_EQ(r.v.at("waitall_part_at"), 1'000'000 + r.v.at("waitall_rcvtimeo_ns")) << r.text;
}

TEST_F(VtimeProbe, GettimeofdayTakesANullTimeval) {
  const Run r = run_mode("gtod-null");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("gtod_null_rc"), 0);
}

// O_NONBLOCK set on a timerfd after its creation (fcntl, ioctl FIONBIO) and cleared again; and
// timerfd_settime's EINVALs.
TEST_F(VtimeProbe, TimerfdsFollowTheirDescriptorsFlagsAndCheckTheirArguments) {
  const Run r = run_mode("timerfd-flags");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("fcntl_read_rc"), -1) << r.text;
  EXPECT_EQ(r.v.at("fcntl_read_errno"), EAGAIN);
  EXPECT_EQ(r.v.at("fionbio_read_rc"), -1);
  EXPECT_EQ(r.v.at("fionbio_read_errno"), EAGAIN);
  EXPECT_EQ(r.v.at("nonblock_at"), 0);
  EXPECT_EQ(r.v.at("blocking_read_rc"), 8);
  EXPECT_EQ(r.v.at("blocking_read_at"), 1'000'000);
  EXPECT_EQ(r.v.at("neg_rc"), -1);
  EXPECT_EQ(r.v.at("neg_errno"), EINVAL);
  EXPECT_EQ(r.v.at("neg_interval_rc"), -1);
  EXPECT_EQ(r.v.at("neg_interval_errno"), EINVAL);
  EXPECT_EQ(r.v.at("bad_flags_rc"), -1);
  EXPECT_EQ(r.v.at("bad_flags_errno"), EINVAL);
}

// poll on 100 descriptors: the 100th becoming ready ends the wait.
TEST_F(VtimeProbe, PollSeesEveryDescriptorNotJustTheFirst64) {
  const Run r = run_mode("many-fds");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("many_rc"), 1) << r.text;
  EXPECT_EQ(r.v.at("many_at"), 1'000'000) << r.text;
}

// ---- the command line -----------------------------------------------------------------------

class CliVtime : public CliTest {
 protected:
  std::string omni_master() const { return OMNITWIN_BINARY_DIR "/controller/omni-master"; }
  std::string probe(const std::string& mode, bool stat = false) const {
    return std::string(OMNITWIN_BINARY_DIR "/tests/vt_probe") + (stat ? "_static " : " ") + mode;
  }
  Finished run_master(const std::string& out, const std::string& cmd, std::vector<std::string> extra = {}) {
    std::vector<std::string> args{"run", test_scenario("ethercat_short.yaml"), "--no-progress", "--out",
                                  (dir_ / out).string(), "--master-cmd", cmd};
    args.insert(args.end(), extra.begin(), extra.end());
    return run(args);
  }
  nlohmann::json metrics(const std::string& out) const { return CliTest::metrics(dir_ / out); }
  // A realtime run of `cmd` (the foreign master, or a wrapper of it) that ends at 1 s: the
  // master's own shutdown (ramp to 0, drives disabled, slaves to INIT) was served. `m`: the
  // run's metrics. (On the wall clock of a busy host a frame may come back late now and then:
  // no count of lost frames is asked here. Unserved, the master never saw its slaves reach INIT.)
  void expect_served_realtime_shutdown(const std::string& out, const std::string& cmd, nlohmann::json& m) {
    const Finished f = run_master(out, cmd, {"--clock", "realtime", "--set", "duration=1"});
    const std::string log = read_bytes(dir_ / out / "master.log");
    ASSERT_EQ(f.code, 0) << f.out << log;
    EXPECT_TRUE(contains(log, "all 4 slaves in INIT")) << log;
    EXPECT_TRUE(contains(log, "(stopped by signal)")) << log;
    m = metrics(out);
    EXPECT_EQ(m["drives"]["running_at_end"], 0) << m["drives"].dump();
    EXPECT_GT(m["master"]["shutdown_s"].get<double>(), 0.2) << m["master"].dump(2);  // the master's own
  }
};

TEST_F(CliVtime, OmniMasterOnTheWallClockRerunsByteIdenticalAndMovesAsItsSimClockRun) {
  const std::string cmd = omni_master() + " --bus ethercat --clock wall --iface {iface} --config {out}/master.yaml";
  const Finished a = run_master("a", cmd);
  const Finished b = run_master("b", cmd);
  ASSERT_EQ(a.code, 0) << a.out << a.err;
  ASSERT_EQ(b.code, 0) << b.out << b.err;
  EXPECT_EQ(read_bytes(dir_ / "a" / "trajectory.csv"), read_bytes(dir_ / "b" / "trajectory.csv"));
  EXPECT_EQ(read_bytes(dir_ / "a" / "bus.csv"), read_bytes(dir_ / "b" / "bus.csv"));
  const nlohmann::json m = metrics("a");
  EXPECT_EQ(m["master"]["clock"], "virtual");
  EXPECT_GT(m["master"]["virtual_time"]["waits"].get<int>(), 900);  // one per 5 ms cycle at least
  EXPECT_GT(m["real_time_factor"].get<double>(), 1.0);
  // The same master in lockstep on the sim-clock handshake: the platform moves identically
  // (the columns of the master's own plan and odometry are not reported by a master we did not
  // write, and are left out).
  const Finished sim = run({"run", test_scenario("ethercat_short.yaml"), "--no-progress", "--out", (dir_ / "sim").string()});
  ASSERT_EQ(sim.code, 0) << sim.out;
  auto columns = [](const std::string& csv) {
    std::vector<std::string> rows;
    std::istringstream in(csv);
    for (std::string line; std::getline(in, line);) {
      std::vector<std::string> f;
      std::istringstream ls(line);
      for (std::string x; std::getline(ls, x, ',');) f.push_back(x);
      std::string keep = f.size() > 16 ? f[0] + "," + f[4] + "," + f[5] + "," + f[6] : line;
      for (std::size_t i = 16; i < f.size(); ++i) keep += "," + f[i];
      rows.push_back(keep);
    }
    return rows;
  };
  // The shutdown included: on its own clock the master ends on SIGTERM, in lockstep on the
  // grants' stop at the same instant, and both are served until they have exited.
  const std::vector<std::string> own = columns(read_bytes(dir_ / "a" / "trajectory.csv"));
  const std::vector<std::string> ours = columns(read_bytes(dir_ / "sim" / "trajectory.csv"));
  EXPECT_EQ(own, ours);
  EXPECT_EQ(m["master"]["exit"], "exit 0");  // it ends on SIGTERM
  EXPECT_GE(m["master"]["exited_at_s"].get<double>(), m["master"]["sigterm_at_s"].get<double>());
}

// The same on bus can: omni-master's Omni CAN master on its wall clock, over the UDP bus, under
// the library; every slave frame reaches it at its end of frame.
TEST_F(CliVtime, OmniCanMasterOnTheWallClockRerunsByteIdentical) {
  const std::string cmd = omni_master() + " --bus can --clock wall --iface {iface} --config {out}/master.yaml";
  std::vector<std::string> base{"run", test_scenario("run_short_line.yaml"), "--bus", "can", "--no-progress",
                                "--master-cmd", cmd, "--out"};
  std::vector<std::string> a = base, b = base;
  a.push_back((dir_ / "ca").string());
  b.push_back((dir_ / "cb").string());
  const Finished fa = run(a);
  const Finished fb = run(b);
  ASSERT_EQ(fa.code, 0) << fa.out << read_bytes(dir_ / "ca" / "master.log");
  ASSERT_EQ(fb.code, 0) << fb.out;
  EXPECT_EQ(read_bytes(dir_ / "ca" / "trajectory.csv"), read_bytes(dir_ / "cb" / "trajectory.csv"));
  EXPECT_EQ(read_bytes(dir_ / "ca" / "bus.csv"), read_bytes(dir_ / "cb" / "bus.csv"));
  const nlohmann::json m = metrics("ca");
  EXPECT_EQ(m["master"]["clock"], "virtual");
  EXPECT_GT(m["master"]["virtual_time"]["frame_wakes"].get<int>(), 100);  // woken by the slaves' frames
  EXPECT_GT(m["bus"]["frames_rx"].get<int>(), 100);
}

// A master written as a customer writes one (plain C, AF_PACKET or UDP, clock_nanosleep, poll):
// under the library it brings the drives to OP, runs them in CSV faster than real time, and
// two runs are byte-identical.
TEST_F(CliVtime, AForeignStyleMasterRunsFasterThanRealTimeAndRerunsByteIdentical) {
  // It would run 5 s; the run ends at 2.5 s and stops it with SIGTERM, which it handles.
  const std::string cmd = std::string(OMNITWIN_BINARY_DIR "/tests/ec_foreign_master") + " {iface} 5";
  const Finished a = run_master("fa", cmd, {"--set", "duration=2.5"});
  const Finished b = run_master("fb", cmd, {"--set", "duration=2.5"});
  ASSERT_EQ(a.code, 0) << a.out << read_bytes(dir_ / "fa" / "master.log");
  ASSERT_EQ(b.code, 0) << b.out;
  EXPECT_FALSE(contains(a.out, "drives: not all in operation")) << a.out;
  const std::string log = read_bytes(dir_ / "fa" / "master.log");
  EXPECT_TRUE(contains(log, "all drives Operation Enabled in CSV")) << log;
  // Every frame came back, its own shutdown's too: the twin serves the bus (and the virtual
  // clock) after the SIGTERM of the run's end until the master has exited (it answered none of
  // them before; found in review).
  EXPECT_FALSE(contains(log, "(lost)")) << log;
  EXPECT_FALSE(contains(log, "WKC")) << log;
  EXPECT_TRUE(contains(log, "all 4 slaves in INIT")) << log;
  EXPECT_TRUE(contains(log, " 0 lost, 0 wkc errors")) << log;
  EXPECT_TRUE(contains(log, "(stopped by signal)")) << log;
  EXPECT_EQ(read_bytes(dir_ / "fa" / "trajectory.csv"), read_bytes(dir_ / "fb" / "trajectory.csv"));
  EXPECT_EQ(log, read_bytes(dir_ / "fb" / "master.log"));
  const std::string events = read_bytes(dir_ / "fa" / "events.log");
  EXPECT_TRUE(contains(events, "drive operation enabled"));
  EXPECT_TRUE(contains(events, "end of the run: SIGTERM")) << events;
  EXPECT_TRUE(contains(events, "slave 4 AL INIT")) << events;  // logged before the records end
  EXPECT_LT(events.find("ended: exit 0"), events.rfind("slave 4 AL INIT")) << events;  // in time order
  const nlohmann::json m = metrics("fa");
  EXPECT_GT(m["real_time_factor"].get<double>(), 1.0);
  EXPECT_EQ(m["master"]["exit"], "exit 0");
  EXPECT_FALSE(m["master"]["lost"].get<bool>());
  EXPECT_DOUBLE_EQ(m["master"]["sigterm_at_s"].get<double>(), 2.5);
  // Its ramp to 0 takes 0.2 s, then the drives and slaves come down: well inside its grace.
  EXPECT_GT(m["master"]["shutdown_s"].get<double>(), 0.2) << m["master"].dump(2);
  EXPECT_LT(m["master"]["shutdown_s"].get<double>(), 1.0) << m["master"].dump(2);
  EXPECT_NEAR(m["master"]["exited_at_s"].get<double>(), 2.5 + m["master"]["shutdown_s"].get<double>(), 1e-9);
  EXPECT_GT(m["sim_time_s"].get<double>(), m["master"]["exited_at_s"].get<double>());
  EXPECT_EQ(m["drives"]["running_at_end"], 0) << m["drives"].dump();
  EXPECT_GT(m["drives"]["stopped_at_s"].get<double>(), 2.5) << m["drives"].dump();
}

// The same master on the wall clock (realtime): at the run's end it gets SIGTERM and the twin
// goes on answering its frames until it has exited, so its own shutdown (ramp to 0, drives
// disabled, slaves to INIT) is served and recorded (it was not; found in review).
TEST_F(CliVtime, AMasterOfYourOwnInRealtimeIsServedUntilItHasShutDown) {
  nlohmann::json m;
  ASSERT_NO_FATAL_FAILURE(
      expect_served_realtime_shutdown("rt", std::string(OMNITWIN_BINARY_DIR "/tests/ec_foreign_master") + " {iface} 5", m));
  EXPECT_EQ(m["master"]["exit"], "exit 0");
  EXPECT_FALSE(m["master"]["lost"].get<bool>()) << m["master"].dump(2);  // its silence at the end is its end
  EXPECT_NEAR(m["master"]["sigterm_at_s"].get<double>(), 1.0, 1e-9);
  EXPECT_LT(m["master"]["shutdown_s"].get<double>(), 3.0) << m["master"].dump(2);
  EXPECT_TRUE(contains(read_bytes(dir_ / "rt" / "events.log"), "slave 1 AL INIT, drive switch on disabled"));
  // Seen gone at a master tick (a control sample here): the records end one period later (two,
  // before; found in review).
  EXPECT_NEAR(m["sim_time_s"].get<double>(), m["master"]["exited_at_s"].get<double>() + 0.005, 1e-9);
}

// A master started through a wrapper that does not exec (a shell script): the SIGTERM reaches
// the master itself, not only its shell, and the run is served until it and everything it
// started have ended (shutdown_s is the master's, not the shell's). The shell alone was
// signalled and died of it: the run passed as "served" while the master ran on, unserved, and
// failed after the run (found in review).
TEST_F(CliVtime, AMasterBehindAWrapperIsSignalledItselfAndServed) {
  nlohmann::json m;
  ASSERT_NO_FATAL_FAILURE(expect_served_realtime_shutdown(
      "wrap", "sh -c '" + std::string(OMNITWIN_BINARY_DIR "/tests/ec_foreign_master") + " {iface} 5; echo wrapper-done'",
      m));
}

TEST_F(CliVtime, AMasterThatExitsEarlyEndsTheRunWithExit3) {
  const Finished f = run_master("early", probe("exit-early"));
  EXPECT_EQ(f.code, 3) << f.out;
  EXPECT_TRUE(contains(f.out, "left the virtual clock at t = 0.100")) << f.out;
  EXPECT_TRUE(contains(f.out, "exit 0")) << f.out;
  EXPECT_TRUE(fs::exists(dir_ / "early" / "metrics.json"));
  EXPECT_TRUE(fs::exists(dir_ / "early" / "master.log"));
  // A lost master, as in realtime: master.lost and its instant (it stayed false; found in
  // review).
  const nlohmann::json ms = metrics("early")["master"];
  EXPECT_TRUE(ms.value("lost", false)) << ms.dump(2);
  EXPECT_NEAR(ms.value("lost_at_s", -1.0), 0.1, 0.011) << ms.dump(2);
  EXPECT_TRUE(contains(f.out, "master lost: the master process left the virtual clock")) << f.out;
}

// {ifname}: the interface's bare name (raw:NAME → NAME), as SOEM's samples take it.
TEST_F(CliVtime, IfnameIsTheBareInterfaceName) {
  const Finished f = run_master("ifname", probe("exit-early") + " {ifname} {iface}");
  EXPECT_EQ(f.code, 3) << f.out;  // it exits early: only its command line matters here
  const std::string cmd = metrics("ifname")["master"]["command"];
  const std::string iface = cmd.substr(cmd.rfind(' ') + 1);
  const std::string name = iface.starts_with("raw:") ? iface.substr(4) : iface;
  EXPECT_TRUE(cmd.ends_with(" exit-early " + name + " " + iface)) << cmd;
  EXPECT_FALSE(contains(cmd, "{")) << cmd;
}

TEST_F(CliVtime, AMasterThatCrashesEndsTheRunWithExit3) {
  const Finished f = run_master("crash", probe("crash"));
  EXPECT_EQ(f.code, 3) << f.out;
  EXPECT_TRUE(contains(f.out, "killed by signal 11")) << f.out;
}

TEST_F(CliVtime, AMasterThatNeverWaitsIsCaughtByTheWatchdog) {
  const auto t0 = std::chrono::steady_clock::now();
  const Finished f = run_master("busy", probe("busy"), {"--set", "master.watchdog=1"});
  EXPECT_EQ(f.code, 3) << f.out;
  EXPECT_TRUE(contains(f.out, "neither waited nor ended for 1 s of wall time at t = 0.100")) << f.out;
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));
}

TEST_F(CliVtime, AMasterThatIgnoresSigtermIsKilledAndSaidSo) {
  const Finished f = run_master("term", probe("ignore-term"), {"--set", "duration=0.5", "--set", "master.stop_grace=0.5"});
  EXPECT_EQ(f.code, 3) << f.out;
  EXPECT_TRUE(contains(f.out, "did not end within 0.5 s of SIGTERM: killed")) << f.out;
  EXPECT_TRUE(fs::exists(dir_ / "term" / "trajectory.csv"));
  // It was served on the virtual clock for its whole grace after the SIGTERM, then killed.
  const nlohmann::json m = metrics("term");
  EXPECT_NEAR(m["master"]["sigterm_at_s"].get<double>(), 0.5, 1e-9);
  EXPECT_EQ(m["master"]["exited_at_s"].get<double>(), -1.0);
  EXPECT_NEAR(m["sim_time_s"].get<double>(), 1.0, 1e-6) << m.dump(2);
  EXPECT_EQ(m["master"]["exit"], "killed by signal 9");
}

// The SIGTERM of the run's end ends the wait it finds the master in, as Linux does: a sleep,
// poll, select, epoll or receive returns EINTR at that instant once the master's handler has
// run (its flag set), and a master without a handler dies of it there. The library did not
// simulate signals: a master waiting 100 s was served for its whole grace and failed the run
// with "did not end within … of SIGTERM" (a handler's flag was seen only at the wait's
// deadline), and one killed in its wait was seen gone only at the grace's end (found in review).
// A receive whose handler has SA_RESTART goes on, as the kernel restarts it.
TEST_F(CliVtime, TheEndsSigtermEndsTheWaitItFindsTheMasterInAsLinuxDoes) {
  for (const std::string how : {"nanosleep", "signal", "sleep", "poll", "select", "epoll", "recv", "default",
                                 "siginterrupt", "oneshot", "ppoll-mask", "pselect-mask", "epoll-mask"}) {
    SCOPED_TRACE(how);
    const Finished f = run_master("tw-" + how, probe("term-in-wait " + how),
                                  {"--set", "duration=1", "--set", "master.stop_grace=0.5"});
    // It never talks EtherCAT: "no master connected" fails the expectations (exit 1), nothing else.
    EXPECT_EQ(f.code, 1) << f.out;
    EXPECT_FALSE(contains(f.out, "did not end")) << f.out;
    // Its drives never ran, and the summary says so (it did not, for a run that passed so).
    EXPECT_TRUE(contains(f.out, "drives: not all in operation at any time of the run (0 running at its end")) << f.out;
    const nlohmann::json m = metrics("tw-" + how)["master"];
    EXPECT_NEAR(m["sigterm_at_s"].get<double>(), 1.0, 1e-9) << m.dump(2);
    EXPECT_NEAR(m["exited_at_s"].get<double>(), 1.0, 1e-9) << m.dump(2);
    EXPECT_EQ(m["shutdown_s"].get<double>(), 0.0) << m.dump(2);
    EXPECT_NEAR(metrics("tw-" + how)["sim_time_s"].get<double>(), 1.005, 1e-9);  // one control period after
    if (how == "default") {
      EXPECT_EQ(m["exit"], "killed by signal 15");
      continue;
    }
    EXPECT_EQ(m["exit"], "exit 0");
    const std::string log = read_bytes(dir_ / ("tw-" + how) / "master.log");
    EXPECT_TRUE(contains(log, "handler_reads_back 1\n")) << log;  // sigaction's old action is its own
    // sleep: the whole seconds left (glibc truncates: 99.001 s is 99)
    EXPECT_TRUE(contains(log, how == "sleep" ? "wait_rc 99\n" : "wait_rc -1\n")) << log;
    if (how != "sleep") {
      EXPECT_TRUE(contains(log, "wait_errno 4\n")) << log;  // EINTR
    }
    EXPECT_TRUE(contains(log, "wait_flag 1\n")) << log;
    EXPECT_TRUE(contains(log, "wait_ns 999000000\n")) << log;  // from 1 ms to the SIGTERM at 1 s
    if (how == "nanosleep") {
      EXPECT_TRUE(contains(log, "wait_rem_s 99\n")) << log;
    }
    if (how == "select" || how == "pselect-mask") {  // EINTR leaves the sets as given (they were emptied)
      EXPECT_TRUE(contains(log, "wait_still_in_set 1\n")) << log;
    }
    if (how == "siginterrupt") {  // what siginterrupt(SIGTERM, 1) did reads back, and holds
      EXPECT_TRUE(contains(log, "restart_reads_back 0\n")) << log;
    }
  }
  const Finished r = run_master("tw-restart", probe("term-in-wait recv-restart"),
                                {"--set", "duration=1", "--set", "master.stop_grace=0.5"});
  EXPECT_EQ(r.code, 3) << r.out;
  EXPECT_TRUE(contains(r.out, "did not end within 0.5 s of SIGTERM: killed")) << r.out;
}

// A signal the process sends itself (pthread_kill to a thread blocked in a receive) ends that
// receive with EINTR at once, with no time passing, as on Linux: the library saw handlers only
// at the twin's next Wake, which for a wait without a deadline never came (found in review).
TEST_F(VtimeProbe, ASignalTheProcessSendsItselfEndsTheWaitAtOnce) {
  const Run r = run_mode("self-signal");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("self_usr1_runs"), 1) << r.text;
  EXPECT_EQ(r.v.at("self_rx_rc"), -1) << r.text;
  EXPECT_EQ(r.v.at("self_rx_errno"), EINTR) << r.text;
  EXPECT_EQ(r.v.at("self_rx_at"), 300'000) << r.text;  // the usleep(300) before it, nothing more
  EXPECT_EQ(r.v.at("self_joined_at"), 300'000) << r.text;
}

// Dispositions through the library's sigaction read and act as the kernel's: SIG_IGN in a
// struct that still has SA_SIGINFO is ignored (the library took it for a handler and the program
// crashed), signal(SIG_ERR) is refused with EINVAL, and after an SA_RESETHAND handler fired the
// action reads SIG_DFL without the SA_SIGINFO the library had added (found in review).
TEST_F(VtimeProbe, SignalDispositionsReadAndActAsTheKernels) {
  const Run r = run_mode("dispositions");
  ASSERT_EQ(r.exit, 0) << r.text;
  EXPECT_EQ(r.v.at("ignored_survived"), 1);
  EXPECT_EQ(r.v.at("signal_sig_err_refused"), 1);
  EXPECT_EQ(r.v.at("signal_sig_err_errno"), EINVAL);
  EXPECT_EQ(r.v.at("reset_handler_ran"), 1);
  EXPECT_EQ(r.v.at("reset_reads_dfl"), 1);
  EXPECT_EQ(r.v.at("reset_reads_siginfo"), 0);
}

// Served for its whole grace, it ends by itself in the moment before SIGKILL (on the unserved
// bus a real master fails there): still a master that did not end in its grace (it passed,
// exit 0; found in review).
TEST_F(CliVtime, AMasterThatOutlivesItsGraceFailsTheRunHoweverItEndsAfter) {
  const Finished f = run_master("late", probe("ignore-term-exit-late"),
                                {"--set", "duration=0.5", "--set", "master.stop_grace=0.5"});
  EXPECT_EQ(f.code, 3) << f.out;
  EXPECT_TRUE(contains(f.out, "did not end within 0.5 s of SIGTERM: it ended after (exit 1)")) << f.out;
  EXPECT_TRUE(contains(f.out, "it had not ended when the run did (exit 1)")) << f.out;
  EXPECT_EQ(metrics("late")["master"]["exit_code"], 1);
}

// A master that exits non-zero during its served shutdown failed it: the run says so (exit 3;
// it passed as a normal end, found in review). master.exit_code lets expectations judge it too.
TEST_F(CliVtime, AMasterWhoseShutdownFailsFailsTheRun) {
  const Finished f = run_master("failterm", probe("fail-on-term"), {"--set", "duration=0.5"});
  EXPECT_EQ(f.code, 3) << f.out;
  EXPECT_TRUE(contains(f.out, "ended its shutdown with exit 1 (see master.log)")) << f.out;
  EXPECT_TRUE(contains(f.out, "served until it ended 0.0")) << f.out;
  const nlohmann::json m = metrics("failterm")["master"];
  EXPECT_EQ(m["exit_code"], 1);
  EXPECT_FALSE(m["lost"].get<bool>());
  // The SIGTERM ends its sleep at once (it waited for the sleep's end, 0–10 ms, before the
  // library simulated signals), then 20 ms.
  EXPECT_NEAR(m["shutdown_s"].get<double>(), 0.02, 1e-9) << m.dump(2);
}

// The tracking figures cover the run to `duration`, not the master's shutdown after it: a path
// ending in the shutdown is not done (path_done_s was set there, after the run's end), and the
// platform's figures and final pose are those of the run's last sample within `duration`.
// Faults stay as the run left them: none ends during the shutdown, and the "still active" lines
// come last, in time order (found in review).
TEST_F(CliVtime, TheFiguresAndFaultsEndAtTheDurationNotWithTheMastersShutdown) {
  const std::string cmd = omni_master() + " --bus ethercat --clock wall --iface {iface} --config {out}/master.yaml";
  const Finished f = run_master("cut", cmd,
                                {"--set", "duration=3.9", "--set", "expect={}", "--set",
                                 "faults=[{wheel_slip: {wheel: 2, at: 2.0, duration: 1.91, friction_scale: 0.5}}]"});
  ASSERT_EQ(f.code, 0) << f.out;
  const nlohmann::json m = metrics("cut");
  ASSERT_GT(m["sim_time_s"].get<double>(), 3.9);  // records past the end: its shutdown
  EXPECT_EQ(m["platform"]["path_done_s"].get<double>(), -1.0) << m["platform"].dump(2);
  // The rows up to 3.9 s are the figures' samples; the final pose is the 3.9 s row's.
  std::istringstream csv(read_bytes(dir_ / "cut" / "trajectory.csv"));
  std::string line, at_end;
  int within = 0;
  std::getline(csv, line);
  while (std::getline(csv, line))
    if (std::stod(line.substr(0, line.find(','))) <= 3.9 + 1e-9) {
      ++within;
      at_end = line;
    }
  EXPECT_EQ(m["platform"]["samples"].get<int>(), within);
  std::istringstream row(at_end);
  std::vector<double> v;
  for (std::string x; std::getline(row, x, ',');) v.push_back(x.empty() ? 0.0 : std::stod(x));
  ASSERT_GT(v.size(), 6u);
  EXPECT_NEAR(m["platform"]["final_x_m"].get<double>(), v[4], 1e-9);  // the CSV has 10 digits
  // The slip fault would end at 3.91 s, after the run: it does not, and its line is the last.
  const std::string events = read_bytes(dir_ / "cut" / "events.log");
  // bus.csv counts it active to the end too (it read 0 from 3.91 s on; found in review).
  const std::string bus = read_bytes(dir_ / "cut" / "bus.csv");
  const std::string last_row = bus.substr(bus.rfind('\n', bus.size() - 2) + 1);
  std::vector<std::string> cells;
  std::istringstream lr(last_row);
  for (std::string x; std::getline(lr, x, ',');) cells.push_back(x);
  ASSERT_GT(cells.size(), 6u) << last_row;
  ASSERT_GT(std::stod(cells[0]), 3.91) << last_row;
  EXPECT_EQ(cells[6], "1") << last_row;  // active_faults
  EXPECT_FALSE(contains(events, "friction x1 (ends)")) << events;
  const std::size_t still = events.find("still active at the end of the run");
  ASSERT_NE(still, std::string::npos) << events;
  EXPECT_GT(still, events.rfind("ended: exit 0")) << events;
  double last = 0;
  std::istringstream ev(events);
  for (std::string l; std::getline(ev, l);) {
    const double t = std::stod(l);
    EXPECT_GE(t, last) << l;
    last = t;
  }
}

TEST_F(CliVtime, AStaticMasterIsRefusedOrRunsInRealtimeWhenAsked) {
  const Finished f = run_master("static", probe("sleep", true));
  EXPECT_EQ(f.code, 3) << f.out;
  EXPECT_TRUE(contains(f.out, "statically linked")) << f.out;
  EXPECT_TRUE(contains(f.out, "--clock realtime")) << f.out;
  const Finished r = run_master("static-rt", probe("sleep", true),
                                {"--set", "master.on_static=realtime", "--set", "duration=0.3"});
  EXPECT_TRUE(contains(r.out + r.err, "runs on the wall clock")) << r.out << r.err;
  EXPECT_EQ(metrics("static-rt")["clock"], "realtime");
}

TEST_F(CliVtime, AMasterThatForksEndsTheRunWithExit3) {
  const Finished f = run_master("fork", probe("fork"));
  EXPECT_EQ(f.code, 3) << f.out;
  EXPECT_TRUE(contains(f.out, "a second process")) << f.out;
}

TEST_F(CliVtime, ABadCommandIsRefusedBeforeTheRun) {
  const Finished f = run_master("bad", "'unbalanced");
  EXPECT_NE(f.code, 0);
  EXPECT_TRUE(contains(f.out + f.err, "unbalanced quote")) << f.out << f.err;
  const Finished d = run({"run", test_scenario("run_short_line.yaml"), "--master-cmd", "x", "--out", (dir_ / "d").string()});
  EXPECT_EQ(d.code, 2) << d.out << d.err;
  EXPECT_TRUE(contains(d.err, "runs on bus ethercat or can")) << d.err;
}

}  // namespace
