// controller/canopen — the SDO client core of our CANopen master (CiA 301 §7.2.4): uploads and
// downloads of the nodes' objects through their default SDO servers (requests on 0x600 + node,
// responses on 0x580 + node).
//
// A protocol core like the emulated nodes': frames and time (integer ns) in, frames out through
// SendFn; no socket, no clock. Transfers to different nodes run side by side, one per node at a
// time, each on one of cfg.channels channels whose buffers (cfg.max_object_bytes) are allocated
// at construction. Downloads of 1..4 bytes go expedited (size indicated), longer ones (and
// empty ones) segmented, unless the caller asks for segmented or block transfer; uploads are
// expedited or segmented as the server answers, or block transfer on request (CRC when both
// sides support it; protocol switch threshold 0 = never switch). A transfer ends done or
// aborted (by the server's abort, or by ours: a protocol error, a timeout, cancel()); the result
// is kept in its channel for polling and handed to the completion callback.
//
// States of a channel (`ss` = the server's frame; anything not listed aborts with 0x05040001,
// the server's abort ends any of them, no frame for cfg.timeout_ns aborts with 0x05040000):
//   idle           — free; upload()/download() start a transfer.
//   up_initiate    — sent initiate upload: ss initiate upload response (expedited → done).
//   up_segment     — sent upload segment request: ss upload segment (toggle checked).
//   down_initiate  — sent initiate download: ss initiate download response.
//   down_segment   — sent download segment: ss download segment response (toggle checked).
//   blk_down_init  — sent block download initiate: ss response with the server's blksize.
//   blk_down_ack   — sent a sub-block: ss block ack (retransmission from ackseq + 1).
//   blk_down_end   — sent block end (CRC): ss end response → done.
//   blk_up_init    — sent block upload initiate: ss response (size) → start sent.
//   blk_up_sub     — receiving a sub-block: segments by seqno, ack after blksize or c = 1.
//   blk_up_end     — ack of the last sub-block sent: ss block end (CRC checked) → done.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "bus_emulators/canopen/co_sdo.hpp"
#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::controller::canopen {

using omnitwin::canopen::SdoAbort;
using omnitwin::canopen::SendFn;
using omnitwin::canopen::SimTime;

enum class TransferMode : std::uint8_t {
  automatic,  // download: expedited for 1..4 bytes, else segmented; upload: as the server answers
  segmented,  // download: segmented even for 1..4 bytes; upload: same as automatic
  block,      // block download / block upload
};
const char* to_string(TransferMode m);

enum class SdoStatus : std::uint8_t { idle, busy, done, aborted };
const char* to_string(SdoStatus s);

// Why upload()/download() did not start a transfer.
enum class SdoStart : std::uint8_t {
  ok,
  busy,        // a transfer to this node is running
  no_channel,  // every channel is busy
  bad_node,    // node ID outside 1..127
  too_long,    // download data longer than cfg.max_object_bytes
};
const char* to_string(SdoStart s);

struct SdoResult {
  SdoStatus status = SdoStatus::idle;
  SdoAbort code = SdoAbort::none;  // aborted: the abort code
  bool server_abort = false;       // aborted by the server (else by us)
  bool upload = false;
  TransferMode mode = TransferMode::automatic;
  std::uint8_t node = 0;
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::span<const std::uint8_t> data;  // upload done: the bytes (valid until the channel's next transfer)
};
// Called once when a transfer ends (done or aborted), from on_frame/on_time/cancel.
using SdoDoneFn = std::function<void(const SdoResult& r)>;

struct SdoClientConfig {
  SimTime timeout_ns = 1'000'000'000;   // no response for this long aborts the transfer [ns]
  std::size_t max_object_bytes = 1024;  // largest object transferred [bytes]
  std::size_t channels = 4;             // transfers running at once (to different nodes)
  std::uint8_t blksize = omnitwin::canopen::sdo::kMaxBlockSize;  // block upload sub-block size we ask for
  bool crc = true;                      // CRC support announced in block transfers
};

struct SdoClientStats {
  std::uint64_t started = 0, done = 0, aborted = 0;
  std::uint64_t aborts_sent = 0, aborts_received = 0, timeouts = 0;
  std::uint64_t ignored = 0;        // frames on an SDO response COB-ID of no running transfer
  std::uint64_t retransmitted = 0;  // block download segments sent again after a short ack
  std::uint64_t send_failures = 0;  // SendFn returned false
};

