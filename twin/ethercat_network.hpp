// twin layer — the twin's side of the EtherCAT segment (bus `ethercat`): four single-axis
// CiA 402 drive slaves, one per wheel, on one simulated line between a real transport and
// the physics.
//
// The slaves are built from the ESI file (models/ethercat/omnitwin_drive.xml by default):
// each is a DriveSlave (ESC core + object dictionary + CoE + a drive::Cia402Drive) with its
// own drifting oscillator. The segment is an EscChain. A frame the master sends enters the
// chain at the receiving instant + T_pre; it passes the slaves (each reads and writes its
// datagrams on the fly) and comes back, and the returned frame goes to the transport (in
// lockstep batched until the next grant, in realtime at once). Both directions go into the
// capture. Each drive runs its loops at the drive period on its own oscillator, reading its
// wheel shaft from the physics and setting the wheel amplifier's speed setpoint; its process
// data moves on SYNC0 when the master activated distributed clocks, else at the same cycle.
//
// Faults: frame loss (the frame never returns), delay of the returned frames, oscillator
// drift, a slave's power loss and return, a link break after slave k.
//
// Time: every entry point first runs the segment to the caller's instant (advance()).
// Nothing here reads the wall clock except drain_transport()'s timeout. Set-up allocates; the
// per-frame and per-cycle paths do not (apart from the event log on state changes).
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bus_emulators/ethercat/device/ec_esi.hpp"
#include "bus_emulators/ethercat/ec_chain.hpp"
#include "bus_emulators/ethercat/ec_frame.hpp"
#include "twin/bus_claim.hpp"
#include "twin/bus_network.hpp"
#include "twin/scenario.hpp"
#include "twin/scheduler.hpp"

namespace omnitwin::ethercat {
class DriveSlave;
class EcTransport;
class PcapWriter;
enum class Direction : std::uint8_t;
class VethPair;
}  // namespace omnitwin::ethercat

namespace omnitwin::twin {

// The ESI file a scenario's ethercat bus uses (its `esi`, else the shipped drive).
std::string ethercat_esi_path(const EthercatSpec& e);
// The ESI file of seed 001's multi-axis slave (bus.ethercat.extra_axes).
std::string ethercat_multiaxis_esi_path();
// How many multi-axis slaves `extra_axes` axis cards take (8 per slave, the rest on the last).
int ethercat_extra_slaves(const EthercatSpec& e);

class EthercatNetwork final : public BusNetwork {
 public:
  // Builds the slaves from the ESI file, the chain and the transport (a veth pair is made
  // here when the spec asks for one). Throws ethercat::TransportError for a transport that
  // cannot be opened and EsiError for a bad device description. Not real-time safe.
  EthercatNetwork(const Scenario& s, Scheduler& sched, Hooks hooks);
  ~EthercatNetwork() override;

  const char* name() const override { return "ethercat"; }
  std::string master_iface() const override { return master_iface_; }

  void open_pcap(const std::string& path) override;
  void flush_pcap() override;
  std::string close_pcap() override;
  std::string pcap_error() const override;
  void flush_transport() override;
  SimTime next_master_event() const override;
  void release_due(SimTime t) override { release_replies(t); }

  void advance(SimTime t) override;
  bool drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) override;
  int poll_transport(SimTime t) override;
  int wake_fd() const override;
  void on_wake(SimTime t) override;
  void observe_wheels() override {}  // the drives read their shafts at each cycle

  void apply_fault(const FaultSpec& f, bool begin, SimTime t) override;

  std::uint64_t frames_to_transport() const override { return to_transport_; }
  std::uint64_t frames_from_transport() const override { return from_transport_; }
  SimTime master_start_ns() const override { return op_since_ns_; }

  nlohmann::json bus_metrics(SimTime now) const override;
  nlohmann::json slave_metrics() const override;
  BusSample bus_sample() const override;
  std::int64_t wire_busy_ns() const override { return busy_ns_; }
  DriveStateCode drive_state(int axis0) const override;
  DriveDetail drive_detail(int axis0) const override;
  WheelRecord wheel_record(int axis0) const override;

  const ethercat::DriveSlave& slave(int axis0) const { return *slaves_[static_cast<std::size_t>(axis0)]; }

