// bus_emulators/ethercat/device — mailbox header codec (see ec_mailbox.hpp).
#include "bus_emulators/ethercat/device/ec_mailbox.hpp"

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::ethercat {

const char* to_string(MailboxError e) {
  switch (e) {
    case MailboxError::syntax: return "syntax of the mailbox header wrong";
    case MailboxError::unsupported_protocol: return "mailbox protocol not supported";
    case MailboxError::invalid_channel: return "channel field invalid";
    case MailboxError::service_not_supported: return "service in the mailbox protocol not supported";
    case MailboxError::invalid_header: return "mailbox protocol header wrong";
    case MailboxError::size_too_short: return "mailbox data too short";
    case MailboxError::no_more_memory: return "no memory for the mailbox protocol";
    case MailboxError::invalid_size: return "data length inconsistent";
  }
  return "unknown mailbox error";
}

std::optional<MailboxHeader> decode_mailbox_header(std::span<const std::uint8_t> m) noexcept {
  if (m.size() < kMailboxHeaderSize) return std::nullopt;
  MailboxHeader h;
  h.length = get_u16(m.data());
  h.address = get_u16(m.data() + 2);
  h.channel = m[4] & 0x3F;
  h.priority = static_cast<std::uint8_t>(m[4] >> 6);
  h.type = m[5] & 0x0F;
  h.counter = (m[5] >> 4) & 0x07;
  return h;
}

void encode_mailbox_header(const MailboxHeader& h, std::uint8_t* out) noexcept {
  put_u16(out, h.length);
  put_u16(out + 2, h.address);
  out[4] = static_cast<std::uint8_t>((h.channel & 0x3F) | ((h.priority & 0x03) << 6));
  out[5] = static_cast<std::uint8_t>((h.type & 0x0F) | ((h.counter & 0x07) << 4));
}

std::size_t encode_mailbox_error(MailboxError e, std::uint8_t counter, std::span<std::uint8_t> out) noexcept {
  if (out.size() < kMailboxHeaderSize + 4) return 0;
  MailboxHeader h;
  h.length = 4;
  h.type = static_cast<std::uint8_t>(MailboxType::error);
  h.counter = counter;
  encode_mailbox_header(h, out.data());
  put_u16(out.data() + 6, 0x0001);
  put_u16(out.data() + 8, static_cast<std::uint16_t>(e));
  return kMailboxHeaderSize + 4;
}

}  // namespace omnitwin::ethercat
