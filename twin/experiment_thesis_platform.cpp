// twin layer — `omnitwin experiment thesis-platform`: seed 002's platform experiment (4-4-2,
// tables 4-3 … 4-14) on the whole twin.
//
// Each configuration is a real run of models/scenarios/thesis_line.yaml (200 cm along world X
// in 20 s) with bus `can`: the master program in its own process, the twin with the four Omni
// slaves, UDP multicast between them, lockstep. Bit rates 125/250/500/1000 kbit/s, each without
// and with the synchronisation of 3-2-2, under both readings of the slaves' 0.362 % drift:
//  - fast (the slave's timer gains 0.362 %): the reading chapter 2's dropout findings need
//    (docs/experiments.md, the can-dropout experiment), with that experiment's rule for the
//    resync interval: K = floor(T_post / (0.362 % · P)) interrupts (2 at 10 ms);
//  - slow (it loses 0.362 %): the scenario default, the reading 4-4-2's observation points to
//    (the forced resync SHORTENS a sampling period), with the scenario's K = 20.
// The thesis scored the runs with its master's odometry (what it could measure), so our table
// uses `platform_odometry` beside it, with the true (MuJoCo) pose's figures in the CSV as well.
// The markdown states, effect by effect and reading by reading, whether the direction matches the
// thesis's and where magnitudes differ; the exit status follows the fast reading (the project's
// reading of the drift). Each run gets its own UDP port so nothing else on the machine is heard.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "twin/experiment.hpp"
#include "twin/csv_columns.hpp"
#include "twin/experiment_thesis.hpp"
#include "twin/run.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin {

