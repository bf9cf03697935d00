// twin layer — the twin's side of a CANopen network (bus `canopen`): the simulated CAN wire
// between a real transport and four emulated CiA 402 drives, each a CANopen node
// (bus_emulators/canopen/co_drive) built from the drives' EDS and driving one MuJoCo wheel.
//
// One CanBus core is the wire, exactly as for bus `can` (bit timing, arbitration, error
// confinement): node 0 stands for everything on the far side of the transport (our master,
// python-can, a third-party CANopen master), nodes 1..4 are the drives with node IDs 1..4.
// Each drive runs its period on its own drifting timer (Phase::device): node timers, drive
// step against its wheel, the amplifier's velocity set-point back to the physics. A frame a
// drive sends reaches the transport when it completes on the wire; every completed frame goes
// into bus-can.pcap. The CAN faults (frame loss, delay, drift, power loss, bus-off) act here.
//
// Time: every entry point first runs the wire to the caller's instant. Nothing here reads the
// wall clock except drain_transport()'s timeout. Set-up allocates; per-event paths do not.
#pragma once

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
#include "bus_emulators/canopen/co_drive.hpp"
#include "bus_emulators/canopen/co_eds.hpp"
#include "twin/bus_network.hpp"
#include "twin/run_state.hpp"
#include "twin/scenario.hpp"
#include "twin/scheduler.hpp"

namespace omnitwin::twin {

// The EDS a scenario's canopen bus uses (absolute path).
std::string canopen_eds_path(const CanopenSpec& c);
// The wire's share the four-drive configuration needs: per SYNC the SYNC, four RPDO1 and four
// TPDO1 (6 bytes), TPDO2 at most every 10 SYNCs, five heartbeats per heartbeat period; with
// the stuffing of all-zero data (nominal) and the worst case. nominal > 1: it does not fit.
struct LoadBudget {
  double nominal = 0, worst = 0;
};
LoadBudget canopen_load_budget(const Scenario& s);

class CanopenNetwork final : public BusNetwork {
 public:
  // Loads the EDS, builds the wire and the drives, opens the transport (throws
  // can::TransportError, canopen::EdsError, std::runtime_error). Not real-time safe.
  CanopenNetwork(const Scenario& s, Scheduler& sched, Hooks hooks);
  ~CanopenNetwork() override;

  const char* name() const override { return "canopen"; }
  const char* wire_name() const override { return "can"; }
  std::string master_iface() const override { return transport_->spec(); }

  void open_pcap(const std::string& path) override;
  void flush_pcap() override {
    if (pcap_) pcap_->flush();
  }
  std::string close_pcap() override;
  std::string pcap_error() const override;
  // Not after an NMT stop to all nodes seen on the wire, until an NMT start.
  bool master_must_talk() const override { return !bus_stopped_; }
  void flush_transport() override;

  void advance(SimTime t) override { bus_.advance(t); }
  bool drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) override;
  int poll_transport(SimTime t) override;
  void observe_wheels() override {}

  void apply_fault(const FaultSpec& f, bool begin, SimTime t) override;

  std::uint64_t frames_to_transport() const override { return to_transport_; }
  std::uint64_t frames_from_transport() const override { return from_transport_; }
  // When the master's NMT start (to all) completed on the wire [ns], or -1.
  SimTime master_start_ns() const override { return master_start_ns_; }

  nlohmann::json bus_metrics(SimTime now) const override;
  nlohmann::json slave_metrics() const override;
  BusSample bus_sample() const override;
  std::int64_t wire_busy_ns() const override { return bus_.stats().busy_ns; }
  DriveStateCode drive_state(int axis0) const override;
  WheelRecord wheel_record(int axis0) const override;

  const canopen::DriveNode& drive(int axis0) const { return *drives_[static_cast<std::size_t>(axis0)]; }
  const can::CanBus& bus() const { return bus_; }

 private:
  struct LossState {
    double rate = 0;
    int burst = 1;
    int left = 0;
    bool active = false;
  };
  struct DelayState {
    double extra_ns = 0, jitter_ns = 0;
    bool active = false;
  };
  static constexpr int kFar = 0;
  static int bus_node(int axis0) { return axis0 + 1; }

  void on_deliver(can::BusNode receiver, const can::Frame& f, const can::FrameTiming& timing);
  void on_tx_done(can::BusNode sender, const can::Frame& f, const can::FrameTiming& timing);
  void on_bus_event(const can::BusEvent& e);
  void on_drive_timer(int axis0, SimTime t);
  void submit_from_far(const can::Frame& f, SimTime t);
  bool lose(int target);
  std::int64_t extra_delay(int node);
  void watch(int axis0, SimTime t);
  nlohmann::json slave_json(int axis0) const;

  const Scenario& s_;
  const CanopenSpec& spec_;
  Scheduler& sched_;
  Hooks hooks_;
  canopen::EdsDevice eds_;
  can::CanBus bus_;
  std::unique_ptr<can::Transport> transport_;
  std::unique_ptr<can::PcapWriter> pcap_;
  std::array<std::unique_ptr<canopen::DriveNode>, 4> drives_;
  std::array<Scheduler::TimerId, 4> timers_{};
  std::array<bool, 4> powered_{true, true, true, true};
  std::array<canopen::NmtState, 4> last_nmt_{};
  std::array<drive::State, 4> last_fsa_{};
  std::array<LossState, 6> loss_{};
  std::array<DelayState, 5> delay_{};
  std::mt19937_64 rng_;
  std::uint64_t to_transport_ = 0, from_transport_ = 0;
  bool batch_ = false;
  std::vector<can::TimedFrame> pending_;
  bool bus_stopped_ = false;
  std::uint64_t lost_frames_ = 0, send_failures_ = 0, refused_from_far_ = 0, bus_off_events_ = 0;
  std::uint64_t power_cycles_ = 0;
  LoadBudget budget_;
  SimTime master_start_ns_ = -1;
};

}  // namespace omnitwin::twin
