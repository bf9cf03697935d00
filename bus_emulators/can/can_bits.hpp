// bus_emulators/can — the exact bit sequence of a classic CAN frame on the wire (ISO 11898-1).
//
// A data or remote frame is, in transmission order:
//   SOF (1, dominant)
//   arbitration: base identifier (11), RTR                                   — standard (CAN 2.0A)
//                base identifier (11), SRR (1), IDE (1), extension (18), RTR  — extended (CAN 2.0B)
//   control:     IDE (0), r0 (0), DLC (4)                                    — standard
//                r1 (0), r0 (0), DLC (4)                                     — extended
//   data (8 · payload bytes, most significant bit first)
//   CRC sequence (15): CRC-15, polynomial 0x4599, initial value 0, over the destuffed bits
//                      from SOF through the last data bit
//   — the stuffed region (SOF … last CRC bit) ends here; after five equal consecutive bits
//     a bit of the opposite value is inserted, and stuff bits themselves count towards the
//     next run —
//   CRC delimiter (1, recessive), ACK slot (1), ACK delimiter (1, recessive), EOF (7,
//   recessive), and, between frames, the intermission (3, recessive).
// Bits are stored as std::uint8_t: 0 = dominant, 1 = recessive. The ACK slot is written
// dominant, i.e. as seen on a bus where some receiver acknowledged.
//
// An error frame (FrameKind::error) is an active error flag (6 dominant) and the error
// delimiter (8 recessive); it is never stuffed and carries no CRC.
//
// Nothing here allocates: every sequence fits a fixed BitBuffer of kMaxWireBits bits (the
// longest possible frame, an extended 8-byte frame with the worst-case 29 stuff bits plus
// the intermission, is 160 bits). Every function is real-time safe.
#pragma once

#include <array>
#include <cstdint>

#include "bus_emulators/can/can_frame.hpp"

namespace omnitwin::can {

// Field lengths and bus-level constants [bits].
inline constexpr int kSofBits = 1;
inline constexpr int kCrcBits = 15;
inline constexpr int kEofBits = 7;
inline constexpr int kIntermissionBits = 3;
inline constexpr int kErrorFlagBits = 6;
inline constexpr int kErrorDelimiterBits = 8;
inline constexpr int kSuspendTransmissionBits = 8;   // error-passive transmitter, after intermission
inline constexpr int kBusOffRecoverySequences = 128; // occurrences of …
inline constexpr int kRecoverySequenceBits = 11;     // … 11 consecutive recessive bits
inline constexpr int kMaxWireBits = 160;             // worst-case extended 8-byte frame + intermission
inline constexpr std::uint16_t kCrc15Polynomial = 0x4599;

// Whether a length or sequence includes the 3-bit intermission that follows every frame.
enum class Intermission : bool { excluded = false, included = true };

// A fixed-capacity sequence of bits (0 = dominant, 1 = recessive). Real-time safe.
struct BitBuffer {
  std::array<std::uint8_t, kMaxWireBits> bits{};
  int size = 0;

  // Appends one bit; throws std::length_error past kMaxWireBits (cannot happen for a valid
  // Frame: a programmer error).
  void push(std::uint8_t bit);
  // Appends the `count` low bits of `value`, most significant first.
  void push_value(std::uint32_t value, int count);
  std::uint8_t operator[](int i) const { return bits[static_cast<std::size_t>(i)]; }
  const std::uint8_t* data() const { return bits.data(); }
  const std::uint8_t* begin() const { return bits.data(); }
  const std::uint8_t* end() const { return bits.data() + size; }
};

// CRC-15/CAN of `count` bits (each 0 or 1, transmission order). Real-time safe.
std::uint16_t crc15(const std::uint8_t* bits, int count);

// The CRC input: the destuffed bits from SOF through the last data bit (empty for an error
// frame). Real-time safe.
BitBuffer crc_input_bits(const Frame& f);

// The whole frame without stuff bits: SOF … EOF, plus the intermission if asked. Standard
// data frames are 44 + 8·n bits, extended 64 + 8·n (remote frames: n = 0). Real-time safe.
BitBuffer unstuffed_bits(const Frame& f, Intermission ifs = Intermission::excluded);

// The frame exactly as on the wire: stuffed SOF … CRC, then the fixed-form tail, plus the
// intermission if asked. Real-time safe.
BitBuffer stuffed_bits(const Frame& f, Intermission ifs = Intermission::excluded);

// Number of stuff bits the frame's actual content needs (0 for an error frame).
int stuff_bit_count(const Frame& f);

// Length of the stuffed region, SOF through the last CRC bit, including stuff bits [bits].
// The ACK slot is bit number stuffed_region_bits(f) + 1 counted from SOF = 0.
int stuffed_region_bits(const Frame& f);

// Total bits on the wire including stuff bits, delimiters, ACK and EOF, WITHOUT the
// intermission [bits]. Real-time safe.
int frame_bits(const Frame& f);
// The same WITH the 3-bit intermission: the bus time one frame occupies back to back [bits].
int frame_bits_with_intermission(const Frame& f);

// The classic worst-case bound (Tindell, Burns & Wellings): every bit of the stuffable region
// after the first five costs a stuff bit every four bits, floor((g + 8n − 1) / 4) with
// g = 34 (standard) or 54 (extended). Including the intermission that is 55 + 10n standard
// and 80 + 10n extended. No real frame reaches it exactly (fixed bits and the CRC break the
// pattern). Throws std::invalid_argument for n outside 0..8 (set-up use).
int worst_case_frame_bits(bool extended, int data_bytes, Intermission ifs = Intermission::included);

// Removes the stuff bits from a received stuffed region (SOF … last CRC bit, any length).
// Returns false on a stuff error (six equal consecutive bits), leaving `out` with the bits
// decoded so far. Real-time safe.
bool destuff(const std::uint8_t* stuffed, int count, BitBuffer& out);

}  // namespace omnitwin::can
