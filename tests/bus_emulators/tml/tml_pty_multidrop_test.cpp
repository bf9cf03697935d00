// Tests bus_emulators/tml/tml_pty's RS-485 multi-drop line: three drives (axes 1, 2, 3) share one
// pseudo-terminal opened by the test with plain termios (8N2, 9600 bit/s). A command to one axis
// is acknowledged once, by that drive alone, and changes only it; a group message (RS-485: no
// acknowledgement, seed ch. 3) reaches every member; GiveMeData to one axis is answered by that
// axis; GROUPID/ADDGRID change which group messages reach a drive (found in review: the ports
// filtered with the group mask of the set-up); two drives of other protocols cannot share the line.
#include "bus_emulators/tml/tml_pty.hpp"
#include "tests/support/raw_serial.hpp"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <memory>
#include <vector>

namespace omnitwin::tml {
namespace {

using Bytes = std::vector<std::uint8_t>;

DriveSetup rs485(std::uint8_t axis) {
  DriveSetup s;
  s.axis = axis, s.host_axis = 15, s.protocol = Protocol::rs485;
  return s;
}

struct MultiDrop : ::testing::Test {
  std::vector<std::unique_ptr<TmlDrive>> drives;
  std::unique_ptr<TmlPty> pty;
  int fd = -1;

  void SetUp() override {
    for (std::uint8_t a : {1, 2, 3}) {
      drives.push_back(std::make_unique<TmlDrive>(rs485(a), nullptr));
      drives.back()->power_on(TmlPty::monotonic_ns());
    }
    pty = std::make_unique<TmlPty>(*drives[0], 9600);
    pty->add_drop(*drives[1]);
    pty->add_drop(*drives[2]);
    fd = omnitwin::testing::open_raw_serial_8n2(pty->slave_path(), B9600);
    ASSERT_GE(fd, 0) << pty->slave_path();
  }
  void TearDown() override {
    if (fd >= 0) close(fd);
  }
  void send(const Message& m) {
    const Packet p = encode_packet(m);
    ASSERT_EQ(write(fd, p.bytes.data(), p.size), static_cast<ssize_t>(p.size));
  }
  // Runs the line for timeout_ms; everything that came back.
  Bytes receive(int timeout_ms) {
    Bytes got;
    const std::int64_t end = TmlPty::monotonic_ns() + timeout_ms * 1'000'000LL;
    for (std::int64_t now = TmlPty::monotonic_ns(); now < end; now = TmlPty::monotonic_ns()) {
      pty->service(now);
      for (auto& d : drives) d->step(now, drive::Feedback{});
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
  std::uint32_t kpp(int i) {
    std::uint32_t v = 0;
    EXPECT_TRUE(drives[static_cast<std::size_t>(i)]->read(0x025E, false, v));
    return v;
  }
};

TEST_F(MultiDrop, OnlyTheAddressedDriveAcknowledgesAndChanges) {
  send(*assign16(axis_id_code(2), 0x025E, 5));
  EXPECT_EQ(receive(100), Bytes{0x4F});  // one 'O', not three
  EXPECT_EQ(kpp(0), 0x0120u);
  EXPECT_EQ(kpp(1), 5u);
  EXPECT_EQ(kpp(2), 0x0120u);
}

TEST_F(MultiDrop, AGroupMessageReachesEveryoneUnacknowledged) {
  send(*assign16(group_id_code(group_mask(1)), 0x025E, 7));
  EXPECT_TRUE(receive(100).empty());
  for (int i = 0; i < 3; ++i) EXPECT_EQ(kpp(i), 7u) << i;
}

TEST_F(MultiDrop, GroupIdAndAddGridChangeWhichGroupMessagesReachADrive) {
  send(instruction(axis_id_code(2), instr::addgrid, 2));  // axis 2: groups 1 and 2
  EXPECT_EQ(receive(60), Bytes{0x4F});
  send(instruction(axis_id_code(3), instr::groupid, 2));  // axis 3: group 2 only
  EXPECT_EQ(receive(60), Bytes{0x4F});
  ASSERT_EQ(drives[1]->groups(), 0x03);
  send(*assign16(group_id_code(group_mask(2)), 0x025E, 9));
  EXPECT_TRUE(receive(60).empty());
  EXPECT_EQ(kpp(0), 0x0120u);
  EXPECT_EQ(kpp(1), 9u);
  EXPECT_EQ(kpp(2), 9u);
  send(*assign16(group_id_code(group_mask(1)), 0x025E, 7));
  EXPECT_TRUE(receive(60).empty());
  EXPECT_EQ(kpp(0), 7u);
  EXPECT_EQ(kpp(1), 7u);
  EXPECT_EQ(kpp(2), 9u);  // no longer in group 1
}

TEST_F(MultiDrop, GiveMeDataIsAnsweredByTheAddressedAxis) {
  send(*assign16(axis_id_code(3), 0x025E, 9));
  receive(60);
  send(give_me_data(axis_id_code(3), axis_id_code(15), 0x025E, false));
  const Bytes got = receive(150);
  ASSERT_GE(got.size(), 1u + 12u) << got.size();
  EXPECT_EQ(got[0], 0x4F);
  Message m;
  ASSERT_EQ(decode_packet(std::span<const std::uint8_t>(got.data() + 1, 12), m), PacketStatus::ok);
  const Classified c = classify(m);
  EXPECT_EQ(c.kind, Kind::take_data);
  EXPECT_EQ(c.value, 9u);
  EXPECT_EQ(c.sender, axis_id_code(3));
}

TEST(MultiDropSetup, OnlyRs485SharesALine) {
  DriveSetup a = rs485(1);
  a.protocol = Protocol::rs232;
  TmlDrive d1(a, nullptr), d2(rs485(2), nullptr);
  TmlPty pty(d1, 9600);
  EXPECT_THROW(pty.add_drop(d2), std::invalid_argument);
}

}  // namespace
}  // namespace omnitwin::tml
