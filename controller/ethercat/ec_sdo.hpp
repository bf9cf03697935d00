// controller/ethercat — the master's CoE SDO client: mailbox frames in and out, one transfer
// at a time (facts/ethercat.md "Mailbox and CoE").
//
// Pure protocol: SdoTransfer builds the next mailbox request (SM0 contents) and digests the
// slave's mailbox reply (SM1 contents); the master core (ec_master) moves those bytes through
// FPWR/FPRD datagrams and owns the timeouts. Shaped so because one transfer may take several
// mailbox round trips (segmented up/download) and the core must stay one-frame-per-tick:
// every round trip is a begin → next_request → on_reply step the core can interleave with
// cyclic traffic. Supported: upload expedited/normal/segmented, download
// expedited/normal/segmented, abort (both directions' codes reported), mailbox error replies.
// Nothing here allocates after begin() (the data vector grows during a segmented upload).
#pragma once

#include <cstddef>
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace omnitwin::controller::ethercat {

inline constexpr std::size_t kMbxHeaderSize = 6;   // length, address, channel/priority, type|counter
inline constexpr std::size_t kCoeSdoSize = 10;     // CoE header 2 + SDO command 1 + index 2 + sub 1 + data 4

// Mailbox types (low nibble of header byte 5).
enum class MbxType : std::uint8_t { error = 0, aoe = 1, eoe = 2, coe = 3, foe = 4, soe = 5, voe = 15 };
// CoE services (CoE header bits 15:12).
enum class CoeService : std::uint8_t { emergency = 1, sdo_request = 2, sdo_response = 3, sdo_info = 8 };

// Common SDO abort codes (CiA 301 / ETG.1000.6); any other u32 is reported as received.
enum class SdoAbort : std::uint32_t {
  toggle = 0x05030000, timeout = 0x05040000, command_unknown = 0x05040001,
  unsupported_access = 0x06010000, write_only = 0x06010001, read_only = 0x06010002,
  no_object = 0x06020000, not_mappable = 0x06040041, pdo_length = 0x06040042,
  type_mismatch = 0x06070010, too_long = 0x06070012, too_short = 0x06070013,
  no_subindex = 0x06090011, value_range = 0x06090030, general = 0x08000000,
  cannot_store = 0x08000020, device_state = 0x08000022,
};
const char* sdo_abort_text(std::uint32_t code);  // short text, "unknown abort code" otherwise

// A CoE emergency message (ETG.1000.6 service 1) as read from SM1.
struct CoeEmergency {
  std::uint16_t code = 0;            // CiA 301/402 error code (0x0000: error reset / no error)
  std::uint8_t error_register = 0;   // 0x1001 at the time
  std::array<std::uint8_t, 5> data{};  // manufacturer-specific
};
// The emergency in a whole mailbox read (header + CoE), or nullopt when it is something else.
std::optional<CoeEmergency> parse_emergency(std::span<const std::uint8_t> mailbox) noexcept;
// Short text of an error code by its CiA 301/402 class ("following error", "generic error", …).
const char* emergency_text(std::uint16_t code);

// The outcome of one transfer.
enum class SdoStatus : std::uint8_t {
  pending,        // queued or in progress
  done,           // completed; uploads carry the data
  aborted,        // the slave (or we, on a protocol violation) aborted: abort_code says why
  timeout,        // no answer within the core's SDO timeout
  mailbox_error,  // the slave answered with a mailbox error (type 0): abort_code = its u16 code
  failed,         // the slave vanished or has no CoE mailbox
};
const char* to_string(SdoStatus s);

struct SdoRequest {
  bool upload = true;
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::vector<std::uint8_t> data;  // download: the value, little endian
};

// One SDO transfer's client side.
class SdoTransfer {
 public:
  enum class Step : std::uint8_t {
    send,     // next_request() has a request to go out
    done,     // finished (see status())
  };
  enum class ReplyOutcome : std::uint8_t {
    ignored,   // not an answer to this transfer (other type, emergency, old counter); keep reading
    progress,  // accepted; another request follows (segments)
    finished,  // the transfer ended (status() done/aborted/mailbox_error)
  };

  // Starts `req` on a slave whose SM0 (master → slave) is `mbx_out_size` bytes. Allocates.
  void begin(SdoRequest req, std::size_t mbx_out_size);
  // The next mailbox request into `out` (out.size() = SM0 length; unused bytes zeroed) with
  // mailbox counter `counter` (1..7). Returns the bytes that matter (header + length), 0 when
  // nothing is to be sent. Real-time safe.
  std::size_t next_request(std::span<std::uint8_t> out, std::uint8_t counter);
  // One mailbox read from SM1. Real-time safe apart from segmented upload growth.
  ReplyOutcome on_reply(std::span<const std::uint8_t> mbx);
  // Marks the transfer failed from outside (timeout, slave gone).
  void fail(SdoStatus status);

  Step step() const { return step_; }
  SdoStatus status() const { return status_; }
  std::uint32_t abort_code() const { return abort_code_; }
  const SdoRequest& request() const { return req_; }
  const std::vector<std::uint8_t>& data() const { return data_; }  // upload result

 private:
  enum class Phase : std::uint8_t { initiate, segment };
  void abort_local(std::uint32_t code);
  ReplyOutcome finish();          // done: status done, nothing more to send
  ReplyOutcome begin_segments();  // initiate answered: the segments follow, toggle from 0
  SdoRequest req_;
  std::size_t mbx_size_ = 0;
  Phase phase_ = Phase::initiate;
  Step step_ = Step::done;
  SdoStatus status_ = SdoStatus::pending;
  std::uint32_t abort_code_ = 0;
  bool toggle_ = false;
  std::size_t sent_ = 0;          // download: data bytes already sent
  std::uint32_t total_ = 0;       // upload: announced size
  std::vector<std::uint8_t> data_;
};

// Helpers shared with tests and the drive layer.
// Builds a mailbox header at out[0..5].
void put_mbx_header(std::uint8_t* out, std::uint16_t length, MbxType type, std::uint8_t counter);
// Value ↔ little-endian bytes of `bits` width (8, 16, 32, 64).
std::vector<std::uint8_t> value_bytes(std::int64_t value, unsigned bytes);
std::int64_t bytes_value(std::span<const std::uint8_t> bytes, bool is_signed);

}  // namespace omnitwin::controller::ethercat
