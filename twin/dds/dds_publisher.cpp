// twin/dds — the DDS publisher: real-time hand-over in offer(), DDS writes on its own thread
// (see dds_publisher.hpp).
#include "twin/dds/dds_publisher.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <sstream>
#include <thread>

#include "twin/dds/dds_messages.hpp"

namespace omnitwin::twin {

// The topics and writers, created once in the constructor (Cyclone deletes them with the
// participant). The scratch messages belong to the publishing thread.
struct DdsPublisher::Writers {
  dds_entity_t state = 0, odom = 0, joints = 0, cmd_vel = 0, drives = 0, bus = 0, events = 0, clock = 0;
  ddsmsg::StateMessages scratch;
};

namespace {

dds_entity_t make_writer(dds_entity_t participant, std::string_view short_name, const dds_qos_t* qos) {
  const TopicInfo topic = *find_topic(short_name);
  const dds_entity_t t = create_topic(participant, topic);
  const dds_entity_t w = dds_create_writer(participant, t, qos, nullptr);
  if (w < 0) throw_dds("create_writer " + std::string(topic.name), w);
  return w;
}

void check_settings(const DdsSettings& s) {
  if (!(s.rate_hz > 0) || !std::isfinite(s.rate_hz))
    throw DdsError("DDS publish rate must be a positive number of Hz, not " + std::to_string(s.rate_hz));
  if (s.queue_capacity == 0) throw DdsError("DDS queue capacity must be at least 1");
}

const DdsSettings& checked(const DdsSettings& s) {
  check_settings(s);
  return s;
}

std::string start_text(const RunInfo& i) {
  std::ostringstream os;
  os << "scenario=" << i.scenario << " bus=" << i.bus << " clock=" << i.clock
     << " control_period_s=" << i.control_period_s << " duration_s=" << i.duration_s
     << " run_dir=" << i.run_dir;
  return os.str();
}

}  // namespace

DdsPublisher::DdsPublisher(const DdsSettings& settings)
    : settings_(checked(settings)),
      participant_(DdsEndpoint{settings.domain, settings.interface, settings.config_file}),
      writers_(std::make_unique<Writers>()),
      decimator_(settings.rate_hz),
      ring_(settings.queue_capacity) {
  const dds_entity_t p = participant_.get();
  const DdsQos state = state_qos(1), events = event_qos(kEventHistory);
  Writers& w = *writers_;
  w.state = make_writer(p, "state", state.get());
  w.odom = make_writer(p, "odom", state.get());
  w.joints = make_writer(p, "joint_states", state.get());
  w.cmd_vel = make_writer(p, "cmd_vel", state.get());
  w.drives = make_writer(p, "drives", state.get());
  w.bus = make_writer(p, "bus", state.get());
  w.events = make_writer(p, "events", events.get());
  w.clock = make_writer(p, "clock", state.get());  // ROS 2's clock QoS: best effort, keep last 1
}

DdsPublisher::~DdsPublisher() { finish(); }

int DdsPublisher::wait_for_readers(int readers, double timeout_s, const std::atomic<bool>* stop) const {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    // A reader of any state topic counts: a ROS 2 node reads rt/clock or odom, not our own
    // platform_state type (only that one counted; found in review). The most on any topic.
    int matched = 0;
    for (const dds_entity_t w : {writers_->state, writers_->odom, writers_->joints, writers_->cmd_vel,
                                 writers_->drives, writers_->bus, writers_->clock}) {
      dds_publication_matched_status_t st{};
      if (dds_get_publication_matched_status(w, &st) == 0) matched = std::max(matched, static_cast<int>(st.current_count));
    }
    if (matched >= readers || (stop && stop->load()) || std::chrono::steady_clock::now() >= give_up) return matched;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

void DdsPublisher::start(const RunInfo& info) {
  if (started_ || finished_) return;
  info_ = info;
  {
    // The start event goes out first, before any sample or event queued before start().
    std::lock_guard lock(events_mutex_);
    events_.emplace_front(RunEvent{0, RunEventKind::start, "twin", start_text(info)}, 0);
  }
  started_ = true;
  thread_ = std::thread([this] { run_thread(); });
}

bool DdsPublisher::offer(const StateSample& s) {
  offered_.fetch_add(1, std::memory_order_relaxed);
  last_t_ns_.store(s.t_ns, std::memory_order_relaxed);
  if (!decimator_.take(s.t_ns)) {
    skipped_.fetch_add(1, std::memory_order_relaxed);
    return true;
  }
  if (!ring_.push(s)) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  pushed_.fetch_add(1, std::memory_order_release);
  wake();
  return true;
}

void DdsPublisher::event(const RunEvent& e) {
  {
    std::lock_guard lock(events_mutex_);
    events_.emplace_back(e, pushed_.load(std::memory_order_acquire));
  }
  wake();
}

void DdsPublisher::wake() {
  wake_.fetch_add(1, std::memory_order_release);
  wake_.notify_one();
}

void DdsPublisher::finish() {
  if (finished_) return;
  finished_ = true;
  stopping_.store(true, std::memory_order_release);
  wake();
  if (thread_.joinable()) thread_.join();
}

DdsPublisher::Stats DdsPublisher::stats() const {
  constexpr auto r = std::memory_order_relaxed;
  return Stats{offered_.load(r), skipped_.load(r), dropped_.load(r),
               published_.load(r), events_n_.load(r), write_errors_.load(r)};
}

// The publishing thread: samples and events in the order they were offered, sleeping on
// wake_ when there is nothing to do.
void DdsPublisher::run_thread() {
  for (;;) {
    const std::uint32_t seen = wake_.load(std::memory_order_acquire);
    const bool stopping = stopping_.load(std::memory_order_acquire);
    const bool worked = publish_in_order();
    if (stopping && !worked) break;
    if (!worked) wake_.wait(seen, std::memory_order_acquire);
  }
  publish_end_and_flush();
}

// Publishes what is queued: the next event as soon as every sample pushed before it is out,
// samples otherwise. An event used to go out before the samples still in the ring, so the run's
// `end` reached readers before its last states (found in review). True if anything went out.
bool DdsPublisher::publish_in_order() {
  bool any = false;
  for (;;) {
    std::optional<std::pair<RunEvent, std::uint64_t>> next;
    {
      std::lock_guard lock(events_mutex_);
      if (!events_.empty()) next = events_.front();
    }
    if (next && popped_ >= next->second) {
      publish_event(next->first);
      std::lock_guard lock(events_mutex_);
      events_.pop_front();
    } else if (!publish_sample()) {
      return any;
    }
    any = true;
  }
}

void DdsPublisher::publish_event(const RunEvent& e) {
  const omnitwin_msg_dds__RunEvent_ m = ddsmsg::to_message(e, info_.scenario);
  if (dds_write(writers_->events, &m) < 0) write_errors_.fetch_add(1, std::memory_order_relaxed);
  else events_n_.fetch_add(1, std::memory_order_relaxed);
  end_seen_ = end_seen_ || e.kind == RunEventKind::end;
}

// One sample from the ring on every state topic; false when the ring is empty.
bool DdsPublisher::publish_sample() {
  Writers& w = *writers_;
  StateSample s;
  if (!ring_.pop(s)) return false;
  ++popped_;
  w.scratch.fill(s, info_.bus);
  int failed = (dds_write(w.state, &w.scratch.state) < 0) + (dds_write(w.odom, &w.scratch.odom) < 0) +
               (dds_write(w.joints, &w.scratch.joints) < 0) + (dds_write(w.drives, &w.scratch.drives) < 0) +
               (dds_write(w.bus, &w.scratch.bus) < 0) + (dds_write(w.clock, &w.scratch.clock) < 0);
  if (w.scratch.has_cmd_vel) failed += dds_write(w.cmd_vel, &w.scratch.cmd_vel) < 0;
  published_.fetch_add(1, std::memory_order_relaxed);
  if (failed) write_errors_.fetch_add(static_cast<std::uint64_t>(failed), std::memory_order_relaxed);
  return true;
}

void DdsPublisher::publish_end_and_flush() {
  if (!end_seen_) {
    const Stats st = stats();
    const std::string text = "published=" + std::to_string(st.published) + " dropped=" +
                             std::to_string(st.dropped) + " skipped=" + std::to_string(st.skipped);
    event(RunEvent{last_t_ns_.load(std::memory_order_relaxed), RunEventKind::end, "twin", text});
    publish_in_order();
  }
  const auto timeout = static_cast<dds_duration_t>(settings_.finish_timeout_s * 1e9);
  dds_wait_for_acks(writers_->events, timeout);  // a timeout only means a reader was slow
}

}  // namespace omnitwin::twin
