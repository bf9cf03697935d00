// controller/canopen — our CANopen master (CiA 301/402) as a protocol core: NMT master,
// an SDO client with one channel per drive, PDO configuration of each drive following CiA 301's procedure
// with the object sizes of the drives' EDS, the SYNC producer, its own heartbeat, the
// heartbeat consumer for every drive, EMCY handling and the CiA 402 power-up of the four
// wheel drives; the platform application (co_program) sets wheel velocities and reads
// positions through it.
//
// Frames and time [ns] in (on_frame, on_tick), frames out through SendFn; no sockets, no
// clock, so that the program can run it on the wall clock or in lockstep with the twin.
// One tick = one SYNC period: SYNC first, then the RPDOs (CiA 301: a synchronous RPDO takes
// effect at the next SYNC), then SDO requests and NMT commands. With a drive as SYNC producer
// (config sync_producer) the master sends no SYNC and ticks at its own period.
// Configuration is fixed at construction; on_frame/on_tick do not allocate.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/canopen/co_nmt.hpp"
#include "bus_emulators/canopen/co_sync.hpp"
#include "bus_emulators/canopen/co_types.hpp"
#include "controller/canopen/co_config.hpp"
#include "controller/canopen/co_sdo_client.hpp"
#include "controller/sim_clock.hpp"

namespace omnitwin::canopen {
struct EdsDevice;
}

namespace omnitwin::controller::canopen {

using omnitwin::canopen::NmtState;
using omnitwin::canopen::SendFn;
using omnitwin::canopen::SimTime;

// One SDO transfer of a node's start-up script.
struct SdoStep {
  bool upload = false;
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::uint8_t bytes = 0;       // download size
  std::uint32_t value = 0;      // download value (little-endian on the wire)
  std::string what;             // for logs
};

// The start-up script of one drive: checks (device type 0x1000 is CiA 402, identity 0x1018
// matches the EDS), heartbeat 0x1017 and consumer 0x1016, SYNC counter 0x1019, RPDO1 =
// controlword + target velocity (synchronous), TPDO1 = statusword + position actual
// (synchronous), TPDO2 = statusword + velocity actual (event-driven, inhibit time 10 SYNC
// periods, event timer 100), and for the SYNC-producing drive (sync_producer) 0x1006 and 0x1005
// with the gen bit, the other PDOs off, modes of operation 0x6060. Mapping entries carry the bit
// sizes of the EDS; throws std::runtime_error when the EDS lacks an object or does not allow
// it in that PDO (set-up).
std::vector<SdoStep> startup_script(const CoProgramConfig& c, const omnitwin::canopen::EdsDevice& eds, std::uint8_t node);

// Master phases (MasterReport: resetting..enabling = detecting). Legal in each:
//  resetting   — NMT reset communication sent to all; waits for every drive's boot-up.
//                Legal: all_booted, startup_timeout.
//  configuring — each drive's script runs on its own SDO client. Legal: all_configured,
//                config_failed (an SDO aborted, device type not CiA 402, vendor or product
//                not the EDS's: → failed with that node), startup_timeout.
//  Heartbeats are supervised from starting on (the drives produce them once configured).
//  starting    — NMT start all sent, SYNC and heartbeat running; waits for every drive's
//                heartbeat to say operational. Legal: all_operational, startup_timeout.
//  enabling    — controlwords take each drive to operation enabled. Legal: all_enabled,
//                startup_timeout, node_lost, drive_fault.
//  running     — velocities every SYNC. Legal: node_lost, drive_fault, finish, shutdown.
//  stopped     — a drive was lost or faulted: the others quick-stop at zero velocity; a lost
//                drive that boots again is configured and started again (recovered). Legal:
//                shutdown.
//  finished    — the application ended: drives shut down (controlword 0x06). Legal: shutdown.
//  failed      — start-up did not complete (reason startup_timeout or config_failed, node,
//                in the report; no heartbeat supervision). Legal: shutdown.
// shutdown (the program ends) is not a phase but an end sequence over the following ticks:
// an enabled drive (operation enabled, quick stop active) is quick-stopped, then its voltage
// disabled; NMT stop to all once every drive whose TPDOs run has sent a statusword since the end
// began and none is enabled, or after kEndNs; the master then sends nothing more (shut_down()).
// An NMT stop to an enabled drive would fault it (0x6007). Until the end is over the master
// reports the state it ended from (a cut-short end leaves the drives running).
enum class CoPhase : std::uint8_t { resetting, configuring, starting, enabling, running, stopped, finished, failed };
const char* to_string(CoPhase p);

struct CoMasterStats {
  std::uint64_t ticks = 0, frames_rx = 0, frames_tx = 0, tx_refused = 0, syncs = 0, sdo_done = 0,
                sdo_aborts = 0, emcy = 0, heartbeat_timeouts = 0, boot_ups = 0, recoveries = 0,
                tpdo_rx = 0, nmt_sent = 0;
  std::uint32_t last_abort = 0;  // the last SDO abort code received or sent
};

// Per drive, for logs and metrics.
struct CoNodeView {
  std::uint8_t id = 0;
  NmtState nmt = NmtState::initialising;
  std::uint16_t statusword = 0;
  std::int32_t position = 0, velocity = 0;
  std::uint16_t last_emcy = 0;
  std::uint64_t emcy = 0, tpdos = 0;
  bool configured = false, lost = false;
};

class CoMaster {
 public:
  using EventFn = std::function<void(SimTime t, const std::string& text, bool warning)>;

