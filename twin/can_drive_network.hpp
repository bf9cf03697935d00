// twin layer — four servo drives on the simulated CAN wire, whatever protocol they speak on
// it (CANopen nodes: canopen_network; Technosoft TML drives: tml_network).
//
// One CanBus core is the wire, exactly as for bus `can` (bit timing, arbitration, error
// confinement): node 0 stands for everything on the far side of the transport (our master,
// python-can, a third-party master), nodes 1..4 are the drives of wheels 1..4. Each drive runs
// its period on its own drifting timer (Phase::device): the protocol's step, the shared drive
// core against its wheel, the amplifier's velocity set-point back to the physics. A frame a
// drive sends reaches the transport when it completes on the wire (batched for the master's
// next grant in lockstep); every completed frame goes into bus-can.pcap. The CAN faults
// (frame loss, delay, drift, power loss, bus-off) act here.
//
// A protocol derives from this class and supplies the drives: what a drive does with a frame
// and in its period, its power, its state for logs and metrics. Time: every entry point first
// runs the wire to the caller's instant. Nothing here reads the wall clock except
// drain_transport()'s timeout. Set-up allocates; per-event paths do not.
#pragma once

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bus_emulators/can/can_bus.hpp"
#include "bus_emulators/can/can_pcap.hpp"
#include "bus_emulators/can/transport.hpp"
#include "bus_emulators/drive/cia402_drive.hpp"
#include "twin/bus_network.hpp"
#include "twin/can_wire.hpp"
#include "twin/run_state.hpp"
#include "twin/scenario.hpp"
#include "twin/scheduler.hpp"

namespace omnitwin::twin {

struct CanDriveSetup {
  const char* name = "";             // "canopen", "tml": --bus and the metrics' bus.name
  double drive_period = 0.001;       // [s]
  std::array<double, 4> drift{};     // the drives' oscillators [-]
  int counts_per_rev = 131072;       // the drives' position units per wheel revolution
};

class CanDriveNetwork : public BusNetwork {
 public:
  ~CanDriveNetwork() override;

  const char* name() const override { return setup_.name; }
  const char* wire_name() const override { return "can"; }
  std::string master_iface() const override { return wire_.transport().spec(); }

  void open_pcap(const std::string& path) override { wire_.open_pcap(path); }
  void flush_pcap() override { wire_.flush_pcap(); }
  std::string close_pcap() override { return wire_.close_pcap(); }
  std::string pcap_error() const override { return wire_.pcap_error(); }
  void flush_transport() override { wire_.flush_transport(); }
  void advance(SimTime t) override {
    wire_.bus().advance(t);
    now_ = std::max(now_, t);
  }
  bool drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) override {
    return wire_.drain_transport(count, t, timeout);
  }
  int poll_transport(SimTime t) override { return wire_.poll_transport(t); }
  // Realtime: the transport's descriptor; a master's frames enter the wire the moment they
  // arrive (between the run's own events), not at the next master tick.
  int wake_fd() const override { return wire_.batch() ? -1 : wire_.transport().poll_fd(); }
  void on_wake(SimTime t) override;
  void observe_wheels() override {}
  void apply_fault(const FaultSpec& f, bool begin, SimTime t) override;
  std::uint64_t frames_to_transport() const override { return wire_.to_transport(); }
  std::uint64_t frames_from_transport() const override { return wire_.from_transport(); }
  SimTime master_start_ns() const override { return master_start_ns_; }
  BusSample bus_sample() const override;
  std::int64_t wire_busy_ns() const override { return wire_.bus().stats().busy_ns; }
  DriveStateCode drive_state(int axis0) const override;
  WheelRecord wheel_record(int axis0) const override;
  nlohmann::json slave_metrics() const override;

  const can::CanBus& bus() const { return wire_.bus(); }

 protected:
  // Builds the wire and opens the transport (throws can::TransportError). The derived class
  // makes its drives, then calls start() to arm their timers. Not real-time safe.
  CanDriveNetwork(const Scenario& s, Scheduler& sched, Hooks hooks, CanDriveSetup setup);
  void start();

  // The protocol's drives.
  virtual void deliver(int axis0, const can::Frame& f, SimTime t) = 0;  // a frame reached drive axis0
  virtual drive::Command drive_step(int axis0, SimTime t, const drive::Feedback& fb) = 0;
  virtual const drive::Cia402Drive& drive_core(int axis0) const = 0;
  virtual void drive_power(int axis0, bool on, SimTime t) = 0;
  virtual void drive_bus_off_recovered(int /*axis0*/, SimTime /*t*/) {}
  // The drive follows commands (its protocol's running state as well as operation enabled).
  virtual bool drive_running(int axis0) const = 0;
  // One word for the event log and metrics ("operational", "axis on" …).
  virtual std::string drive_protocol_state(int axis0) const = 0;
  // A frame from the master completed on the wire (start detection, bus stopped…).
  virtual void on_master_frame(const can::Frame& /*f*/, SimTime /*end*/) {}
  // The protocol's own per-drive figures, merged into slaves[k].
  virtual nlohmann::json drive_json(int axis0) const = 0;
  // bus.* common to every protocol on the wire; the derived bus_metrics() adds its own.
  nlohmann::json wire_metrics(SimTime now) const;

  // What a drive hands to the wire (with the delay fault applied). Real-time safe.
  bool submit(int axis0, const can::Frame& f, SimTime at) {
    return wire_.bus().submit(axis0 + 1, f, at + wire_.extra_delay(axis0)) == can::SubmitStatus::queued;
  }
  void note_master_start(SimTime end) {
    if (master_start_ns_ < 0) master_start_ns_ = end;
  }
  bool powered(int axis0) const { return powered_[static_cast<std::size_t>(axis0)]; }
  // The latest instant the network was run to [ns] (rates in the metrics).
  SimTime now() const { return now_; }
  const Scenario& scenario() const { return s_; }
  Hooks& hooks() { return hooks_; }

 private:
  void on_deliver(can::BusNode receiver, const can::Frame& f, const can::FrameTiming& timing);
  void on_tx_done(can::BusNode sender, const can::Frame& f, const can::FrameTiming& timing);
  void on_bus_event(const can::BusEvent& e);
  void on_drive_timer(int axis0, SimTime t);
  void watch(int axis0, SimTime t);

  const Scenario& s_;
  CanDriveSetup setup_;
  Scheduler& sched_;
  Hooks hooks_;
  CanWire wire_;  // node 0 the transport side, 1..4 the drives
  std::array<Scheduler::TimerId, 4> timers_{};
  std::array<bool, 4> powered_{true, true, true, true};
  std::array<std::string, 4> last_state_{};
  std::uint64_t power_cycles_ = 0;
  SimTime master_start_ns_ = -1;
  SimTime now_ = 0;
};

}  // namespace omnitwin::twin
