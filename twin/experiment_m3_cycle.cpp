// twin layer — experiment "m3-cycle": seed 000's statement that "data length and slave count
// bound the cycle" made into numbers on our MECHATROLINK-III emulation (event-driven latency
// against the cyclic mode's is experiment_m3_latency.cpp, written into the same README).
//
// Two halves, kept apart so the second can check the first:
//   1. computed: m3::plan_cycle for 1 … 62 slaves × 8/16/32/48/64 bytes × cascade/star (10 m
//      cables, the wire model's default delays) × 0/1/2 retry slots → shortest_cycle.csv and
//      m3_cycle.png (media/plots/plot_experiment.py, as the other experiments);
//   2. run: for a few configurations, our C1 master, the in-process line and emulated servo
//      slaves on one simulated timeline (the Rig of tests/controller/mechatrolink3), once at
//      the planned shortest cycle rounded up to whole µs (must reach cyclic communication and
//      run with no miss, retry, late or bad response and no COMM_ALM; the last response of
//      every cycle must arrive exactly when the plan's arithmetic says) and once 1 µs below
//      (the master must refuse it naming the shortest cycle) → verified.csv.
// README.md states what the seed's limits imply and what the emulation computes. Exit 1
// (kExperimentCheckFailed) when any run disagrees with the plan.
#include <algorithm>
#include <array>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/mechatrolink3/m3_stations.hpp"
#include "bus_emulators/mechatrolink3/m3_wire.hpp"
#include "controller/mechatrolink3/m3_master.hpp"
#include "controller/mechatrolink3/m3_servo_axis.hpp"
#include "twin/experiment.hpp"

