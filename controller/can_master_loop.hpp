// controller layer — the two clocks a master program on a CAN transport runs under (the
// CANopen and TML masters; the thesis's Omni master keeps its own in omni_master_main):
//  * lockstep with the twin's sim clock (docs/protocols/sim-clock.md): each Grant carries the
//    twin's cumulative frames; the bus is read while the grant is awaited (the frames held for
//    the grant's instant) and drained until that many arrived, the tick runs at the
//    grant's time, the tick's frames go out in one batch, Done carries the cumulative frames
//    sent and the master's report;
//  * the wall clock: CLOCK_MONOTONIC absolute deadlines, one tick per period, frames handled
//    as they arrive, SCHED_FIFO where permitted.
// A Runner provides: on_frame(frame, t), tick(t), flush(), report(), frames_rx, frames_tx(), and
// shutdown(t) for the end of a wall-clock run or of a signalled lockstep run; CanOutbox is what
// its master core sends through, CanRunner the Runner both programs build on, run_can_master()
// the clock and its failures.
// Header-only (templates).
#pragma once

#include <fmt/format.h>
#include <poll.h>
#include <unistd.h>
#include <spdlog/spdlog.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/can/transport.hpp"
#include "controller/platform_driver.hpp"
#include "controller/program_support.hpp"
#include "controller/sim_clock.hpp"

namespace omnitwin::controller {

// The command line a CAN master program runs with (omni-master --bus canopen | tml).
struct CanProgramOptions {
  std::string iface;          // CAN transport spec: udp:GROUP:PORT, socketcan:IFACE, mem:NAME
  std::string config;         // the program's configuration YAML
  std::string clock = "wall"; // sim | wall
  std::string sim_clock;      // unix:PATH with --clock sim
  double duration = -1;       // wall: seconds, < 0 = until SIGINT/SIGTERM
  bool print_config = false;  // print what was loaded and exit
  std::string stats;          // write the counters as JSON here at exit ("" = no)
  double frames_timeout = 5;  // sim: how long the frames a grant counts may take to arrive [s]
};

// The transport --iface names (a bare interface name means SocketCAN), or null after logging
// why it cannot be opened (the program then exits 2). Not real-time safe.
inline std::unique_ptr<can::Transport> open_can_iface(const std::string& iface) {
  try {
    return can::open_transport(normalize_iface(iface));
  } catch (const can::TransportError& e) {
    spdlog::error("--iface {}: {}", iface, e.what());
    return nullptr;
  }
}

// "[  123.4567 ms]": a program time in the log.
inline std::string log_stamp(std::int64_t t_ns) { return fmt::format("[{:10.4f} ms]", static_cast<double>(t_ns) * 1e-6); }

// What a master core sends: held and sent in one batch after each tick in lockstep (the twin
// reads them only after Done), straight to the transport on the wall clock.
class CanOutbox {
 public:
  CanOutbox(can::Transport& tr, bool hold) : tr_(tr), hold_(hold) { frames_.reserve(64); }
  // The core's send callback. Real-time safe while holding (capacity kept), else a send.
  bool send(const can::Frame& f, std::int64_t t) {
    if (hold_) {
      frames_.push_back(can::TimedFrame{f, t});
      return true;
    }
    const bool ok = tr_.send(f, t);
    sent_ += ok ? 1 : 0;
    return ok;
  }
  // Sends what is held; returns how many frames the transport refused.
  std::uint64_t flush() {
    std::uint64_t refused = 0;
    while (!frames_.empty()) {
      const std::size_t n = tr_.send_many(frames_);
      sent_ += n;
      refused += frames_.size() - n;
      frames_.clear();
    }
    return refused;
  }
  // The end of the run: whatever comes now (the shutdown) goes straight out.
  void release() { hold_ = false; }
  std::uint64_t frames_tx() const { return sent_; }