namespace {

namespace fs = std::filesystem;

using thesis::ClockReading;
using thesis::Result;

// Runs per configuration, each with its own random start phases of the slaves' timers.
constexpr int kTrials = 5;

// The configuration thesis-calibrate fits (fast clocks, thesis::kFitRateKbps, no sync); every
// other one is a prediction.
bool is_fit_row(const Result& r, const std::string& fast) {
  return r.clock.name == fast && r.rate_kbps == thesis::kFitRateKbps && !r.sync;
}

std::string to_csv(const std::vector<Result>& rs) {
  std::string s =
      "clock,drift,sync_interval,rate_kbps,sync,trials,iae_x_cm,iae_y_cm,iae_contour_cm,iae_contour_min_cm,"
      "iae_contour_max_cm,std_x_cm,std_y_cm,std_contour_cm,true_iae_contour_cm,true_final_error_cm,axis_iae_pulse,"
      "axis_iae_min_pulse,axis_iae_max_pulse,axis_std_pulse,dropout_pct,stale_samples,bus_load_pct,"
      "thesis_iae_x_cm,thesis_iae_y_cm,thesis_iae_contour_cm,thesis_axis_iae_pulse\n";
  for (const Result& r : rs) {
    const auto& tv = r.sync ? thesis::row(r.rate_kbps).sync : thesis::row(r.rate_kbps).nosync;
    s += fmt::format(
        "{},{},{},{},{},{},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.5f},{:.5f},{:.5f},{:.4f},{:.5f},{:.3f},{:.3f},{:.3f},"
        "{:.5f},{:.3f},{:.1f},{:.3f},{},{},{},{}\n",
        r.clock.name, r.clock.drift, r.clock.sync_interval, r.rate_kbps, r.sync ? 1 : 0, r.trials, r.iae_x, r.iae_y,
        r.iae_c, r.c_min, r.c_max, r.std_x, r.std_y, r.std_c, r.true_iae_c, r.true_final, r.axis_iae, r.a_min,
        r.a_max, r.axis_std, r.dropout_pct, r.stale, r.load_pct, tv[0], tv[1], tv[2], tv[3]);
  }
  return s;
}

double improvement(double without, double with) { return without > 0 ? 100.0 * (without - with) / without : 0.0; }

// Table 4-12's rate: each axis's improvement, then their mean (not the improvement of the mean
// IAE: the thesis averages rates, 10.6 % at 125 kbit/s where the mean IAE improves 12.1 %).
double axes_improvement(const std::array<double, 4>& without, const std::array<double, 4>& with) {
  double sum = 0;
  for (std::size_t k = 0; k < 4; ++k) sum += improvement(without[k], with[k]);
  return sum / 4.0;
}

// A direction check: `ours` and `thesis` improvements [%] agree in sign (|x| < 1 % counts as
// no effect, which agrees with nothing but another "no effect").
std::string sign_word(double pct) { return std::fabs(pct) < 1.0 ? "none" : (pct > 0 ? "better" : "worse"); }

// The sync effect at one bit rate under one clock reading [% improvement], ours and the thesis's.
struct Effect {
  int rate_kbps = 0;
  std::array<double, 4> ours{};    // x, y, contour, axis
  std::array<double, 4> thesis{};
  const Result* without = nullptr;
  const Result* with = nullptr;
  bool matches() const {  // the judged effects: contour (table 4-11) and axis (table 4-12)
    return sign_word(ours[2]) == sign_word(thesis[2]) && sign_word(ours[3]) == sign_word(thesis[3]);
  }
};

// Pairs (no sync, sync) of one clock reading, in run order.
std::vector<Effect> effects(const std::vector<Result>& rs, const std::string& clock) {
  std::vector<Effect> out;
  for (std::size_t i = 0; i + 1 < rs.size(); i += 2) {
    const Result& a = rs[i];
    const Result& b = rs[i + 1];
    if (a.clock.name != clock) continue;
    const thesis::Row& t = thesis::row(a.rate_kbps);
    Effect e;
    e.rate_kbps = a.rate_kbps;
    e.without = &a, e.with = &b;
    e.ours = {improvement(a.iae_x, b.iae_x), improvement(a.iae_y, b.iae_y), improvement(a.iae_c, b.iae_c),
              axes_improvement(a.axes_iae, b.axes_iae)};
    for (std::size_t k = 0; k < 3; ++k) e.thesis[k] = improvement(t.nosync[k], t.sync[k]);
    e.thesis[3] = axes_improvement(t.nosync_axes, t.sync_axes);
    out.push_back(e);
  }
  return out;
}

std::string effect_table(const std::vector<Effect>& es) {
  std::ostringstream out;
  out << "| kbit/s | X IAE: ours / thesis | Y IAE: ours / thesis | contour IAE: ours / thesis | axis IAE (mean of "
         "the axes' rates): ours / thesis | direction (contour, axis) |\n|---|---|---|---|---|---|\n";
  for (const Effect& e : es) {
    out << fmt::format("| {} |", e.rate_kbps);
    for (std::size_t k = 0; k < 4; ++k) out << fmt::format(" {:+.1f} % / {:+.1f} % |", e.ours[k], e.thesis[k]);
    out << (e.matches() ? " matches |\n" : " **differs** |\n");
  }
  return out.str();
}

int failed(const std::vector<Effect>& es) {
  int n = 0;
  for (const Effect& e : es) n += e.matches() ? 0 : 1;
  return n;
}

// "a … b" over the k-th improvement [%] of ours (or, with `thesis`, the thesis's), at bit rates
// from `from_kbps` up.
// "helps" / "hurts" / "barely matters" when every bit rate agrees, else how many it helps.
std::string verdict(const std::vector<Effect>& es, std::size_t k) {
  std::size_t better = 0, worse = 0;
  for (const Effect& e : es) {
    if (sign_word(e.ours[k]) == "better") ++better;
    if (sign_word(e.ours[k]) == "worse") ++worse;
  }
  if (!es.empty() && better == es.size()) return "helps";
  if (!es.empty() && worse == es.size()) return "hurts";
  if (better == 0 && worse == 0) return "barely matters";
  return fmt::format("helps at {} of {} bit rates and hurts at {}", better, es.size(), worse);
}

std::string span(const std::vector<Effect>& es, std::size_t k, bool thesis = false, int from_kbps = 0) {
  double lo = 1e300, hi = -1e300;
  for (const Effect& e : es) {
    if (e.rate_kbps < from_kbps) continue;
    const double v = thesis ? e.thesis[k] : e.ours[k];
    lo = std::min(lo, v), hi = std::max(hi, v);
  }
  return lo > hi ? "-" : fmt::format("{:+.1f} … {:+.1f} %", lo, hi);
}

std::string run_table(const std::vector<Result>& rs) {
  std::ostringstream out;
  out << "| clock | kbit/s | sync | IAE x | IAE y | IAE contour [min … max] | σ x / y / contour | axis IAE [min … max] | "
         "axis σ | dropouts | loops skipped | bus load | thesis IAE x / y / contour | thesis σ x / y / contour | "
         "thesis axis IAE / σ |\n"
      << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const Result& r : rs) {
    const thesis::Row& row = thesis::row(r.rate_kbps);
    const auto& tv = r.sync ? row.sync : row.nosync;
    const auto& ts = r.sync ? row.sync_std : row.nosync_std;
    out << fmt::format("| {} | {} | {} | {:.1f} | {:.1f} | {:.1f} [{:.1f} … {:.1f}] | {:.3f} / {:.3f} / {:.3f} | {:.1f} "
                       "[{:.1f} … {:.1f}] | {:.3f} | {:.1f} % | {:.1f} | {:.1f} % | {} / {} / {} | {} / {} / {} | {} / {} |\n",
                       r.clock.name, r.rate_kbps, r.sync ? fmt::format("K = {}", r.clock.sync_interval) : "no",
                       r.iae_x, r.iae_y, r.iae_c, r.c_min, r.c_max, r.std_x, r.std_y, r.std_c, r.axis_iae, r.a_min,
                       r.a_max, r.axis_std, r.dropout_pct, r.stale, r.load_pct, tv[0], tv[1], tv[2], ts[0], ts[1], ts[2],
                       tv[3], ts[3]);
  }
  return out.str();
}

