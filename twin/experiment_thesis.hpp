// twin layer — the rig that `thesis-platform` and `thesis-calibrate` share: seed 002's tables
// 4-3 … 4-10, the two readings of the slaves' drift, and one run of the thesis line on bus
// `can` scored as the thesis scored it (see experiment_thesis_platform.cpp for the study,
// experiment_thesis_calibrate.cpp for the fit).
#pragma once

#include <atomic>

#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "twin/scenario.hpp"

namespace omnitwin::twin::thesis {

// The thesis's tables by bit rate, no sync and sync, each {X, Y, contour [cm], axis average
// [pulses]}: IAE from tables 4-3/4-4 and 4-7/4-8, σ from tables 4-5/4-6 and 4-9/4-10; and
// each axis's IAE and σ [pulses] (tables 4-4, 4-8; 4-6, 4-10), from which tables 4-12 and
// 4-14 take their rates.
struct Row {
  int rate_kbps;
  std::array<double, 4> nosync;
  std::array<double, 4> sync;
  std::array<double, 4> nosync_std;
  std::array<double, 4> sync_std;
  std::array<double, 4> nosync_axes;
  std::array<double, 4> sync_axes;
  std::array<double, 4> nosync_axes_std;
  std::array<double, 4> sync_axes_std;
};
const std::array<Row, 4>& rows();
const Row& row(int rate_kbps);  // throws std::logic_error for a rate the thesis did not run

// The one configuration thesis-calibrate fits (no sync, fast clocks) is at this bit rate; every
// other row of the tables is a prediction.
constexpr int kFitRateKbps = 1000;

// One reading of the slaves' oscillators.
struct ClockReading {
  std::string name;       // "fast" / "slow"
  double drift = 0;       // every slave's drift [-]
  int sync_interval = 0;  // K: timer interrupts between resyncs
};

// The two readings for scenario `s` (its T_post, routine, period and drift size): fast (the
// slave's timer gains) first, slow second. K follows can-dropout's rule (resync before the
// slave's slip per interrupt eats the T_post margin) for the fast reading, and for both when
// the slaves reload their timer at the routine's end (bus.isr_us > 0: each interrupt then
// slips by the routine, and l.962 asks for the resync before the clocks part by a period);
// a hardware-reloaded slow reading keeps the scenario's K, which also bounds the rule's K (a
// slip of zero never eats the margin).
std::array<ClockReading, 2> clock_readings(const Scenario& s);

// The thesis's node firmware as these experiments run it, applied before the experiment's
// --set (which may change it): the timer routine's run time (bus.isr_us, seed 002 fig. 4-20:
// the four feedback frames leave 3.1 … 3.5 ms after the command; the 8051's 16-bit timer
// reloads in software at the routine's end). A bus setting; thesis-calibrate writes it into
// the fit with the fitted row's other bus settings (bus_overrides).
std::vector<Override> firmware_overrides();

// The bus of one run (run_one): CAN at `rate_kbps`, every slave at the clock reading's drift,
// sync or not at its K, random start phases from seed trial + 1, UDP port `port`; then
// firmware_overrides(). The experiment's --set go after these. Not real-time safe.
std::vector<Override> bus_overrides(const ClockReading& clock, int rate_kbps, bool sync, int trial, int port);

// One run's figures, or the mean of a configuration's trials.
struct Result {
  ClockReading clock;
  int rate_kbps = 0;
  bool sync = false;
  double iae_x = 0, iae_y = 0, iae_c = 0, std_x = 0, std_y = 0, std_c = 0;  // odometry [cm]
  double true_iae_c = 0, true_final = 0;                                    // MuJoCo pose [cm]
  double axis_iae = 0, axis_std = 0;                                        // averages over the four axes [pulses]
  std::array<double, 4> axes_iae{}, axes_std{};                             // each axis's IAE, σ [pulses]
  double dropout_pct = 0, load_pct = 0;
  double stale = 0;  // interrupts without a new command (loop skipped), four slaves
  // Over the trials (random start phases) of one configuration; a single run: all equal.
  int trials = 1;
  double c_min = 0, c_max = 0, a_min = 0, a_max = 0;  // contour IAE [cm], axis IAE [pulses]
  int exit_code = 0;
  std::string master_state;
  std::string run_dir;  // the first trial's run folder
};

// What one run needs besides its configuration.
struct RunSetup {
  std::string scenario;             // the thesis line's scenario file
  std::vector<Override> overrides;  // applied after the configuration's own
  std::filesystem::path dir;        // run folders go under it
  bool quick = false;               // 40 cm in 4 s instead of 200 cm in 20 s
  bool records = true;              // false: no video and no report (the figures need neither)
  const std::atomic<bool>* interrupt = nullptr;  // passed to each run (SIGINT/SIGTERM)
};

// One run of clock reading `clock` at `rate_kbps`, with or without sync; trial t draws the
// slaves' timer phases at NMT start from seed t + 1; `port` is its own UDP port.
Result run_one(const RunSetup& setup, const ClockReading& clock, int rate_kbps, bool sync, int trial, int port);

// The mean of a configuration's trials, with the spread of contour and axis IAE.
Result average(const std::vector<Result>& trials);

// `path` on bus can with the experiment's --set applied: a bad key or value throws
// ScenarioError here, before any folder is made.
Scenario load_with_sets(const std::string& path, const std::vector<Override>& sets);
// The experiment's --set overrides as a reader can repeat them ("--set K=V --set …"; "" none).
std::string sets_text(const std::vector<Override>& sets);
// `text` with a paragraph saying which --set every run had, after its first paragraph (the
// reports) or before its `name:` line (a scenario file, as a comment); unchanged without sets.
std::string note_sets(std::string text, const std::vector<Override>& sets, bool yaml);

// The default scenario: the fitted thesis line when it exists, else the plain one.
std::string default_scenario();
std::string plain_scenario();   // models/scenarios/thesis_line.yaml
std::string fitted_scenario();  // models/scenarios/thesis_line_fitted.yaml (thesis-calibrate)

// `p` relative to the source tree when it lies inside it (how the committed files name each
// other), else "".
std::string source_relative(const std::filesystem::path& p);

}  // namespace omnitwin::twin::thesis
