// bus_emulators/canopen — the default SDO server of a CANopen node (CiA 301 §7.2.4): requests
// on COB-ID 0x600 + node, responses on 0x580 + node, served from the node's object dictionary.
//
// Services: expedited upload/download (download with and without size indicated), segmented
// upload/download with the toggle bit, block download (size and CRC, sub-blocks of blksize
// segments, sequence numbers, ack with the last good seqno, CRC checked at the end) and block
// upload (the same the other way, with retransmission from the client's ackseq). The protocol
// switch threshold of a block upload request is ignored: every block upload request is served
// as a block upload, whatever the size (CiA 301 allows the server this choice).
//
// Uploads read the whole entry into a buffer at the initiate (a consistent snapshot); downloads
// collect into a buffer and write the OD once at the end (an object is never half written).
// Both buffers are allocated once at construction (cfg.max_object_bytes; a longer object or
// download is aborted with 0x05040005). Requests arrive as frames with the caller's time; the
// server answers through SendFn at that time. A request frame whose DLC is not 8 is aborted
// with 0x05040001 (command specifier not valid): CiA 301 requires 8 bytes and names no better
// code. Remote and extended frames, and frames on other COB-IDs, are ignored.
//
// States (one transfer at a time; `cs` = the client's frame):
//   idle              — initiate download/upload, block download/upload initiate; cs abort is
//                       ignored; segment requests and unknown specifiers → abort 0x05040001.
//   download_segments — download segment requests (toggle alternating from 0) until c = 1.
//   upload_segments   — upload segment requests (toggle alternating from 0) until the last.
//   block_down_sub    — sub-block segments (byte 0 = c | seqno); 0x80 is the client's abort.
//   block_down_end    — the block download end request (unused bytes, CRC).
//   block_up_start    — the block upload start request (0xA3).
//   block_up_ack      — the client's ack of the sub-block just sent.
//   block_up_end      — the client's end response (0xA1) to our end request.
// In every state but idle, a client abort drops the transfer silently, anything else not listed
// aborts it with 0x05040001, and no frame for cfg.timeout_ns aborts it with 0x05040000.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "bus_emulators/canopen/co_sdo.hpp"
#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::canopen {

struct SdoServerConfig {
  SimTime timeout_ns = 1'000'000'000;   // a transfer stalled this long is aborted [ns]
  std::size_t max_object_bytes = 1024;  // largest object uploaded or downloaded in segments/blocks
  std::uint8_t blksize = sdo::kMaxBlockSize;  // segments per sub-block we accept (1..127)
  bool crc = true;                      // CRC support announced in block transfers
};

struct SdoServerStats {
  static constexpr std::size_t kCodes = 16;  // distinct abort codes counted one by one
  std::uint64_t requests = 0;        // frames on our COB-ID taken as requests
  std::uint64_t uploads = 0;         // uploads completed (all kinds)
  std::uint64_t downloads = 0;       // downloads completed (all kinds)
  std::uint64_t aborts_sent = 0;
  std::uint64_t aborts_received = 0;
  std::uint64_t timeouts = 0;
  std::uint64_t segments = 0;        // segments of segmented transfers, both ways
  std::uint64_t block_segments = 0;  // sub-block segments, both ways (retransmissions too)
  std::uint64_t blocks = 0;          // sub-blocks completed (acked)
  std::uint64_t send_failures = 0;   // SendFn returned false
  // Aborts sent per code (the first kCodes distinct codes; others only in aborts_sent).
  std::array<std::uint32_t, kCodes> abort_code{};
  std::array<std::uint64_t, kCodes> abort_count{};
  std::uint64_t aborts_with(SdoAbort code) const;
};

class SdoServer {
 public:
  // Throws std::invalid_argument for an invalid node ID or blksize (set-up error). Allocates.
  SdoServer(ObjectDictionary& od, std::uint8_t node_id, SendFn send, SdoServerConfig cfg = {});

  // One frame from the bus at t [ns], the OD accessed in `state`. Frames not on 0x600 + node are
  // ignored. Real-time safe apart from the OD's hooks and the SendFn.
  void on_frame(const can::Frame& f, SimTime t, OdState state);
  // Aborts a transfer with no frame for cfg.timeout_ns (0x05040000). Real-time safe.
  void on_time(SimTime t);
  // NMT reset communication: drops any transfer without a frame. Real-time safe.
  void reset();

  bool busy() const { return state_ != State::idle; }
  std::uint32_t rx_cob() const { return cob::sdo_rx + node_; }
  std::uint32_t tx_cob() const { return cob::sdo_tx + node_; }
  const SdoServerStats& stats() const { return stats_; }

 private:
  enum class State : std::uint8_t {
    idle, download_segments, upload_segments, block_down_sub, block_down_end, block_up_start, block_up_ack,
    block_up_end,
  };
  void request(const sdo::Payload& p, OdState s);
  void send(const sdo::Payload& p);
  void abort(std::uint16_t index, std::uint8_t sub, SdoAbort code);
  void abort_transfer(SdoAbort code) { abort(index_, sub_, code); }
  void begin(State st, std::uint16_t index, std::uint8_t sub);
  SdoAbort check_download(std::uint16_t index, std::uint8_t sub, OdState s, bool sized, std::size_t size) const;
  SdoAbort commit(OdState s);
  void initiate_download(const sdo::Payload& p, OdState s);
  void download_segment(const sdo::Payload& p, OdState s);
  void initiate_upload(const sdo::Payload& p, OdState s);
  void upload_segment(const sdo::Payload& p);
  void block_download_initiate(const sdo::Payload& p, OdState s);
  void block_download_segment(const sdo::Payload& p);
  void block_download_end(const sdo::Payload& p, OdState s);
  void block_upload_initiate(const sdo::Payload& p, OdState s);
  void block_upload_ack(const sdo::Payload& p);
  void send_sub_block();
  void count_abort(SdoAbort code);

  ObjectDictionary& od_;
  std::uint8_t node_;
  SendFn send_;
  SdoServerConfig cfg_;
  State state_ = State::idle;
  SimTime now_ = 0, last_ = 0;  // current frame's time, last activity of the transfer [ns]
  std::uint16_t index_ = 0;
  std::uint8_t sub_ = 0;
  bool toggle_ = false;       // segmented: the toggle expected next
  bool sized_ = false;        // download: size indicated
  bool crc_ = false;          // block: CRC in use (both sides support it)
  std::size_t size_ = 0;      // download: indicated size; upload: object size [bytes]
  std::size_t pos_ = 0;       // bytes received / sent and acknowledged
  std::uint8_t blksize_ = 0;  // block upload: current sub-block size (client's choice)
  std::uint8_t seq_ = 0;      // block download: last good seqno in this sub-block
  std::uint8_t sent_ = 0;     // block upload: segments sent in this sub-block
  bool last_seen_ = false;    // block: the segment with c = 1 was received / sent
  std::vector<std::uint8_t> buf_;  // download data or upload snapshot, max_object_bytes + 7
  SdoServerStats stats_;
};

}  // namespace omnitwin::canopen