// Tables 4-4, 4-8 and 4-12 (IAE) or 4-6, 4-10 and 4-14 (σ) for clock reading `clock`: each
// axis's figure without and with sync, ours / thesis, and each axis's improvement.
std::string axes_table(const std::vector<Result>& rs, const std::string& clock, bool sigma) {
  const char* name = sigma ? "σ" : "IAE";
  const auto value = [sigma](double ours, double theirs) {
    return sigma ? fmt::format(" {:.3f} / {} |", ours, theirs) : fmt::format(" {:.0f} / {} |", ours, theirs);
  };
  std::ostringstream out;
  out << "| kbit/s | | axis 1: ours / thesis | axis 2 | axis 3 | axis 4 |\n|---|---|---|---|---|---|\n";
  for (std::size_t i = 0; i + 1 < rs.size(); i += 2) {
    const Result &a = rs[i], &b = rs[i + 1];
    if (a.clock.name != clock) continue;
    const thesis::Row& t = thesis::row(a.rate_kbps);
    const auto& ours_no = sigma ? a.axes_std : a.axes_iae;
    const auto& ours_yes = sigma ? b.axes_std : b.axes_iae;
    const auto& thesis_no = sigma ? t.nosync_axes_std : t.nosync_axes;
    const auto& thesis_yes = sigma ? t.sync_axes_std : t.sync_axes;
    std::string no = fmt::format("| {} | {}, no sync |", a.rate_kbps, name);
    std::string yes = fmt::format("| {} | {}, sync |", a.rate_kbps, name);
    std::string rate = fmt::format("| {} | improvement |", a.rate_kbps);
    for (std::size_t k = 0; k < 4; ++k) {
      no += value(ours_no[k], thesis_no[k]);
      yes += value(ours_yes[k], thesis_yes[k]);
      rate += fmt::format(" {:+.1f} % / {:+.1f} % |", improvement(ours_no[k], ours_yes[k]),
                          improvement(thesis_no[k], thesis_yes[k]));
    }
    out << no << "\n" << yes << "\n" << rate << "\n";
  }
  return out.str();
}

// The bit-rate paragraph: the lowest bit rate against the others, fast reading, from the data.
std::string bit_rate_text(const std::vector<Effect>& fast) {
  if (fast.size() < 2) return "";
  const Effect& low = fast.front();
  double others = 0;
  for (std::size_t i = 1; i < fast.size(); ++i) others += fast[i].ours[3];
  others /= static_cast<double>(fast.size() - 1);
  const Effect& high = fast.back();
  if (low.ours[3] < others - 1.0 && low.with->stale > high.with->stale + 0.5) {
    return fmt::format(
        "- **Bit rate.** At {} kbit/s every frame takes {:.0f} times as long on the wire as at {} kbit/s and the "
        "bus is {:.0f} % loaded; a command held up behind a feedback frame can arrive after a synchronised "
        "interrupt's T_post margin, so with sync {:.1f} loops per run are still skipped there ({:.1f} at {} "
        "kbit/s) and the axes gain {:+.1f} % against {:+.1f} % on average above: the thesis's own explanation of "
        "its weaker 125 kbit/s result (long frames, nodes contending for the bus), where its contour IAE even got "
        "worse with sync. Above, the bit rate changes little in our deterministic model: it shifts when a command "
        "arrives, not whether.\n",
        low.rate_kbps, static_cast<double>(high.rate_kbps) / low.rate_kbps, high.rate_kbps, low.without->load_pct,
        low.with->stale, high.with->stale, high.rate_kbps, low.ours[3], others);
  }
  return fmt::format(
      "- **Bit rate.** The axes gain {:+.1f} % from sync at {} kbit/s against {:+.1f} % on average above: in our "
      "deterministic model the bit rate shifts when a command arrives, not whether. The thesis's 125 kbit/s runs "
      "gained least (its contour IAE even got worse with sync), which it blames on long frames and nodes "
      "contending for the bus.\n",
      low.ours[3], low.rate_kbps, others);
}

// The odometric pose error over time of the first trial without and with sync at `rate_kbps`
// (clock reading `clock`): t, sync, X, Y and contour error [cm], as figs. 4-21 … 4-28 show it.
std::string time_csv(const std::vector<Result>& rs, const std::string& clock, int rate_kbps) {
  std::string s = "rate_kbps,sync,t_s,ex_cm,ey_cm,ec_cm\n";
  for (const Result& r : rs) {
    if (r.clock.name != clock || r.rate_kbps != rate_kbps) continue;
    const fs::path csv = fs::path(r.run_dir) / "trajectory.csv";
    const CsvColumns tr = read_csv_columns(csv.string());
    const auto &t = tr.column("t"), &rx = tr.column("ref_x"), &ry = tr.column("ref_y"), &ox = tr.column("odom_x"),
               &oy = tr.column("odom_y");
    for (std::size_t i = 0; i < t.size(); ++i) {
      const double ex = 100 * (rx[i] - ox[i]), ey = 100 * (ry[i] - oy[i]);
      s += fmt::format("{},{},{:.3f},{:.5f},{:.5f},{:.5f}\n", rate_kbps, r.sync ? 1 : 0, t[i], ex, ey, std::hypot(ex, ey));
    }
  }
  return s;
}

// ours / thesis for X, Y, contour and axis IAE of one configuration.
std::array<double, 4> ratios(const Result& r) {
  const auto& t = r.sync ? thesis::row(r.rate_kbps).sync : thesis::row(r.rate_kbps).nosync;
  return {r.iae_x / t[0], r.iae_y / t[1], r.iae_c / t[2], r.axis_iae / t[3]};
}

bool within_2x(double ratio) { return ratio >= 0.5 && ratio <= 2.0; }

