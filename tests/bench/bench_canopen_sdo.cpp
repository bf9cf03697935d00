// Benchmarks SDO round trips per second against the twin's CANopen drives, as a user gets
// them: `omnitwin twin models/scenarios/thesis_line.yaml --bus canopen` (the real program,
// realtime, four CiA 402 drives on the simulated 1 Mbit/s wire, UDP multicast on loopback,
// group 239.74.163.2 port 47330) and our SDO client core (controller/canopen/co_sdo_client) on
// the same UDP bus, reading from node 1 one transfer after another. Baseline, in the same
// benchmark binary: the same client against the same SDO server core (bus_emulators/canopen,
// dictionary from the same EDS) wired directly, no transport, no wire, no twin.
//
//   BM_SdoTwin/K          K = 0: expedited upload of 0x1018:1 (vendor ID, 4 bytes: one request,
//                         one response); 1: segmented upload of 0x1008 (device name, 22 bytes:
//                         initiate + 4 segments); 2: block upload of 0x1008; 3: expedited
//                         download of 0x1017. Counters: transfers_per_s (wall), frames_per_transfer,
//                         aborts.
//   BM_SdoInProcess/K     the same transfers between the two cores directly.
// The twin takes the master's frames when its realtime loop polls the transport (every
// millisecond, its master tick), so one request-response exchange costs about a millisecond
// there: this is the twin's service rate, not the protocol's.
#include <benchmark/benchmark.h>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bus_emulators/can/transport.hpp"
#include "bus_emulators/canopen/co_eds.hpp"
#include "bus_emulators/canopen/co_sdo_server.hpp"
#include "controller/canopen/co_sdo_client.hpp"

extern char** environ;

namespace {

namespace co = omnitwin::canopen;
namespace cc = omnitwin::controller::canopen;
namespace fs = std::filesystem;

const std::string kEds = std::string(OMNITWIN_SOURCE_DIR) + "/models/canopen/omnitwin_drive.eds";
const std::string kSpec = "udp:239.74.163.2:47330";

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Starts one transfer of kind k on the client.
void start(cc::SdoClient& c, int k, std::int64_t t) {
  static const std::uint8_t hb[2] = {100, 0};
  switch (k) {
    case 0: c.upload(1, 0x1018, 1, t); break;
    case 1: c.upload(1, 0x1008, 0, t); break;
    case 2: c.upload(1, 0x1008, 0, t, cc::TransferMode::block); break;
    default: c.download(1, 0x1017, 0, hb, t); break;
  }
}

// `omnitwin twin` in the background until the benchmark ends.
class TwinProcess {
 public:
  TwinProcess() {
    const fs::path out = fs::temp_directory_path() / "omnitwin-bench-sdo";
    log_ = out.string() + ".log";
    std::vector<std::string> args{OMNITWIN_EXE, "twin", std::string(OMNITWIN_SOURCE_DIR) + "/models/scenarios/thesis_line.yaml",
                                  "--bus", "canopen", "--set", "bus.transport=" + kSpec, "--set", "duration=600",
                                  "--no-progress", "--out", out.string()};
    std::string cmd;
    for (const auto& a : args) cmd += (cmd.empty() ? "" : " ") + a;
    std::cerr << "  $ " << cmd << "\n";
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    if (posix_spawn(&pid_, argv[0], &fa, nullptr, argv.data(), environ) != 0) pid_ = 0;
    posix_spawn_file_actions_destroy(&fa);
  }
  ~TwinProcess() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGINT);
    int st = 0;
    ::waitpid(pid_, &st, 0);
  }
  // Waits until the twin says it listens (10 s at most).
  bool ready() const {
    for (int i = 0; i < 200 && pid_ > 0; ++i) {
      std::ifstream f(log_);
      std::stringstream ss;
      ss << f.rdbuf();
      if (ss.str().find("waiting for a master") != std::string::npos) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
  }

 private:
  pid_t pid_ = 0;
  std::string log_;
};

void BM_SdoTwin(benchmark::State& state) {
  static TwinProcess twin;
  if (!twin.ready()) {
    state.SkipWithError("omnitwin twin did not start (see /tmp/omnitwin-bench-sdo.log)");
    return;
  }
  auto tr = omnitwin::can::open_transport(kSpec);
  std::uint64_t frames = 0, aborts = 0, done = 0;
  cc::SdoClient client([&](const omnitwin::can::Frame& f, co::SimTime) {
    ++frames;
    return tr->send(f, 0);
  }, cc::SdoClientConfig{.timeout_ns = 500'000'000});
  const int k = static_cast<int>(state.range(0));
  for (auto _ : state) {
    start(client, k, now_ns());
    for (;;) {
      if (auto r = tr->receive()) {
        if ((r->frame.id & 0x780) == 0x580) ++frames;
        client.on_frame(r->frame, now_ns());
      } else {
        omnitwin::can::wait_readable(*tr, std::chrono::milliseconds(5));
      }
      client.on_time(now_ns());
      const cc::SdoResult* res = client.result(1);
      if (res && res->status != cc::SdoStatus::busy) {
        (res->status == cc::SdoStatus::done ? done : aborts)++;
        break;
      }
    }
  }
  state.counters["transfers_per_s"] = benchmark::Counter(static_cast<double>(done), benchmark::Counter::kIsRate);
  state.counters["frames_per_transfer"] = done ? static_cast<double>(frames) / static_cast<double>(done + aborts) : 0;
  state.counters["aborts"] = static_cast<double>(aborts);
}

void BM_SdoInProcess(benchmark::State& state) {
  const co::EdsDevice eds = co::load_eds(kEds);
  co::ObjectDictionary od;
  co::add_to_od(eds, 1, od);
  std::vector<omnitwin::can::Frame> to_server, to_client;
  co::SdoServer server(od, 1, [&](const omnitwin::can::Frame& f, co::SimTime) {
    to_client.push_back(f);
    return true;
  });
  std::uint64_t frames = 0, done = 0, aborts = 0;
  cc::SdoClient client([&](const omnitwin::can::Frame& f, co::SimTime) {
    to_server.push_back(f);
    return true;
  });
  const int k = static_cast<int>(state.range(0));
  std::int64_t t = 0;
  for (auto _ : state) {
    start(client, k, t);
    while (!to_server.empty() || !to_client.empty()) {
      for (std::size_t i = 0; i < to_server.size(); ++i) server.on_frame(to_server[i], t, co::OdState::preop);
      frames += to_server.size();
      to_server.clear();
      std::vector<omnitwin::can::Frame> in;
      in.swap(to_client);
      frames += in.size();
      for (const auto& f : in) client.on_frame(f, t);
      t += 1000;
    }
    const cc::SdoResult* res = client.result(1);
    (res && res->status == cc::SdoStatus::done ? done : aborts)++;
  }
  state.counters["transfers_per_s"] = benchmark::Counter(static_cast<double>(done), benchmark::Counter::kIsRate);
  state.counters["frames_per_transfer"] = done ? static_cast<double>(frames) / static_cast<double>(done + aborts) : 0;
  state.counters["aborts"] = static_cast<double>(aborts);
}

}  // namespace

BENCHMARK(BM_SdoTwin)->DenseRange(0, 3)->ArgName("kind")->MinTime(3.0)->UseRealTime();
BENCHMARK(BM_SdoInProcess)->DenseRange(0, 3)->ArgName("kind");
BENCHMARK_MAIN();
