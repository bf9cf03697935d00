// twin layer — a run's live observer that publishes on DDS (twin/dds): the adapter between
// the run loop's RunObserver and the DdsPublisher, so that run.cpp knows nothing of DDS.
#pragma once

#include "twin/dds/dds_publisher.hpp"
#include "twin/run.hpp"

namespace omnitwin::twin {

class DdsRunObserver : public RunObserver {
 public:
  // Joins the DDS domain now (throws DdsError on a bad domain, interface or config).
  explicit DdsRunObserver(const DdsSettings& s) : pub_(s) {}

  void on_start(const RunInfo& info) override { pub_.start(info); }
  // Real-time safe: a copy into the publisher's ring.
  void on_state(const StateSample& s) override { pub_.offer(s); }
  void on_event(const RunEvent& e) override { pub_.event(e); }
  // The end event has been queued by the run; drain and flush what is left.
  void on_end(const nlohmann::json&) override { pub_.finish(); }

  DdsPublisher::Stats stats() const { return pub_.stats(); }
  // See DdsPublisher::wait_for_readers.
  int wait_for_readers(int readers, double timeout_s, const std::atomic<bool>* stop = nullptr) const {
    return pub_.wait_for_readers(readers, timeout_s, stop);
  }

 private:
  DdsPublisher pub_;
};

}  // namespace omnitwin::twin
