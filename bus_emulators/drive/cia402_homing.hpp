// bus_emulators/drive — CiA 402 homing (mode 6): methods 1–14, 17–30, 33, 34, 35, 37 of the
// fact sheet / seed 004 diagrams, on the drive's physical position [counts] (polarity not
// applied: the switches are wired to the physical axis).
//
// Every switch method is one rule: "cross boundary b of the switch's pattern in direction d",
// then (methods < 17) "go on in d to the first index pulse". The patterns, left to right:
//   NL (1, 11–14 reversal, 17): active | inactive        PL (2, 7–10 reversal, 18): inactive | active
//   positive home switch (3, 4, 19, 20): inactive | active
//   negative home switch (5, 6, 21, 22): active | inactive
//   home cam (7–14, 23–30): inactive | active | inactive
// Homing state machine (Homing::step, one flat switch over Phase):
//   idle        Legal: start → locate (switch methods), index (33, 34), attained (35, 37).
//   locate      unknown cam side: move in the initial direction (+ for 7–10 and 23–26,
//               − for 11–14 and 27–30) at speed 0x6099:1 until the cam or the reversing
//               limit switch tells the region. Legal: → approach; → error.
//   approach    region known: move toward the region before the boundary at 0x6099:1, then
//               cross the boundary in d at 0x6099:2 (reversing as needed). Legal: the
//               boundary crossed in d → index (methods < 17) or move_home; → error.
//   index       go on in d at 0x6099:2 until the first index pulse beyond the edge (or, 33/34,
//               beyond the start). Legal: → move_home; → error.
//   move_home   trapezoid back to the latched home position (0x6099:2, 0x609A). Legal:
//               standing on it within 1 count → attained.
//   attained    Legal: start.
//   error       a limit switch hit that the method does not use, a search longer than
//               max_search_counts, unknown method. Decelerates, then stands. Legal: start.
// Every phase honours `abort`: decelerate to standstill → idle. The drive (cia402_drive) aborts
// on halt only, not on controlword bit 4 falling, which CiA 402 also makes an abort: seed 004's
// master clears bit 4 as soon as the drive has answered, so its homing would never run (a
// deliberate departure; a master that aborts by dropping bit 4 must use halt here).
// Edges are latched exactly (a touch-probe model): the drive hands in the position where an
// input changed; index pulses lie at index_offset + k·counts_per_rev.
#pragma once

#include <cstdint>

#include "bus_emulators/drive/cia402_profile.hpp"

namespace omnitwin::drive {

// Is `method` one of the implemented homing methods?
bool homing_method_supported(int method) noexcept;

struct HomingSignals {
  double pos = 0;                  // actual physical position [counts]
  bool nl = false, pl = false, home = false;
  // Where each input last changed, valid in the period it changes [counts].
  double nl_edge = 0, pl_edge = 0, home_edge = 0;
};
struct HomingParams {
  int method = 35;
  double v_switch = 0, v_zero = 0, acc = 0;  // [counts/s], [counts/s²]
  double counts_per_rev = 10000;             // motor revolution = index pulse spacing [counts]
  double index_offset = 0;                   // index pulse phase [counts]
  double max_search = 1e9;                   // search travel before a homing error [counts]
  double stop_dec = 0;                       // deceleration after an error (0x6085; 0 = acc)
};
struct HomingOutput {
  double demand_pos = 0, demand_vel = 0;     // physical [counts], [counts/s]
  bool active = false;                       // moving under homing control
  bool attained = false, error = false;
  bool latched = false;                      // the home position was latched this period
  double home_pos = 0;                       // the latched home position (valid from latch on)
};

class Homing {
 public:
  enum class Phase : std::uint8_t { idle, locate, approach, index, move_home, attained, error };
  // Starts `method` from the current demand (pos, vel).
  void start(const HomingParams& p, const HomingSignals& s, double demand_pos, double demand_vel) noexcept;
  // One period; `abort` stops the search (start bit cleared, halt).
  HomingOutput step(const HomingParams& p, const HomingSignals& s, bool abort, double dt) noexcept;
  void reset(double pos) noexcept;   // idle, holding pos
  Phase phase() const noexcept { return phase_; }

 private:
  void fail() noexcept { phase_ = Phase::error; }
  double index_beyond(const HomingParams& p, double from, int dir) const noexcept;
  bool switch_state(const HomingSignals& s) const noexcept;
  double switch_edge(const HomingSignals& s) const noexcept;
  // Drives the demand at velocity v_target (signed) with acceleration acc.
  void run_at(double v_target, double acc, double dt) noexcept;

  Phase phase_ = Phase::idle;
  Trapezoid traj_;
  int method_ = 0;
  int kind_ = 0;        // switch pattern: 0 none, 1 NL, 2 PL, 3 pos home, 4 neg home, 5 cam
  int boundary_ = 0;    // boundary index b (between regions b and b+1)
  int dir_ = 1;         // final crossing direction d
  int init_dir_ = 1;    // cam methods: initial search direction
  int region_ = -1;     // current region, -1 unknown
  bool use_index_ = false;
  bool prev_state_ = false;
  double prev_pos_ = 0, travel_ = 0, index_target_ = 0, home_ = 0;
  bool has_home_ = false, latch_now_ = false;
};

}  // namespace omnitwin::drive
