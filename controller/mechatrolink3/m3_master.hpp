// controller/mechatrolink3 — our C1 master's communication core: what the master ASIC and
// its driver do in seed 000 figs. 9-11, below the application (servo start-up, the platform
// loop), which only reads the response buffer and writes the command buffer at the cyclic
// interrupt.
//
// Driver sequence (one flat switch over named states, step()):
//   init        ASIC set-up and normal-operation check, SRAM test, parameters initialised
//   detect      connected-station detection: DETECT to each configured address in turn
//   delay       TR_DLY measurement: DLY_REQ to each detected slave, TR_DLY = round trip −
//               both frame times − the slaves' fixed echo turnaround (m3_link kDelayEchoNs)
//   params      T_RSP per slave and INT_OFFSET from the measured TR_DLY (m3_wire), and the
//               check that the transmission cycle fits (else `failed`, naming the shortest)
//   notify      transmission-cycle notification (CYC_NOTIFY to all)
//   start       communication start (COMM_START to all)
//   cyclic      every transmission cycle: SYNC, then one command per slave from the command
//               buffer, each waiting at most T_RSP(k) for its response; slaves whose response
//               was missing or bad are retried in the same cycle (retry slots); at INT_OFFSET
//               the interrupt hands the response buffer to the application
//   event       event-driven communication (config.event_driven; no SYNC, no cycle): the
//               application requests an exchange with one slave (request()); the master
//               sends EVT_CMD (64 bytes) and waits for EVT_RSP the slave's own response time
//               (fig. 6): T_RSP(k) from its measured TR_DLY as in cyclic communication, at most
//               event_timeout (seed 000: a slave answers within 50 ms), retrying event_retries
//               times (retries are the driver's job here), one exchange on the line at a time,
//               requests queued in order (a silent slave holds the line 3 × T_RSP, µs); each
//               slave's requests carry sequence numbers of their own (a retry repeats the number)
//   failed      a detected slave missing, a configuration that does not fit: why() says
//
// Protocol core: frames and simulated time in, frames out through a callback, no sockets, no
// clock. The owner calls advance(t) at next_wakeup() and hands received frames to on_frame().
// Fixed configuration (MasterConfig) apart from state; no allocation after start().
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "bus_emulators/mechatrolink3/m3_command.hpp"
#include "bus_emulators/mechatrolink3/m3_frame.hpp"
#include "bus_emulators/mechatrolink3/m3_wire.hpp"

namespace omnitwin::m3 {

struct MasterSlave {
  std::uint8_t address = kFirstSlave;
  std::size_t data_bytes = 32;     // cyclic data length (8/16/32/48/64)
  SimTime response_ns = 2'000;     // the slave's response time the master allows for
};

struct MasterConfig {
  std::vector<MasterSlave> slaves;
  SimTime cycle_ns = 1'000'000;    // transmission cycle
  int retry_slots = 1;
  SimTime margin_ns = 1'000;       // added to every T_RSP
  SimTime software_ns = 100'000;   // the application's time after INT_OFFSET
  SimTime detect_timeout_ns = 100'000;  // per station, detection and delay measurement
  bool event_driven = false;            // event-driven instead of cyclic (data_bytes must be 64)
  SimTime event_timeout_ns = 50'000'000;  // seed 000: a slave answers within 50 ms (caps T_RSP)
  int event_retries = 2;
};

enum class DriverState : std::uint8_t { idle, init, detect, delay, params, notify, start, cyclic, event, failed };
const char* to_string(DriverState);

// Per-slave counters (the master's statistics and the twin's metrics).
struct SlaveCounters {
  std::uint64_t exchanges = 0, retries = 0, retry_recovered = 0, missed = 0, late = 0, bad = 0;
};

class C1Master {
 public:
  // emit(frame, t_start): a frame the master starts sending at t_start [ns].
  using Emit = std::function<void(std::span<const std::uint8_t>, SimTime)>;
  // The cyclic interrupt at INT_OFFSET of cycle n: read responses, write commands. Real-time.
  using Interrupt = std::function<void(std::uint64_t cycle, SimTime t)>;
  // A line of the driver's log (the sequence of figs. 9-11). Not on the cyclic path.
  using Log = std::function<void(SimTime t, const std::string&)>;
  // Event-driven: the exchange requested for slave k ended (ok: a response is in response(k);
  // latency: from the request to the response's last bit, or to giving up) [ns].
  using EventDone = std::function<void(int k, bool ok, SimTime latency_ns)>;

  C1Master(MasterConfig config, Emit emit, Interrupt interrupt, Log log = {});

