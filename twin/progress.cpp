// twin layer — terminal progress bar; see progress.hpp.
#include "twin/progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "twin/clock.hpp"

namespace omnitwin::twin {

namespace {
constexpr std::int64_t kRedrawNs = 200'000'000;   // 5 redraws per second at most
constexpr std::int64_t kShowAfterNs = 1'000'000'000;  // quiet for short runs
constexpr int kWidth = 30;
}  // namespace

bool stderr_is_terminal() {
  const char* term = std::getenv("TERM");
  return isatty(STDERR_FILENO) && !(term && std::strcmp(term, "dumb") == 0);
}

ProgressBar::ProgressBar(double total_s, std::string label, bool enabled)
    : total_s_(total_s), label_(std::move(label)), enabled_(enabled && total_s > 0),
      start_ns_(monotonic_ns()) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(double sim_s) {
  if (!enabled_) return;
  const std::int64_t now = monotonic_ns();
  if (now - start_ns_ < kShowAfterNs || now - last_draw_ns_ < kRedrawNs) return;
  last_draw_ns_ = now;
  const double frac = std::clamp(sim_s / total_s_, 0.0, 1.0);
  const int filled = static_cast<int>(frac * kWidth);
  const double wall = (now - start_ns_) * 1e-9;
  char bar[kWidth + 1];
  for (int i = 0; i < kWidth; ++i) bar[i] = i < filled ? '#' : '.';
  bar[kWidth] = '\0';
  std::fprintf(stderr, "\r%s [%s] %3.0f%%  sim %.1f/%.1f s  %.1fx real time ", label_.c_str(), bar,
               frac * 100.0, sim_s, total_s_, wall > 0 ? sim_s / wall : 0.0);
  std::fflush(stderr);
  drawn_ = true;
}

void ProgressBar::finish() {
  if (!drawn_) return;
  std::fprintf(stderr, "\r\033[K");
  std::fflush(stderr);
  drawn_ = false;
}

}  // namespace omnitwin::twin
