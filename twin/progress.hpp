// twin layer — a terminal progress bar for long runs.
//
// Drawn on stderr only when stderr is a terminal, at most a few times per second of wall
// time, and only once a run has lasted long enough to be worth it; otherwise it prints
// nothing, so logs and CI output stay quiet.
#pragma once

#include <cstdint>
#include <string>

namespace omnitwin::twin {

class ProgressBar {
 public:
  // total_s: simulated length of the run [s]; label: shown before the bar.
  ProgressBar(double total_s, std::string label, bool enabled);
  ~ProgressBar();
  // sim_s: simulated time reached [s]. Cheap when it does not redraw.
  void update(double sim_s);
  // Clears the bar line (if one was drawn).
  void finish();

 private:
  double total_s_;
  std::string label_;
  bool enabled_;
  bool drawn_ = false;
  std::int64_t start_ns_;
  std::int64_t last_draw_ns_ = 0;
};

// True when stderr is a terminal and TERM is not "dumb".
bool stderr_is_terminal();

}  // namespace omnitwin::twin
