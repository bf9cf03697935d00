// twin layer — the twin's side of a MECHATROLINK-III line (bus `m3`): four standard servo
// slaves (profile 10h), one per wheel, on one simulated line (cascade or star) between a real
// transport and the physics, and optionally more servo stations (bus.stations, up to 62)
// whose motors turn unloaded shafts of their own.
//
// The line and the stations are the segment (bus_emulators/mechatrolink3/transport/
// m3_segment): each slave is a SlaveLink (phases, watchdog, alarms) over a ServoProfile on the
// shared drive core. The C1 master polls, so in lockstep every frame it sends is met inside
// the tick (exchange-level lockstep, docs/protocols/sim-clock.md "Inside a tick"): on_sent()
// lets the frame enter the line at its simulated send time and answers with the Horizon of
// the response the line delivers. Between the master's exchanges the scheduler runs each
// servo's drive period against its wheel. In realtime the master's frames are taken when the
// pacer wakes on the transport (wake_fd), enter the line at the instant the kernel received
// them (m3_segment poll), and are answered at once. Both directions go into bus-m3.pcap.
//
// Faults: frame loss and corruption (bad FCS) to and from one slave or all, a second C1 master
// (its commands at each tick's start, before ours, with a WDT count that never advances; our
// master hears them and the slaves' answers to them at the next grant), a late response
// (extra delay of a slave's frames), a slave's power loss and return (in a cascade the
// stations behind a powered-off one drop off too: nothing passes a dead station), a cable
// break. Power and cable state make up each station's reachability.
//
// Time: every entry point first runs the slaves' link timers to the caller's instant; the
// exchange inside a tick runs the line (not the physics) at the master's send times, which
// lie at most one transmission cycle ahead of the scheduler. Set-up allocates; the per-frame
// and per-period paths do not (apart from the event log on state changes).
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <random>
#include <string>

#include <nlohmann/json.hpp>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_segment.hpp"
#include "twin/bus_claim.hpp"
#include "twin/bus_network.hpp"

namespace omnitwin::ethercat {
class VethPair;
}

namespace omnitwin::twin {

class M3Network final : public BusNetwork {
 public:
  // Builds the line, the four servo slaves and the transport (a veth pair is made here when
  // the spec asks for one). Throws m3::TransportError for a transport that cannot be opened.
  M3Network(const Scenario& s, Scheduler& sched, Hooks hooks);
  ~M3Network() override;

  const char* name() const override { return "m3"; }
  std::string master_iface() const override { return master_iface_; }

  void open_pcap(const std::string& path) override { segment_->open_pcap(path); }
  void flush_pcap() override;
  std::string close_pcap() override {
    segment_->flush_capture();
    return close_capture(segment_->pcap());
  }
  std::string pcap_error() const override;
  // Answers go out as the line delivers them; here, before each grant, a second C1 master
  // (fault) sends its commands.
  void flush_transport() override;

  bool answers_inside_tick() const override { return clock_ == ClockMode::lockstep; }
  simclock::Horizon on_sent(const simclock::Sent& s, std::chrono::milliseconds timeout) override;

  void advance(SimTime t) override;
  bool drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) override;
  int poll_transport(SimTime t) override;
  int wake_fd() const override;
  void on_wake(SimTime t) override;
  void observe_wheels() override {}  // the servos read their shafts every drive period

  void apply_fault(const FaultSpec& f, bool begin, SimTime t) override;

  std::uint64_t frames_to_transport() const override { return segment_->to_master(); }
  std::uint64_t frames_from_transport() const override { return segment_->from_master(); }
  SimTime master_start_ns() const override { return running_since_ns_; }

  nlohmann::json bus_metrics(SimTime now) const override;
  nlohmann::json slave_metrics() const override;
  BusSample bus_sample() const override;
  std::int64_t wire_busy_ns() const override { return segment_->busy_ns(); }
  DriveStateCode drive_state(int axis0) const override;
  DriveDetail drive_detail(int axis0) const override;
  WheelRecord wheel_record(int axis0) const override;

  const m3::M3Segment& segment() const { return *segment_; }

 private:
  void open_transport(const Scenario& s);
  m3::Fate fate(bool from_master, int slave, std::span<const std::uint8_t> frame);
  void on_drive_timer(int axis0, SimTime t);
  void set_power(int axis0, bool on, SimTime t);
  void update_reachability();
  void watch_states(SimTime t);

  const M3Spec& spec_;
  ClockMode clock_;
  Scheduler& sched_;
  Hooks hooks_;
  std::vector<std::unique_ptr<BusClaim>> claims_;  // raw: interfaces the scenario names: one twin on each (bus_claim.hpp)
  std::shared_ptr<ethercat::VethPair> veth_;  // the pair made for the run (bus.transport veth)
  std::unique_ptr<m3::M3Transport> transport_;
  std::unique_ptr<m3::M3Segment> segment_;
  std::string transport_spec_, master_iface_;
  SimTime linked_to_ = 0;                  // the slaves' link timers have run to here
  struct StationState {                    // what the event log reports changes of
    std::uint8_t phase = 0, comm = 0, cmd = 0, servo = 0;
    bool operator==(const StationState&) const = default;
  };
  std::vector<bool> powered_;              // per station
  int cut_after_ = -1;                     // link_break: stations from this index on are cut off
  std::vector<StationState> last_;
  std::vector<drive::AxisModel> shafts_;   // the unloaded shafts of the stations beyond the wheels
  // Frame faults: per target station, the loss and corruption probabilities.
  std::vector<double> loss_, corrupt_;
  double master_loss_ = 0;                 // frames from the master, to every slave
  double master_corrupt_ = 0;              // the same for corruption (node master)
  bool second_master_ = false;             // fault: another C1 master on the line
  std::uint8_t second_sequence_ = 0;
  std::mt19937_64 rng_;
  // Delay fault, per station: the fixed part and the per frame jitter [ns], and the jitter's
  // own generator (seeded from bus.seed) so the loss and corruption draws stay as they were.
  std::vector<SimTime> delay_ns_, jitter_ns_;
  std::mt19937_64 jitter_rng_;
  std::uint64_t lost_ = 0, corrupted_ = 0;
  SimTime running_since_ns_ = -1;
};

}  // namespace omnitwin::twin
