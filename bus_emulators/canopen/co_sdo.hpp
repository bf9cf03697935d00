// bus_emulators/canopen — the SDO protocol's frame layer (CiA 301 §7.2.4.3), shared by the SDO
// server of a node (co_sdo_server) and the SDO client of our master (controller/canopen).
//
// Every SDO frame is 8 data bytes; byte 0 holds the command specifier (CCS client→server, SCS
// server→client, bits 7..5) and the flags of the service, the rest index/subindex/data. Each
// service is a plain struct with an encode function (struct → 8-byte payload) and a decode
// function (payload → struct, with a status). The sub-block segments of block transfer carry
// no command specifier (byte 0 = last flag | sequence number): only the transfer's state tells
// them apart, so callers pick the decoder. Several block services share one layout in both
// directions (ack 0xA2, end 0xC1, end response 0xA1) and so share one encoder.
// Also here: the CRC-16 of block transfer (CRC-CCITT x^16+x^12+x^5+1, initial value 0, no
// reflection, no final XOR: the CRC-16/XMODEM parameters).
// Everything here is real-time safe (no allocation, no throw).
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::canopen::sdo {

// Abort codes of CiA 301 missing from ethercat::SdoAbort (kept here, not in ec_od.hpp).
inline constexpr SdoAbort abort_invalid_seqno = static_cast<SdoAbort>(0x05040003);  // invalid sequence number
inline constexpr SdoAbort abort_crc = static_cast<SdoAbort>(0x05040004);            // CRC error (block mode)
// Short description of any abort code, including the two above. Never nullptr.
const char* abort_text(SdoAbort a);

// Client command specifiers (byte 0 bits 7..5 of a request).
enum class Ccs : std::uint8_t {
  download_segment = 0,
  initiate_download = 1,
  initiate_upload = 2,
  upload_segment = 3,
  abort = 4,
  block_upload = 5,
  block_download = 6,
};
// Server command specifiers (byte 0 bits 7..5 of a response).
enum class Scs : std::uint8_t {
  upload_segment = 0,
  download_segment = 1,
  initiate_upload = 2,
  initiate_download = 3,
  abort = 4,
  block_download = 5,
  block_upload = 6,
};
inline constexpr std::uint8_t specifier(std::uint8_t b0) { return static_cast<std::uint8_t>(b0 >> 5); }

// Sub-commands of the block services (byte 0 bits 1..0 for block upload requests and block
// download responses; bit 0 for block download requests and block upload responses).
namespace block_cs {
inline constexpr std::uint8_t initiate = 0, end = 1, ack = 2, start = 3;
}

inline constexpr std::uint8_t kMaxBlockSize = 127;  // segments per sub-block
inline constexpr std::size_t kSegmentData = 7;      // data bytes per segment (normal and block)

using Payload = std::array<std::uint8_t, 8>;

enum class FrameStatus : std::uint8_t {
  ok,
  not_sdo,          // not a standard data frame with 8 bytes
  wrong_command,    // the specifier/sub-command is not the one this decoder reads
  bad_seqno,        // block segment with sequence number 0
  bad_block_size,   // blksize outside 1..127
};
const char* to_string(FrameStatus s);

// The 8 data bytes of an SDO frame: ok only for a standard data frame with DLC 8.
FrameStatus payload_of(const can::Frame& f, Payload& out);
// A standard data frame on `cob_id` carrying `p`.
can::Frame make_frame(std::uint32_t cob_id, const Payload& p);

// Initiate download request (CCS 1) and initiate upload response (SCS 2): same layout.
// expedited && sized: `size` = data bytes in `data` (1..4); expedited && !sized: 4 bytes, the
// length is unspecified; !expedited && sized: `size` = total bytes to follow in segments;
// !expedited && !sized: the length is not indicated (size 0).
struct Initiate {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  bool expedited = false;
  bool sized = false;
  std::uint32_t size = 0;
  std::array<std::uint8_t, 4> data{};
};
Payload encode_initiate_download(const Initiate& m);  // client → server
Payload encode_initiate_upload_response(const Initiate& m);  // server → client
FrameStatus decode_initiate(const Payload& p, Initiate& m);  // either; checks the specifier (1 or 2)

// Index and subindex (initiate upload request, initiate download response, aborts, block
// initiates): bytes 1..3.
struct ObjectRef {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
};
ObjectRef object_of(const Payload& p);
Payload encode_initiate_upload(ObjectRef o);             // CCS 2
Payload encode_initiate_download_response(ObjectRef o);  // SCS 3

// Segments of a segmented transfer: download segment request (CCS 0) and upload segment
// response (SCS 0) share the layout [0 0 0 t n n n c][7 data bytes], n = bytes without data.
struct Segment {
  bool toggle = false;
  bool last = false;     // c: no more segments
  std::uint8_t len = 0;  // data bytes 0..7
  std::array<std::uint8_t, 7> data{};
};
Payload encode_segment(const Segment& s);
FrameStatus decode_segment(const Payload& p, Segment& s);  // checks specifier 0
Payload encode_upload_segment_request(bool toggle);       // CCS 3
Payload encode_download_segment_response(bool toggle);    // SCS 1
inline bool toggle_of(std::uint8_t b0) { return (b0 & 0x10) != 0; }

// Abort transfer (CCS/SCS 4): index, subindex, u32 abort code.
struct Abort {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  SdoAbort code = SdoAbort::none;
};
Payload encode_abort(const Abort& a);
FrameStatus decode_abort(const Payload& p, Abort& a);  // checks specifier 4

// Block initiates. Which fields a direction carries:
//   download request  (CCS 6, cs 0): crc (client supports CRC), sized, size
//   download response (SCS 5, ss 0): crc (server supports CRC), blksize
//   upload request    (CCS 5, cs 0): crc, blksize, pst (protocol switch threshold)
//   upload response   (SCS 6, ss 0): crc, sized, size
struct BlockInitiate {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  bool crc = false;
  bool sized = false;
  std::uint32_t size = 0;
  std::uint8_t blksize = 0;
  std::uint8_t pst = 0;
};
Payload encode_block_download_initiate(const BlockInitiate& m);
Payload encode_block_download_initiate_response(const BlockInitiate& m);
Payload encode_block_upload_initiate(const BlockInitiate& m);
Payload encode_block_upload_initiate_response(const BlockInitiate& m);
// Decoders check the specifier and sub-command; those of services with a blksize field check
// it too (1..127 else bad_block_size, the fields still filled in).
FrameStatus decode_block_download_initiate(const Payload& p, BlockInitiate& m);           // CCS 6
FrameStatus decode_block_download_initiate_response(const Payload& p, BlockInitiate& m);  // SCS 5
FrameStatus decode_block_upload_initiate(const Payload& p, BlockInitiate& m);             // CCS 5
FrameStatus decode_block_upload_initiate_response(const Payload& p, BlockInitiate& m);    // SCS 6
Payload encode_block_upload_start();  // CCS 5, cs 3 (0xA3)

// One segment of a sub-block: [c seqno(7)][7 data bytes]; seqno 1..127.
struct BlockSegment {
  bool last = false;  // c: no more segments to transfer
  std::uint8_t seqno = 0;
  std::array<std::uint8_t, 7> data{};
};
Payload encode_block_segment(const BlockSegment& s);
FrameStatus decode_block_segment(const Payload& p, BlockSegment& s);  // bad_seqno when 0

// Block ack (0xA2 both ways: SCS 5 ss 2 in download, CCS 5 cs 2 in upload): the last sequence
// number received in order and the next sub-block's size.
struct BlockAck {
  std::uint8_t ackseq = 0;
  std::uint8_t blksize = 0;
};
Payload encode_block_ack(const BlockAck& a);
FrameStatus decode_block_ack(const Payload& p, BlockAck& a);  // 0xA2 exactly; blksize checked

// Block end (0xC1 | n << 2 both ways: CCS 6 cs 1 in download, SCS 6 ss 1 in upload): unused
// bytes in the last segment and the CRC; and its response 0xA1 (SCS 5 ss 1 / CCS 5 cs 1).
struct BlockEnd {
  std::uint8_t unused = 0;  // 0..7
  std::uint16_t crc = 0;
};
Payload encode_block_end(const BlockEnd& e);
// Unused bytes of the last segment of a block transfer of `size` bytes (an empty object is
// one segment without data: 7).
constexpr std::uint8_t block_unused(std::size_t size) {
  return static_cast<std::uint8_t>(size == 0 ? 7 : (kSegmentData - size % kSegmentData) % kSegmentData);
}
FrameStatus decode_block_end(const Payload& p, BlockEnd& e);  // specifier 6, bit 0 set
Payload encode_block_end_response();
bool is_block_end_response(const Payload& p);  // 0xA1 (bits 4..2 reserved, ignored)

// CRC-16 of block transfer, continued from `crc` (0 to start). Real-time safe.
std::uint16_t crc16(std::span<const std::uint8_t> data, std::uint16_t crc = 0) noexcept;

}  // namespace omnitwin::canopen::sdo
