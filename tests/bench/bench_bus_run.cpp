// Benchmarks whole bus runs through the real programs: `omnitwin run` (built beside this
// benchmark) with `--bus ethercat`, `--bus m3`, `--bus canopen` or `--bus tml`, which starts `omni-master --bus …` as its own
// process.
// Every figure is read from the run's metrics.json; the baseline is the same scenario with
// `--bus direct`, run in the same benchmark (DESIGN §11).
//
//   BM_EthercatLockstep/P/T  the thesis line (22 s simulated) in lockstep over EtherCAT:
//                    master period P ms (10 or 1: --set controller.period), transport T
//                    (0: a veth pair made for the run, raw AF_PACKET on both ends — needs root,
//                    skipped otherwise; 1: EtherCAT over UDP on 127.0.0.1, ports 47950–47959),
//                    the sim-clock handshake every master tick, four drive slaves at 1 kHz with
//                    distributed clocks. Each iteration runs the EtherCAT command and then the
//                    same command with --bus direct (same period), so both see the same
//                    machine load. Counters: rtf and direct_rtf (metrics.json
//                    real_time_factor: simulated seconds per wall second of the run itself),
//                    slowdown = direct_rtf / rtf, us_per_tick (EtherCAT wall time per master
//                    tick), process_rtf (simulated seconds per wall second of the whole command,
//                    start-up, master start and OP included), wkc_errors / lost_frames / cycles
//                    per run from the master's statistics (metrics.json master.*), passed (1 when
//                    every EtherCAT run met the scenario's expectations).
//   BM_EthercatRealtime/P    `--clock realtime` for 60 s of simulated time (--set duration=60:
//                    the 20 s path and 40 s standing still) at master period P ms (1), the
//                    transport the default `auto` (veth as root). One run. Counters:
//                    metrics.json realtime.{ticks, overruns, jitter_mean_us, jitter_p99_us,
//                    jitter_max_us} (the twin's master tick against its CLOCK_MONOTONIC deadline)
//                    and the master's own statistics (cycles, wkc_errors, lost_frames,
//                    recoveries, … whatever master-stats.json holds; printed whole on stderr).
//   BM_DirectRealtime/P      the same realtime run with --bus direct: the baseline of the
//                    deadline figures (the twin's clock without a bus).
//   BM_M3Lockstep/T/N        the thesis line (22.5 s simulated) in exchange-level lockstep over
//                    MECHATROLINK-III: N servo stations (4: the wheels, a 1 ms transmission
//                    cycle; 62: a full line, 3 ms, the shortest the wire model fits being
//                    2.82 ms), one master tick per cycle, every frame met inside the tick
//                    (Sent/Horizon); transport T (0: veth, needs root; 1: UDP on 127.0.0.1). Baseline: the same
//                    scenario with --bus direct at a 1 ms control period (one master tick per
//                    ms too), in the same iteration. Counters as BM_EthercatLockstep (rtf,
//                    direct_rtf, slowdown, process_rtf, us_per_tick) and the master's retries,
//                    missed and late responses per run.
//   BM_M3Realtime/N          `--bus m3 --clock realtime` for 60 s (--set duration=60), N stations
//                    (4 at a 1 ms cycle; 62 at 10 ms: across processes the measured round
//                    trips make 9.3 ms the shortest that fits), the default transport: the twin's tick figures (realtime.*), the master's
//                    statistics (cycles, exchanges, retries, missed, late …) and the slaves'
//                    communication alarms, watchdog errors and missed SYNCs summed over the four.
//   BM_CanopenLockstep/R/C   the thesis line (22 s simulated) in lockstep over CANopen: our master
//                    and four CiA 402 drives on the simulated CAN wire at R kbit/s with a C ms SYNC
//                    (one master tick per SYNC), UDP multicast on loopback. Baseline: --bus direct
//                    at a C ms control period, in the same iteration. Counters as
//                    BM_EthercatLockstep plus load (metrics.json bus.load: the wire's busy
//                    fraction over the run) and the master's SDO transfers, EMCYs and heartbeat
//                    timeouts per run; passed says whether the run met the scenario's
//                    expectations (500 kbit/s at 1 ms does not fit: the wire saturates).
//   BM_CanopenDriveSync    the same at 1 Mbit/s with a 1 ms SYNC produced by drive 1 (0x1005 gen
//                    bit) and the master ticking at the 10 ms control period (RPDOs taking
//                    effect at the drive's next SYNC). Baseline: --bus direct at 10 ms.
//   BM_TmlLockstep/P       the thesis line in lockstep over TML: our TML master and four IDM
//                    drives on the simulated 1 Mbit/s CAN wire, P = 0 TMLCAN, 1 TechCAN, a 2 ms
//                    tick (CSPD to each axis, UPD, a group GiveMeData2 of APOS). Baseline: --bus
//                    direct at a 2 ms control period, same iteration. Counters as
//                    BM_CanopenLockstep (the master's answers and lost axes per run).
// The exact command of every run is printed on stderr. A run that cannot start (exit 2 or 3)
// skips with the tail of its log.
#include <benchmark/benchmark.h>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