// The fit-and-predict section (issue 15's acceptance) for clock reading `clock`: every
// configuration's IAE as a ratio to the thesis's, the held-out ones counted, the sync's signs at
// 250 … 1000 kbit/s, 125 kbit/s the weakest, the overall axis improvement against 16.31 %.
std::string prediction_section(const std::vector<Result>& rs, const std::vector<Effect>& es, const std::string& clock) {
  std::ostringstream out;
  out << "| kbit/s | sync | role | X IAE ours / thesis | Y | contour | axis | all four within 2× | X, contour, axis "
         "within 2× |\n|---|---|---|---|---|---|---|---|---|\n";
  int held = 0, held_ok = 0, held_ok3 = 0;
  double ours_lo = 1e300, ours_hi = 0, theirs_lo = 1e300, theirs_hi = 0;  // contour IAE over the rows
  for (const Result& r : rs) {
    if (r.clock.name != clock) continue;
    const double theirs = r.sync ? thesis::row(r.rate_kbps).sync[2] : thesis::row(r.rate_kbps).nosync[2];
    ours_lo = std::min(ours_lo, r.iae_c), ours_hi = std::max(ours_hi, r.iae_c);
    theirs_lo = std::min(theirs_lo, theirs), theirs_hi = std::max(theirs_hi, theirs);
    const auto q = ratios(r);
    const bool ok = std::all_of(q.begin(), q.end(), within_2x);
    const bool ok3 = within_2x(q[0]) && within_2x(q[2]) && within_2x(q[3]);
    const bool fit = is_fit_row(r, clock);
    if (!fit) ++held, held_ok += ok ? 1 : 0, held_ok3 += ok3 ? 1 : 0;
    out << fmt::format("| {} | {} | {} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {} | {} |\n", r.rate_kbps,
                       r.sync ? "yes" : "no", fit ? "**fitted**" : "held out", q[0], q[1], q[2], q[3], ok ? "yes" : "no",
                       ok3 ? "yes" : "no");
  }
  // The sync's sign for X, contour and axis IAE above 125 kbit/s.
  int signs = 0, sign_checks = 0;
  double axis_sum = 0;
  const Effect* low = nullptr;
  bool weakest = !es.empty();
  for (const Effect& e : es) {
    axis_sum += e.ours[3];
    if (e.rate_kbps == 125) low = &e;
    if (e.rate_kbps < 250) continue;
    for (std::size_t k : {0, 2, 3}) ++sign_checks, signs += sign_word(e.ours[k]) == sign_word(e.thesis[k]) ? 1 : 0;
  }
  // Weakest by more than the 1 point under which an effect counts as none: a tie within the
  // trials' scatter is not the thesis's 125 kbit/s result.
  double margin = 1e300;  // the smallest lead of another rate over 125 kbit/s, contour or axis [points]
  for (const Effect& e : es)
    if (low && &e != low) margin = std::min({margin, e.ours[2] - low->ours[2], e.ours[3] - low->ours[3]});
  weakest = weakest && low && es.size() > 1 && margin > 1.0;
  const double overall = es.empty() ? 0.0 : axis_sum / static_cast<double>(es.size());
  out << fmt::format("\n- Held-out configurations with X, Y, contour and axis IAE all within 2× of the thesis's: **{} of "
                     "{}** (the acceptance asks for 6 of 7); leaving Y out: {} of {}.\n",
                     held_ok, held, held_ok3, held)
      << fmt::format("- Read it with the spread: over the eight rows our contour IAE spans a factor {:.2f} (largest / "
                     "smallest), the thesis's {:.2f}. Within 2× says the twin holds the thesis's level; what differs "
                     "between the configurations is in the sync rows below.\n",
                     held ? ours_hi / ours_lo : 0.0, held ? theirs_hi / theirs_lo : 0.0)
      << fmt::format("- The sync's effect has the thesis's sign (|x| < 1 % counts as none) for X, contour and axis IAE "
                     "at 250, 500 and 1000 kbit/s: **{} of {}**.\n",
                     signs, sign_checks)
      << (low ? fmt::format("- At 125 kbit/s the sync's effect on contour and axis IAE is the weakest of the bit rates, "
                            "by more than 1 point: **{}** (contour {:+.1f} %, axis {:+.1f} %; the thesis: -5.2 %, "
                            "+10.6 %){}.\n",
                            weakest ? "yes" : "no", low->ours[2], low->ours[3],
                            es.size() < 2 ? std::string()
                            : margin < 0  ? fmt::format("; another bit rate gains {:.1f} points less", -margin)
                                          : fmt::format("; the nearest other bit rate gains {:.1f} points more", margin))
              : std::string("- 125 kbit/s was not run.\n"))
      << fmt::format("- Overall axis-IAE improvement (mean over the bit rates): **{:+.2f} %** against the thesis's "
                     "16.31 % ({} the ±5 points asked).\n",
                     overall, std::fabs(overall - 16.31) <= 5.0 ? "within" : "outside");
  return out.str();
}