  void start(SimTime t);  // begins the driver sequence at t
  void on_event(EventDone done) { event_done_ = std::move(done); }
  // Event-driven: asks for one exchange with slave k (its command buffer) at t. False when
  // the master is not in event-driven communication or the queue (4 per slave) is full.
  bool request(int k, SimTime t);
  void on_frame(std::span<const std::uint8_t> bytes, SimTime t);  // a frame fully received at t
  void advance(SimTime t);             // runs everything due at or before t
  SimTime next_wakeup() const { return wake_; }  // -1: nothing scheduled

  // Buffers of slave k (config order): the command sent next cycle (header byte 1, WDT, is
  // filled in by the master), the last good response and whether it came this cycle.
  std::span<std::uint8_t> command(int k);
  std::span<const std::uint8_t> response(int k) const;
  bool fresh(int k) const { return slave_[static_cast<std::size_t>(k)].fresh; }

  DriverState state() const { return state_; }
  const std::string& why() const { return why_; }
  // Failed because the configuration does not fit the line (the cycle, event-driven data),
  // not because a slave was silent at start-up.
  bool misfit() const { return misfit_; }
  std::uint8_t address(int k) const { return cfg_.slaves[static_cast<std::size_t>(k)].address; }
  SimTime tr_dly_ns(int k) const { return slave_[static_cast<std::size_t>(k)].tr_dly; }
  SimTime t_rsp_ns(int k) const { return slave_[static_cast<std::size_t>(k)].t_rsp; }
  SimTime int_offset_ns() const { return int_offset_; }
  SimTime min_cycle_ns() const { return min_cycle_; }
  std::uint64_t cycles() const { return cycle_; }
  // Frames on the line that another C1 master sent (source address 01h, not ours): a second
  // C1 master on one line is a configuration error; counted, logged once, never acted on.
  std::uint64_t foreign_master_frames() const { return foreign_master_; }
  const SlaveCounters& counters(int k) const { return slave_[static_cast<std::size_t>(k)].counters; }
  int slaves() const { return static_cast<int>(cfg_.slaves.size()); }

 private:
  struct Slave {
    std::array<std::uint8_t, kMaxData> cmd{}, rsp{};
    bool fresh = false, detected = false, answered = false;
    std::uint8_t sequence = 0;  // event-driven: the sequence number of its last new request
    SimTime tr_dly = 0, t_rsp = 0;
    SlaveCounters counters;
  };
  // One exchange in progress: who, its sequence number, when it gives up.
  struct Pending {
    int k = -1;
    FrameType expect = FrameType::cyclic_response;
    SimTime sent = 0, deadline = 0;
  };
  void step(SimTime t);
  void send(FrameType type, std::uint8_t dst, std::span<const std::uint8_t> data, SimTime t, bool retry = false);
  void next_station(SimTime t);
  void finish_setup_exchange(SimTime t, bool answered);
  CyclePlan plan() const;
  bool compute_params(SimTime t);
  void begin_cycle(SimTime t);
  void poll_next(SimTime t);
  void close_exchange(SimTime t, bool good);
  void fail(SimTime t, std::string why);
  void event_next(SimTime t);
  void event_send(int k, SimTime t, bool retry);
  void event_end(SimTime t, bool ok);
  void log(SimTime t, const std::string& line) const;

  MasterConfig cfg_;
  Emit emit_;
  Interrupt interrupt_;
  Log log_;
  EventDone event_done_;
  std::vector<int> queue_;             // event-driven requests, a ring
  std::vector<SimTime> requested_at_;  // per slave: when its request was made
  std::size_t queue_head_ = 0, queue_count_ = 0;
  int attempts_ = 0;
  std::vector<Slave> slave_;
  DriverState state_ = DriverState::idle;
  std::string why_;
  bool misfit_ = false;
  SimTime wake_ = -1, cycle_start_ = 0, int_offset_ = 0, min_cycle_ = 0;
  std::uint64_t cycle_ = 0, foreign_master_ = 0;
  int station_ = 0;                 // setup: the station being detected or measured
  Pending pending_;
  bool pending_retry_ = false;      // the exchange in progress is a retry
  std::vector<int> retry_;          // retry targets this cycle (reserved at start)
  std::size_t retry_next_ = 0;
  int poll_ = 0;                    // cyclic: next slave to poll; slaves() = retries
  bool interrupted_ = false;        // this cycle's interrupt done
  std::uint8_t sequence_ = 0, wdt_ = 0;  // sequence_: of the exchange in progress
  std::array<std::uint8_t, kMaxFrame> out_{};
};

}  // namespace omnitwin::m3
