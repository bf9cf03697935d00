// bus_emulators/mechatrolink3/transport — the twin's side of an M-III line in exchange-level
// lockstep (docs/protocols/sim-clock.md, "Inside a tick"): the line model and its slave
// stations (link + servo profile on the shared drive core) behind a real transport, with the
// capture of both directions. The twin's bus network wraps it; the sim-clock channel stays
// outside (the caller turns take_sent()'s answer into a Horizon), so this layer depends on no
// controller code.
//
// take_sent(): the master reported `count` frames sent, the last starting at t_send. Each new
// frame is taken from the transport and enters the line when it started: the last at t_send,
// earlier ones (reported together, e.g. a SYNC with the command after it) back to back
// before it, a frame slot each; the line then runs until
// nothing is in flight (a slave only answers what it receives), and every frame that reaches
// the master goes onto the transport and into the capture. The answer says how many frames
// the twin has sent in all and when the last of them reached the master. Between the
// master's exchanges the twin runs the slaves' timers (advance()) and their drives
// (step_drive()) on its own schedule.
//
// Real-time: take_sent() waits on the transport (bounded by its argument) and otherwise
// allocates nothing; set-up allocates and may throw.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/drive/cia402_drive.hpp"
#include "bus_emulators/mechatrolink3/m3_pcap.hpp"
#include "bus_emulators/mechatrolink3/m3_stations.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"

namespace omnitwin::m3 {

using SegmentConfig = StationsConfig;

// What take_sent() answers: the twin's cumulative frames to the master, and when the last
// one delivered by this exchange reached the master (-1: none).
struct SegmentAnswer {
  bool ok = false;                // false: the master's frames did not all arrive in time
  std::uint64_t to_master = 0;
  SimTime arrival_ns = -1;
};

class M3Segment {
 public:
  // Builds the line and the slaves (powered on at t = 0). `transport` is the slaves' end and
  // must outlive the segment.
  M3Segment(const SegmentConfig& config, M3Transport& transport);
  ~M3Segment();
  M3Segment(const M3Segment&) = delete;
  M3Segment& operator=(const M3Segment&) = delete;

  // Starts the capture (both directions); throws std::runtime_error naming the file. The
  // capture is the master's port: its frames as it sent them, the slaves' as they reached it.
  // Records are held and written in time order by flush_capture(): a response that a delay
  // fault made late arrives after the master's next command has started, and was written
  // before it (500 records out of order in a 0.5 s fault; found in review).
  void open_pcap(const std::string& path);
  PcapWriter* pcap() { return pcap_.get(); }
  const PcapWriter* pcap() const { return pcap_.get(); }
  // Writes the held records, sorted by time (stable), to the capture. Call it at each record
  // boundary (the twin's control tick) and before closing the capture. Real-time safe.
  void flush_capture();

  SegmentAnswer take_sent(std::uint64_t master_frames, SimTime t_send, std::chrono::nanoseconds wait);
  // Realtime: every frame the transport holds now enters the line when it arrived — t minus
  // its age from the kernel's receive stamp (t where there is none), in arrival order, never
  // before not_before nor after t — with the slaves' timers run to that instant first, and the
  // line runs dry after each (the answers go out at once). So a twin that was busy when frames
  // came still has its slaves see them when they came. Returns the frames taken. Real-time safe.
  int poll(SimTime t, SimTime not_before = 0);
  // A frame another station puts on the line at t (a second C1 master: fault injection): it
  // enters the line towards the slaves, reaches our master too (every station hears the
  // line) and goes into the capture; the line then runs dry. The frames it causes reach our
  // master outside any exchange: the next Grant counts them. Real-time safe.
  void inject(std::span<const std::uint8_t> frame, SimTime t);
  // The slaves' communication timers up to t (missing sync or commands). Real-time safe.
  void advance(SimTime t);
  // One drive period of slave k at t (its servo profile and drive core). Real-time safe.
  drive::Command step_drive(int k, SimTime t, const drive::Feedback& fb);

  int slaves() const { return stations_.size(); }
  Line& line() { return stations_.line(); }
  const Line& line() const { return stations_.line(); }
  const SlaveLink& link(int k) const { return stations_.link(k); }
  SlaveLink& link(int k) { return stations_.link(k); }
  ServoProfile& servo(int k) { return stations_.servo(k); }
  const ServoProfile& servo(int k) const { return stations_.servo(k); }
  std::uint64_t from_master() const { return from_master_; }
  std::uint64_t to_master() const { return to_master_; }
  std::uint64_t send_failures() const { return send_failures_; }
  // Time the wire has carried frames (each with its inter-frame gap) since the start [ns].
  std::int64_t busy_ns() const { return busy_ns_; }

 private:
  void to_master_frame(std::span<const std::uint8_t> frame, SimTime t);
  void capture(std::span<const std::uint8_t> frame, SimTime t, Direction dir);
  void enter(int n, SimTime t);
  void run_dry();

  M3Stations stations_;
  M3Transport& transport_;
  std::unique_ptr<PcapWriter> pcap_;
  std::uint64_t from_master_ = 0, to_master_ = 0, send_failures_ = 0;
  SimTime last_arrival_ = -1;
  SimTime last_entry_ = 0;  // realtime: when the last polled frame entered the line
  std::int64_t busy_ns_ = 0;
  std::array<std::uint8_t, 2 * kMaxFrame> rx_{};
  struct Batched {  // a frame of a Sent that covered several
    std::array<std::uint8_t, 2 * kMaxFrame> bytes{};
    std::size_t size = 0;
    SimTime at = 0;
  };
  std::array<Batched, 8> batch_{};
  static constexpr std::size_t kHeld = 4096;  // the capture's hold (EthernetCapture)
};

}  // namespace omnitwin::m3
