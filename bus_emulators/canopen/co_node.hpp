// bus_emulators/canopen — one CANopen slave node (CiA 301): the NMT slave, error control
// (heartbeat producer, node/life guarding, heartbeat consumer 0x1016), the default SDO server,
// SYNC consumer, PDOs, the EMCY producer and the TIME consumer over one object dictionary.
//
// The node is the dispatch layer of lely-core's `co_dev`/`co_nmt` shape: frames and time in
// (on_frame, on_time), frames out through SendFn, no sockets and no clock, so that the twin's
// simulated wire, a test or a fuzzer can own it. The dictionary is built by the caller (from an
// EDS, co_eds) with the application's objects bound into it (co_drive binds CiA 402's); the
// node reads its communication parameters from it on every use, so an SDO write takes effect
// as on a real device. The application hears SYNCs, NMT transitions and communication errors
// through NodeHooks.
//
// SYNC producer: with bit 30 (gen) of 0x1005 set and 0x1006 > 0 [µs] the node sends SYNC itself
// every 0x1006 µs (with a counter when 0x1019 is 2..240) and acts on it as on one received (a
// CAN controller does not receive its own frames). 0x1019 takes 0 or 2..240 (else 0x06090030),
// and only while 0x1006 is 0 (else 0x08000022), as CiA 301 asks.
// Communication errors (heartbeat consumer timeout, life guarding, bus-off recovery) raise an
// EMCY and take the NMT state given by 0x1029:1 (0 → pre-operational if operational, 1 → no
// change, 2 → stopped; 0 when the object is absent), as CiA 301 §7.2.8.3.
// Set-up allocates; on_frame/on_time and the hooks' calls are real-time safe.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>

#include "bus_emulators/canopen/co_emcy.hpp"
#include "bus_emulators/canopen/co_nmt.hpp"
#include "bus_emulators/canopen/co_pdo.hpp"
#include "bus_emulators/canopen/co_sdo_server.hpp"
#include "bus_emulators/canopen/co_sync.hpp"
#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::canopen {

struct NodeHooks {
  // After a SYNC was processed (buffered RPDOs applied, synchronous TPDOs sent).
  std::function<void(std::uint8_t counter, SimTime t)> on_sync;
  // After an NMT transition was applied (reset_node: reset the application here, before
  // the boot-up; it is called before the dictionary's communication objects are restored).
  std::function<void(NmtTransition tr, SimTime t)> on_nmt;
  // A communication error (EMCY code 0x8130 heartbeat/life guarding, 0x8140 bus-off
  // recovered) — after its EMCY, before the NMT state change 0x1029 asks for.
  std::function<void(std::uint16_t emcy_code, SimTime t)> on_comm_error;
};

struct NodeStats {
  std::uint64_t frames_rx = 0, frames_tx = 0, tx_refused = 0, nmt_commands = 0, syncs = 0,
                sync_length_errors = 0, time_stamps = 0, emcy = 0;
};

class Node {
 public:
  // od must outlive the node; node_id 1..127 (throws std::invalid_argument otherwise: set-up).
  Node(ObjectDictionary& od, std::uint8_t node_id, SendFn send, NodeHooks hooks = {});
  Node(const Node&) = delete;
  Node& operator=(const Node&) = delete;

  // Power on (or back on after a power loss): initialising → boot-up → pre-operational.
  void power_on(SimTime now);
  // Every frame seen on the bus (the node filters by COB-ID). Real-time safe.
  void on_frame(const can::Frame& f, SimTime now);
  // Timers: heartbeat, life guarding, consumer timeouts, SDO timeouts, EMCY inhibit,
  // event-driven TPDOs, RPDO deadlines. Call at least every millisecond. Real-time safe.
  void on_time(SimTime now);
  // The CAN controller recovered from bus-off (the twin's wire model tells us). Real-time safe.
  void on_bus_off_recovered(SimTime now);
  // An application error: EMCY with `code` (raise) or its end (clear); while STOPPED recorded
  // only (0x1001, 0x1003) and signalled when the node is back (co_emcy). Real-time safe.
  void raise_error(std::uint16_t code, SimTime now, std::array<std::uint8_t, 5> mfr = {});
  void clear_error(std::uint16_t code, SimTime now);

  std::uint8_t node_id() const { return nmt_.node_id(); }
  NmtState state() const { return nmt_.state(); }
  ObjectDictionary& od() { return od_; }
  const ObjectDictionary& od() const { return od_; }
  const SdoServer& sdo() const { return sdo_; }
  const PdoEngine& pdo() const { return pdo_; }
  const EmcyProducer& emcy() const { return emcy_; }
  const ErrorControlProducer& error_control() const { return ec_; }
  const HeartbeatConsumer& heartbeat_consumer() const { return consumer_; }
  const NodeStats& stats() const { return stats_; }
  // The last TIME stamp received and when; nullopt before the first.
  std::optional<TimeOfDay> last_time() const { return last_time_; }
  SimTime last_time_at() const { return last_time_at_; }

 private:
  bool send(const can::Frame& f, SimTime t);
  void apply(NmtTransition tr, SimTime now);
  void reset_communication(SimTime now);
  void configure_consumer();
  void communication_error(std::uint16_t code, SimTime now);
  ErrorControlParams ec_params() const;
  std::uint32_t cob_of(const OdEntry* e, std::uint32_t dflt) const {
    return e ? static_cast<std::uint32_t>(e->as_int()) : dflt;
  }
  static void pdo_error(void* ctx, std::uint16_t code, SimTime now);
  void on_sync(std::uint8_t counter, SimTime now);
  void produce_sync(SimTime now);

  ObjectDictionary& od_;
  SendFn send_;
  SendFn send_counted_;  // send_ with statistics: what the layers get
  NodeHooks hooks_;
  NmtSlave nmt_;
  ErrorControlProducer ec_;
  HeartbeatConsumer consumer_;
  SdoServer sdo_;
  PdoEngine pdo_;
  EmcyProducer emcy_;
  // Parameters read on every use (entries are stable: the dictionary is not rebuilt).
  const OdEntry* heartbeat_ms_ = nullptr;  // 0x1017
  const OdEntry* guard_ms_ = nullptr;      // 0x100C
  const OdEntry* life_factor_ = nullptr;   // 0x100D
  const OdEntry* sync_cob_ = nullptr;      // 0x1005
  const OdEntry* sync_overflow_ = nullptr; // 0x1019
  const OdEntry* sync_period_ = nullptr;   // 0x1006 [µs]
  SyncProducer sync_producer_;
  const OdEntry* time_cob_ = nullptr;      // 0x1012
  const OdEntry* error_behaviour_ = nullptr;  // 0x1029:1
  std::optional<TimeOfDay> last_time_;
  SimTime last_time_at_ = -1;
  NodeStats stats_;
};

// Restores the defaults of every entry of objects lo..hi (own storage, and bound storage of
// writable entries), as NMT reset communication (0x1000..0x1FFF) and reset node do.
void restore_defaults(ObjectDictionary& od, std::uint16_t lo, std::uint16_t hi);

}  // namespace omnitwin::canopen
