// twin layer — the twin's side of the thesis CAN network (bus `can`): the simulated wire
// between a real transport and the four emulated 8051 wheel nodes.
//
// One CanBus core is the wire. Node 0 stands for everything on the far side of the transport
// (the master process, a PC node, a python-can script): frames received from the transport are
// queued on it, stamped at the receiving tick + T_pre. Nodes 1..4 are the OmniSlaves of axes
// 1..4, each on its own drifting timer on the scheduler (Phase::device). A frame a slave sends
// is forwarded to the transport when it completes on the simulated wire (with its end-of-frame
// time as timestamp), so the master hears it exactly when a real controller would. Every frame
// that completes on the wire goes into the pcap. The scenario's CAN faults (frame loss, delay,
// drift, power loss, bus-off) are applied here.
//
// Time: every entry point first runs the bus to the caller's instant (advance()), so bus
// deliveries and timer interrupts interleave in exact time order. Nothing here reads the wall
// clock except drain_transport()'s timeout. Set-up allocates; the per-event paths do not
// (apart from the event log, which only writes on state changes).
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "bus_emulators/can/can_bus.hpp"
#include "bus_emulators/can/can_pcap.hpp"
#include "bus_emulators/can/transport.hpp"
#include "bus_emulators/omni/omni_slave.hpp"
#include "twin/bus_network.hpp"
#include "twin/can_wire.hpp"
#include "twin/run_state.hpp"
#include "twin/scenario.hpp"
#include "twin/scheduler.hpp"

namespace omnitwin::twin {

class OmniCanNetwork final : public BusNetwork {
 public:
  // Hooks: wheel_angle feeds the counters, set_setpoint the drivers; axis_sample gets
  // command − measured [pulses] each slave sample; axis_sample_at_master the same per master
  // period as the master sees it: at each speed command on the wire, the command before it
  // minus the latest feedback that reached the master (the one before when none came in the
  // period), for each axis (wheel_speed is not used).

  // Builds the bus and the slaves and opens the transport (throws can::TransportError for a
  // bad spec or a socket that cannot be opened). Timers are added to `sched` (all off: the
  // slaves start stopped). Not real-time safe.
  OmniCanNetwork(const Scenario& s, Scheduler& sched, Hooks hooks);
  ~OmniCanNetwork() override;

  const char* name() const override { return "can"; }
  bool samples_axes() const override { return true; }  // each slave step, by hooks.axis_sample
  std::string master_iface() const override { return wire_.transport().spec(); }  // as opened (a port 0 named)

  // Starts the capture file (set-up; throws std::runtime_error if it cannot be created).
  // Records are buffered; flush_pcap() pushes them to the kernel (the run does so each master
  // tick), and close_pcap() (the run's end) closes it, so SIGINT/SIGTERM leave it complete.
  void open_pcap(const std::string& path) override { wire_.open_pcap(path); }
  void flush_pcap() override { wire_.flush_pcap(); }
  std::string close_pcap() override { return wire_.close_pcap(); }
  std::string pcap_error() const override { return wire_.pcap_error(); }
  // Not after an NMT stop to all nodes seen on the wire (from anyone), until an NMT start.
  bool master_must_talk() const override { return !bus_stopped_; }
  // Hands the batched frames to the transport, all at once. In lockstep the slaves' frames
  // are batched (the master reads them only after its grant), so this must run before
  // frames_to_transport() goes into a grant (the run calls it just before); nothing is
  // batched in realtime.
  void flush_transport() override { wire_.flush_transport(); }
  SimTime next_master_event() const override { return wire_.bus().next_event_ns(); }

  // Runs the simulated bus to t [ns]. Real-time safe (callbacks forward frames).
  void advance(SimTime t) override;

  // Lockstep: receives frames from the transport until `count` frames have arrived in all
  // since the start, queueing each on node 0 at t + T_pre (+ any delay fault). Returns false
  // when they did not all arrive within `timeout`.
  bool drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) override {
    return wire_.drain_transport(count, t, timeout);
  }
  // Realtime: queues whatever the transport holds now at t + T_pre. Returns the number taken.
  int poll_transport(SimTime t) override { return wire_.poll_transport(t); }

  // Every physics step: the counters follow the shafts. Real-time safe.
  void observe_wheels() override;

  // A scenario CAN fault begins or ends at t. Not real-time safe (logs).
  void apply_fault(const FaultSpec& f, bool begin, SimTime t) override;

  std::uint64_t frames_to_transport() const override { return wire_.to_transport(); }
  std::uint64_t frames_from_transport() const override { return wire_.from_transport(); }
  const can::CanBus& bus() const { return wire_.bus(); }
  const omni::OmniSlave& slave(int axis0) const { return *slaves_[static_cast<std::size_t>(axis0)]; }
  const can::Transport& transport() const { return wire_.transport(); }
  // Time the master's NMT start-all completed on the wire [ns], or -1.
  SimTime master_start_ns() const override { return master_start_ns_; }

  // bus.* of metrics.json (frames_tx, frames_rx, dropouts, dropout_rate, errors, …) and the
  // per-slave figures. Not real-time safe.
  nlohmann::json bus_metrics(SimTime now) const override;
  nlohmann::json slave_metrics() const override;
  // The cumulative counters of bus_metrics (load left 0: the caller knows its interval) and
  // a slave's state for observers. Real-time safe (no allocation).
  BusSample bus_sample() const override;
  std::int64_t wire_busy_ns() const override { return wire_.bus().stats().busy_ns; }
  DriveStateCode drive_state(int axis0) const override;
  DriveDetail drive_detail(int axis0) const override;
  // The slave's held command, counter, PI and DA (output = DA code). Real-time safe.
  WheelRecord wheel_record(int axis0) const override;

 private:
  static int bus_node(int axis0) { return axis0 + 1; }

  void on_deliver(can::BusNode receiver, const can::Frame& f, const can::FrameTiming& timing);
  void on_tx_done(can::BusNode sender, const can::Frame& f, const can::FrameTiming& timing);
  void on_bus_event(const can::BusEvent& e);
  void on_slave_timer(int axis0, SimTime t);
  void on_command_at_master(const omni::SpeedCommand& c);
  void on_feedback_at_master(const omni::SpeedFeedback& f);
  void after_slave_input(int axis0, std::uint64_t steps_before, const omni::TimerAction& a);
  void make_slave(int axis0);
  nlohmann::json slave_json(int axis0) const;

  const Scenario& s_;
  Scheduler& sched_;
  Hooks hooks_;
  CanWire wire_;  // node 0 the transport side, 1..4 the slaves
  std::array<std::unique_ptr<omni::OmniSlave>, 4> slaves_;
  std::array<Scheduler::TimerId, 4> timers_{};
  std::array<bool, 4> powered_{true, true, true, true};
  std::array<double, 4> start_phase_{};  // each slave's timer phase at NMT start [fraction of a period]
  bool bus_stopped_ = false;  // the last NMT command to all nodes was stop
  // The axes as the master sees them (hooks.axis_sample_at_master): the speed command it sent
  // for the current control period and each axis's latest feedback it has stored.
  struct AtMaster {
    bool open = false;                      // a command was sent since the last NMT
    std::array<int, 4> command{};           // [counts/period]
    std::array<std::int32_t, 4> feedback{}; // the latest feedback value received [counts]
  };
  AtMaster at_master_;
  SimTime master_start_ns_ = -1;
};

}  // namespace omnitwin::twin