// Where the scenario's odometric Y error comes from: the diagonal pairs' gain mismatch when it has
// one (wheels 1, 3 one way, 2, 4 the other), else the velocity loops' ringing alone; whether
// sync moves it is read from the fast reading's effects.
std::string y_cause(const Scenario& sc, const std::vector<Effect>& fast) {
  const auto& g = sc.platform.driver.gain_error;
  bool moved = false;  // sync moves our Y by a point or more at some bit rate
  for (const Effect& e : fast) moved = moved || std::fabs(e.ours[1]) >= 1.0;
  if (g[0] == g[2] && g[1] == g[3] && g[0] == -g[1] && g[1] != 0)
    return fmt::format(
        "Our Y error comes from the drivers' gain mismatch between the diagonal wheel pairs (±{:g}): with a "
        "velocity PI whose integral is weak (ki {:g} DA codes per count/sample per sample against kp {:g}), wheels "
        "1 and 3 turn slower than commanded and 2 and 4 faster, in proportion to the speed, so an X command drives "
        "a Y motion the odometry sees and the master's Y loop follows it with a lag as X's. The thesis's Y followed "
        "its X sample by sample in the same way (reading_sync.md, D2). {}",
        g[1], sc.platform.velocity_loop.ki, sc.platform.velocity_loop.kp,
        moved ? "It grows with the speed the wheels deliver and the master's lag, so sync moves it as it moves X."
              : "Nothing in it depends on the bus, so sync does not move it.");
  return "Our Y error is the ringing of the four velocity loops seen through the master's Y loop, tenths of a "
         "millimetre (thesis_platform_time.png); the thesis's platform wandered a centimetre off its line, which "
         "nothing in this model does to an unloaded platform its master holds on the line, unless its drivers' "
         "gains differ between the diagonal wheel pairs (docs/results/thesis-calibrate/).";
}

// The scenario as the docs name it: relative to the source tree where it lies inside it.
std::string source_relative_name(const std::string& scenario) {
  const std::string rel = thesis::source_relative(scenario);
  return rel.empty() ? scenario : rel;
}

// Why, for slaves whose timer reloads in hardware (bus.isr_us 0): the drift alone moves their
// samples against the commands.
std::string hardware_reload_why(const std::vector<Effect>& fast, const std::vector<Effect>& slow,
                                const std::array<ClockReading, 2>& clocks, const Scenario& sc, double fast_skips,
                                double fast_sync_skips, double slow_skips, double y_lo, double y_hi) {
  std::ostringstream out;
  out << fmt::format(
             "- **Axis velocity IAE, fast clocks: sync {} ({}; the thesis: {}).** A fast slave's "
             "interrupt overtakes the command once every 1/0.00362 = 276 samples; that interrupt finds no new "
             "command and skips its velocity loop (fig. 4-16; up to {:.1f} skipped loops per run over the four "
             "slaves), so the next loop reads the counter over two periods, sees twice the commanded count and "
             "the PI kicks the wheel back: the axis rings, as the thesis's unsynchronised axes did. From the first "
             "overtaking on, every sample also holds the previous sample's command. The resync keeps the "
             "interrupt within T_post behind its command: dropouts vanish and at most {:.1f} loops per run are "
             "skipped (where a command is late, at the start or behind a feedback frame), but each resync also runs "
             "one short sample whose count falls short of the command, and the velocity PI (kp {:g} DA codes per "
             "count/sample) kicks the wheel for it. Where the short samples cost more than the skipped loops did, "
             "sync does not help.\n",
             verdict(fast, 3),
             span(fast, 3), span(fast, 3, true), fast_skips, fast_sync_skips, sc.platform.velocity_loop.kp)
      << fmt::format(
             "- **Axis velocity IAE, slow clocks: sync {} ({}).** A slow slave's command is almost never "
             "missing (at most {:.1f} skipped loops per run without sync); it loses one command (overwritten) per 276 "
             "samples, which costs little. "
             "Each forced resync runs one sample in the receive interrupt, T_post + K·36 µs earlier than the "
             "timer would have: that sample is short, measures fewer counts than commanded, and the error spikes "
             "(the thesis saw these spikes). With K = {} the spikes outweigh what sync wins back.\n",
             verdict(slow, 3),
             span(slow, 3), slow_skips, clocks[1].sync_interval)
      << fmt::format(
             "- **X and contour IAE (fast: X {}, contour {}; slow: contour {}; the thesis: contour {} above "
             "125 kbit/s).** Our odometric X error is the following lag of the master's position loop without "
             "feed-forward (the thesis's structure, fig. 4-13) on the 20 s trapezoid, σ {:.2f} cm, with the "
             "scenario's gains kp {:g}/s, ki {:g}/s²: it grows with the planned speed, and where ki is not negligible "
             "the integral carries it past zero before the path ends (thesis_platform_time.png). Its size is set by "
             "the gains whatever the drives do, and the odometry is summed from every feedback frame, so lost or late "
             "commands hardly change it: the drift of 0.362 % costs one command in 276. The thesis's X "
             "fell by 25 … 39 % with sync, so its lag depended on the bus in a way a hardware-reloaded timer does "
             "not give (reading_sync.md: the slaves' routine, `bus.isr_us`, does).\n",
             span(fast, 0), span(fast, 2), span(slow, 2), span(fast, 2, true, 250),
             fast.empty() ? 0.0 : fast.back().without->std_c, sc.controller.kp[0], sc.controller.ki[0])
      << fmt::format(
             "- **Y IAE: {:.1f} … {:.1f} % of the thesis's**; sync changes it by {} under the fast reading (the "
             "thesis: {}). {}\n",
             y_lo, y_hi, span(fast, 1), span(fast, 1, true), y_cause(sc, fast))
      << "- **Dropouts.** With the thesis's definition (2-2-1: the command held does not belong to the sample) "
         "a pure drift of 0.362 % makes every sample after N_drift a dropout (fast: from the first overtaking; "
         "slow: from the first overwritten command), so the rate without sync is high at every bit rate; sync "
         "brings it to zero.\n";
  return out.str();
}

