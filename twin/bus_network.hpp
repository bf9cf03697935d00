// twin layer — what the run needs from a simulated bus network, whatever the bus.
//
// A bus network is the twin's side of one fieldbus: the simulated wire (or segment), the
// emulated slaves that drive the four wheels, the real transport the master process talks
// over, the capture file and the bus faults. The run (run.cpp) owns the physics, the master
// process and the sim-clock handshake; it drives a network only through this interface, so
// the CAN network of the thesis nodes (can_network) and the EtherCAT segment of CiA 402
// drives (ethercat_network) run under the same lockstep and realtime loops, records and
// observers.
//
// Time: every entry point first runs the network to the caller's instant (advance()), so the
// network's own events (bus deliveries, device timers) interleave with the run's in exact
// time order. Set-up allocates; the per-tick paths do not (apart from event logging).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "controller/sim_clock.hpp"
#include "twin/run_state.hpp"
#include "twin/scenario.hpp"
#include "twin/scheduler.hpp"

namespace omnitwin::twin {

// On the wall clock (realtime runs, `omnitwin twin`) a sender the bus hears after its master
// has been silent this long is taken for the master: a master started again on UDP sends from
// a new port (it was counted foreign, and refused with bus.refuse_foreign). A second program
// sending while the master is active stays foreign. [ns]
inline constexpr std::int64_t kMasterHandoverNs = 500'000'000;

// One wheel's drive for trajectory.csv (docs/run-directory.md gives each bus's meaning). The
// motor setpoint is not here: the run records what the network last asked of the physics.
struct WheelRecord {
  double command_rad_s = 0;     // the speed command the drive holds [rad/s]
  double count = 0;             // encoder / position actual [counts]
  double command_counts = 0;    // the command in the drive's own units
  double measured_counts = 0;   // the measured speed in the drive's own units
  double output = 0;            // CAN: DA code; EtherCAT: torque demand [0.1 % rated]
  std::uint16_t node = 0;       // bus address (CAN node id, EtherCAT station address)
};

// What a network may ask of the run: the wheels' shafts and amplifiers, statistics, the log.
struct NetworkHooks {
  // Shaft angle of wheel 0..3 [rad] at the scheduler's current time: between two physics
  // steps it is interpolated with the wheel's speed, so that a device sampling at any instant
  // (a drifting slave timer, a SYNC0 offset) reads its counter then, not at the last step.
  std::function<double(int wheel)> wheel_angle;
  // The same at an instant t [ns] the scheduler has already passed (a frame's end, delivered
  // when the bus is next advanced); may be empty, then wheel_angle is used.
  std::function<double(int wheel, SimTime t)> wheel_angle_at;
  std::function<double(int wheel)> wheel_speed;              // shaft speed [rad/s]
  std::function<void(int wheel, double rad_s)> set_setpoint; // amplifier speed setpoint [rad/s]
  // The analog amplifier's input voltage [V], from a node that ends at a DA (the thesis
  // node): physics makes the speed setpoint of it (PlatformSim::set_wheel_amplifier_input).
  std::function<void(int wheel, double volts)> set_amplifier_input;
  // Velocity error (command − measured) of one node's control step [encoder pulses per step];
  // used by networks whose samples_axes() is true.
  std::function<void(int wheel, double err)> axis_sample;
  // The same error as the master sees it each control period [encoder pulses per period]:
  // the command it sent for the period minus the latest feedback it holds at the period's end
  // (stored per axis, kept when none came), read off the wire; may be empty. Bus `can` only
  // (the thesis's master logged its axes so).
  std::function<void(int wheel, double err)> axis_sample_at_master;
  std::function<void(SimTime t, std::string_view kind, const std::string& text)> log;
};

class BusNetwork {
 public:
  using Hooks = NetworkHooks;

  virtual ~BusNetwork() = default;

  // "can", "ethercat": the master's --bus and the capture's name (bus-<name>.pcap).
  virtual const char* name() const = 0;
  // The wire the capture records (bus-<wire>.pcap): the bus's name, except for protocols that
  // share a wire (canopen runs on the CAN wire: bus-can.pcap).
  virtual const char* wire_name() const { return name(); }
  // The transport spec the master process is given (--iface).
  virtual std::string master_iface() const = 0;

