// twin/web — a run's live observer that feeds the browser view: the adapter between the run
// loop's RunObserver and the WebServer, as dds_observer is for DDS.
//
// The run's thread only decimates (by simulated time, 20 samples per simulated second as for
// DDS) and copies the sample into a lock-free ring; a pump thread wakes every 100 ms of wall
// time, turns what arrived into one JSON batch and publishes it, so that a lockstep run
// that goes 20 times faster than real time still costs the page a few messages a second.
#pragma once

#include <atomic>
#include <mutex>
#include <thread>
#include <vector>

#include "twin/dds/rate_decimator.hpp"
#include "twin/dds/spsc_ring.hpp"
#include "twin/run.hpp"
#include "twin/web/web_server.hpp"

namespace omnitwin::twin {

class WebRunObserver : public RunObserver {
 public:
  // rate_hz: samples per simulated second the page gets [Hz].
  WebRunObserver(WebServer& server, double rate_hz = 20.0);
  ~WebRunObserver() override;

  void on_start(const RunInfo& info) override;
  // Real-time safe: a decimation test and, when due, a copy into the ring.
  void on_state(const StateSample& s) override;
  void on_event(const RunEvent& e) override;
  void on_end(const nlohmann::json& metrics) override;

  struct Stats {
    std::uint64_t published = 0;  // samples handed to the server
    std::uint64_t ring_full = 0;  // samples lost: the pump fell behind
  };
  Stats stats() const;

 private:
  void pump();
  void flush();

  WebServer& server_;
  RateDecimator decimator_;
  SpscRing<StateSample> ring_;
  std::mutex events_mu_;
  std::vector<RunEvent> events_;
  std::thread pump_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> published_{0}, ring_full_{0};
};

}  // namespace omnitwin::twin