// The smallest and largest of a figure over a clock reading's runs with or without sync.
std::string range_of(const std::vector<Effect>& es, bool sync, double Result::*f) {
  double lo = 1e300, hi = -1e300;
  for (const Effect& e : es) {
    const double v = (sync ? e.with : e.without)->*f;
    lo = std::min(lo, v), hi = std::max(hi, v);
  }
  return lo > hi ? "-" : fmt::format("{:.1f} … {:.1f}", lo, hi);
}

// The master's position loop in x as the report names it: a P loop (integral 0, the fit's
// reading of D1) or a PI, without feed-forward either way (fig. 4-13), with its gains.
std::string master_loop(const Scenario& sc) {
  if (sc.controller.ki[0] == 0)
    return fmt::format("a P loop without feed-forward: fig. 4-13 names the controller, and the tables' lag asks for no "
                       "integral, reading_sync.md D1; kp {:g}/s in x, {:g}/s in y",
                       sc.controller.kp[0], sc.controller.kp[1]);
  return fmt::format("a PI without feed-forward, fig. 4-13; kp {:g}/s, ki {:g}/s²", sc.controller.kp[0],
                     sc.controller.ki[0]);
}

// Why, for slaves that reload their timer at the end of their control routine (bus.isr_us > 0,
// reading_sync.md H9): without sync each samples every period + routine; the resync zeroes the
// count on the command (l.962).
std::string routine_why(const std::vector<Effect>& fast, const std::vector<Effect>& slow,
                        const std::array<ClockReading, 2>& clocks, const Scenario& sc, double y_lo, double y_hi) {
  const double period_ms = sc.controller.period * 1e3, isr_ms = sc.bus.can.isr_us * 1e-3;
  const double share = period_ms / (period_ms + isr_ms);  // what the wheels deliver without sync
  std::ostringstream out;
  out << fmt::format(
             "- **X and contour IAE: sync helps by {} (X) and {} (contour) under the fast reading, {} (contour) under "
             "the slow one; the thesis: contour {} above 125 kbit/s.** Each slave reloads its timer at the end of its "
             "{:.1f} ms control routine (an 8051's 16-bit timer has no auto-reload; fig. 4-20 puts the feedback "
             "3.1 … 3.5 ms after the command), so without sync it samples every {:.1f} ms and takes the latest "
             "command: {:.0f} % of the commands are overwritten, the thesis's \"lost commands\" (l.1452). Its wheel "
             "turns a command's counts per {:.1f} ms, {:.0f} % of what the master asked, and the master's position "
             "loop ({}) lags by that much more. The resync (K = {}) "
             "takes every other command in the receive interrupt, which zeroes the timer count as it takes the frame "
             "(l.962), so every counter window is the command period to within T_post and the wheels deliver the "
             "whole command: the lag falls as the thesis's did (its X error is a speed-proportional lag whose gain "
             "rises with sync, reading_sync.md D1).\n",
             span(fast, 0), span(fast, 2), span(slow, 2), span(fast, 2, true, 250), isr_ms, period_ms + isr_ms,
             100 * (1 - share), period_ms + isr_ms, 100 * share, master_loop(sc), clocks[0].sync_interval)
      << fmt::format(
             "- **Axis velocity IAE: sync {} ({}; slow reading {}; the thesis: {}).** The master compares each "
             "command with the latest feedback it holds a period later (l.1339). Without sync that feedback is a "
             "count over {:.1f} ms against a command per {:.0f} ms, and a period in four brings none (the value "
             "before is held); with sync every window is the command's. The thesis's synchronised axes still rang, "
             "with a pulse at every forced resync (l.1500: a shortened sample); resynced every interrupt, ours have "
             "no such pulse, and they gain alike at every bit rate where the thesis's gains scatter.\n",
             verdict(fast, 3), span(fast, 3), span(slow, 3), span(fast, 3, true), period_ms + isr_ms, period_ms)
      << fmt::format(
             "- **Y IAE: {:.1f} … {:.1f} % of the thesis's**; sync changes it by {} under the fast reading (the "
             "thesis: {}). {}\n",
             y_lo, y_hi, span(fast, 1), span(fast, 1, true), y_cause(sc, fast))
      << fmt::format(
             "- **Dropouts.** With the thesis's definition (2-2-1: the command held does not belong to the sample) "
             "{} % of the samples are dropouts without sync (fast reading), {} % with it.\n",
             range_of(fast, false, &Result::dropout_pct), range_of(fast, true, &Result::dropout_pct));
  return out.str();
}

