// Tests bus_emulators/ethercat/device/ec_mailbox: the 6-byte mailbox header codec (golden
// bytes both ways, channel/priority and type/counter packing), the counter sequence, and the
// mailbox error reply (type 0, service 0x0001, detail code).
#include "bus_emulators/ethercat/device/ec_mailbox.hpp"

#include <gtest/gtest.h>

#include <array>

namespace omnitwin::ethercat {
namespace {

TEST(EcMailbox, DecodeGoldenHeader) {
  const std::array<std::uint8_t, 6> b = {0x0A, 0x00, 0x34, 0x12, 0x45, 0x53};
  const auto h = decode_mailbox_header(b);
  ASSERT_TRUE(h.has_value());
  EXPECT_EQ(h->length, 10);
  EXPECT_EQ(h->address, 0x1234);
  EXPECT_EQ(h->channel, 5);
  EXPECT_EQ(h->priority, 1);
  EXPECT_EQ(h->type, static_cast<std::uint8_t>(MailboxType::coe));
  EXPECT_EQ(h->counter, 5);
  EXPECT_FALSE(decode_mailbox_header(std::span<const std::uint8_t>(b.data(), 5)).has_value());
}

TEST(EcMailbox, EncodeGoldenHeader) {
  MailboxHeader h;
  h.length = 0x0102;
  h.address = 0x1001;
  h.channel = 3;
  h.priority = 2;
  h.type = 3;
  h.counter = 7;
  std::array<std::uint8_t, 6> b{};
  encode_mailbox_header(h, b.data());
  EXPECT_EQ(b, (std::array<std::uint8_t, 6>{0x02, 0x01, 0x01, 0x10, 0x83, 0x73}));
  const auto back = decode_mailbox_header(b);
  EXPECT_EQ(back->counter, 7);
  EXPECT_EQ(back->priority, 2);
}

TEST(EcMailbox, CounterSequence) {
  EXPECT_EQ(next_mailbox_counter(0), 1);
  EXPECT_EQ(next_mailbox_counter(1), 2);
  EXPECT_EQ(next_mailbox_counter(6), 7);
  EXPECT_EQ(next_mailbox_counter(7), 1);
}

TEST(EcMailbox, ErrorReply) {
  std::array<std::uint8_t, 16> out{};
  ASSERT_EQ(encode_mailbox_error(MailboxError::unsupported_protocol, 2, out), 10u);
  EXPECT_EQ(out[0], 4);     // length
  EXPECT_EQ(out[5], 0x20);  // type 0, counter 2
  EXPECT_EQ(out[6], 0x01);  // service 0x0001
  EXPECT_EQ(out[7], 0x00);
  EXPECT_EQ(out[8], 0x02);  // detail
  EXPECT_EQ(out[9], 0x00);
  std::array<std::uint8_t, 9> small{};
  EXPECT_EQ(encode_mailbox_error(MailboxError::syntax, 1, small), 0u);
  EXPECT_STREQ(to_string(MailboxError::invalid_size), "data length inconsistent");
}

}  // namespace
}  // namespace omnitwin::ethercat
