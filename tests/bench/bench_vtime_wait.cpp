// Benchmarks the cost of one intercepted wait under libomnitwin_vtime.so, against a raw
// socket ping-pong of the same size measured in the same run (DESIGN §11: ratios against a
// baseline measured alongside).
//
//   BM_VtimeWait     tests/vt_probe waits N times (usleep(1)) under the library; this process is
//                    the twin's end (VtimeServer) and wakes each wait at its deadline with no
//                    simulation in between: the library's whole path (the wrapper, the leader's
//                    bookkeeping, encode, send, poll, receive, decode, waking the waiter) plus the
//                    twin's receive and answer. Reports ns per wait.
//   BM_RawPingPong   64-byte records over a connected Unix SOCK_SEQPACKET pair, echoed by a forked
//                    child: the floor any hand-over between two processes pays.
// Both processes are pinned to one CPU, as `omnitwin run` pins the master and the twin.
#include <benchmark/benchmark.h>
#include <sched.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <string>

#include "tests/support/temp_dir.hpp"
#include "twin/master_process.hpp"
#include "twin/master_vtime.hpp"

namespace {

using namespace omnitwin::twin;
namespace vt = omnitwin::vtime;

void pin(pid_t pid) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(static_cast<int>(sched_getcpu()), &set);
  sched_setaffinity(0, sizeof set, &set);
  sched_setaffinity(pid, sizeof set, &set);
}

void BM_VtimeWait(benchmark::State& st) {
  const long n = st.range(0);
  omnitwin::testing::TempDir dir("omnitwin-bench-vtime");
  double waits = 0;
  for (auto _ : st) {
    VtimeServer server;
    MasterProcess p(OMNITWIN_BINARY_DIR "/tests/vt_probe", {"waits", std::to_string(n)}, (dir.path() / "p.log").string(),
                    server.environment(find_vtime_library(), "udp:127.0.0.1:9"));
    pin(p.pid());
    if (server.accept(std::chrono::seconds(10), 0) != VtimeServer::Status::ok) {
      st.SkipWithError("the probe did not connect");
      return;
    }
    const auto t0 = std::chrono::steady_clock::now();
    SimTime now = 0;
    long served = 0;
    vt::Record w;
    while (server.next_wait(w, std::chrono::seconds(10), now) == VtimeServer::Status::ok) {
      now = w.deadline;
      server.wake(w.seq, now, 0);
      ++served;
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    st.SetIterationTime(s);
    waits += static_cast<double>(served);
    p.wait(std::chrono::seconds(5));
  }
  st.counters["ns_per_wait"] = benchmark::Counter(waits, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_VtimeWait)->Arg(20000)->UseManualTime()->Iterations(3)->Unit(benchmark::kMillisecond);

void BM_RawPingPong(benchmark::State& st) {
  int sv[2];
  if (socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv) != 0) {
    st.SkipWithError("socketpair");
    return;
  }
  const pid_t child = fork();
  if (child == 0) {
    close(sv[0]);
    char b[64];
    while (recv(sv[1], b, sizeof b, 0) == 64) send(sv[1], b, 64, 0);
    _exit(0);
  }
  close(sv[1]);
  pin(child);
  char b[64] = {};
  for (auto _ : st) {
    send(sv[0], b, 64, 0);
    recv(sv[0], b, 64, 0);
  }
  close(sv[0]);
  waitpid(child, nullptr, 0);
}
BENCHMARK(BM_RawPingPong);

}  // namespace

BENCHMARK_MAIN();