  // Builds the drives' scripts from the EDS (throws std::runtime_error: set-up).
  CoMaster(const CoProgramConfig& config, const omnitwin::canopen::EdsDevice& eds, SendFn send);
  CoMaster(const CoMaster&) = delete;
  CoMaster& operator=(const CoMaster&) = delete;

  void set_event_callback(EventFn fn) { event_ = std::move(fn); }

  // A frame from the bus at t. Real-time safe.
  void on_frame(const can::Frame& f, SimTime t);
  // One SYNC period at t. Real-time safe (events excepted).
  void on_tick(SimTime t);
  // The application: wheel i's velocity set-point [counts/s] (sent from the next tick on).
  void set_velocity(int wheel, std::int32_t counts_per_s) { velocity_[static_cast<std::size_t>(wheel)] = counts_per_s; }
  // Wheel i's last position actual [counts] from TPDO1.
  std::int32_t position(int wheel) const { return nodes_[static_cast<std::size_t>(wheel)].view.position; }
  // The application ended its path: drives to ready to switch on (controlword 0x06).
  void finish(SimTime t);
  // The program ends: the end sequence begins at t (above); the ticks that follow run it. Real-time safe.
  void shutdown(SimTime t);
  // The end sequence is over: NMT stop sent (the program may exit).
  bool shut_down() const { return end_done_; }
  static constexpr SimTime kEndNs = 100'000'000;  // the longest the drives get to stop [ns]
  // The transport refused n frames.
  void note_send_failures(std::uint64_t n) { stats_.tx_refused += n; }

  CoPhase phase() const { return phase_; }
  simclock::MasterState report_state() const;
  simclock::StopReason reason() const { return reason_; }
  std::uint8_t reason_node() const { return reason_node_; }
  SimTime running_since() const { return running_since_; }  // -1 before
  const CoMasterStats& stats() const { return stats_; }
  CoNodeView node(int wheel) const { return nodes_[static_cast<std::size_t>(wheel)].view; }
  const CoProgramConfig& config() const { return cfg_; }

 private:
  struct Node {
    CoNodeView view;
    std::uint64_t tpdos_at_end = 0;  // TPDOs received when the end began
    std::vector<SdoStep> script;
    std::size_t step = 0;
    bool step_sent = false;
    bool start_sent = false;        // NMT start after a recovery
    bool fault_reset = false;       // fault reset edge in progress
  };

  bool send(const can::Frame& f, SimTime t);
  void nmt(omnitwin::canopen::NmtCommand c, std::uint8_t node, SimTime t);
  void enter(CoPhase p, SimTime t);
  void stop(simclock::StopReason r, std::uint8_t node, SimTime t, const std::string& why);
  void event(SimTime t, const std::string& text, bool warning = false);
  void on_heartbeat_event(const omnitwin::canopen::HeartbeatEvent& e);
  void on_emcy(Node& n, const can::Frame& f, SimTime t);
  void on_tpdo(Node& n, const can::Frame& f);
  void run_scripts(SimTime t);
  bool run_script(Node& n, SimTime t);
  bool identity_ok(Node& n, std::uint8_t sub, std::uint32_t v, SimTime t);
  void send_rpdos(SimTime t);
  void send_heartbeat(SimTime t);
  std::uint16_t controlword_for(Node& n);
  std::uint16_t ending_controlword(const Node& n, SimTime t) const;
  static bool enabled(const Node& n);
  bool any_enabled() const;
  bool reporting(const Node& n) const;
  bool awaiting_statusword(const Node& n) const;
  bool statuswords_fresh() const;
  void warn_unfinished_end(SimTime t);
  void end_tick(SimTime t);
  Node* by_id(std::uint8_t id);

  CoProgramConfig cfg_;
  SendFn send_;
  EventFn event_;
  std::array<Node, 4> nodes_;
  SdoClient sdo_;  // one channel per drive
  std::array<std::int32_t, 4> velocity_{};
  omnitwin::canopen::HeartbeatConsumer consumer_;
  omnitwin::canopen::SyncProducer sync_;
  std::uint32_t vendor_ = 0, product_ = 0;  // the EDS's identity (0: not given, not checked)
  CoPhase phase_ = CoPhase::resetting;
  simclock::StopReason reason_ = simclock::StopReason::none;
  std::uint8_t reason_node_ = 0;
  SimTime start_ = -1, running_since_ = -1, next_heartbeat_ = 0;
  bool reset_sent_ = false;
  SimTime end_from_ = -1;   // shutdown() began the end sequence (-1: not ending)
  bool end_done_ = false;   // NMT stop sent: nothing more goes out
  simclock::MasterState state_at_end_ = simclock::MasterState::detecting;  // reported until the end is over
  CoMasterStats stats_;
};

}  // namespace omnitwin::controller::canopen
