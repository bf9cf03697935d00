// bus_emulators/can — python-can's `udp_multicast` wire format (one msgpack map per datagram).
//
// A pure codec: Frame + timestamp <-> the bytes python-can's
// can/interfaces/udp_multicast/utils.py pack_message()/unpack_message() produce and accept.
// The map has exactly these keys (python-can 4.1), in this order when we encode:
//   timestamp (float64, seconds), arbitration_id (uint), is_extended_id (bool),
//   is_remote_frame (bool), is_error_frame (bool), channel (nil | str | int),
//   dlc (uint), data (bin), is_fd (bool), bitrate_switch (bool), error_state_indicator (bool)
// Our encoding of a frame is byte-identical to python-can's for the same message.
//
// Decoding follows python-can's receiving side (Message(check=True, **map)): a missing key
// takes python-can's default (note: is_extended_id defaults to true, dlc to len(data)); an
// unknown key, a wrong value type, an out-of-range identifier, dlc != len(data) for data and
// error frames, data on a remote frame, remote+error together, or bitrate_switch /
// error_state_indicator on a classic frame are rejected. `data` may also be an array of
// integers 0..255 (python-can accepts that). CAN FD frames are well-formed but unsupported.
// decode() never throws and never reads outside the given bytes; its only allocation is the
// msgpack parser's small stack.
#pragma once

#include "bus_emulators/can/can_frame.hpp"

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace omnitwin::can::msgpack_wire {

enum class DecodeStatus : std::uint8_t {
  ok,
  malformed,        // not one complete msgpack value, trailing bytes, not a map, nesting, too big
  unknown_key,      // a key python-can's Message() does not accept (or a duplicate key)
  bad_type,         // a known key with a value of the wrong msgpack type
  bad_id,           // identifier outside its format (11 / 29 bits) or negative
  wrong_dlc,        // dlc > 8, or dlc != number of data bytes for a data / error frame
  invalid_flags,    // remote+error, data on a remote frame, BRS/ESI on a classic frame
  fd_unsupported,   // a well-formed CAN FD frame: this twin models classic CAN only
};
const char* to_string(DecodeStatus s);

struct Decoded {
  Frame frame;
  double timestamp = 0.0;  // seconds, as the sender stamped it (python-can: time.time())
};

// Our largest encoding (8 data bytes, identifier >= 0x10000) is 164 bytes.
inline constexpr std::size_t kMaxEncodedSize = 256;
// python-can's receiver reads at most this many bytes per datagram.
inline constexpr std::size_t kMaxDatagramSize = 4096;

// Encodes into `out`; returns the number of bytes written, or 0 when the frame is invalid
// (identifier out of range, dlc > 8) or `out` is too small. Data and error frames carry
// min(dlc, 8) data bytes; remote frames carry their dlc and no data. Real-time safe.
std::size_t encode(const Frame& f, double timestamp_s, std::span<std::uint8_t> out);
// Convenience for set-up code and tests; throws std::invalid_argument on an invalid frame.
std::vector<std::uint8_t> encode(const Frame& f, double timestamp_s);

// Decodes one datagram. On anything but ok, `out` is unspecified.
DecodeStatus decode(std::span<const std::uint8_t> bytes, Decoded& out) noexcept;

}  // namespace omnitwin::can::msgpack_wire