extern char** environ;

namespace {

namespace fs = std::filesystem;

const std::string kScenario = std::string(OMNITWIN_SOURCE_DIR) + "/models/scenarios/thesis_line.yaml";

struct RunOutcome {
  int exit_code = -1;
  double wall_s = 0;            // the whole command
  nlohmann::json metrics;       // metrics.json (null when absent)
  std::string log;              // stdout + stderr of the command
  std::string command;
};

std::string quoted(const std::vector<std::string>& args) {
  std::string s;
  for (const auto& a : args) s += (s.empty() ? "" : " ") + a;
  return s;
}

// Runs `omnitwin run <thesis_line> <extra…> --out DIR --no-video --no-report --no-progress`,
// stdout and stderr into DIR.log; reads DIR/metrics.json.
RunOutcome run_omnitwin(const std::string& name, const std::vector<std::string>& extra) {
  const fs::path root = fs::temp_directory_path() / "omnitwin-bench-bus";
  const fs::path out = root / name;
  fs::remove_all(out);
  fs::create_directories(root);
  const fs::path log = root / (name + ".log");
  std::vector<std::string> args{OMNITWIN_EXE, "run", kScenario};
  args.insert(args.end(), extra.begin(), extra.end());
  args.insert(args.end(), {"--no-video", "--no-report", "--no-progress", "--out", out.string()});
  RunOutcome r;
  r.command = quoted(args);
  std::cerr << "  $ " << r.command << "\n";

  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  const auto t0 = std::chrono::steady_clock::now();
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) {
    r.log = std::string("posix_spawn failed: ") + std::strerror(rc);
    return r;
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  std::ifstream lf(log);
  std::stringstream ss;
  ss << lf.rdbuf();
  r.log = ss.str();
  std::ifstream mf(out / "metrics.json");
  if (mf) r.metrics = nlohmann::json::parse(mf, nullptr, false);
  fs::remove_all(out);
  return r;
}

// False (and the benchmark skipped with the log's tail) when the run produced no metrics.
bool usable(benchmark::State& state, const RunOutcome& r) {
  if ((r.exit_code == 0 || r.exit_code == 1) && r.metrics.is_object()) return true;
  const std::string tail = r.log.size() > 600 ? r.log.substr(r.log.size() - 600) : r.log;
  state.SkipWithError(("exit " + std::to_string(r.exit_code) + ": " + r.command + "\n" + tail).c_str());
  return false;
}

double number(const nlohmann::json& j, const char* section, const char* key) {
  if (!j.contains(section) || !j[section].is_object()) return -1;
  const auto& s = j[section];
  return s.contains(key) && s[key].is_number() ? s[key].get<double>() : -1;
}

std::string period_s(std::int64_t ms) { return ms == 10 ? "0.01" : ms == 1 ? "0.001" : std::to_string(ms / 1000.0); }

// Each iteration: the bus run, then the same scenario with --bus direct. Counters: rtf,
// direct_rtf, slowdown, process_rtf, us_per_tick (the bus run's wall time per master tick,
// tick_s long), the master's `keys` per run (metrics.json master.*), passed.
void lockstep_vs_direct(benchmark::State& state, const char* name, const std::vector<std::string>& bus,
                        const std::vector<std::string>& direct, double tick_s, const std::vector<const char*>& keys) {
  double sim = 0, wall = 0, process_wall = 0, dsim = 0, dwall = 0, passed = 1, load = -1;
  std::vector<double> sums(keys.size(), 0.0);
  for (auto _ : state) {
    const RunOutcome e = run_omnitwin(name, bus);
    if (!usable(state, e)) break;
    const RunOutcome d = run_omnitwin("direct", direct);
    if (!usable(state, d)) break;
    sim += e.metrics.at("sim_time_s").get<double>();
    wall += e.metrics.at("wall_time_s").get<double>();
    process_wall += e.wall_s;
    dsim += d.metrics.at("sim_time_s").get<double>();
    dwall += d.metrics.at("wall_time_s").get<double>();
    for (std::size_t i = 0; i < keys.size(); ++i) sums[i] += number(e.metrics, "master", keys[i]);
    load = std::max(load, number(e.metrics, "bus", "load"));
    passed = std::min(passed, e.exit_code == 0 ? 1.0 : 0.0);
    std::cerr << "    " << name << ": rtf " << e.metrics.value("real_time_factor", 0.0) << ", exit " << e.exit_code
              << "\n    direct: rtf " << d.metrics.value("real_time_factor", 0.0) << "\n";
  }
  if (wall <= 0 || dwall <= 0) return;
  state.counters["rtf"] = sim / wall;
  state.counters["direct_rtf"] = dsim / dwall;
  state.counters["slowdown"] = (dsim / dwall) / (sim / wall);
  state.counters["process_rtf"] = sim / process_wall;
  state.counters["us_per_tick"] = 1e6 * wall / (sim / tick_s);
  const auto runs = static_cast<double>(state.iterations());
  for (std::size_t i = 0; i < keys.size(); ++i) state.counters[keys[i]] = sums[i] / runs;  // per run
  state.counters["passed"] = passed;
  if (load >= 0) state.counters["load"] = load;
}

void BM_EthercatLockstep(benchmark::State& state) {
  const std::int64_t ms = state.range(0);
  const bool udp = state.range(1) == 1;
  std::vector<std::string> ecat{"--bus", "ethercat", "--set", "controller.period=" + period_s(ms)};
  if (udp)
    ecat.insert(ecat.end(), {"--set", "bus.transport=udp:127.0.0.1:" + std::to_string(47950 + (ms == 1 ? 1 : 0))});
  else
    ecat.insert(ecat.end(), {"--set", "bus.transport=veth"});
  const std::vector<std::string> direct{"--bus", "direct", "--set", "controller.period=" + period_s(ms)};
  lockstep_vs_direct(state, "ethercat", ecat, direct, static_cast<double>(ms) / 1000.0,
                     {"wkc_errors", "lost_frames", "cycles"});
}

// The cycle a line of N stations gets: 1 ms for the four wheels; 62 stations need 2.82 ms in
// lockstep (the wire model) and 9.3 ms across processes (the measured round trips).
std::string m3_cycle(std::int64_t stations, bool realtime) {
  return stations <= 4 ? "bus.cycle=0.001" : realtime ? "bus.cycle=0.010" : "bus.cycle=0.003";
}

void realtime(benchmark::State& state, const char* bus) {
  // The M-III master's tick is its transmission cycle (bus.cycle); the others' the control
  // period. For M-III the argument is the number of stations.
  const bool m3 = std::string(bus) == "m3";
  std::vector<std::string> args{"--bus", bus, "--clock", "realtime", "--set",
                                m3 ? m3_cycle(state.range(0), true) : "controller.period=" + period_s(state.range(0)),
                                "--set", "duration=60"};
  if (m3) args.insert(args.end(), {"--set", "bus.stations=" + std::to_string(state.range(0))});
  for (auto _ : state) {
    const RunOutcome r = run_omnitwin(std::string("realtime-") + bus, args);
    if (!usable(state, r)) break;
    const auto& m = r.metrics;
    state.counters["sim_s"] = m.value("sim_time_s", 0.0);
    state.counters["wall_s"] = m.value("wall_time_s", 0.0);
    for (const char* k : {"ticks", "overruns", "jitter_mean_us", "jitter_p99_us", "jitter_max_us"})
      state.counters[k] = number(m, "realtime", k);
    if (m.contains("realtime")) std::cerr << "    realtime: " << m["realtime"].dump() << "\n";
    if (m.contains("master") && m["master"].is_object()) {
      std::cerr << "    master:   " << m["master"].dump() << "\n";
      for (const auto& [k, v] : m["master"].items())
        if (v.is_number()) state.counters["master." + k] = v.get<double>();
    }
    if (m.contains("bus")) std::cerr << "    bus:      " << m["bus"].dump() << "\n";
    if (m.contains("slaves") && m["slaves"].is_array()) {
      for (const char* k : {"comm_alarms", "wdt_errors", "missed_syncs", "missed_commands"}) {
        double sum = 0;
        for (const auto& sl : m["slaves"]) sum += sl.value(k, 0.0);
        if (m["bus"].value("name", "") == "m3") state.counters[std::string("slaves.") + k] = sum;
      }
    }
    state.counters["passed"] = r.exit_code == 0 ? 1 : 0;
  }
}

void BM_M3Lockstep(benchmark::State& state) {
  const bool udp = state.range(0) == 1;
  const std::int64_t stations = state.range(1);
  const std::vector<std::string> m3{"--bus", "m3", "--set", udp ? "bus.transport=udp:127.0.0.1:0" : "bus.transport=veth",
                                    "--set", "bus.stations=" + std::to_string(stations), "--set", m3_cycle(stations, false)};
  const std::vector<std::string> direct{"--bus", "direct", "--set", "controller.period=0.001"};
  lockstep_vs_direct(state, "m3", m3, direct, stations <= 4 ? 0.001 : 0.003, {"retries", "missed", "late", "cycles"});
}

void BM_CanopenLockstep(benchmark::State& state) {
  const std::int64_t kbit = state.range(0), ms = state.range(1);
  const std::vector<std::string> co{"--bus", "canopen", "--set", "bus.bit_rate=" + std::to_string(kbit * 1000),
                                    "--set", "bus.cycle=" + period_s(ms)};
  const std::vector<std::string> direct{"--bus", "direct", "--set", "controller.period=" + period_s(ms)};
  lockstep_vs_direct(state, "canopen", co, direct, static_cast<double>(ms) / 1000.0,
                     {"sdo_done", "emcy", "heartbeat_timeouts", "cycles"});
}

void BM_CanopenDriveSync(benchmark::State& state) {
  const std::vector<std::string> co{"--bus", "canopen", "--set", "bus.sync_producer=drive"};
  const std::vector<std::string> direct{"--bus", "direct", "--set", "controller.period=0.01"};
  lockstep_vs_direct(state, "canopen", co, direct, 0.01, {"sdo_done", "emcy", "heartbeat_timeouts", "cycles"});
}

void BM_TmlLockstep(benchmark::State& state) {
  const std::vector<std::string> tml{"--bus", "tml", "--set", std::string("bus.protocol=") + (state.range(0) ? "techcan" : "tmlcan")};
  const std::vector<std::string> direct{"--bus", "direct", "--set", "controller.period=0.002"};
  lockstep_vs_direct(state, "tml", tml, direct, 0.002, {"answers", "axes_lost", "cycles"});
}

void BM_EthercatRealtime(benchmark::State& state) { realtime(state, "ethercat"); }
void BM_M3Realtime(benchmark::State& state) { realtime(state, "m3"); }
void BM_DirectRealtime(benchmark::State& state) { realtime(state, "direct"); }

}  // namespace