class SdoClient {
 public:
  // Throws std::invalid_argument for no SendFn, no channel or a blksize outside 1..127. Allocates.
  explicit SdoClient(SendFn send, SdoClientConfig cfg = {}, SdoDoneFn done = {});

  // Starts reading node's index:sub at t [ns]. Real-time safe.
  SdoStart upload(std::uint8_t node, std::uint16_t index, std::uint8_t sub, SimTime t,
                  TransferMode mode = TransferMode::automatic);
  // Starts writing `bytes` (copied) to node's index:sub at t [ns]. Real-time safe.
  SdoStart download(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::span<const std::uint8_t> bytes,
                    SimTime t, TransferMode mode = TransferMode::automatic);
  // A frame from the bus at t [ns]; frames other than 0x580 + node of a running transfer are
  // ignored. Real-time safe apart from the callbacks.
  void on_frame(const can::Frame& f, SimTime t);
  // Aborts transfers with no response for cfg.timeout_ns (0x05040000 sent and reported).
  void on_time(SimTime t);
  // Aborts the transfer to node with `code` (sent to the server). false when none runs.
  bool cancel(std::uint8_t node, SimTime t, SdoAbort code = SdoAbort::general);

  bool busy(std::uint8_t node) const;
  // The latest result for node while a channel still holds it (busy, done or aborted); nullptr
  // when no channel has served node since, or it was reused for another node.
  const SdoResult* result(std::uint8_t node) const;
  void set_done_callback(SdoDoneFn done) { done_ = std::move(done); }
  const SdoClientStats& stats() const { return stats_; }

 private:
  enum class Phase : std::uint8_t {
    idle, up_initiate, up_segment, down_initiate, down_segment, blk_down_init, blk_down_ack, blk_down_end,
    blk_up_init, blk_up_sub, blk_up_end,
  };
  struct Channel {
    Phase phase = Phase::idle;
    SdoResult result;
    std::uint64_t used = 0;     // start order, to reuse the least recently used channel
    SimTime last = 0;           // last frame sent or received [ns]
    bool toggle = false;        // segmented: the toggle of the next segment
    bool expedited = false;     // download: sent expedited
    bool sized = false;         // upload: size indicated by the server
    bool crc = false;           // block: CRC in use
    std::size_t size = 0;       // download: bytes to send; upload: indicated size
    std::size_t pos = 0;        // download: bytes acknowledged; upload: bytes received
    std::uint8_t blksize = 0;   // block download: the server's sub-block size
    std::uint8_t seq = 0;       // block upload: last good seqno in this sub-block
    std::uint8_t sent = 0;      // block download: segments sent in this sub-block
    bool last_seen = false;     // block: the segment with c = 1 was sent / received in order
    std::vector<std::uint8_t> buf;
  };
  using Payload = omnitwin::canopen::sdo::Payload;

  Channel* channel_for(std::uint8_t node);
  const Channel* channel_for(std::uint8_t node) const;
  Channel* start(std::uint8_t node, std::uint16_t index, std::uint8_t sub, SimTime t, TransferMode mode, SdoStart& st);
  void send(const Channel& c, const Payload& p, SimTime t);
  void finish(Channel& c);
  void fail(Channel& c, SdoAbort code, SimTime t);  // we abort: frame to the server, result
  void response(Channel& c, const Payload& p, SimTime t);
  void up_initiate(Channel& c, const Payload& p, SimTime t);
  void up_segment(Channel& c, const Payload& p, SimTime t);
  void down_next_segment(Channel& c, SimTime t);
  void blk_down_sub_block(Channel& c, SimTime t);
  void blk_down_ack(Channel& c, const Payload& p, SimTime t);
  void blk_up_init(Channel& c, const Payload& p, SimTime t);
  void blk_up_segment(Channel& c, const Payload& p, SimTime t);
  void blk_up_end(Channel& c, const Payload& p, SimTime t);

  SendFn send_;
  SdoClientConfig cfg_;
  SdoDoneFn done_;
  std::vector<Channel> channels_;
  std::uint64_t uses_ = 0;
  SdoClientStats stats_;
};

}  // namespace omnitwin::controller::canopen