namespace omnitwin::twin {

namespace {

using m3::SimTime;

constexpr double kCableM = 10.0;
constexpr SimTime kUsNs = 1'000, kMsNs = 1'000'000;
constexpr SimTime kGapNs = m3::kInterFrameGapNs;
constexpr std::array<int, 5> kDataBytes{8, 16, 32, 48, 64};
constexpr std::array<int, 3> kRetrySlots{0, 1, 2};
constexpr std::array<SimTime, 4> kBudgetsNs{125'000, 250'000, 500'000, 1'000'000};
constexpr double kCountsPerRev = 10'000;
constexpr SimTime kStartupLimitNs = 2'000 * kMsNs;  // servo start-up must end by then

const char* topology_name(bool star) { return star ? "star" : "cascade"; }

SimTime round_up_us(SimTime ns) { return (ns + kUsNs - 1) / kUsNs * kUsNs; }

// ---- 1. the computed sweep ----

// The plan's inputs for one configuration: 10 m cables, every default delay of m3_wire.
m3::CycleInputs cycle_inputs(bool star, int slaves, int data_bytes, int retry_slots) {
  m3::CycleInputs in;
  in.topology = star ? m3::Topology::star_of(slaves, kCableM) : m3::Topology::cascade_of(slaves, kCableM);
  in.stations.assign(static_cast<std::size_t>(slaves),
                     m3::StationTiming{.data_bytes = static_cast<std::size_t>(data_bytes)});
  in.retry_slots = retry_slots;
  if (const std::string why = m3::check_inputs(in); !why.empty()) throw std::invalid_argument("m3-cycle: " + why);
  return in;
}

struct ShortestRow {
  bool star = false;
  int slaves = 0, data_bytes = 0, retry_slots = 0;
  SimTime int_offset_ns = 0, min_cycle_ns = 0;
};

std::vector<int> slave_counts(bool quick) {
  if (quick) return {1, 2, 4, 8, 16, 32, 62};
  std::vector<int> n;
  for (int k = 1; k <= m3::kMaxSlaves; ++k) n.push_back(k);
  return n;
}

std::vector<ShortestRow> sweep(bool quick) {
  std::vector<ShortestRow> rows;
  for (const bool star : {false, true})
    for (const int bytes : kDataBytes)
      for (const int retry : kRetrySlots)
        for (const int n : slave_counts(quick)) {
          const m3::CyclePlan p = m3::plan_cycle(cycle_inputs(star, n, bytes, retry));
          rows.push_back(ShortestRow{star, n, bytes, retry, p.int_offset_ns, p.min_cycle_ns});
        }
  return rows;
}

std::string shortest_csv(const std::vector<ShortestRow>& rows) {
  std::string out = "topology,slaves,data_bytes,retry_slots,int_offset_ns,min_cycle_ns\n";
  for (const ShortestRow& r : rows)
    out += fmt::format("{},{},{},{},{},{}\n", topology_name(r.star), r.slaves, r.data_bytes, r.retry_slots,
                       r.int_offset_ns, r.min_cycle_ns);
  return out;
}

// The largest slave count of (star, bytes, retry) whose shortest cycle (or, with
// `exchange_only`, INT_OFFSET alone) fits `budget_ns`; 0 when not even one slave fits.
int largest_fitting(const std::vector<ShortestRow>& rows, bool star, int bytes, int retry, SimTime budget_ns,
                    bool exchange_only) {
  int best = 0;
  for (const ShortestRow& r : rows) {
    if (r.star != star || r.data_bytes != bytes || r.retry_slots != retry) continue;
    if ((exchange_only ? r.int_offset_ns : r.min_cycle_ns) <= budget_ns) best = std::max(best, r.slaves);
  }
  return best;
}

// The shortest cycle of one configuration in the sweep [ns] (-1 if the sweep lacks it).
SimTime shortest_of(const std::vector<ShortestRow>& rows, bool star, int bytes, int retry, int slaves) {
  for (const ShortestRow& r : rows)
    if (r.star == star && r.data_bytes == bytes && r.retry_slots == retry && r.slaves == slaves) return r.min_cycle_ns;
  return -1;
}

// The smallest slave count from which the star's shortest cycle is never above the
// cascade's (any data length, any retry slots, every larger count too).
int star_no_slower_from(const std::vector<ShortestRow>& rows) {
  int from = 1;
  for (const ShortestRow& r : rows)
    if (r.star && r.min_cycle_ns > shortest_of(rows, false, r.data_bytes, r.retry_slots, r.slaves))
      from = std::max(from, r.slaves + 1);
  return from;
}

// The most slaves any topology and data length fits into `budget_ns` with `retry` slots.
int most_fitting(const std::vector<ShortestRow>& rows, int retry, SimTime budget_ns) {
  int most = 0;
  for (const bool star : {false, true})
    for (const int bytes : kDataBytes) most = std::max(most, largest_fitting(rows, star, bytes, retry, budget_ns, false));
  return most;
}

// ---- 2. the runs ----

// Our C1 master, the line and the trial's slaves on one simulated timeline, with probes on
// the master's side of the line: when each cycle's SYNC left and its last response arrived.
// Servo slaves whose profile takes the data length run the fig. 8 start-up (ServoAxis) to
// phase 3, where their watchdog and missing-sync/command checks are live; at other lengths
// the master's command buffers stay zero (NOP) and the slaves answer in phase 1.
class M3Rig {
 public:
  M3Rig(const M3CycleTrial& trial, SimTime cycle_ns);
  M3Rig(const M3Rig&) = delete;
  M3Rig& operator=(const M3Rig&) = delete;

  // Runs every event up to `end` [ns] or until done() holds.
  void run(SimTime end, const std::function<bool()>& done);
  bool servo_apps() const { return !apps_.empty(); }
  bool all_running() const;
  // The first axis not running, as "axis k: step (why)"; "" when all run.
  std::string axis_problem() const;

  m3::C1Master& master() { return *master_; }
  const m3::M3Stations& stations() const { return stations_; }
  SimTime now() const { return now_; }
  // Cycle start → last response and → cyclic interrupt, min and max over every cycle [ns].
  SimTime last_min = std::numeric_limits<SimTime>::max(), last_max = -1;
  SimTime irq_min = std::numeric_limits<SimTime>::max(), irq_max = -1;

 private:
  void add_slave(int k, bool with_app);
  void on_interrupt(SimTime t);
  void step_drives(SimTime t);

  M3CycleTrial trial_;
  m3::M3Stations stations_;
  m3::Line& line_ = stations_.line();
  std::vector<drive::AxisModel> axes_;
  std::vector<m3::ServoAxis> apps_;
  std::unique_ptr<m3::C1Master> master_;
  SimTime now_ = 0, next_drive_ = -1, cycle_start_ = -1, last_rsp_ = -1;
  std::uint64_t responses_ = 0;
};

m3::Topology trial_topology(const M3CycleTrial& t) {
  return t.star ? m3::Topology::star_of(t.slaves, kCableM) : m3::Topology::cascade_of(t.slaves, kCableM);
}

// The stations of a trial: its topology, servos with 10000 counts/rev, its slaves' response time.
m3::StationsConfig trial_stations(const M3CycleTrial& t) {
  m3::StationsConfig c;
  c.topology = trial_topology(t);
  c.servo.drive.counts_per_rev = kCountsPerRev;
  c.servo.drive.max_speed_rad_s = 200;
  c.response_ns = 2'000 + t.slave_slower_ns;
  return c;
}

M3Rig::M3Rig(const M3CycleTrial& trial, SimTime cycle_ns) : trial_(trial), stations_(trial_stations(trial)) {
  m3::MasterConfig cfg;
  cfg.cycle_ns = cycle_ns;
  cfg.retry_slots = trial.retry_slots;
  const bool with_app = m3::ServoProfile(m3::ServoConfig{}).accepts_length(static_cast<std::size_t>(trial.data_bytes));
  for (int k = 0; k < trial.slaves; ++k) {
    cfg.slaves.push_back(m3::MasterSlave{.address = static_cast<std::uint8_t>(m3::kFirstSlave + k),
                                         .data_bytes = static_cast<std::size_t>(trial.data_bytes)});
    add_slave(k, with_app);
  }
  if (with_app) next_drive_ = 0;
  master_ = std::make_unique<m3::C1Master>(
      cfg,
      [this](std::span<const std::uint8_t> f, SimTime t) {
        if (f[3] == static_cast<std::uint8_t>(m3::FrameType::sync)) {
          cycle_start_ = t;
          last_rsp_ = -1;
        }
        line_.from_master(f, t);
      },
      [this](std::uint64_t, SimTime t) { on_interrupt(t); });
  line_.attach_master([this](std::span<const std::uint8_t> f, SimTime t) {
    if (f.size() > 3 && f[3] == static_cast<std::uint8_t>(m3::FrameType::cyclic_response)) last_rsp_ = t;
    master_->on_frame(f, t);
  });
  if (trial.corrupt_every > 0)
    line_.set_fault_hook([this](bool from_master, int, std::span<const std::uint8_t> f) {
      const bool response = !from_master && f[3] == static_cast<std::uint8_t>(m3::FrameType::cyclic_response);
      return response && ++responses_ % static_cast<std::uint64_t>(trial_.corrupt_every) == 0 ? m3::Fate::corrupt
                                                                                               : m3::Fate::deliver;
    });
}

// The master's side of slave k: its axis model and, when the servo takes the data length, its
// servo-axis application (the stations themselves are built with the rig).
void M3Rig::add_slave(int k, bool with_app) {
  axes_.emplace_back();
  if (!with_app) return;
  apps_.emplace_back(fmt::format("axis {}", k + 1), m3::ServoAxisConfig{});
  apps_.back().set_velocity(static_cast<std::int32_t>(kCountsPerRev));  // 1 rev/s
}

void M3Rig::on_interrupt(SimTime t) {
  for (std::size_t k = 0; k < apps_.size(); ++k) {
    const int i = static_cast<int>(k);
    apps_[k].on_interrupt(master_->response(i), master_->fresh(i), master_->command(i), t);
  }
  if (cycle_start_ < 0 || last_rsp_ < 0) return;
  last_min = std::min(last_min, last_rsp_ - cycle_start_);
  last_max = std::max(last_max, last_rsp_ - cycle_start_);
  irq_min = std::min(irq_min, t - cycle_start_);
  irq_max = std::max(irq_max, t - cycle_start_);
}

void M3Rig::step_drives(SimTime t) {
  for (std::size_t k = 0; k < axes_.size(); ++k) {
    m3::ServoProfile& servo = stations_.servo(static_cast<int>(k));
    axes_[k].step(servo.step(t, axes_[k].feedback()), 1e-3);
  }
  next_drive_ += kMsNs;
}

void M3Rig::run(SimTime end, const std::function<bool()>& done) {
  while (!done()) {
    SimTime t = end + 1;
    for (const SimTime c : {master_->next_wakeup(), line_.next_due(), next_drive_})
      if (c >= 0 && c < t) t = c;
    if (t > end) break;
    now_ = t;
    line_.advance(t);
    master_->advance(t);
    stations_.advance(t);
    if (t == next_drive_) step_drives(t);
  }
}

bool M3Rig::all_running() const {
  return std::all_of(apps_.begin(), apps_.end(), [](const m3::ServoAxis& a) { return a.step() == m3::AxisStep::running; });
}

std::string M3Rig::axis_problem() const {
  for (std::size_t k = 0; k < apps_.size(); ++k)
    if (apps_[k].step() != m3::AxisStep::running)
      return fmt::format("axis {}: {} {}", k + 1, m3::to_string(apps_[k].step()), apps_[k].why());
  return "";
}

// Brings the rig to cyclic communication (and its servos to `running`), then runs
// trial.cycles more cycles. Returns "" or why it could not.
std::string run_fitting_cycles(M3Rig& rig, const M3CycleTrial& trial, SimTime cycle_ns) {
  m3::C1Master& m = rig.master();
  const auto stopped = [&m] { return m.state() == m3::DriverState::failed; };
  m.start(0);
  rig.run(kStartupLimitNs, [&] { return stopped() || (m.cycles() >= 1 && rig.all_running()); });
  if (m.state() != m3::DriverState::cyclic) return fmt::format("master {}: {}", m3::to_string(m.state()), m.why());
  if (!rig.all_running()) return "servo start-up did not finish: " + rig.axis_problem();
  const std::uint64_t target = m.cycles() + static_cast<std::uint64_t>(trial.cycles);
  rig.run(rig.now() + (trial.cycles + 2) * cycle_ns, [&] { return stopped() || m.cycles() >= target; });
  if (m.cycles() < target) return fmt::format("only {} of {} cycles ran", m.cycles(), target);
  return rig.all_running() ? "" : "an axis stopped: " + rig.axis_problem();
}

// The master's and slaves' counters into `v`.
void collect(M3Rig& rig, M3CycleVerified& v) {
  m3::C1Master& m = rig.master();
  v.cycles = m.cycles();
  for (int k = 0; k < m.slaves(); ++k) {
    const m3::SlaveCounters& c = m.counters(k);
    v.missed += c.missed;
    v.retries += c.retries;
    v.late += c.late;
    v.bad += c.bad;
  }
  v.phase = 9;
  for (int k = 0; k < rig.stations().size(); ++k) {
    const m3::SlaveLink& l = rig.stations().link(k);
    v.comm_alarms += l.stats().comm_alarms + (l.comm_alarm() != m3::CommAlarm::normal ? 1 : 0);
    v.phase = std::min(v.phase, static_cast<int>(l.phase()));
  }
  v.measured_min_ns = rig.last_max < 0 ? -1 : rig.last_min;
  v.measured_max_ns = rig.last_max;
  v.interrupt_min_ns = rig.irq_max < 0 ? -1 : rig.irq_min;
  v.interrupt_max_ns = rig.irq_max;
}

// The first check the fitting run fails, or "".
std::string judge_fitting(M3Rig& rig, const m3::CyclePlan& plan, M3CycleVerified& v) {
  const m3::C1Master& m = rig.master();
  if (m.int_offset_ns() != plan.int_offset_ns || m.min_cycle_ns() != plan.min_cycle_ns)
    return fmt::format("the master planned INT_OFFSET {} ns / shortest {} ns from its measured TR_DLY, the wire "
                       "model {} / {} ns", m.int_offset_ns(), m.min_cycle_ns(), plan.int_offset_ns, plan.min_cycle_ns);
  if (v.missed + v.retries + v.late + v.bad != 0)
    return fmt::format("missed {}, retries {}, late {}, bad {}", v.missed, v.retries, v.late, v.bad);
  if (v.comm_alarms != 0) return fmt::format("{} slave COMM_ALM", v.comm_alarms);
  if (const int want = rig.servo_apps() ? 3 : 1; v.phase != want)
    return fmt::format("a slave ended in phase {}, not {}", v.phase, want);
  if (rig.stations().line().overflow() != 0) return "the line's queue overflowed";
  if (v.measured_min_ns != v.expected_last_ns || v.measured_max_ns != v.expected_last_ns)
    return fmt::format("last response {} … {} ns after the cycle start, the plan says {} ns", v.measured_min_ns,
                       v.measured_max_ns, v.expected_last_ns);
  if (v.interrupt_min_ns != v.int_offset_ns || v.interrupt_max_ns != v.int_offset_ns)
    return fmt::format("cyclic interrupt {} … {} ns after the cycle start, INT_OFFSET is {} ns", v.interrupt_min_ns,
                       v.interrupt_max_ns, v.int_offset_ns);
  return "";
}

// 1 µs below the shortest whole-µs cycle: the master must fail naming that cycle.
std::string judge_shorter(const M3CycleTrial& trial, SimTime cycle_ns, bool& refused) {
  M3Rig rig(trial, cycle_ns - kUsNs);
  m3::C1Master& m = rig.master();
  m.start(0);
  rig.run(kStartupLimitNs, [&m] {
    return m.state() == m3::DriverState::failed || m.state() == m3::DriverState::cyclic;
  });
  const std::string want = fmt::format("the shortest cycle that fits is {} µs", cycle_ns / kUsNs);
  refused = m.state() == m3::DriverState::failed && m.why().find(want) != std::string::npos;
  if (refused) return "";
  return fmt::format("{} µs was not refused as it should be (master {}: {})", (cycle_ns - kUsNs) / kUsNs,
                     m3::to_string(m.state()), m.why());
}

// ---- outputs ----

std::vector<M3CycleTrial> verification_set(bool quick) {
  std::vector<M3CycleTrial> set;
  const std::vector<int> slaves = quick ? std::vector<int>{1, 16} : std::vector<int>{1, 4, 16, 62};
  for (const bool star : {false, true})
    for (const int bytes : {8, 32, 64})
      for (const int n : slaves) set.push_back(M3CycleTrial{.star = star, .slaves = n, .data_bytes = bytes});
  return set;
}

std::string csv_text(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string verified_csv(const std::vector<M3CycleVerified>& rows) {
  std::string out =
      "topology,slaves,data_bytes,retry_slots,servo_app,min_cycle_ns,cycle_ns,int_offset_ns,retry_ns,"
      "expected_last_rsp_ns,measured_last_rsp_min_ns,measured_last_rsp_max_ns,interrupt_min_ns,interrupt_max_ns,"
      "cycles,missed,retries,late,bad,comm_alarms,phase,shorter_refused,ok,why\n";
  for (const M3CycleVerified& v : rows) {
    const M3CycleTrial& t = v.trial;
    out += fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
                       topology_name(t.star), t.slaves, t.data_bytes, t.retry_slots, v.phase == 3 ? 1 : 0,
                       v.min_cycle_ns, v.cycle_ns, v.int_offset_ns, v.retry_ns, v.expected_last_ns, v.measured_min_ns,
                       v.measured_max_ns, v.interrupt_min_ns, v.interrupt_max_ns, v.cycles, v.missed, v.retries,
                       v.late, v.bad, v.comm_alarms, v.phase, v.shorter_refused ? 1 : 0, v.ok() ? 1 : 0,
                       csv_text(v.why));
  }
  return out;
}

std::string ms(SimTime ns) { return fmt::format("{:.3f}", static_cast<double>(ns) / kMsNs); }

// What the seed's figures alone imply: 100 Mbit/s and our frame format give each slave at
// least a command and a response frame with gaps, so a budget holds at most this many
// slaves even with no cable, station, response or software time at all.
int wire_only_bound(int bytes, SimTime budget_ns) {
  const SimTime per_slave = 2 * m3::frame_slot_ns(static_cast<std::size_t>(bytes));
  return static_cast<int>(std::clamp<SimTime>((budget_ns - m3::frame_slot_ns(8)) / per_slave, 0, m3::kMaxSlaves));
}

std::string budget_header(const std::string& first) {
  std::string h = "| " + first + " |", rule = "|---|";
  for (const SimTime b : kBudgetsNs) h += fmt::format(" {} ms |", ms(b)), rule += "---|";
  return h + "\n" + rule + "\n";
}

std::string seed_section() {
  std::string out =
      "## What the seed's limits imply\n\n"
      "Seed 000 and the fact sheet give: at most 62 slaves, 100 Mbit/s (4B/5B: 80 ns per byte), cyclic data "
      "lengths 8/16/32/48/64 bytes, cascade and star, one command and one response per slave per transmission "
      "cycle, retries inside the cycle, and a typical servo accepting communication cycles of 0.125 ms to 32 ms. "
      "They give no formula and no figure for the shortest cycle of a given network. The bare wire time alone "
      "(a sync frame, then a command and a response frame with inter-frame gaps per slave; preamble/SFD 8 bytes, "
      "header 5, FCS 4, gap 12 — the framing is ours) bounds how many slaves a cycle can hold even with zero "
      "cable, station, response and software time:\n\n" +
      budget_header("data bytes (wire time only)");
  for (const int bytes : kDataBytes) {
    out += fmt::format("| {} |", bytes);
    for (const SimTime b : kBudgetsNs) out += fmt::format(" {} |", wire_only_bound(bytes, b));
    out += "\n";
  }
  return out + fmt::format("\nSo 62 slaves at 64 bytes ({} × {:.2f} µs of frames) cannot share a 0.125 ms "
                           "cycle on one line whatever the delays; the 0.125 ms figure is what one servo accepts, "
                           "not what a full network reaches.\n\n",
                           m3::kMaxSlaves, 2.0 * static_cast<double>(m3::frame_slot_ns(64)) / kUsNs);
}

// One table of the largest slave counts: `exchange_only` compares INT_OFFSET alone.
std::string fitting_table(const std::vector<ShortestRow>& rows, bool exchange_only) {
  std::string out = budget_header("topology, data bytes, retry slots");
  for (const bool star : {false, true})
    for (const int bytes : kDataBytes)
      for (const int retry : kRetrySlots) {
        out += fmt::format("| {}, {} B, {} |", topology_name(star), bytes, retry);
        for (const SimTime b : kBudgetsNs)
          out += fmt::format(" {} |", largest_fitting(rows, star, bytes, retry, b, exchange_only));
        out += "\n";
      }
  return out + "\n";
}

std::string emulation_section(const std::vector<ShortestRow>& rows, int most) {
  std::string out =
      "## What the emulation computes\n\n"
      "`m3::plan_cycle` (bus_emulators/mechatrolink3/m3_wire): T_RSP(k) = TR_DLY(k) + command and response "
      "frame times + the slave's response time + a margin; INT_OFFSET = sync slot + Σ(T_RSP(k) + gap) + retry "
      "slots × the slowest (T_RSP + gap); shortest cycle = INT_OFFSET + the master's software time. 10 m "
      "cables everywhere (the star's master-to-hub cable too). The full curves are in `shortest_cycle.csv` "
      "and `m3_cycle.png`.\n\n"
      "**Modelled, not measured:** the per-station forwarding delay (500 ns, cut-through, cascade), the star "
      "hub's delay (500 ns), the slave response time (2 µs), the margin on every T_RSP (1 µs), the master's "
      "software time after the interrupt (100 µs) and 5 ns/m of cable are our choices "
      "(docs/protocols/mechatrolink3.md), not figures of real M-III hardware; the results below are as good "
      "as they are.\n\n"
      "Largest slave count whose shortest cycle (INT_OFFSET + 100 µs software) fits:\n\n" +
      fitting_table(rows, false) +
      "Largest slave count whose INT_OFFSET alone fits (the exchange without the 100 µs software time, e.g. "
      "with the software overlapped or much faster):\n\n" +
      fitting_table(rows, true) + fmt::format("Shortest cycle [ms] at 1 and {} slaves:\n\n", most) +
      "| topology, data bytes | 0 retry slots | 1 retry slot | 2 retry slots |\n|---|---|---|---|\n";
  for (const bool star : {false, true})
    for (const int bytes : kDataBytes) {
      out += fmt::format("| {}, {} B |", topology_name(star), bytes);
      for (const int retry : kRetrySlots)
        out += fmt::format(" {} … {} |", ms(shortest_of(rows, star, bytes, retry, 1)),
                           ms(shortest_of(rows, star, bytes, retry, most)));
      out += "\n";
    }
  return out + fmt::format(
                   "\nFrom {} slaves on a star is never slower than a cascade: the C1 master polls, each "
                   "slave's T_RSP holds the round trip through every station before it (2 × 500 ns each) and "
                   "polling adds them up, while a star's slaves are all one hub away. Below that the star's hub "
                   "and its extra 10 m master-to-hub cable cost a little more than the few stations a short "
                   "cascade passes. With 100 µs of software time only {} µs of a 0.125 ms cycle remain for "
                   "the exchange: at most {} slave(s) fit it (16 bytes, no retry slot), with one retry slot at "
                   "most {}.\n\n",
                   star_no_slower_from(rows), (kBudgetsNs[0] - m3::CycleInputs{}.software_ns) / kUsNs,
                   most_fitting(rows, 0, kBudgetsNs[0]), most_fitting(rows, 1, kBudgetsNs[0]));
}

std::string verified_section(const std::vector<M3CycleVerified>& rows, bool ok) {
  std::string out = fmt::format(
      "## Verified by running it\n\n"
      "Each configuration (1 retry slot) ran on our C1 master over the in-process line with emulated servo "
      "slaves: at the planned shortest cycle rounded up to whole µs (32 bytes: the servo start-up of fig. 8 to "
      "phase 3 and VELCTRL at 1 rev/s; 8 and 64 bytes, which the servo profile does not take: NOP in phase 1), then "
      "{} cycles more; and 1 µs below, which the master must refuse naming the shortest cycle. The last "
      "response of each cycle must arrive exactly INT_OFFSET − retry room − n × margin − one gap after the "
      "cycle's SYNC (the line's delays and the plan are the same arithmetic; the margins and the last gap are "
      "slack the plan keeps), and the cyclic interrupt exactly at INT_OFFSET. Every check passed: **{}**.\n\n"
      "| topology | slaves | bytes | cycle run [µs] | INT_OFFSET [ns] | last response: plan / measured [ns] | "
      "cycles | missed / retries / late / bad | COMM_ALM | phase | 1 µs less refused | ok |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|\n",
      rows.empty() ? 0 : rows.front().trial.cycles, ok ? "yes" : "NO");
  for (const M3CycleVerified& v : rows) {
    const M3CycleTrial& t = v.trial;
    out += fmt::format("| {} | {} | {} | {} | {} | {} / {} | {} | {} / {} / {} / {} | {} | {} | {} | {} |\n",
                       topology_name(t.star), t.slaves, t.data_bytes, v.cycle_ns / kUsNs, v.int_offset_ns,
                       v.expected_last_ns, v.measured_max_ns, v.cycles, v.missed, v.retries, v.late, v.bad,
                       v.comm_alarms, v.phase, v.shorter_refused ? "yes" : "**no**", v.ok() ? "yes" : "**" + v.why + "**");
  }
  return out + "\n";
}

std::string readme(const std::vector<ShortestRow>& rows, const std::vector<M3CycleVerified>& verified, bool ok,
                   bool quick) {
  const int most = slave_counts(quick).back();
  return std::string("# m3-cycle: the shortest MECHATROLINK-III transmission cycle on our emulation\n\n") +
         "`omnitwin experiment m3-cycle` (twin/experiment_m3_cycle.cpp, twin/experiment_m3_latency.cpp; "
         "docs/experiments.md): the shortest cyclic transmission cycle, verified by running it, and at the end "
         "event-driven against cyclic response latency." +
         (quick ? " This is a `--quick` run (a handful of slave counts)." : "") + "\n\n" + seed_section() +
         emulation_section(rows, most) + verified_section(verified, ok);
}

}  // namespace

M3CycleVerified run_m3_cycle_trial(const M3CycleTrial& trial) {
  const m3::CyclePlan plan = m3::plan_cycle(cycle_inputs(trial.star, trial.slaves, trial.data_bytes, trial.retry_slots));
  M3CycleVerified v;
  v.trial = trial;
  v.min_cycle_ns = plan.min_cycle_ns;
  v.cycle_ns = round_up_us(plan.min_cycle_ns);
  v.int_offset_ns = plan.int_offset_ns;
  v.retry_ns = plan.retry_ns;
  const m3::CycleInputs defaults;
  v.expected_last_ns = plan.int_offset_ns - plan.retry_ns - trial.slaves * defaults.margin_ns - kGapNs;
  M3Rig rig(trial, v.cycle_ns);
  v.why = run_fitting_cycles(rig, trial, v.cycle_ns);
  collect(rig, v);
  if (v.why.empty()) v.why = judge_fitting(rig, plan, v);
  const std::string shorter = judge_shorter(trial, v.cycle_ns, v.shorter_refused);
  if (v.why.empty()) v.why = shorter;
  return v;
}

int run_m3_cycle(const ExperimentOptions& options) { return run_m3_cycle(options, M3CycleTrial{}); }

int run_m3_cycle(const ExperimentOptions& options, const M3CycleTrial& faults) {
  // Compute the sweep, run the verification set, then write everything before judging.
  const std::vector<ShortestRow> rows = sweep(options.quick);
  std::vector<M3CycleVerified> verified;
  for (M3CycleTrial t : verification_set(options.quick)) {
    t.slave_slower_ns = faults.slave_slower_ns;
    t.corrupt_every = faults.corrupt_every;
    verified.push_back(run_m3_cycle_trial(t));
  }
  std::vector<M3LatencyRow> latency;
  for (const bool star : {false, true})
    for (const int n : options.quick ? std::vector<int>{1, 16} : std::vector<int>{1, 4, 16, 62})
      latency.push_back(m3_event_latency(star, n));
  const bool ok = std::all_of(verified.begin(), verified.end(), [](const M3CycleVerified& v) { return v.ok(); }) &&
                  std::all_of(latency.begin(), latency.end(), [](const M3LatencyRow& r) { return r.ok(); });
  const std::filesystem::path dir = experiment::output_dir("m3-cycle", options);
  experiment::write_text(dir / "shortest_cycle.csv", shortest_csv(rows));
  experiment::write_text(dir / "verified.csv", verified_csv(verified));
  experiment::write_text(dir / "latency.csv", m3_latency_csv(latency));
  experiment::write_text(dir / "README.md", readme(rows, verified, ok, options.quick) + m3_latency_section(latency));
  experiment::plot("m3-cycle", dir / "shortest_cycle.csv", dir);
  for (const M3LatencyRow& r : latency)
    if (!r.ok()) std::cerr << fmt::format("m3-cycle: event-driven, {} {} slaves: {}\n", r.star ? "star" : "cascade", r.slaves, r.why);
  for (const M3CycleVerified& v : verified)
    if (!v.ok())
      std::cerr << fmt::format("m3-cycle: {} {} slaves {} B: {}\n", topology_name(v.trial.star), v.trial.slaves,
                               v.trial.data_bytes, v.why);
  std::cout << fmt::format("m3-cycle: {} configurations planned, {} run: {}; outputs in {}\n", rows.size(),
                           verified.size(), ok ? "all agree with the plan" : "SOME DISAGREE", dir.string());
  return ok ? kExperimentOk : kExperimentCheckFailed;
}

}  // namespace omnitwin::twin
