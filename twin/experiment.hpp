// twin layer — `omnitwin experiment NAME`: seed 002's own measurements re-run on the twin
// (DESIGN §10), and seed 000's M-III cycle study (m3-cycle), each writing CSV + markdown
// (ours beside the source's where it has numbers) + PNG plots.
//
// Shaped as a small name → function registry so the CLI (twin/main.cpp) stays a thin
// dispatcher and each experiment lives in its own file (experiment_can_timing.cpp,
// experiment_can_dropout.cpp, experiment_thesis_platform.cpp, experiment_m3_cycle.cpp). The
// dropout model and the M-III cycle trial are declared here too, because the tests drive
// single trials of them directly; everything else an experiment needs (output folder, text
// files, the matplotlib script) is in namespace experiment below and shared by all of them.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "twin/scenario.hpp"

namespace omnitwin::twin {

struct CsvColumns;

struct ExperimentOptions {
  ExperimentOptions(std::string out = {}, bool quick_run = false) : out_dir(std::move(out)), quick(quick_run) {}
  std::string out_dir;  // output folder; empty: out/<name> under the working directory
  bool quick = false;   // fewer configurations and messages (tests); the same checks run
  // thesis-platform: the thesis-line scenario to run (default: models/scenarios/
  // thesis_line_fitted.yaml when it exists, else thesis_line.yaml); thesis-calibrate: where to
  // write the fitted scenario (default: that fitted file; in quick mode: the output folder).
  std::string model;
  int budget = 0;       // thesis-calibrate: objective evaluations (0: its default; else >= 9)
  // thesis-platform and thesis-calibrate: scenario overrides (--set KEY=VALUE) applied to every
  // run after the experiment's own, e.g. a model option to try; named in the outputs. The other
  // experiments refuse them (bad input).
  std::vector<Override> sets;
  // Set by SIGINT/SIGTERM: checked between runs and passed to each run; an interrupted
  // experiment exits 3 and writes no summary files.
  const std::atomic<bool>* interrupt = nullptr;
};

// Exit codes of run_experiment() and of each experiment function.
inline constexpr int kExperimentOk = 0;
inline constexpr int kExperimentCheckFailed = 1;   // a direction (or claimed accuracy) check failed
inline constexpr int kExperimentUnknown = 2;       // unknown name (the known names go to stderr), bad input
inline constexpr int kExperimentRuntimeError = 3;  // outputs could not be written, a run failed, or interrupted

// Runs experiment `name` (one of experiment_names()) into options.out_dir. Prints a short
// summary and the output paths on stdout. Returns one of the exit codes above.
int run_experiment(const std::string& name, const ExperimentOptions& options);

// The registered names, in the order `omnitwin experiment` lists them.
std::vector<std::string> experiment_names();

// The experiments themselves (registered under "can-timing", "can-dropout", "thesis-platform",
// "m3-cycle", "thesis-calibrate", "fast-model").
int run_can_timing(const ExperimentOptions& options);
int run_can_dropout(const ExperimentOptions& options);
int run_thesis_platform(const ExperimentOptions& options);
int run_m3_cycle(const ExperimentOptions& options);
int run_thesis_calibrate(const ExperimentOptions& options);
int run_fast_model(const ExperimentOptions& options);

// ---- the fast-model comparison (experiment_fast_model.cpp) ----

// How closely one run's platform follows another's, from their trajectory.csv records.
struct TwistAgreement {
  // RMS over windows of |mean twist difference| / RMS of |mean reference twist|, twist =
  // (vx, vy, L·wz) [-]; the windows average out the roller model's ripple.
  double twist_error = 0;
  double final_pose_diff_m = 0;  // |Δ(x, y)| + L·|Δphi| at the last common sample [m]
  double path_m = 0;             // the reference's travel, Σ |Δ(x, y)| + L·|Δphi| [m]
  int windows = 0;
};
// Compares the common samples of two trajectories (columns t, x, y, phi, vx, vy, wz) in windows of
// window_s; wheel_distance_m is L. Throws std::runtime_error for files without those columns or
// with fewer than two rows.
TwistAgreement twist_agreement(const CsvColumns& ref, const CsvColumns& fast, double wheel_distance_m,
                               double window_s);

inline constexpr double kFastModelTwistBound = 0.005;  // issue 17: within 0.5 % of the reference

struct FastModelRow {
  std::string scenario;  // the file's stem
  std::string config;    // which fast configuration (set by the caller)
  TwistAgreement agreement;
  double rtf_reference = 0, rtf_fast = 0;  // medians of the timed runs
  int exit_reference = 0, exit_fast = 0;   // of the last runs (1: the scenario's expectations failed)
};
// Runs `scenario` on bus direct in lockstep on the reference and on the fast model, `reps` times
// interleaved, into dir/reference and dir/fast, with `fast_overrides` applied to the fast runs
// only; compares the last pair. Throws what load_scenario and run_scenario throw.
FastModelRow compare_fast_model(const std::string& scenario, const std::filesystem::path& dir, int reps,
                                const std::vector<Override>& fast_overrides = {},
                                const std::atomic<bool>* interrupt = nullptr);

// ---- the m3-cycle verification: one configuration run on the in-process M-III rig ----

// One configuration of the cycle study, run at its planned shortest cycle (whole µs) and
// 1 µs below it (see experiment_m3_cycle.cpp). The last two fields are faults for the tests:
// they make a check fail on purpose.
struct M3CycleTrial {
  bool star = false;                  // cascade (false) or star, 10 m cables
  int slaves = 4;                     // 1 … 62
  int data_bytes = 32;                // 32: servo start-up to phase 3; other lengths: NOP in phase 1
  int retry_slots = 1;
  int cycles = 200;                   // cycles checked after start-up
  std::int64_t slave_slower_ns = 0;   // fault: every slave answers this much later than planned
  int corrupt_every = 0;              // fault: every n-th response corrupted on the line (0: none)
};

struct M3CycleVerified {
  M3CycleTrial trial;
  std::int64_t min_cycle_ns = 0, cycle_ns = 0;  // planned shortest; the cycle run (whole µs)
  std::int64_t int_offset_ns = 0, retry_ns = 0;
  std::int64_t expected_last_ns = 0;            // cycle start → last response, from the plan
  std::int64_t measured_min_ns = 0, measured_max_ns = 0;  // the same on the line, over the cycles
  std::int64_t interrupt_min_ns = 0, interrupt_max_ns = 0;  // cycle start → cyclic interrupt
  std::uint64_t cycles = 0, missed = 0, retries = 0, late = 0, bad = 0, comm_alarms = 0;
  int phase = 0;                 // the lowest phase any slave ended in
  bool shorter_refused = false;  // 1 µs less: failed, naming the shortest cycle
  std::string why;               // "" when every check passed, else the first that failed
  bool ok() const { return why.empty(); }
};

// Runs one trial (both cycles) and judges it. Deterministic. Throws std::invalid_argument
// for a configuration m3::check_inputs refuses.
M3CycleVerified run_m3_cycle_trial(const M3CycleTrial& trial);
// run_m3_cycle with the faults of `faults` (slave_slower_ns, corrupt_every) applied to every
// run: how the tests see a failing check give kExperimentCheckFailed.
int run_m3_cycle(const ExperimentOptions& options, const M3CycleTrial& faults);

// ---- the m3-cycle latency part (experiment_m3_latency.cpp) ----

// Event-driven latency on one line, measured and expected from the wire model [ns], beside
// the cyclic mode's shortest cycle at 64 bytes.
struct M3LatencyRow {
  bool star = false;
  int slaves = 0;
  std::int64_t idle_ns = -1, idle_expected_ns = 0;  // one request, farthest slave, idle line
  std::int64_t all_ns = -1, all_expected_ns = 0;    // every slave at once: until the last answers
  std::int64_t cyclic_ns = 0;                       // shortest cycle, 64 bytes, 1 retry slot
  std::string why;                                  // "" when the measurements match the model
  bool ok() const { return why.empty(); }
};
M3LatencyRow m3_event_latency(bool star, int slaves);
std::string m3_latency_csv(const std::vector<M3LatencyRow>& rows);
std::string m3_latency_section(const std::vector<M3LatencyRow>& rows);

// ---- the can-dropout model: one trial of the thesis's chapter-2 test (see the .cpp) ----

// How the slave's timer period departs from the master's nominal period P.
enum class SlaveClock : std::uint8_t {
  rate,     // oscillator error: slave period = P·(1 + drift)
  isr_lag,  // fixed time lost per interrupt: slave period = P + drift·5 ms (the thesis's own
            // estimate reading: 0.72 ms per 40 interrupts whatever the period)
};
const char* to_string(SlaveClock c);

struct DropoutTrial {
  std::int64_t bit_rate_bps = 1'000'000;  // [bit/s]
  int data_bytes = 8;                     // payload of each command frame, 0..8
  std::int64_t period_ns = 5'000'000;     // master sampling period P (nominal timer) [ns]
  int messages = 2000;                    // commands the master sends: N of eq. 2-2
  bool sync = false;                      // the synchronisation of 3-2-2
  int sync_interval = 4;                  // K: timer interrupts between forced resyncs, >= 1
  SlaveClock clock = SlaveClock::rate;
  // Slave clock error against the master [-]: 0.362 % measured (fig. 2-13 … 2-16). The sign
  // says which way the slave's samples slide: negative = they come earlier each period.
  double drift = -3.62e-3;
  // Initial phase θ0: the slave's first sample falls θ0·P after the master's first command
  // tick [-], 0 < θ0 < 1. 0.652 = fig. 2-15: 1.74 ms before the next master tick at 5 ms.
  double initial_phase = 0.652;
  std::int64_t t_pre_ns = 604;      // master processing before its frame (table 2-1) [ns]
  std::int64_t t_post_ns = 88'800;  // slave receive interrupt length (table 2-1) [ns]
};

struct DropoutResult {
  int messages = 0;            // N: commands the master tried to send
  int commands_refused = 0;    // of which its transmit queue refused (bus saturated)
  int commands_received = 0;   // command frames the slave received
  int judged = 0;              // slave samples judged (those numbered 1 … N)
  int dropouts = 0;            // N_dropout, counted by the slave (eq. 2-2)
  int reported_dropouts = -1;  // the count the slave sent back after stop (-1: none arrived)
  int first_dropout = -1;      // judged samples before the first dropout; -1: none
  int resyncs = 0;             // event-driven samples (3-2-2)
  double p_percent = 0.0;      // eq. 2-2: N_dropout / N · 100 [%]
  int n_drift = 0;             // eq. 2-3: N − N_dropout [samples]
  // Gap between a slave sample and the nearest master tick [ms] (what figs. 2-15/2-16 and
  // 3-21/3-22 show), at the first sample and at the 40th (199 ms later at 5 ms; the last
  // sample when a run has fewer).
  double gap_first_ms = 0.0;
  double gap_40_ms = 0.0;
  double tx_ms = 0.0;  // bus time of one command frame (table 2-2's T_tx) [ms]
};

// Runs one trial on a two-node CanBus with the twin's scheduler. Throws
// std::invalid_argument for an unusable trial (bytes outside 0..8, P <= 0, N < 1, θ0 outside
// (0, 1), K < 1 with sync, a bit rate CanBus refuses). Deterministic: same trial, same result.
DropoutResult run_dropout_trial(const DropoutTrial& trial);

// ---- helpers shared by the experiment files ----
namespace experiment {

// Bad input found by an experiment (an --out that is a file, an unwritable --model): exit 2.
struct BadInput : std::runtime_error {
  using std::runtime_error::runtime_error;
};
// A signal (options.interrupt) ended the experiment: exit 3, no summary files.
struct Interrupted : std::runtime_error {
  using std::runtime_error::runtime_error;
};
// Throws Interrupted when options.interrupt (or `interrupt`) is set.
void stop_if_interrupted(const ExperimentOptions& options);
void stop_if_interrupted(const std::atomic<bool>* interrupt);

// The output folder for `name` (options.out_dir, else out/<name>), created with its parents,
// after checking for an interrupt (most experiments ask for it just before writing). Throws
// BadInput when the path is an existing non-directory, std::filesystem::filesystem_error when
// it cannot be created otherwise.
std::filesystem::path output_dir(const std::string& name, const ExperimentOptions& options);

// Writes `text` to `path`, replacing it atomically (a temporary file beside it, then a rename:
// a reader or an interrupted write never sees half a file). Throws std::runtime_error when
// that fails.
void write_text(const std::filesystem::path& path, const std::string& text);

// Runs media/plots/plot_experiment.py KIND CSV OUT_DIR with the Debian python3. Returns true
// when the plots were written; otherwise prints a warning that names what is missing
// (python3, python3-matplotlib) or the script's failure, and returns false. Never throws.
bool plot(const std::string& kind, const std::filesystem::path& csv, const std::filesystem::path& out_dir);

}  // namespace experiment

}  // namespace omnitwin::twin
