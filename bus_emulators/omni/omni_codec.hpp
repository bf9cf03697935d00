// bus_emulators/omni — the thesis's Omni application protocol on classic CAN (seed 002,
// section 3-2-1 and 4-4-1; table 3-3, table 4-2, fig. 4-18 … 4-20).
//
// A pure codec between can::Frame and the six message types the omni-directional platform
// exchanges: NMT start/stop, node detection request and answer, the broadcast four-axis speed
// command, per-axis speed feedback and parameter set-up. Nothing here knows about sockets,
// threads or time; nothing allocates; nothing throws on bad input — decode() and encode()
// report an OmniError instead. Every choice the thesis leaves open (stop code, byte order of
// the command frame, units, data-type codes, 5-byte command frame) is documented in
// docs/protocols/omni-can.md.
//
// Omni-ID (fig. 3-13) = the 11-bit standard identifier: bits 10–8 function code, bits 7–0
// Node-ID. In NMT and broadcast frames the Node-ID is the SENDER; in process-data and
// parameter frames it is the RECEIVER (3-2-1). Where a frame also carries its sender in data
// byte 0, decode() checks that the two agree.
#pragma once

#include "bus_emulators/can/can_frame.hpp"

#include <array>
#include <cstdint>
#include <optional>
#include <variant>

