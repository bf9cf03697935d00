// Tests bus_emulators/tml/tml_pty — THE ACCEPTANCE TEST of the emulated IDM drive on RS-232: the
// test opens the pty's slave path with plain termios (raw, 8N2, 9600 bit/s) like any serial
// program and talks the seed's bytes to it: KPP = 5 (`06 0F F0 20 5E 00 05 88` → 'O'),
// GiveMeData KPP → 'O' then TakeData with KPP = 5, a bad checksum → no acknowledgement (counted),
// and a lost acknowledgement recovered with a SYNC byte 0x0D echoed and the command resent.
// The answer's bytes arrive no sooner than the 8N2 line at 9600 bit/s allows.
#include "bus_emulators/tml/tml_pty.hpp"
#include "tests/support/raw_serial.hpp"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <vector>

namespace omnitwin::tml {
namespace {

using Bytes = std::vector<std::uint8_t>;
constexpr std::uint32_t kBaud = 9600;

struct TmlPtyTest : ::testing::Test {
  TmlDrive drive{make_setup(), nullptr};
  std::unique_ptr<TmlPty> pty;
  int fd = -1;

  static DriveSetup make_setup() {
    DriveSetup s;
    s.axis = 255, s.protocol = Protocol::rs232;
    return s;
  }
  void SetUp() override {
    drive.power_on(TmlPty::monotonic_ns());
    pty = std::make_unique<TmlPty>(drive, kBaud);
    // A plain serial program: open, raw 8N2 at the baud rate.
    fd = omnitwin::testing::open_raw_serial_8n2(pty->slave_path(), B9600);
    ASSERT_GE(fd, 0) << pty->slave_path();
  }
  void TearDown() override {
    if (fd >= 0) close(fd);
  }
  void send(const Bytes& b) { ASSERT_EQ(write(fd, b.data(), b.size()), static_cast<ssize_t>(b.size())); }
  // Runs the adapter (and the drive's period) until n bytes came back or timeout_ms passed.
  Bytes receive(std::size_t n, int timeout_ms) {
    Bytes got;
    const std::int64_t end = TmlPty::monotonic_ns() + timeout_ms * 1'000'000LL;
    for (std::int64_t now = TmlPty::monotonic_ns(); now < end && got.size() < n; now = TmlPty::monotonic_ns()) {
      pty->service(now);
      drive.step(now, drive::Feedback{});
      pty->wait(now, 500'000);
      pollfd p{fd, POLLIN, 0};
      if (poll(&p, 1, 0) > 0) {
        std::uint8_t buf[64];
        const ssize_t r = read(fd, buf, sizeof buf);
        for (ssize_t i = 0; i < r; ++i) got.push_back(buf[i]);
      }
    }
    return got;
  }
};

TEST_F(TmlPtyTest, SeedKppAssignmentThenGiveMeDataOverATerminal) {
  ASSERT_FALSE(pty->slave_path().empty());
  send({0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x05, 0x88});
  EXPECT_EQ(receive(1, 500), Bytes{0x4F});
  std::uint32_t kpp = 0;
  ASSERT_TRUE(drive.read(reg::kpp, false, kpp));
  EXPECT_EQ(kpp, 5u);
  // GiveMeData KPP: 'O', then TakeData with KPP = 5; checksum = sum mod 256.
  const std::int64_t t0 = TmlPty::monotonic_ns();
  send({0x08, 0x0F, 0xF0, 0xB0, 0x04, 0x0F, 0xF1, 0x02, 0x5E, 0x1B});
  const Bytes got = receive(13, 1000);
  const std::int64_t elapsed = TmlPty::monotonic_ns() - t0;
  Bytes take{0x0A, 0x0F, 0xF1, 0xB4, 0x04, 0x0F, 0xF0, 0x02, 0x5E, 0x00, 0x05};
  take.push_back(checksum(take));
  EXPECT_EQ(take.back(), 0x26);  // the seed's 0x42 − 0x01 − 0x20 + 0x05
  Bytes expected{0x4F};
  expected.insert(expected.end(), take.begin(), take.end());
  EXPECT_EQ(got, expected);
  // 13 bytes of 11 bit times at 9600 bit/s: at least 14.9 ms on the line.
  EXPECT_GE(elapsed, ByteTiming(kBaud).duration_ns(13));
  EXPECT_EQ(drive.stats().answers_sent, 1u);
}

TEST_F(TmlPtyTest, BadChecksumGetsNoAcknowledgement) {
  send({0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x05, 0x89});
  EXPECT_TRUE(receive(1, 100).empty());
  EXPECT_EQ(pty->checksum_errors(), 1u);
  std::uint32_t kpp = 0;
  ASSERT_TRUE(drive.read(reg::kpp, false, kpp));
  EXPECT_EQ(kpp, 0x0120u);  // unchanged
}

TEST_F(TmlPtyTest, LostAcknowledgementRecoveredWithSyncBytes) {
  // The host's command is cut short on the line (its last byte lost): the drive waits for it.
  send({0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x07});
  EXPECT_TRUE(receive(1, 30).empty());  // no 'O' within the host's timeout
  // SYNC bytes: the first completes the broken packet (bad checksum, no 'O'); the next ones are
  // echoed — the link is in step again.
  send({0x0D});
  EXPECT_TRUE(receive(1, 30).empty());
  send({0x0D});
  EXPECT_EQ(receive(1, 200), Bytes{0x0D});
  // Resend: acknowledged and executed.
  send({0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x07, 0x8A});
  EXPECT_EQ(receive(1, 200), Bytes{0x4F});
  std::uint32_t kpp = 0;
  ASSERT_TRUE(drive.read(reg::kpp, false, kpp));
  EXPECT_EQ(kpp, 7u);
  EXPECT_EQ(pty->link_stats().syncs_echoed, 1u);
  // A SYNC byte between packets is echoed at once, too.
  send({0x0D});
  EXPECT_EQ(receive(1, 200), Bytes{0x0D});
}

}  // namespace
}  // namespace omnitwin::tml