std::string to_markdown(const std::vector<Result>& rs, const std::array<ClockReading, 2>& clocks, bool quick,
                        const std::string& scenario, const Scenario& sc) {
  const std::vector<Effect> fast = effects(rs, clocks[0].name), slow = effects(rs, clocks[1].name);
  // Skipped loops per run over the four slaves: the most without sync, the most with it.
  double fast_skips = 0, fast_sync_skips = 0, slow_skips = 0;
  for (const Effect& e : fast) fast_skips = std::max(fast_skips, e.without->stale);
  for (const Effect& e : fast) fast_sync_skips = std::max(fast_sync_skips, e.with->stale);
  for (const Effect& e : slow) slow_skips = std::max(slow_skips, e.without->stale);
  // Our Y IAE as a share of the thesis's, over the fast reading's configurations [%].
  double y_lo = 1e300, y_hi = 0;
  for (const Result& r : rs) {
    if (r.clock.name != clocks[0].name) continue;
    y_lo = std::min(y_lo, 100 * ratios(r)[1]), y_hi = std::max(y_hi, 100 * ratios(r)[1]);
  }
  std::ostringstream out;
  out << "# thesis-platform: tables 4-3 … 4-14 on the twin\n\n"
      << "Runs of `" << source_relative_name(scenario) << "` (200 cm along world X in 20 s"
      << (quick ? "; QUICK run: 40 cm in 4 s, not comparable" : "")
      << ") with `--bus can`: the master program and the twin as two processes over UDP multicast in lockstep, "
         "four emulated 8051 slaves whose oscillators drift 0.362 % against the master's"
      << (sc.bus.can.isr_us > 0
              ? fmt::format(" and whose {:g} ms control routine ends before their timer is reloaded (`bus.isr_us: {:g}`, "
                            "fig. 4-20; the experiment applies it, `--set bus.isr_us=0` gives a hardware reload)",
                            sc.bus.can.isr_us * 1e-3, sc.bus.can.isr_us)
              : std::string(" (timers reloaded in hardware, `bus.isr_us: 0`)"))
      << ". IAE = Σ|e| and "
         "σ = sqrt(Σe²/N) over the 10 ms control samples (eq. 4-14, 4-15), position errors from the master's "
         "odometry as the thesis measured them [cm], axis velocity errors as the master sees them each control "
         "period: the command it sent minus the latest feedback it holds at the next, stored per axis "
         "(`axes.N.iae_velocity_pulse_at_master`) [pulses/sample]. \"loops skipped\": timer interrupts of the four slaves that found no new command and so "
         "ran no velocity loop (fig. 4-16).\n\n"
      << fmt::format("Each configuration ran {} times, each time with the four slaves' timers at their own random "
                     "phase when NMT start enabled them (the thesis's slaves handle NMT in their main loop, fig. "
                     "4-16, so every run and every node starts at a phase of its own; `bus.start_phase: random`, "
                     "seeds 1 … {}); the figures are the means, [min … max] over the runs.\n\n",
                     rs.empty() ? 0 : rs.front().trials, rs.empty() ? 0 : rs.front().trials)
      << "The thesis measured the size of the drift, not its sign, so both readings run (docs/experiments.md):\n\n"
      << fmt::format("- **{}** (drift {}, resync every K = {} interrupts): the slave's timer gains; the reading "
                     "chapter 2's dropout findings need (can-dropout), with that experiment's rule for K (resync "
                     "before the slip per interrupt{} eats the T_post margin). The experiment's verdict follows this "
                     "reading.\n",
                     clocks[0].name, clocks[0].drift, clocks[0].sync_interval,
                     sc.bus.can.isr_us > 0 ? ", the routine included," : "")
      << fmt::format("- **{}** (drift {:+}, K = {}, {}): the slave's timer loses; the reading "
                     "4-4-2's remark points to (each forced resync shortens one sampling period).\n\n",
                     clocks[1].name, clocks[1].drift, clocks[1].sync_interval,
                     sc.bus.can.isr_us > 0 ? "the same rule: l.962 asks for the resync before the clocks part by a period"
                                           : "the scenario defaults")
      << run_table(rs)
      << "\n## Fitted and predicted (issue 15)\n\n"
      << fmt::format("Scenario: `{}`. ", fs::path(scenario).filename().string())
      // thesis-calibrate names what it writes thesis_line_fitted, whatever the file is called.
      << (sc.name == "thesis_line_fitted"
              ? "Its free parameters (the position-loop and velocity-PI gains, the driver's dead band, the gearbox "
                "friction and backlash, the diagonal wheel pairs' driver gain mismatch) were fitted by `omnitwin experiment thesis-calibrate` to ONE configuration, fast clocks at "
                "1000 kbit/s without sync (docs/results/thesis-calibrate/); every other row is a prediction. "
              : "Not the fitted scenario: no row was fitted, every row is a plain run. ")
      << "Ratios ours / thesis of IAE, fast clocks:\n\n"
      << prediction_section(rs, fast, clocks[0].name)
      << "\n![pose error over time](thesis_platform_time.png)\n\n"
      << "thesis_platform_time.png: the odometric X, Y and contour error over the run without and with sync at 250 "
         "kbit/s (fast clocks, first trial), the twin's counterpart of the thesis's figs. 4-21 … 4-28. There the "
         "thesis shows the platform oscillating along Y without sync, the oscillation largely gone with it, and the "
         "axes' velocity ringing with a pulse at every forced resync (4-4-2).\n"
      << "\n## Improvement by the synchronisation (tables 4-11, 4-12)\n\n"
      << "Positive = better with sync. A direction matches when contour and axis IAE both move the thesis's way "
         "(|x| < 1 % counts as no effect).\n\n"
      << "### " << clocks[0].name << " slave clocks\n\n" << effect_table(fast) << "\n"
      << "Directions: " << (failed(fast) == 0 ? "every bit rate matches" : fmt::format("{} bit rate(s) differ", failed(fast)))
      << ".\n\n### " << clocks[1].name << " slave clocks\n\n" << effect_table(slow) << "\n"
      << "Directions: " << (failed(slow) == 0 ? "every bit rate matches" : fmt::format("{} bit rate(s) differ", failed(slow)))
      << ".\n\nThe axis column is table 4-12's rate: each axis's improvement, then their mean. Each axis, "
      << clocks[0].name << " slave clocks, IAE (tables 4-4, 4-8, 4-12):\n\n"
      << axes_table(rs, clocks[0].name, false) << "\nand σ (tables 4-6, 4-10, 4-14):\n\n"
      << axes_table(rs, clocks[0].name, true)
      << "\n## What matches, where magnitudes differ, and why\n\n"
      << (sc.bus.can.isr_us > 0
              ? routine_why(fast, slow, clocks, sc, y_lo, y_hi)
              : hardware_reload_why(fast, slow, clocks, sc, fast_skips, fast_sync_skips, slow_skips, y_lo, y_hi))
      << bit_rate_text(fast)
      << "\nThe per-run folders (metrics.json, trajectory.csv, bus-can.pcap, master.log) are written under `runs/` "
         "beside this file by `omnitwin experiment thesis-platform --out DIR` and are not committed.\n";
  return out.str();
}

}  // namespace