  // Starts the capture (set-up; throws std::runtime_error if the file cannot be created).
  virtual void open_pcap(const std::string& path) = 0;
  // Pushes buffered capture records to the kernel (once per tick).
  virtual void flush_pcap() = 0;
  // Realtime supervision: whether a running master must be sending now. A master that has
  // stopped its bus on purpose (CAN: NMT stop to all nodes) may fall silent. Real-time safe.
  virtual bool master_must_talk() const { return true; }
  // Ends the capture: complete, it gets its final name. Returns "" or why it is incomplete
  // (a write failed: it is then not under its final name). Idempotent; not real-time safe.
  virtual std::string close_pcap() = 0;
  // "" while every capture write has succeeded, else why one failed. Real-time safe.
  virtual std::string pcap_error() const = 0;
  // Hands frames batched for the master to the transport (lockstep: before each grant).
  virtual void flush_transport() = 0;
  // Lockstep on a polling bus (M-III): the master reports each frame it sends inside the tick
  // (Sent) and waits for the answer (Horizon) — docs/protocols/sim-clock.md, "Inside a tick".
  virtual bool answers_inside_tick() const { return false; }
  // Whether the network gives the axes' velocity errors itself (hooks.axis_sample, once per
  // its nodes' own control step: the thesis node); otherwise the run takes them from
  // wheel_record() once per control sample while the drive runs.
  virtual bool samples_axes() const { return false; }
  // The frames counted in `s` enter the bus at s.t_ns; answers what reached the master, and
  // when. If the master's frames did not all arrive within `timeout`, arrival_ns is -2 (the
  // run then fails the tick). Real-time safe apart from the wait.
  virtual simclock::Horizon on_sent(const simclock::Sent& s, std::chrono::milliseconds /*timeout*/) {
    simclock::Horizon h;
    h.tick = s.tick;
    return h;
  }

  // A master on the virtual clock (twin/master_vtime.hpp): the earliest instant at which the
  // network does something of its own between the run's events — a frame entering it,
  // completing, or due back at the master [ns]; INT64_MAX when nothing is pending. Real-time safe.
  virtual SimTime next_master_event() const { return std::numeric_limits<SimTime>::max(); }
  // ... and puts on the transport the frames for the master that are due by t. Real-time safe.
  virtual void release_due(SimTime /*t*/) {}

  // Runs the network to t [ns]. Real-time safe.
  virtual void advance(SimTime t) = 0;
  // Lockstep: receives frames until `count` have arrived since the start, each entering the
  // network at t + the master's processing time. False when they did not all come in time.
  virtual bool drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) = 0;
  // Realtime: takes whatever the transport holds now. Returns the number taken.
  virtual int poll_transport(SimTime t) = 0;
  // Realtime: a descriptor that becomes readable when the master's frames arrive (-1: none),
  // and what to do then, at sim time t: take them and answer at once, between the run's own
  // events. Real-time safe.
  virtual int wake_fd() const { return -1; }
  virtual void on_wake(SimTime /*t*/) {}
  // After every physics step: the drives' sensors follow the shafts. Real-time safe.
  virtual void observe_wheels() = 0;

  // A scenario bus fault begins or ends at t. Not real-time safe (logs).
  virtual void apply_fault(const FaultSpec& f, bool begin, SimTime t) = 0;

  virtual std::uint64_t frames_to_transport() const = 0;
  virtual std::uint64_t frames_from_transport() const = 0;
  // Realtime runs: when the master's start completed on the bus [ns], or -1 (the reference
  // path is timed from it when the master does not report its own).
  virtual SimTime master_start_ns() const = 0;

  // bus.* and slaves of metrics.json. Not real-time safe.
  virtual nlohmann::json bus_metrics(SimTime now) const = 0;
  virtual nlohmann::json slave_metrics() const = 0;
  // Cumulative counters for bus.csv and observers; load is the caller's (see wire_busy_ns).
  // Real-time safe.
  virtual BusSample bus_sample() const = 0;
  // Time the wire or segment has been busy since the start [ns] (load = Δbusy / Δt).
  virtual std::int64_t wire_busy_ns() const = 0;
  virtual DriveStateCode drive_state(int axis0) const = 0;
  // drive_state in the protocol's own words (DriveSample::comm_state, device_state): static
  // strings, "" where a layer does not exist. Real-time safe.
  struct DriveDetail {
    const char* comm = "";
    const char* device = "";
  };
  virtual DriveDetail drive_detail(int /*axis0*/) const { return {}; }
  virtual WheelRecord wheel_record(int axis0) const = 0;
};

// The capture's health and end, for either bus's pcap writer (ok(), error(), path(),
// is_open(), close()): what pcap_error() and close_pcap() return.
template <class Writer>
std::string capture_error(const Writer* w) {
  if (!w || w->ok()) return "";
  return w->path() + " left incomplete: " + w->error();
}
template <class Writer>
std::string close_capture(Writer* w) {
  if (!w || !w->is_open()) return "";
  w->close();  // renamed to its final name only if every record reached it
  return capture_error(w);
}

}  // namespace omnitwin::twin