namespace omnitwin::omni {

// Table 3-3: the function code, bits 10–8 of the Omni-ID.
enum class FunctionCode : std::uint8_t {
  nmt = 0b000,                // ID 0: NMT master (commands, detection request); 1–255: slaves' answers
  broadcast_8x1byte = 0b001,  // 0x101–0x1FF: up to 8 nodes, 1 byte each (the speed command)
  process_data_1 = 0b010,     // 0x201–0x2FF: process data (axis 1 feedback, 0x202)
  process_data_2 = 0b011,     // 0x301–0x3FF: process data (axis 2 feedback, 0x302)
  broadcast_4x2byte = 0b100,  // 0x401–0x4FF: up to 4 nodes, 2 bytes each (unused by the platform)
  process_data_3 = 0b101,     // 0x501–0x5FF: process data (axis 3 feedback, 0x502)
  process_data_4 = 0b110,     // 0x601–0x6FF: process data (axis 4 feedback, 0x602)
  parameter_setup = 0b111,    // 0x701–0x7FF: parameter set-up, lowest priority
};

// Node IDs of the platform (4-4-1).
namespace node {
inline constexpr std::uint8_t all = 0x00;     // NMT target "every node"
inline constexpr std::uint8_t pc = 0x01;      // PC monitor
inline constexpr std::uint8_t master = 0x02;  // motion master
inline constexpr std::uint8_t axis1 = 0x04;   // slave of axis 1 (feedback on 0x202)
inline constexpr std::uint8_t axis2 = 0x08;   // slave of axis 2 (feedback on 0x302)
inline constexpr std::uint8_t axis3 = 0x10;   // slave of axis 3 (feedback on 0x502)
inline constexpr std::uint8_t axis4 = 0x20;   // slave of axis 4 (feedback on 0x602)
inline constexpr std::array<std::uint8_t, 4> slaves = {axis1, axis2, axis3, axis4};
}  // namespace node

// Data-type codes (byte 1 of process-data and parameter frames). The thesis names only 0x0C;
// 0x00 and 0x01 are read off fig. 4-20 / 4-19. decode() passes any other code through
// unchanged (see docs/protocols/omni-can.md).
namespace data_type {
inline constexpr std::uint8_t speed = 0x00;                     // slave → master feedback (fig. 4-20)
inline constexpr std::uint8_t axis_controller_setting = 0x01;   // master → slave (fig. 4-19)
inline constexpr std::uint8_t slave_controller_setting = 0x0C;  // PC → master, for all slaves (fig. 4-19)
}  // namespace data_type

// Identifier helpers. Real-time safe, constexpr.
constexpr std::uint16_t omni_id(FunctionCode fc, std::uint8_t node_id) {
  return static_cast<std::uint16_t>((static_cast<unsigned>(fc) << 8) | node_id);
}
constexpr FunctionCode function_code(std::uint16_t id) {
  return static_cast<FunctionCode>((id >> 8) & 0x7u);
}
constexpr std::uint8_t node_id(std::uint16_t id) { return static_cast<std::uint8_t>(id & 0xFFu); }

// Axis number 1..4 of a slave Node-ID, or 0 if `n` is not a slave. Real-time safe.
int axis_of_slave(std::uint8_t n);
// Slave Node-ID of axis 1..4, or 0 for any other axis number. Real-time safe.
std::uint8_t slave_of_axis(int axis);
// The process-data function code axis 1..4 reports its feedback on (table 4-2), or nullopt.
std::optional<FunctionCode> feedback_function(int axis);

// --- messages -------------------------------------------------------------------------------

// NMT state byte (fig. 3-14). 1 = start is the thesis's; 2 = stop is our choice (CANopen's
// "stop remote node"), the thesis never prints the stop code.
enum class NmtState : std::uint8_t { start = 0x01, stop = 0x02 };

// ID 0x000, data, 2 bytes: byte 0 target Node-ID (0 = all), byte 1 state. Sent by the PC
// (to the master or a slave) or by the master (to the slaves): the identifier cannot tell
// which. Target must be all, the master or a slave.
struct NmtCommand {
  std::uint8_t target = node::all;
  NmtState state = NmtState::start;
  bool operator==(const NmtCommand&) const = default;
};

// ID 0x000, remote frame, DLC 0: "every node, answer".
struct DetectionRequest {
  bool operator==(const DetectionRequest&) const = default;
};

// Remote frame, DLC 0, ID = the answering node's own Node-ID (fig. 4-18: 2, 4, 8, 16, 32).
// Only the master and the slaves answer (table 4-2).
struct DetectionAnswer {
  std::uint8_t node = node::master;
  bool operator==(const DetectionAnswer&) const = default;
};

// ID 0x100 | sender (0x102), data, 5 bytes as captured in fig. 4-20:
//   byte 0 sender Node-ID (= the identifier's Node-ID, must be the master),
//   byte 1 axis 4, byte 2 axis 3, byte 3 axis 2, byte 4 axis 1 ("the highest byte is axis 4,
//   then axis 3 …", 4-4-1; the thesis's "highest byte" is the first byte on the wire).
// Each command is int8 two's complement, in encoder counts per sampling period (our choice).
struct SpeedCommand {
  std::uint8_t sender = node::master;
  std::array<std::int8_t, 4> axis{};  // axis[0] = axis 1 … axis[3] = axis 4
  bool operator==(const SpeedCommand&) const = default;
};

// ID (process_data_k << 8) | 0x02 (0x202/0x302/0x502/0x602), data, 6 bytes: byte 0 sender
// (the slave of axis k), byte 1 data type, bytes 2–5 value, int32 big-endian two's
// complement. The identifier's Node-ID is the receiver and must be the master; the function
// code must be the sender's axis's (table 4-2). For data_type::speed the value is in encoder
// counts per sampling period (our choice).
struct SpeedFeedback {
  std::uint8_t sender = node::axis1;
  std::uint8_t data_type = data_type::speed;
  std::int32_t value = 0;
  bool operator==(const SpeedFeedback&) const = default;
};

// ID 0x700 | receiver, data: byte 0 sender, byte 1 data type, then the value big-endian:
// DLC 6 → 4-byte value (PC → master 0x702, fig. 4-19), DLC 4 → 2-byte value (master →
// 0x704/0x708/0x710/0x720). The receiver is the master or a slave; the sender is the PC or
// the master and not the receiver. The value is carried as raw bits (zero-extended for two
// bytes); its meaning and signedness belong to the data type.
enum class ParamWidth : std::uint8_t { two_bytes = 2, four_bytes = 4 };
struct ParameterSetup {
  std::uint8_t receiver = node::master;
  std::uint8_t sender = node::pc;
  std::uint8_t data_type = data_type::slave_controller_setting;
  ParamWidth width = ParamWidth::four_bytes;
  std::uint32_t value = 0;  // raw; must fit `width`
  bool operator==(const ParameterSetup&) const = default;
};

using Message = std::variant<NmtCommand, DetectionRequest, DetectionAnswer, SpeedCommand,
                             SpeedFeedback, ParameterSetup>;

// Why a frame is not a valid Omni message (or a message cannot be encoded). decode() checks
// in this order and reports the first failure.
enum class OmniError : std::uint8_t {
  not_omni,          // extended identifier, error frame, identifier above 0x7FF, unknown kind
  unknown_function,  // a function code the platform sends nothing on (100, broadcast 4×2 bytes)
  wrong_kind,        // remote where a data frame is defined or the other way round
  wrong_dlc,         // DLC other than the message's (remote frames: DLC 0; DLC > 8)
  bad_node,          // identifier Node-ID or sender byte not allowed, or the two disagree
  bad_value,         // NMT state not 1/2; a value that does not fit its field (encode)
};
using DecodeError = OmniError;
using EncodeError = OmniError;
// Stable lowercase name ("not_omni", …); never nullptr. Real-time safe.
const char* to_string(OmniError e);

using DecodeResult = std::variant<Message, DecodeError>;
using EncodeResult = std::variant<can::Frame, EncodeError>;

// Frame → message. Never throws, never allocates; real-time safe. A successful decode
// re-encodes byte-identically (same id, kind, DLC and data bytes).
DecodeResult decode(const can::Frame& f) noexcept;

// Message → frame: a standard-format frame, remote frames with DLC 0. Fails (bad_node,
// bad_value) exactly when decode() would reject the frame or decode it to a different
// message, so encode success implies decode(encode(m)) == m. Real-time safe.
EncodeResult encode(const Message& m) noexcept;

// --- helpers --------------------------------------------------------------------------------

// Saturating conversion to a 1-byte axis command (counts per sampling period):
// clamps to [-128, 127]. Real-time safe.
std::int8_t saturate_axis_command(std::int64_t counts_per_sample) noexcept;
// Same from a real value: rounds to nearest (halves away from zero), clamps, NaN → 0.
std::int8_t axis_command_from(double counts_per_sample) noexcept;

// The master's step in fig. 4-19: a PC → master slave_controller_setting (type 0x0C) becomes
// one axis_controller_setting (type 0x01, 2-byte value) per slave, sender = master, in axis
// order 0x704, 0x708, 0x710, 0x720. nullopt if `from_pc` is not addressed to the master, is
// not type 0x0C, or its value exceeds 0xFFFF. Real-time safe.
std::optional<std::array<ParameterSetup, 4>> fan_out_to_slaves(const ParameterSetup& from_pc) noexcept;

}  // namespace omnitwin::omni