int run_thesis_platform(const ExperimentOptions& options) {
  // The scenario first: a bad --model is refused before any folder is made (found in review).
  const std::string scenario = options.model.empty() ? thesis::default_scenario() : options.model;
  const Scenario sc = thesis::load_with_sets(scenario, options.sets);  // a bad --set: refused here
  const fs::path dir = experiment::output_dir("thesis-platform", options);
  const std::vector<int> rates = options.quick ? std::vector<int>{250, 1000} : std::vector<int>{125, 250, 500, 1000};
  const std::array<ClockReading, 2> clocks = thesis::clock_readings(sc);
  const int trials = options.quick ? 2 : kTrials;
  const thesis::RunSetup setup{scenario, options.sets, dir / "runs", options.quick, false, options.interrupt};
  std::vector<Result> rs;  // one per configuration: the mean of its trials
  int port = 46000, runs = 0;  // 46000 … 46079: no test or scenario uses them
  for (const ClockReading& clock : clocks) {
    for (int rate : rates) {
      for (bool sync : {false, true}) {
        std::vector<Result> ts;
        for (int trial = 0; trial < trials; ++trial, ++runs) {
          ts.push_back(thesis::run_one(setup, clock, rate, sync, trial, port++));
          experiment::stop_if_interrupted(options);
          if (ts.back().exit_code == 3) {
            std::cerr << "thesis-platform: the run at " << rate << " kbit/s (" << clock.name << " clocks, trial "
                      << trial << ") failed (see " << (dir / "runs").string() << ")\n";
            return kExperimentRuntimeError;
          }
        }
        rs.push_back(thesis::average(ts));
        const Result& r = rs.back();
        std::cout << fmt::format("  {} {:4} kbit/s sync {:3}: contour IAE {:6.1f} cm [{:.1f} … {:.1f}], axis IAE "
                                 "{:6.1f} pulses [{:.1f} … {:.1f}], master {}\n",
                                 clock.name, rate, sync ? "yes" : "no", r.iae_c, r.c_min, r.c_max, r.axis_iae, r.a_min,
                                 r.a_max, r.master_state);
      }
    }
  }
  experiment::stop_if_interrupted(options);
  const int differ = failed(effects(rs, clocks[0].name));
  experiment::write_text(dir / "thesis_platform.csv", to_csv(rs));
  experiment::write_text(dir / "thesis_platform.md", thesis::note_sets(to_markdown(rs, clocks, options.quick, scenario, sc), options.sets, false));
  experiment::plot("thesis-platform", dir / "thesis_platform.csv", dir);
  // The pose error over time at 250 kbit/s, fast clocks (a quick run has 250 too).
  experiment::write_text(dir / "thesis_platform_time.csv", time_csv(rs, clocks[0].name, 250));
  experiment::plot("thesis-platform-time", dir / "thesis_platform_time.csv", dir);
  std::cout << "thesis-platform: " << runs << " runs; directions of the sync effect ("
            << clocks[0].name << " clocks) " << (differ == 0 ? "match" : "DIFFER") << "; outputs in " << dir.string() << "\n";
  return differ == 0 ? kExperimentOk : kExperimentCheckFailed;
}

}  // namespace omnitwin::twin
