// Tests controller/can_master_loop's wall clock (run_wall_clock, the CANopen and TML masters'
// real-time loop): ticks come once per period, and a tick that comes late because the process
// did not run (a host stall: here the runner itself sleeps inside a tick) first hands over the
// frames that arrived meanwhile, stamped no later than that tick. Found by the CAN soak: the
// Omni master (which keeps its own loop in omni_master_main, fixed the same way) read a 3 ms
// stall as "none of the four slaves answered". Over the in-process `mem:` transport. And a
// signal or a grant with stop in lockstep: the end sequence (shutdown, then end ticks until the runner says it is
// over) goes out in the ticks the twin grants next; the wall clock's end runs it on its period. And
// a lockstep burst larger than the receive buffer: the master reads its bus while it waits.
#include "controller/can_master_loop.hpp"

#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/eventfd.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <string>
#include <thread>
#include <vector>

#include "bus_emulators/can/transport_mem.hpp"
#include "controller/sim_clock.hpp"

namespace omnitwin::controller {
namespace {

// Records the order of what the loop hands it; tick 1 stalls for `stall`.
struct Recorder {
  struct Call {
    char what;  // 't' tick, 'f' frame
    std::int64_t t;
  };
  std::vector<Call> calls;
  std::chrono::milliseconds stall{0};
  std::function<void()> during_stall;
  void on_frame(const can::Frame&, std::int64_t t) { calls.push_back({'f', t}); }
  void tick(std::int64_t t) {
    calls.push_back({'t', t});
    if (calls.size() == 2 && stall.count() > 0) {  // the second tick: the process "stops"
      if (during_stall) during_stall();
      std::this_thread::sleep_for(stall);
    }
  }
  void shutdown(std::int64_t t) { calls.push_back({'s', t}); }
  void end_tick(std::int64_t t) { calls.push_back({'e', t}); }
  // The end takes `end_ticks` ticks after shutdown().
  int end_ticks = 0;
  bool shut_down() const {
    return std::count_if(calls.begin(), calls.end(), [](const Call& c) { return c.what == 'e'; }) >= end_ticks;
  }
};

TEST(CanMasterLoop, AFrameThatCameDuringAStallGoesBeforeTheLateTick) {
  const std::string bus = "can-master-loop-test";
  can::MemTransport master_end(bus), slave_end(bus);
  Recorder r;
  r.stall = std::chrono::milliseconds(30);
  // The answer arrives while the master is stalled in its tick at 10 ms.
  r.during_stall = [&] {
    can::Frame f;
    f.id = 0x202;
    f.dlc = 1;
    ASSERT_TRUE(slave_end.send(f));
  };
  const int sigfd = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);  // never readable: no signal
  ASSERT_GE(sigfd, 0);
  run_wall_clock(10'000'000, 0.075, r, master_end, sigfd);
  ::close(sigfd);
  // Ticks at 0 and 10 ms; the stall ends near 40 ms, past the deadlines 20 and 30 ms.
  std::size_t frame = r.calls.size();
  for (std::size_t i = 0; i < r.calls.size(); ++i)
    if (r.calls[i].what == 'f') frame = i;
  ASSERT_LT(frame, r.calls.size()) << "the frame was never handed over";
  EXPECT_EQ(frame, 2u) << "right after the stalled tick, before the late one";
  ASSERT_GT(r.calls.size(), 3u);
  EXPECT_EQ(r.calls[3].what, 't');
  EXPECT_LE(r.calls[2].t, r.calls[3].t) << "stamped no later than the late tick";
  EXPECT_EQ(r.calls[1].t, 10'000'000);
}

// A lockstep Runner: records ticks ('t') and the end ('s'); its shutdown sends one frame.
struct Ender {
  explicit Ender(can::Transport& t) : tr(t) {}
  can::Transport& tr;
  std::vector<Recorder::Call> calls;
  std::uint64_t frames_rx = 0, sent = 0;
  void on_frame(const can::Frame&, std::int64_t) { ++frames_rx; }
  void tick(std::int64_t t) { calls.push_back({'t', t}); }
  void shutdown(std::int64_t t) {
    calls.push_back({'s', t});
    can::Frame f;
    f.dlc = 2;  // as an NMT stop or an AXISOFF would go out
    sent += tr.send(f, t) ? 1 : 0;
  }
  // The end takes `end_ticks` ticks after shutdown(), one frame each (a CANopen quick stop).
  int end_ticks = 0, ended = 0;
  void end_tick(std::int64_t t) {
    calls.push_back({'e', t});
    ++ended;
    can::Frame f;
    f.dlc = 6;
    sent += tr.send(f, t) ? 1 : 0;
  }
  bool shut_down() const { return ended >= end_ticks; }
  void flush() {}
  std::uint64_t frames_tx() const { return sent; }
  simclock::MasterReport report() const { return {}; }
};

// A twin's sim clock and an Ender in lockstep on its own thread over the `mem:` transport; a
// pipe stands in for the signalfd.
struct LockstepRig {
  explicit LockstepRig(const std::string& name)
      : master_end(name), slave_end(name), address("unix:@omnitwin-" + name + "-" + std::to_string(::getpid())),
        server(address), r(master_end) {
    EXPECT_EQ(::pipe2(sig, O_NONBLOCK | O_CLOEXEC), 0);
  }
  ~LockstepRig() {
    if (master.joinable()) master.join();
    ::close(sig[0]);
    ::close(sig[1]);
  }
  void start() {
    master = std::thread([this] { code = run_lockstep(address, r, master_end, sig[0], std::chrono::seconds(5)); });
  }
  void signal() {
    const signalfd_siginfo info{};  // what signalled() reads: one siginfo
    ASSERT_EQ(::write(sig[1], &info, sizeof info), static_cast<ssize_t>(sizeof info));
  }
  simclock::WaitStatus grant(std::uint64_t tick, simclock::Done& d, bool stop = false) {
    return server.grant(simclock::Grant{tick, static_cast<std::int64_t>(tick) * 2'000'000, {}, stop}, d,
                        std::chrono::seconds(2));
  }
  // Starts the master, accepts its channel and grants tick 1: true when each went well.
  bool run_first_tick(simclock::Done& d) {
    start();
    return server.accept(std::chrono::seconds(2)) == simclock::WaitStatus::ok && grant(1, d) == simclock::WaitStatus::ok;
  }
  std::string order() const {
    std::string o;
    for (const auto& c : r.calls) o += c.what;
    return o;
  }
  can::MemTransport master_end, slave_end;
  std::string address;
  simclock::Server server;
  Ender r;
  int sig[2] = {-1, -1};
  int code = -1;
  std::thread master;
};

// Found in review: SIGINT/SIGTERM in lockstep returned at once, without the end sequence (TML:
// CSPD 0, UPD, AXISOFF; CANopen: NMT stop all) that the wall clock's end sends.
TEST(CanMasterLoop, ASignalInLockstepSendsTheEndSequenceInTheNextGrantedTick) {
  LockstepRig rig("can-master-loop-signal");
  simclock::Done d;
  ASSERT_TRUE(rig.run_first_tick(d));
  rig.signal();
  EXPECT_EQ(rig.grant(2, d), simclock::WaitStatus::ok) << "the master left without an end tick";
  EXPECT_EQ(d.tick, 2u);
  EXPECT_EQ(d.frames[0], 1u) << "the end sequence is counted in the Done, so the twin delivers it";
  rig.master.join();
  EXPECT_EQ(rig.code, 0);
  EXPECT_EQ(rig.order(), "ts") << "the granted tick after the signal runs the end, not a tick";
  ASSERT_EQ(rig.r.calls.size(), 2u);
  EXPECT_EQ(rig.r.calls[1].t, 4'000'000);
}

// An end sequence longer than one tick (CANopen: quick stop until the drives are disabled,
// then NMT stop) runs in the ticks the twin grants after the signal until the runner says it
// is over. Before, the loop returned after the first: an NMT stop to enabled drives faults them.
TEST(CanMasterLoop, AnEndSequenceOfSeveralTicksRunsInTheTicksTheTwinStillGrants) {
  LockstepRig rig("can-master-loop-long-end");
  rig.r.end_ticks = 2;
  simclock::Done d;
  ASSERT_TRUE(rig.run_first_tick(d));
  rig.signal();
  for (std::uint64_t k = 2; k <= 4; ++k) {
    ASSERT_EQ(rig.grant(k, d), simclock::WaitStatus::ok) << "tick " << k << ": the master left before its end sequence was over";
    EXPECT_EQ(d.frames[0], k - 1) << "each end tick's frame is counted in its Done";
  }
  rig.master.join();
  EXPECT_EQ(rig.code, 0);
  EXPECT_EQ(rig.order(), "tsee");
}

// The run's end in lockstep: the first grant with stop runs the end sequence in place of a
// tick, the following ones its end ticks, and the master leaves when it is over (the twin sees
// the channel closed at the next grant). No signal is involved: the same in every run.
TEST(CanMasterLoop, AGrantWithStopRunsTheEndSequenceAndTheMasterLeavesWhenItIsOver) {
  LockstepRig rig("can-master-loop-stop");
  rig.r.end_ticks = 1;
  simclock::Done d;
  ASSERT_TRUE(rig.run_first_tick(d));
  ASSERT_EQ(rig.grant(2, d, true), simclock::WaitStatus::ok);
  EXPECT_EQ(d.frames[0], 1u) << "the end sequence's first frame, counted in the Done";
  EXPECT_FALSE(d.last);
  ASSERT_EQ(rig.grant(3, d, true), simclock::WaitStatus::ok);
  EXPECT_EQ(d.frames[0], 2u);
  EXPECT_TRUE(d.last) << "the Done of the end sequence's last tick says it leaves";
  rig.master.join();
  EXPECT_EQ(rig.grant(4, d, true), simclock::WaitStatus::closed) << "it left after its end sequence";
  EXPECT_EQ(rig.code, 0);
  EXPECT_EQ(rig.order(), "tse");
  EXPECT_EQ(rig.r.calls[1].t, 4'000'000);
}

// The wall clock's end runs the end sequence's ticks on its period too.
TEST(CanMasterLoop, TheWallClocksEndRunsTheEndSequenceUntilItIsOver) {
  const std::string bus = "can-master-loop-wall-end-test";
  can::MemTransport master_end(bus), slave_end(bus);
  Recorder r;
  r.end_ticks = 3;
  const int sigfd = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);  // never readable: no signal
  ASSERT_GE(sigfd, 0);
  run_wall_clock(5'000'000, 0.02, r, master_end, sigfd);
  ::close(sigfd);
  std::string order;
  std::vector<std::int64_t> end_at;
  for (const auto& c : r.calls) {
    order += c.what;
    if (c.what == 's' || c.what == 'e') end_at.push_back(c.t);
  }
  EXPECT_EQ(order.substr(order.find('s')), "seee");
  ASSERT_EQ(end_at.size(), 4u);
  for (std::size_t i = 1; i < end_at.size(); ++i) EXPECT_GE(end_at[i] - end_at[i - 1], 4'000'000) << "a tick per period";
}