BENCHMARK(BM_EthercatLockstep)
    ->ArgsProduct({{10, 1}, {0, 1}})
    ->ArgNames({"period_ms", "udp"})
    ->Unit(benchmark::kSecond)
    ->Iterations(3)
    ->UseRealTime();
BENCHMARK(BM_M3Lockstep)
    ->Args({0, 4})
    ->Args({1, 4})
    ->Args({0, 62})
    ->ArgNames({"udp", "stations"})
    ->Unit(benchmark::kSecond)
    ->Iterations(3)
    ->UseRealTime();
BENCHMARK(BM_CanopenLockstep)
    ->Args({1000, 1})
    ->Args({500, 1})
    ->Args({500, 2})
    ->Args({250, 4})
    ->Args({125, 8})
    ->ArgNames({"kbit", "sync_ms"})
    ->Unit(benchmark::kSecond)
    ->Iterations(3)
    ->UseRealTime();
BENCHMARK(BM_CanopenDriveSync)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_TmlLockstep)->Arg(0)->Arg(1)->ArgName("techcan")->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_M3Realtime)->Arg(4)->Arg(62)->ArgName("stations")->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_EthercatRealtime)->Arg(1)->ArgName("period_ms")->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_DirectRealtime)->Arg(1)->ArgName("period_ms")->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK_MAIN();
