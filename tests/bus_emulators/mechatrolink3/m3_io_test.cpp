// Tests bus_emulators/mechatrolink3/m3_io: the standard I/O profile through the slave link:
// CONNECT as profile 30h with its data lengths (16-64 bytes; a servo length of 32 too, but
// not 8), DATA_RWA (phases 2 and 3) and DATA_RWS (phase 3 only) write the outputs and answer
// the inputs, ID_RD names the device, a servo command is unsupported, and a lost connection
// puts the outputs to 0.
#include "bus_emulators/mechatrolink3/m3_io.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace omnitwin::m3 {
namespace {

class M3Io : public ::testing::Test {
 protected:
  IoProfile io{IoConfig{.inputs = 4, .outputs = 2, .id = "IO-TEST"}};
  std::vector<std::vector<std::uint8_t>> sent;
  SlaveLink link{LinkConfig{.address = 0x10}, io,
                 [this](std::span<const std::uint8_t> f, SimTime) { sent.emplace_back(f.begin(), f.end()); }};
  std::uint8_t wdt = 0;

  FrameView exchange(std::uint8_t code, std::vector<std::uint8_t> d) {
    wdt = static_cast<std::uint8_t>(wdt + 0x10);
    d[0] = code;
    d[1] = wdt;
    std::vector<std::uint8_t> b(kMaxFrame);
    b.resize(encode(FrameSpec{.dst = 0x10, .type = FrameType::cyclic_command, .data = d}, b));
    link.on_frame(b, 0);
    FrameView v;
    EXPECT_EQ(decode(sent.back(), v), FrameStatus::ok);
    return v;
  }
  CmdAlarm connect(std::size_t len) {
    std::vector<std::uint8_t> d(len, 0);
    d[4] = 0x30;
    d[5] = 0x00;  // asynchronous
    d[6] = 1;
    d[7] = 0x30;  // standard I/O
    return unpack_stat(get_u16(exchange(0x0E, d).data, 2)).cmd_alm;
  }
};

TEST_F(M3Io, ConnectsAsTheIoProfileWithItsLengths) {
  link.power_on(0);
  std::vector<std::uint8_t> d(16, 0);
  d[4] = 0x30;
  d[6] = 1;
  d[7] = 0x10;  // a servo profile to an I/O station
  EXPECT_EQ(unpack_stat(get_u16(exchange(0x0E, d).data, 2)).cmd_alm, CmdAlarm::invalid_data);
  EXPECT_EQ(connect(8), CmdAlarm::invalid_data);
  EXPECT_EQ(connect(16), CmdAlarm::normal);
  EXPECT_EQ(link.phase(), Phase::p2);
}

TEST_F(M3Io, DataExchangeWritesOutputsAndAnswersInputs) {
  link.power_on(0);
  ASSERT_EQ(connect(16), CmdAlarm::normal);
  io.set_input(0, 0xA5);
  io.set_input(3, 0x3C);
  std::vector<std::uint8_t> d(16, 0);
  d[4] = 0x81;
  d[5] = 0x42;
  const FrameView v = exchange(kDataRwa, d);
  EXPECT_EQ(io.output(0), 0x81);
  EXPECT_EQ(io.output(1), 0x42);
  EXPECT_EQ(v.data[4], 0xA5);
  EXPECT_EQ(v.data[7], 0x3C);
  EXPECT_EQ(v.data[8], 0) << "only the station's four input bytes";
  EXPECT_EQ(unpack_stat(get_u16(v.data, 2)).cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(io.writes(), 1u);
}

// DATA_RWS is the synchronous data command: like INTERPOLATE it needs phase 3, and before it
// is a phase error that writes nothing; DATA_RWA works in phases 2 and 3.
TEST_F(M3Io, DataRwsNeedsPhase3) {
  link.power_on(0);
  std::vector<std::uint8_t> n(16, 0);
  put_u32(n, 0, 1'000'000);
  std::vector<std::uint8_t> b(kMaxFrame);
  b.resize(encode(FrameSpec{.dst = kBroadcast, .type = FrameType::cycle_notify, .data = n}, b));
  link.on_frame(b, 0);
  std::vector<std::uint8_t> d(16, 0);
  d[4] = 0x30;
  d[5] = kComModSync;
  d[6] = 1;
  d[7] = 0x30;
  ASSERT_EQ(unpack_stat(get_u16(exchange(0x0E, d).data, 2)).cmd_alm, CmdAlarm::normal);
  std::vector<std::uint8_t> w(16, 0);
  w[4] = 0xA5;
  const FrameView v = exchange(kDataRws, w);
  EXPECT_EQ(v.data[0], kDataRws);
  EXPECT_EQ(unpack_stat(get_u16(v.data, 2)).cmd_alm, CmdAlarm::phase_error) << "phase 2";
  EXPECT_EQ(io.output(0), 0);
  EXPECT_EQ(io.writes(), 0u);
  ASSERT_EQ(unpack_stat(get_u16(exchange(kDataRwa, w).data, 2)).cmd_alm, CmdAlarm::normal);
  ASSERT_EQ(unpack_stat(get_u16(exchange(0x0D, d).data, 2)).cmd_alm, CmdAlarm::normal);  // SYNC_SET
  ASSERT_EQ(link.phase(), Phase::p3);
  w[4] = 0x5A;
  EXPECT_EQ(unpack_stat(get_u16(exchange(kDataRws, w).data, 2)).cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(io.output(0), 0x5A);
  EXPECT_EQ(unpack_stat(get_u16(exchange(kDataRwa, w).data, 2)).cmd_alm, CmdAlarm::normal);
}

// The profile reads its fields at fixed offsets, so a command shorter (or longer) than the
// connection's length is refused, not executed: an 8-byte ID_RD after a 16-byte CONNECT read
// bytes 12-14 past the frame (ASan, found in review).
TEST_F(M3Io, ACommandOfAnotherLengthThanTheConnectionsIsRefusedNotRun) {
  link.power_on(0);
  ASSERT_EQ(connect(16), CmdAlarm::normal);
  std::vector<std::uint8_t> shorter(8, 0);
  const FrameView v = exchange(0x03, shorter);
  EXPECT_EQ(v.data.size(), 8u);
  EXPECT_EQ(unpack_stat(get_u16(v.data, 2)).cmd_alm, CmdAlarm::invalid_data);
  std::vector<std::uint8_t> longer(32, 0);
  longer[4] = 0x81;
  EXPECT_EQ(unpack_stat(get_u16(exchange(kDataRwa, longer).data, 2)).cmd_alm, CmdAlarm::invalid_data);
  EXPECT_EQ(io.writes(), 0u);
  EXPECT_EQ(link.stats().length_errors, 2u);
  std::vector<std::uint8_t> right(16, 0);
  EXPECT_EQ(unpack_stat(get_u16(exchange(kDataRwa, right).data, 2)).cmd_alm, CmdAlarm::normal);
}

TEST_F(M3Io, IdReadAndAServoCommand) {
  link.power_on(0);
  ASSERT_EQ(connect(32), CmdAlarm::normal);
  std::vector<std::uint8_t> d(32, 0);
  d[14] = 7;
  const FrameView v = exchange(0x03, d);
  EXPECT_EQ(std::string(v.data.begin() + 16, v.data.begin() + 23), "IO-TEST");
  EXPECT_EQ(unpack_stat(get_u16(exchange(0x3C, d).data, 2)).cmd_alm, CmdAlarm::unsupported) << "VELCTRL";
}

TEST_F(M3Io, ALostConnectionPutsTheOutputsToZero) {
  link.power_on(0);
  ASSERT_EQ(connect(16), CmdAlarm::normal);
  std::vector<std::uint8_t> d(16, 0);
  d[4] = 0xFF;
  exchange(kDataRwa, d);
  ASSERT_EQ(io.output(0), 0xFF);
  exchange(0x0F, d);  // DISCONNECT
  EXPECT_EQ(io.output(0), 0);
}

}  // namespace
}  // namespace omnitwin::m3
