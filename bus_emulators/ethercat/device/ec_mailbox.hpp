// bus_emulators/ethercat/device — the EtherCAT mailbox header codec (ETG.1000.4 / .6).
//
// Every mailbox message (SM0 master→slave, SM1 slave→master) starts with a 6-byte header:
// u16 length of the data after the header, u16 station address (of the source for requests),
// u8 channel (bits 0–5) | priority (bits 6–7), u8 type (bits 0–3: 0 error, 1 AoE, 2 EoE,
// 3 CoE, 4 FoE, 5 SoE, 15 VoE) | counter (bits 4–6, 1–7, 0 = not used) | reserved bit 7.
// Unsupported or malformed requests get a mailbox error reply (type 0) with a u16 service type
// 0x0001 and a u16 detail code. Pure functions on caller buffers: RT-safe, no throw.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

namespace omnitwin::ethercat {

inline constexpr std::size_t kMailboxHeaderSize = 6;

enum class MailboxType : std::uint8_t { error = 0, aoe = 1, eoe = 2, coe = 3, foe = 4, soe = 5, voe = 15 };

// Detail codes of a mailbox error reply (type 0, service 0x0001).
enum class MailboxError : std::uint16_t {
  syntax = 0x0001, unsupported_protocol = 0x0002, invalid_channel = 0x0003, service_not_supported = 0x0004,
  invalid_header = 0x0005, size_too_short = 0x0006, no_more_memory = 0x0007, invalid_size = 0x0008,
};
const char* to_string(MailboxError e);

struct MailboxHeader {
  std::uint16_t length = 0;    // bytes after the header
  std::uint16_t address = 0;
  std::uint8_t channel = 0;    // 0..63
  std::uint8_t priority = 0;   // 0..3
  std::uint8_t type = 0;       // MailboxType value (0..15)
  std::uint8_t counter = 0;    // 0..7
};

// Decodes the header of a mailbox buffer; nullopt when shorter than 6 bytes.
std::optional<MailboxHeader> decode_mailbox_header(std::span<const std::uint8_t> mbx) noexcept;
// Writes the header into out[0..5]; out must hold 6 bytes.
void encode_mailbox_header(const MailboxHeader& h, std::uint8_t* out) noexcept;
// The counter a slave uses after `c` (1..7, wrapping 7 → 1; 0 → 1).
inline std::uint8_t next_mailbox_counter(std::uint8_t c) noexcept { return c >= 7 ? 1 : static_cast<std::uint8_t>(c + 1); }
// A complete error reply (header + 4 bytes) into out (>= 10 bytes); returns its size (10), 0 if out is too small.
std::size_t encode_mailbox_error(MailboxError e, std::uint8_t counter, std::span<std::uint8_t> out) noexcept;

}  // namespace omnitwin::ethercat
