// Tests controller/can_master_loop's wall clock (run_wall_clock, the CANopen and TML masters'
// real-time loop): ticks come once per period, and a tick that comes late because the process
// did not run (a host stall: here the runner itself sleeps inside a tick) first hands over the
// frames that arrived meanwhile, stamped no later than that tick. Found by the CAN soak: the
// Omni master (which keeps its own loop in omni_master_main, fixed the same way) read a 3 ms
// stall as "none of the four slaves answered". Over the in-process `mem:` transport. And a
// signal in lockstep: the end sequence (shutdown) goes out in the next tick the twin grants.
#include "controller/can_master_loop.hpp"

#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/eventfd.h>
#include <sys/signalfd.h>
#include <unistd.h>

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
  void shutdown(std::int64_t) {}
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
  void flush() {}
  std::uint64_t frames_tx() const { return sent; }
  simclock::MasterReport report() const { return {}; }
};

// Found in review: SIGINT/SIGTERM in lockstep returned at once, without the end sequence (TML:
// CSPD 0, UPD, AXISOFF; CANopen: NMT stop all) that the wall clock's end sends.
TEST(CanMasterLoop, ASignalInLockstepSendsTheEndSequenceInTheNextGrantedTick) {
  using namespace std::chrono_literals;
  const std::string bus = "can-master-loop-signal-test";
  can::MemTransport master_end(bus), slave_end(bus);
  Ender r(master_end);
  int sig[2];
  ASSERT_EQ(::pipe2(sig, O_NONBLOCK | O_CLOEXEC), 0);  // stands in for the signalfd
  const std::string address = "unix:@omnitwin-can-master-loop-" + std::to_string(::getpid());
  simclock::Server server(address);
  int code = -1;
  std::thread master([&] { code = run_lockstep(address, r, master_end, sig[0]); });
  ASSERT_EQ(server.accept(2s), simclock::WaitStatus::ok);
  simclock::Done d;
  ASSERT_EQ(server.grant(simclock::Grant{1, 2'000'000, {}}, d, 2s), simclock::WaitStatus::ok);
  const signalfd_siginfo info{};  // what signalled() reads: one siginfo
  ASSERT_EQ(::write(sig[1], &info, sizeof info), static_cast<ssize_t>(sizeof info));
  EXPECT_EQ(server.grant(simclock::Grant{2, 4'000'000, {}}, d, 2s), simclock::WaitStatus::ok)
      << "the master left without an end tick";
  EXPECT_EQ(d.tick, 2u);
  EXPECT_EQ(d.frames[0], 1u) << "the end sequence is counted in the Done, so the twin delivers it";
  master.join();
  ::close(sig[0]);
  ::close(sig[1]);
  EXPECT_EQ(code, 0);
  ASSERT_EQ(r.calls.size(), 2u);
  EXPECT_EQ(r.calls[0].what, 't');
  EXPECT_EQ(r.calls[1].what, 's') << "the granted tick after the signal runs the end, not a tick";
  EXPECT_EQ(r.calls[1].t, 4'000'000);
}

}  // namespace
}  // namespace omnitwin::controller
