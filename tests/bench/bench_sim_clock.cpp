// Benchmarks the sim-clock handshake per control tick against a raw socket ping-pong of the
// same size, in the same run (DESIGN §11: figures are ratios against a baseline measured
// alongside). The master end runs in a forked child process, as the real master does.
//
//   BM_RawPingPong   96-byte records over a connected Unix SOCK_SEQPACKET pair, echoed by the
//                    child: one send + one receive per side, no codec, no checks. The floor.
//   BM_SimClockTick  Server::grant against a Client in the child answering every Grant with
//                    a Done (encode, send, poll, receive, decode, tick check on both sides).
//   BM_Overhead      both of the above alternated inside every iteration, so machine drift
//                    hits them alike; reports raw_ns, tick_ns and tick_over_raw = Σ tick / Σ raw.
//   BM_Codec         encode + decode of a full Done record alone (no system calls).
#include <benchmark/benchmark.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <functional>
#include <memory>

#include "controller/sim_clock.hpp"
#include "tests/support/temp_dir.hpp"

namespace {

using namespace omnitwin;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
constexpr std::size_t kSize = simclock::kMessageSize;

// A forked child running `body`, then _exit (it never runs the parent's destructors).
class ChildProcess {
 public:
  explicit ChildProcess(const std::function<int()>& body) : pid_(::fork()) {
    if (pid_ == 0) ::_exit(body());
  }
  ~ChildProcess() {
    if (pid_ > 0) ::waitpid(pid_, nullptr, 0);
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;
  bool ok() const { return pid_ > 0; }

 private:
  pid_t pid_;
};

// The baseline: a socket pair whose far end a child echoes until end of stream.
class RawPeer {
 public:
  RawPeer() : fds_(make_pair()), child_([this] { return echo(); }) { ::close(fds_[1]); }
  ~RawPeer() { ::close(fds_[0]); }  // the child sees end of stream and exits (then waited)
  // One round trip of a 96-byte record; false when the child is gone.
  bool round_trip() {
    std::array<std::uint8_t, kSize> buf{};
    buf[0] = 1;
    const auto n = static_cast<ssize_t>(kSize);
    if (::send(fds_[0], buf.data(), kSize, MSG_NOSIGNAL) != n) return false;
    return ::recv(fds_[0], buf.data(), kSize, 0) == n;
  }

 private:
  static std::array<int, 2> make_pair() {
    std::array<int, 2> fds{-1, -1};
    ::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, fds.data());
    return fds;
  }
  // Child side: echo every record until the parent closes its end.
  int echo() {
    ::close(fds_[0]);
    std::array<std::uint8_t, kSize> buf{};
    for (;;) {
      const ssize_t n = ::recv(fds_[1], buf.data(), kSize, 0);
      if (n <= 0) return 0;
      if (::send(fds_[1], buf.data(), static_cast<std::size_t>(n), MSG_NOSIGNAL) != n) return 0;
    }
  }
  std::array<int, 2> fds_;
  ChildProcess child_;
};

// The handshake: a Server here, a Client in a child answering each Grant with a Done.
class SimClockPeer {
 public:
  SimClockPeer()
      : dir_("omnitwin-bench-simclock"),
        address_("unix:" + (dir_ / "clock.sock").string()),
        server_(address_),
        child_([this] { return master(); }) {
    accepted_ = server_.accept(5s) == simclock::WaitStatus::ok;
  }
  ~SimClockPeer() { server_.end(0); }  // the child sees End and exits (then waited)
  bool accepted() const { return accepted_; }
  // One tick: grant k with cumulative counts, wait for its Done.
  bool tick() {
    ++k_;
    const simclock::Grant g{k_, static_cast<std::int64_t>(k_) * 10'000'000, {k_, 2 * k_, 0, 0}};
    simclock::Done d;
    return server_.grant(g, d, 5s) == simclock::WaitStatus::ok && d.frames[0] == k_;
  }

 private:
  // Child side: what a master does per tick, minus the tick's own work.
  int master() {
    simclock::Client c(address_, 5s);
    simclock::Grant g;
    simclock::Done d;
    d.report.state = simclock::MasterState::running;
    while (c.next(g, 5s) == simclock::WaitStatus::ok) {
      d.tick = g.tick;
      d.frames = g.frames;
      d.report.odometry = {static_cast<double>(g.tick), 0.5, 0.25};
      if (!c.done(d)) return 1;
    }
    return 0;
  }
  testing::TempDir dir_;
  std::string address_;
  simclock::Server server_;
  ChildProcess child_;
  std::uint64_t k_ = 0;
  bool accepted_ = false;
};

void BM_RawPingPong(benchmark::State& state) {
  RawPeer peer;
  for (auto _ : state)
    if (!peer.round_trip()) state.SkipWithError("echo child gone");
  state.counters["ns_per_tick"] =
      benchmark::Counter(static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_SimClockTick(benchmark::State& state) {
  SimClockPeer peer;
  if (!peer.accepted()) state.SkipWithError("master child did not connect");
  for (auto _ : state)
    if (!peer.tick()) state.SkipWithError("grant failed");
  state.counters["ns_per_tick"] =
      benchmark::Counter(static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

// Wall time of one call of `f` [ns]; false from f is reported through ok.
std::int64_t timed(const std::function<bool()>& f, bool& ok) {
  const auto t0 = Clock::now();
  ok = f() && ok;
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count();
}

void BM_Overhead(benchmark::State& state) {
  RawPeer raw;
  SimClockPeer clock;
  if (!clock.accepted()) state.SkipWithError("master child did not connect");
  std::int64_t raw_ns = 0, tick_ns = 0;
  bool ok = true;
  for (auto _ : state) {
    raw_ns += timed([&] { return raw.round_trip(); }, ok);
    tick_ns += timed([&] { return clock.tick(); }, ok);
  }
  if (!ok) state.SkipWithError("a round trip failed");
  const double n = static_cast<double>(state.iterations());
  state.counters["raw_ns"] = static_cast<double>(raw_ns) / n;
  state.counters["tick_ns"] = static_cast<double>(tick_ns) / n;
  state.counters["tick_over_raw"] = raw_ns > 0 ? static_cast<double>(tick_ns) / raw_ns : 0.0;
}

void BM_Codec(benchmark::State& state) {
  simclock::Done d;
  d.tick = 17;
  d.frames = {1000, 2000, 0, 0};
  d.report = {simclock::MasterState::running, simclock::StopReason::none, 0, 5'000'000,
              {1.0, 0.5, 0.1}, {0.99, 0.51, 0.1}};
  for (auto _ : state) {
    const auto bytes = simclock::encode(d);
    const auto back = simclock::decode(bytes.data(), bytes.size());
    benchmark::DoNotOptimize(back);
    ++d.tick;
  }
}

}  // namespace

BENCHMARK(BM_RawPingPong)->UseRealTime();
BENCHMARK(BM_SimClockTick)->UseRealTime();
BENCHMARK(BM_Overhead)->UseRealTime();
BENCHMARK(BM_Codec);
BENCHMARK_MAIN();
