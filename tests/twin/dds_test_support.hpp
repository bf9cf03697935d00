// Test support for the DDS tests — a unique domain per test process, the shipped loopback
// Cyclone configuration, a C API reader with bounded waits, and sample StateSamples whose
// every field is distinct, so that a test can assert exact values after the wire.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <functional>
#include <string>
#include <thread>

#include "tests/support/dds_domain.hpp"
#include "twin/dds/dds_common.hpp"
#include "twin/run_state.hpp"

namespace omnitwin::twin::ddstest {

// A domain this test process alone uses; k picks a further one (several per test).
inline int test_domain(int k = 0) { return omnitwin::testing::owned_dds_domain(k); }

inline std::string loopback_config() {
  return std::string(OMNITWIN_SOURCE_DIR) + "/tests/data/dds/cyclonedds-loopback.xml";
}

// Sample i of a synthetic run at 1 kHz: t = i ms; every field differs from the others.
inline StateSample make_sample(std::uint64_t i) {
  StateSample s;
  const double k = static_cast<double>(i);
  s.t_ns = static_cast<std::int64_t>(i) * 1'000'000;
  s.seq = i;
  s.x = 0.125 + 0.01 * k, s.y = -0.25 + 0.02 * k, s.phi = 0.3 + 0.7 * k;
  s.vx = 0.2 + k, s.vy = -0.1 - k, s.wz = 0.05 * k;
  s.ref_x = 1 + k, s.ref_y = 2 + k, s.ref_phi = 3 + k;
  s.cmd_vx = 0.4 + k, s.cmd_vy = 0.6 - k, s.cmd_wz = -0.01 * k;
  for (std::size_t w = 0; w < 4; ++w) {
    const double d = static_cast<double>(w);
    s.wheel_angle[w] = 10 * d + k, s.wheel_speed[w] = 20 * d - k;
    s.wheel_cmd[w] = 30 * d + 0.5 * k, s.wheel_torque[w] = 0.001 * (d + 1) * (k + 1);
    DriveSample& dr = s.drives[w];
    dr.node = static_cast<std::uint8_t>(w + 1);
    dr.state = w == 2 ? DriveStateCode::fault : DriveStateCode::running;
    dr.command_rad_s = 1.5 * d + k, dr.setpoint_rad_s = -1.5 * d + k;
    dr.dac_code = static_cast<std::int32_t>(2048 + 100 * w + i);
    dr.encoder_count = static_cast<std::int64_t>(100000 * w) - static_cast<std::int64_t>(i);
  }
  s.bus = BusSample{true, 10 * i, 9 * i, i / 3, i / 5, 0.01 * k};
  s.active_faults = static_cast<std::uint32_t>(i % 3);
  return s;
}

template <class Pred>
bool wait_until(Pred pred, double timeout_s = 5.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!pred()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

// A C API reader of one topic on its own participant (joins the publisher's domain when the
// publisher is in this process).
class TestReader {
 public:
  TestReader(int domain, std::string_view topic, const std::string& interface = "lo")
      : participant_(DdsEndpoint{domain, interface, ""}) {
    const TopicInfo t = *find_topic(topic);
    const DdsQos qos = t.short_name == "events" ? event_qos(kEventHistory) : state_qos(1000);
    reader_ = dds_create_reader(participant_.get(), create_topic(participant_.get(), t), qos.get(), nullptr);
    if (reader_ < 0) throw DdsError("test reader");
  }
  // Waits until a writer has matched (bounded).
  bool wait_matched(double timeout_s = 5.0) const {
    return wait_until([&] {
      dds_subscription_matched_status_t st{};
      return dds_get_subscription_matched_status(reader_, &st) == 0 && st.current_count > 0;
    }, timeout_s);
  }
  // Takes samples, calling fn(const T&) for each valid one, until n were seen or the timeout;
  // returns how many were seen.
  template <class T>
  int take(int n, const std::function<void(const T&)>& fn, double timeout_s = 3.0) {
    int seen = 0;
    wait_until([&] {
      seen += take_available<T>(fn);
      return seen >= n;
    }, timeout_s);
    return seen;
  }
  dds_entity_t get() const { return reader_; }

 private:
  template <class T>
  int take_available(const std::function<void(const T&)>& fn) {
    void* samples[64] = {nullptr};
    dds_sample_info_t infos[64];
    const dds_return_t n = dds_take(reader_, samples, infos, 64, 64);
    int valid = 0;
    for (dds_return_t i = 0; i < n; ++i)
      if (infos[i].valid_data) fn(*static_cast<const T*>(samples[i])), ++valid;
    if (n > 0) dds_return_loan(reader_, samples, n);
    return valid;
  }
  DdsParticipant participant_;
  dds_entity_t reader_ = 0;
};

}  // namespace omnitwin::twin::ddstest
