// Benchmarks the DDS publisher (twin/dds/dds_publisher.hpp) on loopback.
//
//   BM_DdsOffer              the real-time path alone: offer() of a due sample into a ring
//                            with room (no consumer running), i.e. the copy, two atomics and
//                            the wake-up check the run loop pays each control sample.
//   BM_DdsOfferDecimated     offer() of a sample the 100 Hz rate skips (1 kHz offered).
//   BM_DdsSustained          samples/s the publishing thread writes (six state topics each)
//                            when offered as fast as the ring accepts: the head-room over
//                            the 1 kHz control rate. No reader.
//   BM_DdsLatency1kHz/…      offer → take latency at 1 kHz (wall-paced, 1000 samples), the
//                            reader on a waitset in another thread (arg 0: same process, where
//                            Cyclone delivers locally) or in a child process (arg 1: this
//                            program re-executed, discovery and data over the loopback
//                            interface). The sample's t_ns carries the offer's CLOCK_MONOTONIC
//                            time, so the reader computes the latency; median, p90 and p99 in µs.
//   BM_RawWriteLatency1kHz/… baseline for the above: dds_write of the same PlatformState_
//                            from the pacing thread itself (no ring, no thread hop, one
//                            topic), the same readers.
#include <benchmark/benchmark.h>
#include <poll.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "twin/dds/dds_messages.hpp"
#include "twin/dds/dds_publisher.hpp"

extern char** environ;

namespace {

using namespace omnitwin::twin;
using Clock = std::chrono::steady_clock;

constexpr int kLatencySamples = 1000;

int bench_domain(int k) { return 1 + static_cast<int>((::getpid() + 67 * k) % 230); }

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}

DdsSettings loopback(int domain, double rate_hz, std::size_t capacity = 256) {
  DdsSettings s;
  s.domain = domain;
  s.interface = "lo";
  s.rate_hz = rate_hz;
  s.queue_capacity = capacity;
  return s;
}

StateSample sample_at(std::int64_t t_ns, std::uint64_t seq) {
  StateSample s;
  s.t_ns = t_ns;
  s.seq = seq;
  s.x = 0.001 * static_cast<double>(seq), s.phi = 0.1;
  return s;
}

void BM_DdsOffer(benchmark::State& state) {
  DdsPublisher pub(loopback(bench_domain(0), 1e9, static_cast<std::size_t>(state.max_iterations)));
  std::uint64_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(pub.offer(sample_at(static_cast<std::int64_t>(i) * 1000, i))), ++i;
  state.counters["dropped"] = static_cast<double>(pub.stats().dropped);
}
BENCHMARK(BM_DdsOffer)->Iterations(200000);

void BM_DdsOfferDecimated(benchmark::State& state) {
  DdsPublisher pub(loopback(bench_domain(0), 100));
  pub.offer(sample_at(0, 0));  // the one due sample; the rest fall between publish instants
  std::uint64_t i = 1;
  for (auto _ : state) benchmark::DoNotOptimize(pub.offer(sample_at(1 + static_cast<std::int64_t>(i % 9000), i))), ++i;
}
BENCHMARK(BM_DdsOfferDecimated);

