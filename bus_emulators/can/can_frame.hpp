// bus_emulators/can — the classic CAN frame (CAN 2.0A/2.0B), shared by every CAN layer.
//
// A plain value type: identifier, format (standard 11-bit / extended 29-bit), kind (data,
// remote, error), DLC and up to 8 data bytes. The bit-level layer (can_bits), the bus core
// (can_bus), the controller models (sja1000, ecan) and every transport pass frames as this
// type; nothing here knows about sockets or time.
#pragma once

#include <array>
#include <cstdint>
#include <string>

namespace omnitwin::can {

enum class FrameKind : std::uint8_t { data, remote, error };

struct Frame {
  std::uint32_t id = 0;        // 11-bit (standard) or 29-bit (extended) identifier
  bool extended = false;       // CAN 2.0B 29-bit identifier
  FrameKind kind = FrameKind::data;
  std::uint8_t dlc = 0;        // 0..8 (a remote frame still carries its DLC)
  std::array<std::uint8_t, 8> data{};  // the first min(dlc, 8) bytes are meaningful

  // Number of data bytes on the wire: dlc for data frames (capped at 8), 0 otherwise.
  int payload_size() const { return kind == FrameKind::data ? (dlc > 8 ? 8 : dlc) : 0; }
  // Identifier fits its format and dlc <= 8. Real-time safe.
  bool valid() const;
};

bool operator==(const Frame& a, const Frame& b);  // compares only the meaningful bytes

// "0x102 [5] 02 00 00 00 00", "0x000 R [0]", "0x1ABCDEF0 X [2] …" — for logs and tests.
std::string to_string(const Frame& f);

// Convenience constructors (throw std::invalid_argument on a bad id/size: set-up code only).
Frame make_data(std::uint32_t id, std::initializer_list<std::uint8_t> bytes, bool extended = false);
Frame make_remote(std::uint32_t id, std::uint8_t dlc = 0, bool extended = false);

}  // namespace omnitwin::can