// What run_lockstep needs of a runner: it counts the frames handed to it.
struct Counting {
  std::uint64_t frames_rx = 0;
  void on_frame(const can::Frame&, std::int64_t) { ++frames_rx; }
  void tick(std::int64_t) {}
  void shutdown(std::int64_t) {}
  void end_tick(std::int64_t) {}
  bool shut_down() const { return true; }
  void flush() {}
  std::uint64_t frames_tx() const { return 0; }
  simclock::MasterReport report() const { return {}; }
};

// Lockstep over UDP: the twin puts a tick's frames on the transport just before its grant. The
// master read its bus only after the grant, so a burst beyond its socket's receive buffer (435
// frames at a 1 ms CANopen heartbeat and a 100 ms SYNC; about 275 fit in the default buffer)
// was dropped by the kernel and the run died as "master lost". Here the burst is larger than
// the master's receive buffer (even the raised one), sent in pieces before the grant: every
// frame arrives, because the master reads while it waits for the grant.
TEST(CanMasterLoop, ABurstLargerThanTheReceiveBufferArrivesWhileTheMasterWaitsForItsGrant) {
  auto twin_end = can::open_transport("udp:239.74.164.9:0?ttl=0");
  auto master_end = can::open_transport(twin_end->spec());
  int rcvbuf = 0;
  socklen_t len = sizeof rcvbuf;
  ASSERT_EQ(::getsockopt(master_end->poll_fd(), SOL_SOCKET, SO_RCVBUF, &rcvbuf, &len), 0);
  // A datagram costs the buffer far more than 256 bytes (its buffer's true size): more than fit.
  const std::uint64_t burst = static_cast<std::uint64_t>(rcvbuf) / 256 + 512;
  const std::string address = "unix:@omnitwin-can-master-loop-test-" + std::to_string(::getpid());
  simclock::Server server(address);
  const int sigfd = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);  // never readable: no signal
  ASSERT_GE(sigfd, 0);
  Counting r;
  std::string failure;
  std::thread master([&] {
    try {
      run_lockstep(address, r, *master_end, sigfd, std::chrono::seconds(5));
    } catch (const LoopFailure& f) {
      failure = f.message;
    }
  });
  ASSERT_EQ(server.accept(std::chrono::seconds(10)), simclock::WaitStatus::ok);
  can::Frame f;
  f.id = 0x702;
  f.dlc = 1;
  const std::vector<can::TimedFrame> piece(100, can::TimedFrame{f, 0});
  std::uint64_t sent = 0;
  while (sent < burst) {
    sent += twin_end->send_many(piece);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  simclock::Grant g;
  g.frames[0] = sent;
  simclock::Done d;
  const simclock::WaitStatus st = server.grant(g, d, std::chrono::seconds(20));
  server.end(0);
  master.join();
  ::close(sigfd);
  EXPECT_EQ(st, simclock::WaitStatus::ok) << failure;
  EXPECT_EQ(failure, "");
  EXPECT_EQ(r.frames_rx, sent) << "of a burst of " << sent << " with a receive buffer of " << rcvbuf << " bytes";
}

}  // namespace
}  // namespace omnitwin::controller
