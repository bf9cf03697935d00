// bus_emulators/can — the thesis's CAN timing model (seed 002, section 2-2-2).
//
//   T_delay = T_pre + T_wait + T_tx + T_post                                   (eq. 2-1)
//
// T_pre: the sender's processing before the frame is handed to its controller (measured on
// the DSP master: 0.000604 ms, table 2-1); T_wait: time the frame waits for the bus (other
// traffic, arbitration losses, retransmissions: supplied by the bus core, can_bus); T_tx:
// the frame on the wire, frame bits (with the stuff bits its actual content needs, see
// can_bits) divided by the bit rate; T_post: the receiver's processing after reception
// (measured on the 8051 slave: 0.0888 ms, table 2-1).
//
// Table 2-2 (measured T_tx) and which frames reproduce it: the thesis's numbers equal the
// extended-format (29-bit) frame with the INTERMISSION INCLUDED and (near) worst-case bit
// stuffing: 80 + 10·n bit times, the classic worst-case bound, within 3.4 % in every cell.
// No real frame reaches that bound; the most any real extended data frame can need is
// 78 + 10·n bits (found by exhaustive search over identifier, data and the resulting CRC).
// thesis::table_2_2_frame(n) returns such a maximal-stuffing frame for each n; computed
// from their actual bits they reproduce 44 of the 45 cells within 5 %. The cell
// 1000 kbit/s, 0 bytes (0.0828 ms = 82.8 bit times) is NOT claimed: no extended 0-byte data
// frame is longer than 78 bits with the intermission (−5.8 %); even the unreachable bound
// (80 bits) is 3.4 % short. Typical content does not reproduce the table: all-zero data
// with identifier 0 gives 74 + ~9.5·n bits (up to −10.6 %), standard frames are 25–40 %
// shorter. See tests/bus_emulators/can_timing_test.cpp, which prints every cell.
//
// Everything here is pure arithmetic, allocation-free and real-time safe unless noted.
// Times are integer nanoseconds (the twin's timeline), bit rates bits per second.
#pragma once

#include <array>
#include <cstdint>

#include "bus_emulators/can/can_bits.hpp"
#include "bus_emulators/can/can_frame.hpp"

namespace omnitwin::can {

inline constexpr std::int64_t kMinBitRate = 10'000;     // [bit/s]
inline constexpr std::int64_t kMaxBitRate = 1'000'000;  // [bit/s]

// True for a classic-CAN bit rate in 10 kbit/s … 1 Mbit/s.
bool valid_bit_rate(std::int64_t bit_rate_bps);

// Duration of `bits` bit times at `bit_rate_bps`, rounded to the nearest ns [ns]. Exact for
// every rate that divides 10⁹ (all the usual ones). Spans are always computed from a count
// of bits, never by adding rounded bit times, so there is no rounding walk.
std::int64_t bits_to_ns(std::int64_t bits, std::int64_t bit_rate_bps);

// T_tx of one frame [ns]: frame_bits(f) (+ the 3-bit intermission when `ifs` is included,
// as the thesis measured it) at `bit_rate_bps`.
std::int64_t transmission_time_ns(const Frame& f, std::int64_t bit_rate_bps,
                                  Intermission ifs = Intermission::included);

// Per-node processing times of eq. 2-1 [ns].
struct NodeTiming {
  std::int64_t pre_ns = 604;      // T_pre, sender side: 0.000604 ms (DSP, table 2-1)
  std::int64_t post_ns = 88'800;  // T_post, receiver side: 0.0888 ms (8051, table 2-1)
};

// The four terms of eq. 2-1 for one message [ns].
struct MessageDelay {
  std::int64_t pre_ns = 0;
  std::int64_t wait_ns = 0;
  std::int64_t tx_ns = 0;
  std::int64_t post_ns = 0;
  std::int64_t total_ns() const { return pre_ns + wait_ns + tx_ns + post_ns; }
};

// Eq. 2-1 for frame `f` at `bit_rate_bps`, with the bus wait `wait_ns` [ns] measured or
// modelled elsewhere (can_bus), T_pre from the sender's and T_post from the receiver's timing.
MessageDelay message_delay(const Frame& f, std::int64_t bit_rate_bps, std::int64_t wait_ns,
                           const NodeTiming& sender = {}, const NodeTiming& receiver = {});

namespace thesis {

// Table 2-2: measured T_tx [ms], rows by bit rate, columns 0…8 data bytes.
inline constexpr std::array<std::int64_t, 5> kTable22BitRates{1'000'000, 500'000, 250'000,
                                                              125'000, 100'000};
inline constexpr std::array<std::array<double, 9>, 5> kTable22Ms{{
    {0.0828, 0.0904, 0.101, 0.111, 0.121, 0.13, 0.141, 0.15, 0.16},
    {0.16, 0.18, 0.2, 0.218, 0.24, 0.257, 0.278, 0.298, 0.317},
    {0.316, 0.356, 0.394, 0.434, 0.476, 0.51, 0.55, 0.592, 0.63},
    {0.636, 0.708, 0.788, 0.868, 0.944, 1.02, 1.1, 1.18, 1.26},
    {0.776, 0.88, 0.976, 1.08, 1.18, 1.26, 1.37, 1.46, 1.57},
}};

// An extended data frame with `data_bytes` bytes whose content needs the most stuff bits any
// extended frame of that size can need (11 + 2n); its length with the intermission is
// 78 + 10·n bits. Throws std::invalid_argument outside 0..8 (set-up use).
Frame table_2_2_frame(int data_bytes);

// Whether this emulator claims table 2-2's cell (row index into kTable22BitRates, data bytes)
// within 5 %: every cell but 1000 kbit/s with 0 bytes (see the file comment).
bool table_2_2_cell_claimed(int row, int data_bytes);

}  // namespace thesis

}  // namespace omnitwin::can