 private:
  can::Transport& tr_;
  bool hold_;
  std::vector<can::TimedFrame> frames_;
  std::uint64_t sent_ = 0;
};

// A runtime failure of the loop: the program exits 3 with this message.
struct LoopFailure {
  std::string message;
};

// Lockstep: what the master hears while it waits for its grant. The twin puts a tick's frames
// on the transport just before the grant; read only after it, a burst larger than the socket's
// receive buffer was dropped by the kernel (a 1 ms heartbeat at a 100 ms SYNC: 435 frames a
// tick; DESIGN §4: neither side may race the transport). They are taken off the socket as they
// come and handed to the runner at the grant's instant, in order. Real-time safe while the
// held frames fit the reserved capacity.
class HeldFrames {
 public:
  HeldFrames() { frames_.reserve(1024); }
  // Everything the transport holds now.
  void take(can::Transport& tr) {
    while (auto tf = tr.receive()) frames_.push_back(tf->frame);
  }
  template <class Runner>
  void hand_to(Runner& r, std::int64_t t) {
    for (const can::Frame& f : frames_) r.on_frame(f, t);
    frames_.clear();
  }

 private:
  std::vector<can::Frame> frames_;
};

// Waits until the sim-clock channel is readable (ready), the signal fd is (signal) or
// `timeout` passes, taking the bus's frames into `held` meanwhile.
enum class GrantWait : std::uint8_t { ready, signal, timeout };
inline GrantWait wait_for_grant(int channel_fd, int sigfd, can::Transport& tr, HeldFrames& held,
                                std::chrono::milliseconds timeout) {
  const std::int64_t deadline = monotonic_ns() + timeout.count() * 1'000'000;
  for (;;) {
    held.take(tr);
    const std::int64_t left = deadline - monotonic_ns();
    if (left <= 0) return GrantWait::timeout;
    pollfd fds[3] = {{channel_fd, POLLIN, 0}, {sigfd, POLLIN, 0}, {tr.poll_fd(), POLLIN, 0}};
    const int p = ::poll(fds, 3, static_cast<int>((left + 999'999) / 1'000'000));
    if (p < 0 && errno != EINTR) return GrantWait::ready;  // the channel's own receive reports the trouble
    if (p > 0 && (fds[1].revents & POLLIN)) return GrantWait::signal;
    if (p > 0 && fds[0].revents != 0) return GrantWait::ready;
  }
}

// Why a drain came up short: "" when no frame was lost on the way, else the count and the
// kernel's drop counter since `rcvbuf_errors0` (udp_receive_buffer_errors(), -1: unreadable).
inline std::string receive_path_loss(const can::Transport& tr, std::int64_t rcvbuf_errors0) {
  const std::int64_t now = can::udp_receive_buffer_errors();
  const std::uint64_t queue = tr.stats().rx_dropped;
  if (rcvbuf_errors0 >= 0 && now > rcvbuf_errors0)
    return fmt::format("frames were lost in the receive path: the kernel dropped {} UDP datagrams since the master "
                       "started because a receive buffer was full (RcvbufErrors in /proc/net/snmp, whole host)",
                       now - rcvbuf_errors0);
  if (queue > 0) return fmt::format("frames were lost in the receive path: {} dropped from a full receive queue", queue);
  return "";
}

// The failure of a drain that came up short: how many frames are missing, and whether they
// were lost in the receive path.
inline std::string drain_failure(std::uint64_t tick, std::uint64_t received, std::uint64_t target,
                                 std::chrono::milliseconds timeout, const can::Transport& tr,
                                 std::int64_t rcvbuf_errors0) {
  std::string s = fmt::format("tick {}: only {} of the {} frames the twin sent arrived within {} s ({} missing)", tick,
                              received, target, static_cast<double>(timeout.count()) / 1e3, target - received);
  if (const std::string why = receive_path_loss(tr, rcvbuf_errors0); !why.empty()) s += "; " + why;
  return s;
}

// Frames from the transport until `target` have arrived in all (lockstep); false after `timeout`.
template <class Runner>
bool drain_until(can::Transport& tr, Runner& r, std::uint64_t target, std::int64_t t, std::chrono::milliseconds timeout) {
  const std::int64_t give_up = monotonic_ns() + timeout.count() * 1'000'000;
  while (r.frames_rx < target) {
    if (auto tf = tr.receive()) {
      r.on_frame(tf->frame, t);
      continue;
    }
    if (monotonic_ns() >= give_up) return false;
    can::wait_readable(tr, std::chrono::milliseconds(10));
  }
  while (auto tf = tr.receive()) r.on_frame(tf->frame, t);  // anyone else's (python-can, a PC)
  return true;
}

// Lockstep with the twin until it ends the run (End), a signal, or a failure (throws
// LoopFailure / simclock::ChannelError). The bus is read while the grant is awaited
// (HeldFrames); the frames a grant counts may take `frames_timeout` to arrive. After a signal,
// or from the first grant with `stop` (the run's end: the same every run), the next tick the
// twin grants runs r.shutdown() instead of r.tick(), and the ticks after it
// r.end_tick() until r.shut_down() (the end sequence the wall clock's end sends, counted in
// each tick's Done so the twin delivers it; the core bounds its length); without such grants
// (End, the twin gone, nothing in 1 s) the end sequence cannot reach the simulated bus and is
// cut short. Returns 0.
template <class Runner>
int run_lockstep(const std::string& sim_clock, Runner& r, can::Transport& tr, int sigfd,
                 std::chrono::milliseconds frames_timeout) {
  const std::int64_t rcvbuf_errors0 = can::udp_receive_buffer_errors();
  simclock::Client client(sim_clock, std::chrono::seconds(10), sigfd);
  if (client.stopped()) return 0;  // SIGINT/SIGTERM while waiting for the twin's socket
  constexpr std::int64_t kNoEnd = std::numeric_limits<std::int64_t>::min();
  HeldFrames held;
  bool stopping = false, ending = false;  // a signal came; the end sequence has begun
  for (;;) {
    simclock::Grant g;
    simclock::End end{kNoEnd};
    if (!stopping) {
      const GrantWait gw = wait_for_grant(client.fd(), sigfd, tr, held, std::chrono::seconds(60));
      if (gw == GrantWait::timeout) throw LoopFailure{"sim clock: no grant within 60 s"};
      stopping = gw == GrantWait::signal && signalled(sigfd);
    }
    const simclock::WaitStatus w = client.next(g, std::chrono::seconds(1), &end);
    if (stopping && w != simclock::WaitStatus::ok) {
      spdlog::warn("signal: the twin granted no further tick ({}): {}", simclock::to_string(w),
                   ending ? "the end sequence was cut short" : "no end sequence sent");
      return 0;
    }
    if (w == simclock::WaitStatus::closed && end.t_ns != kNoEnd) return 0;
    if (w == simclock::WaitStatus::closed) throw LoopFailure{"sim clock: the twin went away (channel closed without End)"};
    if (w != simclock::WaitStatus::ok) throw LoopFailure{fmt::format("sim clock: {} while waiting for a grant", simclock::to_string(w))};
    stopping = stopping || g.stop;  // the run's end, in simulated time (as a signal here)
    held.hand_to(r, g.t_ns);
    if (!drain_until(tr, r, g.frames[0], g.t_ns, frames_timeout))
      throw LoopFailure{drain_failure(g.tick, r.frames_rx, g.frames[0], frames_timeout, tr, rcvbuf_errors0)};
    if (!stopping) r.tick(g.t_ns);
    else if (ending) r.end_tick(g.t_ns);
    else r.shutdown(g.t_ns), ending = true;
    r.flush();
    const bool last = ending && r.shut_down();  // the end sequence is over: say so, then leave
    const simclock::Done done{g.tick, {r.frames_tx(), 0, 0, 0}, r.report(), last};
    if (!client.done(done)) throw LoopFailure{"sim clock: the twin is gone"};
    if (last) return 0;
  }
}

// Hands r the frames waiting on tr (at most 256), each at `at_ns` [ns since the start].
template <class Runner>
void receive_waiting(Runner& r, can::Transport& tr, std::int64_t at_ns) {
  for (int i = 0; i < 256; ++i) {
    auto tf = tr.receive();
    if (!tf) return;
    r.on_frame(tf->frame, at_ns);
  }
}

// The wall clock between ticks: waits on the bus and the signal fd until `until` [monotonic ns],
// handing the runner each frame at its arrival (since `start`). True when a signal came.
template <class Runner>
bool wait_on_bus(Runner& r, can::Transport& tr, int sigfd, std::int64_t until, std::int64_t start) {
  pollfd fds[2] = {{tr.poll_fd(), POLLIN, 0}, {sigfd, POLLIN, 0}};
  const timespec timeout = to_timespec(std::max<std::int64_t>(0, until - monotonic_ns()));
  const int p = ::ppoll(fds, 2, &timeout, nullptr);
  if (p < 0 && errno != EINTR) throw LoopFailure{fmt::format("poll failed: {}", std::strerror(errno))};
  if (p > 0 && (fds[1].revents & POLLIN) && signalled(sigfd)) return true;
  for (int i = 0; i < 256; ++i) {
    auto tf = tr.receive();
    if (!tf) break;
    r.on_frame(tf->frame, monotonic_ns() - start);
  }
  return false;
}

// The end of a wall-clock run, begun at `start` + t: r.shutdown(), then r.end_tick() every
// period_ns, the bus read in between, until r.shut_down() (the core bounds its length) or a
// second signal.
template <class Runner>
void end_wall_clock(std::int64_t period_ns, Runner& r, can::Transport& tr, int sigfd, std::int64_t start) {
  std::int64_t next = monotonic_ns();
  r.shutdown(next - start);
  next += period_ns;
  while (!r.shut_down()) {
    const std::int64_t now = monotonic_ns();
    if (now >= next) {
      r.end_tick(now - start);
      next = now + period_ns;  // late: one tick, not a burst of them
      continue;
    }
    if (wait_on_bus(r, tr, sigfd, next, start)) {
      spdlog::warn("a second signal: ending without the rest of the end sequence");
      return;
    }
  }
}

// The wall clock: a tick every period_ns until duration_s (< 0: until a signal) or until the
// core has failed (its start-up gave up: nothing more would happen, found by a walkthrough:
// `omni-master --bus canopen` with no drives ran on until killed); then the end sequence
// (end_wall_clock). Returns 0.
template <class Runner>
int run_wall_clock(std::int64_t period_ns, double duration_s, Runner& r, can::Transport& tr, int sigfd) {
  try_realtime(40);
  const std::int64_t start = monotonic_ns();
  const std::int64_t end = duration_s >= 0 ? start + std::llround(duration_s * 1e9) : std::numeric_limits<std::int64_t>::max();
  std::int64_t deadline = start;
  std::uint64_t overruns = 0;
  for (;;) {
    const std::int64_t now = monotonic_ns();
    if (now >= end) break;
    if constexpr (requires { r.failed(); }) {
      if (r.failed()) {
        spdlog::error("the master failed: ending the run");
        break;
      }
    }
    if (now >= deadline) {
      // Late (this process did not run for a while: a host stall): the frames that came
      // meanwhile go first, stamped no later than the tick, as a controller's receive
      // interrupt would have taken them before its timer tick. Otherwise a stall longer
      // than a timeout reads as the nodes' silence (found by the CAN soak).
      if (now > deadline) receive_waiting(r, tr, deadline - start);
      const std::int64_t late = now - deadline;
      if (late >= period_ns) ++overruns, deadline += (late / period_ns) * period_ns;
      r.tick(deadline - start);
      deadline += period_ns;
      continue;
    }
    if (wait_on_bus(r, tr, sigfd, std::min(deadline, end), start)) break;
  }
  if (overruns) spdlog::info("wall clock: {} ticks were a period or more late", overruns);
  end_wall_clock(period_ns, r, tr, sigfd, start);
  return 0;
}

// What a CAN master program's Runner shares, whatever its protocol: the outbox its core sends
// through, the core (`Master`: on_frame, on_tick, finish, shutdown, position, the report's
// state, reason and node), the platform loop, the frames received. `Derived` (CRTP) says when
// the drives follow commands (drives_ready()), hands a wheel its speed (command(i, counts/s))
// and names the start in the log (kStarted). The core is built from `core_args` and its send
// callback.
template <class Derived, class Master>
class CanRunner {
 public:
  template <class... CoreArgs>
  CanRunner(can::Transport& tr, bool hold, PlatformDriver platform, const CoreArgs&... core_args)
      : out_(tr, hold),
        master_(core_args..., [this](const can::Frame& f, std::int64_t t) { return out_.send(f, t); }),
        platform_(std::move(platform)) {
    master_.set_event_callback([](std::int64_t t, const std::string& s, bool warning) {
      if (warning) spdlog::warn("{} {}", log_stamp(t), s);
      else spdlog::info("{} {}", log_stamp(t), s);
    });
  }

  const Master& master() const { return master_; }
  void on_frame(const can::Frame& f, std::int64_t t) {
    ++frames_rx;
    master_.on_frame(f, t);
  }
  // One tick at t: the platform's set-points, then the core's frames.
  void tick(std::int64_t t) {
    platform(t);
    master_.on_tick(t);
  }
  // Lockstep: the tick's frames in one batch. Refusals reach the core.
  void flush() { master_.note_send_failures(out_.flush()); }
  void release() { out_.release(); }
  // The end sequence: shutdown() begins it, end_tick() runs its following ticks (the core's
  // tick without the platform loop) until shut_down().
  void shutdown(std::int64_t t) { master_.shutdown(t); }
  void end_tick(std::int64_t t) { master_.on_tick(t); }
  bool shut_down() const { return master_.shut_down(); }

  simclock::MasterReport report() const {
    simclock::MasterReport r;
    r.state = master_.report_state();
    r.reason = master_.reason();
    r.node = master_.reason_node();
    platform_.fill(r);
    return r;
  }
  std::uint64_t frames_tx() const { return out_.frames_tx(); }
  std::uint64_t frames_rx = 0;

 protected:
  Master& core() { return master_; }

 private:
  void platform(std::int64_t t) {
    WheelCounts c{};
    for (int i = 0; i < 4; ++i) c[static_cast<std::size_t>(i)] = master_.position(i);
    Derived& d = static_cast<Derived&>(*this);
    const PlatformDriver::Step st = platform_.tick(t, d.drives_ready(), c);
    if (st.started) spdlog::info("{} {}: platform loop running", log_stamp(t), Derived::kStarted);
    if (st.command)
      for (int i = 0; i < 4; ++i) d.command(i, st.wheel_counts_per_s[static_cast<std::size_t>(i)]);
    if (st.finished) {
      master_.finish(t);
      spdlog::info("{} path done", log_stamp(t));
    }
  }

  CanOutbox out_;  // before the core: its send callback
  Master master_;
  PlatformDriver platform_;
};

// The program's clock (lockstep with --clock sim, else the wall clock with a tick every
// tick_ns) until its end, then what is held goes out. Returns the exit code: 0, or 3 for a
// runtime failure (logged) or a core that failed. Not real-time safe (sets up, logs).
template <class Runner>
int run_can_master(const CanProgramOptions& o, Runner& r, can::Transport& tr, std::int64_t tick_ns) {
  const int sigfd = open_signal_fd();
  int code = 0;
  try {
    const auto frames_timeout = std::chrono::milliseconds(std::llround(o.frames_timeout * 1e3));
    code = o.clock == "sim" ? run_lockstep(o.sim_clock, r, tr, sigfd, frames_timeout)
                            : run_wall_clock(tick_ns, o.duration, r, tr, sigfd);
  } catch (const LoopFailure& f) {
    spdlog::error("{}", f.message);
    code = 3;
  } catch (const simclock::ChannelError& e) {
    spdlog::error("{}", e.what());
    code = 3;
  }
  r.flush();
  r.release();
  if (r.failed()) code = 3;
  if (sigfd >= 0) ::close(sigfd);
  return code;
}

}  // namespace omnitwin::controller
