// twin/dds — live publishing of a run's state stream and events over DDS (DESIGN §8).
//
// The run loop hands each control sample to offer(), which must not slow the simulation:
// it decimates by simulated time and copies the sample into a fixed-capacity lock-free ring,
// nothing else. A background thread drains the ring and writes the topics (docs/protocols/
// dds.md): ROS 2 shaped nav_msgs/Odometry, sensor_msgs/JointState, geometry_msgs/Twist, and
// omnitwin's own PlatformState, DriveStates, BusStatistics and RunEvent. State topics are
// best-effort and volatile (a late sample is worthless); run events are reliable and
// transient-local, so a listener that joins late still gets the run's events.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "twin/dds/dds_common.hpp"
#include "twin/dds/dds_settings.hpp"
#include "twin/dds/rate_decimator.hpp"
#include "twin/dds/spsc_ring.hpp"
#include "twin/run_state.hpp"

namespace omnitwin::twin {

class DdsPublisher {
 public:
  struct Stats {
    std::uint64_t offered = 0;    // offer() calls
    std::uint64_t skipped = 0;    // not due at the publish rate (decimated away)
    std::uint64_t dropped = 0;    // due but the ring was full
    std::uint64_t published = 0;  // samples written (each to every state topic)
    std::uint64_t events = 0;     // run events written
    std::uint64_t write_errors = 0;  // dds_write failures (any topic)
  };

  // Joins the domain and creates the writers; throws DdsError on a bad domain, interface,
  // config file or rate. Not real-time safe.
  explicit DdsPublisher(const DdsSettings& settings);
  ~DdsPublisher();  // finish()
  DdsPublisher(const DdsPublisher&) = delete;
  DdsPublisher& operator=(const DdsPublisher&) = delete;

  // Waits until at least `readers` readers match one of the state topics (platform_state,
  // odom, joint_states, cmd_vel, drives, bus or clock), or `timeout_s` seconds of
  // wall time have passed, or *stop becomes nonzero; returns how many matched. Polls every
  // 10 ms. Not real-time safe: call before the run.
  int wait_for_readers(int readers, double timeout_s, const std::atomic<bool>* stop = nullptr) const;
  // Queues the run's start event (text from `info`) and starts the publishing thread. Once.
  void start(const RunInfo& info);
  // Real-time safe: never blocks, never allocates; at most one futex wake-up. Decimates by
  // s.t_ns to the publish rate and copies a due sample into the ring. Returns false when the
  // sample was due but the ring was full (counted in Stats::dropped); true otherwise. Samples
  // offered before start() wait in the ring. Call from one thread only.
  bool offer(const StateSample& s);
  // Queues a run event (non-blocking; allocates). Events reach the wire in order, and each
  // after every sample offered before it (so `end` is the last thing a reader gets).
  void event(const RunEvent& e);
  // Drains the ring and the events, publishes the end event (unless one was given to
  // event()), waits up to finish_timeout_s for readers to acknowledge the events, and joins
  // the thread. Idempotent; not real-time safe. Without start(), nothing is published.
  void finish();
  Stats stats() const;
  const ResolvedEndpoint& endpoint() const { return participant_.endpoint(); }

 private:
  struct Writers;
  void run_thread();
  bool publish_in_order();
  void publish_event(const RunEvent& e);
  bool publish_sample();
  void publish_end_and_flush();
  void wake();

  DdsSettings settings_;
  DdsParticipant participant_;
  std::unique_ptr<Writers> writers_;
  RateDecimator decimator_;            // producer only
  SpscRing<StateSample> ring_;
  std::mutex events_mutex_;
  // Each event with the number of samples pushed before it: it goes out once that many were
  // published. Guarded by events_mutex_.
  std::deque<std::pair<RunEvent, std::uint64_t>> events_;
  std::atomic<std::uint64_t> pushed_{0};  // samples in the ring so far (producer)
  std::uint64_t popped_ = 0;              // samples taken from the ring (consumer)
  RunInfo info_;                       // written by start() before the thread starts
  std::atomic<std::int64_t> last_t_ns_{0};  // the last offered sample's time [ns]
  bool end_seen_ = false;              // consumer: an end event went out
  std::atomic<std::uint32_t> wake_{0};
  std::atomic<bool> stopping_{false};
  std::atomic<std::uint64_t> offered_{0}, skipped_{0}, dropped_{0}, published_{0}, events_n_{0},
      write_errors_{0};
  std::thread thread_;
  bool started_ = false;
  bool finished_ = false;
};

}  // namespace omnitwin::twin
