// twin layer — the simulated CAN wire as every CAN network of the twin uses it: the CanBus
// core, the real transport on its far side, the capture, and the faults that act between them.
//
// Node 0 of the wire stands for everything on the far side of the transport (our master,
// python-can, a third-party master): a frame received from the transport is queued on it at the
// receiving instant + T_pre (+ the master's delay fault). A frame another node sends reaches
// the transport when it completes on the wire, with its end-of-frame time (batched for
// flush_transport() in lockstep, where the master reads frames only after its grant); every
// completed frame goes into bus-can.pcap. Frame loss and delay draw from one random stream
// seeded by bus.seed. The thesis's Omni network (can_network) and the CiA 402 drive networks
// (can_drive_network) each own one and add their nodes and protocol. Nothing here reads the
// wall clock except drain_transport()'s timeout. Set-up allocates; per-frame paths do not.
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
#include "bus_emulators/sender_gate.hpp"
#include "twin/bus_claim.hpp"
#include "twin/run_state.hpp"
#include "twin/scenario.hpp"
#include "twin/scheduler.hpp"

namespace omnitwin::twin {

class CanWire {
 public:
  static constexpr can::BusNode kFar = 0;

  // The wire of `nodes` nodes (node 0 the far side) at the scenario's bit rate, and its
  // transport opened (throws can::TransportError). `batch`: frames for the master wait for
  // flush_transport(). Not real-time safe.
  CanWire(const Scenario& s, int nodes, bool batch);
  ~CanWire();  // hands over what is still batched

  can::CanBus& bus() { return bus_; }
  const can::CanBus& bus() const { return bus_; }
  const can::Transport& transport() const { return *transport_; }
  bool batch() const { return batch_; }

  // The capture: records buffered, pushed by flush_pcap() (once per master tick).
  void open_pcap(const std::string& path);
  void flush_pcap() {
    if (pcap_) pcap_->flush();
  }
  std::string close_pcap();
  std::string pcap_error() const;

  // Hands the batched frames to the transport, yielding the CPU after every kBurst frames of
  // a tick (the master takes them off its socket while it waits for its grant; a whole tick
  // at once overflowed its receive buffer). Real-time safe.
  void flush_transport();
  // Lockstep: receives until `count` frames have arrived in all since the start, each queued on
  // node 0 at t + T_pre. False when they did not all come within `timeout`.
  bool drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout);
  // Realtime: queues whatever the transport holds now at t + T_pre. Returns the number taken.
  int poll_transport(SimTime t);

  // A frame completed on the wire: into the capture; a node's frame on to the master unless
  // the master's frame loss takes it. Returns true for a frame from the far side (the
  // protocol looks at those). Real-time safe.
  // *reached_master (if given) says whether a node's frame went on to the master.
  bool completed(can::BusNode sender, const can::Frame& f, const can::FrameTiming& timing,
                 bool* reached_master = nullptr);
  // A frame reached node `target` (FaultSpec numbering): false when frame loss takes it.
  bool arrives(int target);
  // The delay fault's extra time for frames node `node` sends [ns].
  std::int64_t extra_delay(int node);
  // frame_loss and delay faults (the caller checked the node). Return the event-log text.
  std::string apply_loss(const FaultSpec& f, bool begin, const std::string& who);
  std::string apply_delay(const FaultSpec& f, bool begin, const std::string& who);
  void note_bus_off() { ++bus_off_events_; }

  std::uint64_t to_transport() const { return to_transport_; }
  std::uint64_t from_transport() const { return from_transport_; }
  // Frames for the master: handed over or still batched (sent at the end).
  std::uint64_t frames_tx() const { return to_transport_ + pending_.size(); }
  // Error frames, malformed frames from the transport, refused sends and refused arrivals.
  std::uint64_t errors() const;
  // bus.* every CAN network reports; the network adds its own keys.
  nlohmann::json metrics(const char* name, SimTime now) const;

 private:
  struct LossState {
    double rate = 0;
    int burst = 1;
    int left = 0;  // frames of the current burst still to lose
    bool active = false;
  };
  struct DelayState {
    double extra_ns = 0;
    double jitter_ns = 0;
    bool active = false;
  };

  // A frame from the transport: counted when its sender is not the master's (the first
  // sender seen), kept off the wire when the scenario refuses foreign senders, else queued.
  void take_from_far(const can::TimedFrame& r, SimTime t);
  void submit_from_far(const can::Frame& f, SimTime t);
  bool lose(int target);
  std::uint64_t malformed_rx() const;

  const Scenario& s_;
  can::CanBus bus_;
  std::unique_ptr<BusClaim> claim_;  // one twin per bus (before the transport: released after it)
  std::unique_ptr<can::Transport> transport_;
  std::unique_ptr<can::PcapWriter> pcap_;
  std::array<LossState, 6> loss_{};    // by FaultSpec node: 0..3 slaves, 4 master, 5 all
  std::array<DelayState, 5> delay_{};  // by FaultSpec node: 0..3 slaves, 4 master
  std::mt19937_64 rng_;
  bool batch_;
  std::vector<can::TimedFrame> pending_;
  std::size_t unyielded_ = 0;  // frames handed to the transport since the master last had a turn
  std::uint64_t to_transport_ = 0, from_transport_ = 0;
  std::uint64_t extended_frames_ = 0;  // completed on the wire with a 29-bit identifier
  std::uint64_t lost_frames_ = 0, send_failures_ = 0, refused_from_far_ = 0, bus_off_events_ = 0;
  // Who the master is among the transport's senders (the sender id's bytes as the address);
  // on the wall clock one heard after the master's kMasterHandoverNs of silence takes over.
  bus_emulators::SenderGate gate_;
  std::uint64_t foreign_frames_ = 0, refused_foreign_ = 0;
};

}  // namespace omnitwin::twin
