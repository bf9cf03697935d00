// The host alone, below every realtime figure of the twin: how late a SCHED_FIFO thread wakes
// from clock_nanosleep, the way the twin's realtime loop (twin/clock.cpp) and the masters'
// wall-clock loops sleep. The realtime runs' lateness (metrics.json realtime.*, realtime.csv)
// can be no better than this; docs/reliability.md ("sixteenth round") has this machine's
// figures and why a virtual machine's idle vCPU wakes late.
//
//   BM_HostWakeup/N/S  S seconds (30) of 1 ms absolute deadlines on one thread at SCHED_FIFO
//                     40 with mlockall (as the twin's loop, where permitted), pinned to the
//                     last CPU. N, what else runs on that CPU:
//                     0 nothing (the CPU idles between wake-ups, as in a realtime run),
//                     1 a busy loop at SCHED_IDLE (the CPU never idles).
//                     Baseline in the same run: a thread at normal priority on the first CPU that
//                     only reads CLOCK_MONOTONIC and keeps its longest gap (the host taking the
//                     CPU away, whatever the sleeping thread does).
//   Counters: late_p99_us, late_max_us (how late the sleeper woke), over_2ms, over_10ms (wake-ups
//   that late), reader_max_gap_us (the baseline's longest gap), fifo (1: SCHED_FIFO was granted).
//
// Run: build/tests/bench/bench_host_wakeup (about 2 × 30 s); --benchmark_filter=BM_HostWakeup/0.
#include <benchmark/benchmark.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

namespace {

std::int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void pin(int cpu) {
  cpu_set_t s;
  CPU_ZERO(&s);
  CPU_SET(cpu, &s);
  sched_setaffinity(0, sizeof s, &s);
}

int last_cpu() {
  cpu_set_t s;
  CPU_ZERO(&s);
  sched_getaffinity(0, sizeof s, &s);
  int last = 0;
  for (int c = 0; c < CPU_SETSIZE; ++c)
    if (CPU_ISSET(c, &s)) last = c;
  return last;
}

struct Sleeper {
  std::vector<std::int64_t> late_ns;
  bool fifo = false;
};

// 1 ms absolute deadlines for `seconds` on `cpu`, at SCHED_FIFO 40 where permitted.
Sleeper sleep_ticks(double seconds, int cpu) {
  Sleeper r;
  std::thread t([&] {
    pin(cpu);
    sched_param sp{};
    sp.sched_priority = 40;
    r.fifo = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0;
    const auto n = static_cast<std::size_t>(seconds * 1000);
    r.late_ns.reserve(n);
    std::int64_t next = now_ns();
    for (std::size_t i = 0; i < n; ++i) {
      next += 1'000'000;
      const timespec ts{static_cast<time_t>(next / 1'000'000'000), static_cast<long>(next % 1'000'000'000)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) != 0) {
      }
      r.late_ns.push_back(now_ns() - next);
    }
  });
  t.join();
  return r;
}

void BM_HostWakeup(benchmark::State& state) {
  const bool idle_spinner = state.range(0) == 1;
  const double seconds = static_cast<double>(state.range(1));
  const int cpu = last_cpu();
  const bool locked = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
  for (auto _ : state) {
    std::atomic<bool> stop{false};
    std::int64_t reader_gap = 0;
    // The baseline: clock reads only, normal priority, on the first CPU.
    std::thread reader([&] {
      pin(0);
      std::int64_t last = now_ns();
      while (!stop.load(std::memory_order_relaxed)) {
        const std::int64_t t = now_ns();
        reader_gap = std::max(reader_gap, t - last);
        last = t;
      }
    });
    std::thread spinner;
    if (idle_spinner) {
      spinner = std::thread([&] {
        pin(cpu);
        sched_param sp{};
        sched_setscheduler(0, SCHED_IDLE, &sp);
        while (!stop.load(std::memory_order_relaxed)) {
        }
      });
    }
    Sleeper s = sleep_ticks(seconds, cpu);
    stop = true;
    reader.join();
    if (spinner.joinable()) spinner.join();
    std::sort(s.late_ns.begin(), s.late_ns.end());
    const auto count_over = [&](std::int64_t ns) {
      return static_cast<double>(s.late_ns.end() - std::upper_bound(s.late_ns.begin(), s.late_ns.end(), ns));
    };
    state.counters["late_p99_us"] = static_cast<double>(s.late_ns[s.late_ns.size() * 99 / 100]) * 1e-3;
    state.counters["late_max_us"] = static_cast<double>(s.late_ns.back()) * 1e-3;
    state.counters["over_2ms"] = count_over(2'000'000);
    state.counters["over_10ms"] = count_over(10'000'000);
    state.counters["reader_max_gap_us"] = static_cast<double>(reader_gap) * 1e-3;
    state.counters["fifo"] = s.fifo ? 1 : 0;
  }
  if (locked) munlockall();
}
BENCHMARK(BM_HostWakeup)->Args({0, 30})->Args({1, 30})->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