void BM_DdsSustained(benchmark::State& state) {
  constexpr std::uint64_t kSamples = 20000;
  for (auto _ : state) {
    DdsPublisher pub(loopback(bench_domain(0), 1000));
    pub.start(RunInfo{"bench", "direct", "lockstep", "", 0.001, 20});
    const auto t0 = Clock::now();
    for (std::uint64_t i = 0; i < kSamples; ++i)
      while (!pub.offer(sample_at(static_cast<std::int64_t>(i) * 1'000'000, i))) std::this_thread::yield();
    pub.finish();
    const double s = std::chrono::duration<double>(Clock::now() - t0).count();
    state.counters["samples_per_s"] = static_cast<double>(pub.stats().published) / s;
    state.counters["x_1kHz"] = static_cast<double>(pub.stats().published) / s / 1000.0;
  }
}
BENCHMARK(BM_DdsSustained)->Iterations(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// --- the reader: in a thread, or in a child process -----------------------------------

// Takes `n` PlatformState_ samples (or gives up after timeout_s) on a waitset and returns the
// latencies now − t_ns [ns].
std::vector<std::int64_t> read_latencies(const DdsEndpoint& ep, int n, double timeout_s,
                                         std::atomic<bool>* ready) {
  DdsParticipant participant(ep);
  const TopicInfo topic = *find_topic("state");
  const DdsQos qos = state_qos(64);
  const dds_entity_t r = dds_create_reader(participant.get(), create_topic(participant.get(), topic), qos.get(), nullptr);
  DdsEntity ws(dds_create_waitset(participant.get()));
  dds_waitset_attach(ws.get(), dds_create_readcondition(r, DDS_ANY_STATE), 0);
  if (ready) ready->store(true);
  std::vector<std::int64_t> lat;
  const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (static_cast<int>(lat.size()) < n && Clock::now() < end) {
    dds_waitset_wait(ws.get(), nullptr, 0, DDS_MSECS(100));
    void* samples[16] = {nullptr};
    dds_sample_info_t infos[16];
    const dds_return_t k = dds_take(r, samples, infos, 16, 16);
    const std::int64_t t = now_ns();
    for (dds_return_t i = 0; i < k; ++i)
      if (infos[i].valid_data) lat.push_back(t - static_cast<const omnitwin_msg_dds__PlatformState_*>(samples[i])->t_ns);
    if (k > 0) dds_return_loan(r, samples, k);
  }
  return lat;
}

struct Percentiles {
  double median_us = 0, p90_us = 0, p99_us = 0;
  int n = 0;
};
Percentiles percentiles(std::vector<std::int64_t> v) {
  Percentiles p;
  p.n = static_cast<int>(v.size());
  if (v.empty()) return p;
  std::sort(v.begin(), v.end());
  p.median_us = static_cast<double>(v[v.size() / 2]) / 1e3;
  p.p90_us = static_cast<double>(v[v.size() * 9 / 10]) / 1e3;
  p.p99_us = static_cast<double>(v[std::min(v.size() - 1, v.size() * 99 / 100)]) / 1e3;
  return p;
}

// The child: `bench_dds --dds-reader DOMAIN N` prints "n median_us p99_us".
int child_reader(int domain, int n) {
  std::printf("ready\n");
  std::fflush(stdout);
  const Percentiles p = percentiles(read_latencies(DdsEndpoint{domain, "lo", ""}, n, 20.0, nullptr));
  std::printf("%d %.3f %.3f %.3f\n", p.n, p.median_us, p.p90_us, p.p99_us);
  return 0;
}

struct Child {
  pid_t pid = -1;
  int out = -1;
};
Child spawn_reader(int domain, int n) {
  int fds[2];
  if (::pipe(fds) != 0) return {};
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, fds[1], STDOUT_FILENO);
  posix_spawn_file_actions_addclose(&fa, fds[0]);
  std::string exe = "/proc/self/exe", flag = "--dds-reader", d = std::to_string(domain), c = std::to_string(n);
  char* argv[] = {exe.data(), flag.data(), d.data(), c.data(), nullptr};
  Child ch;
  posix_spawn(&ch.pid, exe.c_str(), &fa, nullptr, argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  ::close(fds[1]);
  ch.out = fds[0];
  return ch;
}

std::string read_line(int fd) {
  std::string s;
  char c;
  while (::read(fd, &c, 1) == 1 && c != '\n') s += c;
  return s;
}

// Paces `send(i, t_ns)` at 1 kHz on an absolute grid; a warm-up of 200 samples lets
// discovery finish before the measured ones (the reader counts only the last n).
template <class Send>
void pace_1khz(int total, Send send) {
  auto next = Clock::now();
  for (int i = 0; i < total; ++i) {
    next += std::chrono::milliseconds(1);
    std::this_thread::sleep_until(next);
    send(static_cast<std::uint64_t>(i), now_ns());
  }
}

template <class Send>
Percentiles measure(int domain, bool other_process, Send send) {
  constexpr int kWarmup = 300;
  if (!other_process) {
    std::atomic<bool> ready{false};
    std::vector<std::int64_t> lat;
    std::thread reader([&] { lat = read_latencies(DdsEndpoint{domain, "lo", ""}, kWarmup + kLatencySamples,
                          (kWarmup + kLatencySamples) * 1e-3 + 1.0, &ready); });
    while (!ready) std::this_thread::yield();
    pace_1khz(kWarmup + kLatencySamples, send);
    reader.join();
    if (lat.size() > kLatencySamples) lat.erase(lat.begin(), lat.end() - kLatencySamples);
    return percentiles(lat);
  }
  Child ch = spawn_reader(domain, kLatencySamples);
  read_line(ch.out);  // "ready"
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // discovery over loopback
  pace_1khz(kLatencySamples + 50, send);
  Percentiles p;
  std::sscanf(read_line(ch.out).c_str(), "%d %lf %lf %lf", &p.n, &p.median_us, &p.p90_us, &p.p99_us);
  ::close(ch.out);
  ::waitpid(ch.pid, nullptr, 0);
  return p;
}

void report(benchmark::State& state, const Percentiles& p) {
  state.counters["median_us"] = p.median_us;
  state.counters["p90_us"] = p.p90_us;
  state.counters["p99_us"] = p.p99_us;
  state.counters["received"] = p.n;
}

void BM_DdsLatency1kHz(benchmark::State& state) {
  const bool other = state.range(0) == 1;
  for (auto _ : state) {
    const int domain = bench_domain(1 + static_cast<int>(state.range(0)));
    DdsPublisher pub(loopback(domain, 1000, 1024));
    pub.start(RunInfo{"bench", "direct", "realtime", "", 0.001, 2});
    report(state, measure(domain, other, [&](std::uint64_t i, std::int64_t t) { pub.offer(sample_at(t, i)); }));
    pub.finish();
  }
}
BENCHMARK(BM_DdsLatency1kHz)->Arg(0)->Arg(1)->Iterations(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_RawWriteLatency1kHz(benchmark::State& state) {
  const bool other = state.range(0) == 1;
  for (auto _ : state) {
    const int domain = bench_domain(3 + static_cast<int>(state.range(0)));
    DdsParticipant participant(DdsEndpoint{domain, "lo", ""});
    const DdsQos qos = state_qos(1);
    const dds_entity_t w = dds_create_writer(participant.get(), create_topic(participant.get(), *find_topic("state")),
                                             qos.get(), nullptr);
    omnitwin::twin::ddsmsg::StateMessages m;
    const std::string bus = "direct";
    report(state, measure(domain, other, [&](std::uint64_t i, std::int64_t t) {
      m.fill(sample_at(t, i), bus);
      dds_write(w, &m.state);
    }));
  }
}
BENCHMARK(BM_RawWriteLatency1kHz)->Arg(0)->Arg(1)->Iterations(1)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

int main(int argc, char** argv) {
  if (argc == 4 && std::strcmp(argv[1], "--dds-reader") == 0) return child_reader(std::atoi(argv[2]), std::atoi(argv[3]));
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