 private:
  struct Pending {               // a frame from the master, waiting for its instant
    SimTime at = 0;
    std::uint16_t size = 0;
    bool wire = false;                                     // hdr holds its Ethernet header (raw)
    std::array<std::uint8_t, ethercat::kEthHeaderSize> hdr{};
    std::array<std::uint8_t, ethercat::kMaxPdu> pdu{};
  };
  struct Reply {                 // a returned frame, waiting for its instant / the next grant
    SimTime at = 0;
    bool delayed = false;        // a delay fault held it: it waits for `at` even after the fault
    std::uint16_t size = 0;
    std::array<std::uint8_t, ethercat::kMaxPdu> pdu{};
  };

  void open_transport(const Scenario& s);
  void take_frame(const std::uint8_t* pdu, std::size_t size, SimTime t);
  void process_frame(Pending& p);
  void send_reply(const Pending& p, SimTime t);
  void capture(const Pending& p, std::span<const std::uint8_t> pdu, SimTime t, ethercat::Direction dir);
  // Hands over the replies due by t; with undelayed_too, also every reply no delay fault
  // held (lockstep: those go before the next grant whatever their instant).
  void release_replies(SimTime t, bool undelayed_too = false);
  void on_drive_timer(int axis0, SimTime t);
  void drive_cycle(int axis0, SimTime t);
  void drive_step(int axis0, SimTime t);
  void watch_states(SimTime t);
  bool lose_frame();
  std::uint64_t malformed() const;
  void add_extra_slaves(SimTime period);

  const Scenario& s_;
  const EthercatSpec& spec_;
  Scheduler& sched_;
  Hooks hooks_;
  ethercat::DeviceDescription device_;
  std::array<std::unique_ptr<ethercat::DriveSlave>, 4> slaves_;
  ethercat::DeviceDescription multi_device_;                   // seed 001's multi-axis slave
  std::vector<std::unique_ptr<ethercat::DriveSlave>> extra_;   // bus.ethercat.extra_axes, behind the wheels
  ethercat::EscChain chain_;
  std::vector<std::unique_ptr<BusClaim>> claims_;  // raw: interfaces the scenario names: one twin on each (bus_claim.hpp)
  std::shared_ptr<ethercat::VethPair> veth_;
  std::unique_ptr<ethercat::EcTransport> transport_;
  std::unique_ptr<ethercat::PcapWriter> pcap_;
  // The capture's records wait in its hold (EthernetCapture) until the tick has passed their
  // instant: a reply a delay fault holds is stamped later than frames the master sends
  // meanwhile, and was written before them (40 of 1000 records out of time order under a
  // 12 ms delay; found in review).
  static constexpr std::size_t kHeld = 2048;
  std::string transport_spec_, master_iface_;
  std::array<Scheduler::TimerId, 4> timers_{};
  std::array<bool, 4> powered_{true, true, true, true};
  std::array<double, 4> drift_{};
  std::array<std::uint8_t, 4> last_al_{};   // for state-change events
  std::array<std::uint8_t, 4> last_fsa_{};
  std::vector<Pending> pending_;           // ring of frames in flight towards the chain
  std::size_t pending_head_ = 0, pending_count_ = 0;
  SimTime line_free_ = 0;  // when the master's last frame has left the line's entry [ns]
  std::vector<Reply> replies_;             // returned frames not yet handed to the transport
  std::size_t replies_count_ = 0;
  bool batch_ = false;                     // lockstep: replies wait for flush_transport()
  std::array<std::uint8_t, 2048> rx_{};
  std::mt19937_64 rng_;
  double loss_rate_ = 0;
  int loss_burst_ = 1, loss_left_ = 0;
  double delay_ns_ = 0;                    // delay fault: the fixed part [ns]
  double delay_jitter_ns_ = 0;             // delay fault: per frame uniform in [0, jitter) [ns]
  std::mt19937_64 jitter_rng_;             // the per frame jitter draws (seeded from bus.seed)
  std::uint64_t to_transport_ = 0, from_transport_ = 0;
  std::uint64_t lost_frames_ = 0, not_returned_ = 0, send_failures_ = 0, overflow_ = 0;
  std::int64_t busy_ns_ = 0;
  SimTime op_since_ns_ = -1;
};

}  // namespace omnitwin::twin
