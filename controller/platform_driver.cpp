// controller layer — the platform application of a bus master program (see platform_driver.hpp).
#include "controller/platform_driver.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace omnitwin::controller {

PlatformDriver::PlatformDriver(const std::optional<MasterConfig>& platform, double tick_s, double counts_per_rev)
    : platform_(platform), counts_per_rev_(counts_per_rev) {
  if (!platform_) return;
  PlatformLoopConfig lc = platform_->loop;
  lc.counts_per_rev = static_cast<int>(std::lround(counts_per_rev));
  loop_.emplace(lc, build_path(platform_->path));
  every_ = std::max<std::int64_t>(1, std::llround(lc.period / tick_s));
  // Until the loop starts, its plan and odometry say the start pose (as the Omni master's).
  out_.reference = loop_->path().sample(0.0);
  out_.odom_pose = loop_->path().start_pose();
}

PlatformDriver::Step PlatformDriver::tick(std::int64_t t, bool ready, const WheelCounts& counts) {
  Step s;
  if (!loop_ || !ready || finished_) return s;
  if (!started_) {
    loop_->reset(loop_->path().start_pose(), counts);
    origin_ = t;
    started_ = s.started = true;
    n_ = 0;
  }
  const double ts = static_cast<double>(t - origin_) * 1e-9;
  if (n_++ % every_ == 0) {
    out_ = loop_->step(ts, counts);
    const double k = counts_per_rev_ / (2 * std::numbers::pi);
    for (std::size_t i = 0; i < 4; ++i) s.wheel_counts_per_s[i] = out_.wheel_rad_s[static_cast<Eigen::Index>(i)] * k;
    s.command = true;
  }
  if (platform_->settle >= 0 && ts >= loop_->path().duration() + platform_->settle) finished_ = s.finished = true;
  return s;
}

void PlatformDriver::fill(simclock::MasterReport& r) const {
  r.path_origin_ns = started_ ? origin_ : -1;
  if (!loop_) return;
  const Pose2& ref = out_.reference.pose;
  const Pose2& odo = loop_->odometry().pose();
  r.reference = {ref.x, ref.y, ref.phi};
  r.odometry = {odo.x, odo.y, odo.phi};
}

}  // namespace omnitwin::controller
