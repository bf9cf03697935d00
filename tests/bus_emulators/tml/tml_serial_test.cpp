// Tests bus_emulators/tml/tml_serial: the RS-232/RS-485 packet codec against every serial golden
// vector of facts/tml.md (both directions), packet errors, 8N2 byte timing at 9600 and 115200
// bit/s, the receiver, and the host and drive link cores run against each other over a timed
// byte wire: acknowledgement, GiveMeData → TakeData, a bad checksum (no 'O', counted), a lost
// 'O' and a lost byte recovered with SYNC bytes (RS-232: echo then resend; RS-485: 15 SYNC
// bytes then resend), a dead drive (link broken), RS-485 group broadcasts (no 'O') and the
// messages RS-485 forbids.
#include "bus_emulators/tml/tml_serial.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

namespace omnitwin::tml {
namespace {

using Bytes = std::vector<std::uint8_t>;

Bytes bytes_of(const Packet& p) { return {p.bytes.begin(), p.bytes.begin() + p.size}; }

Message msg(std::uint16_t id, std::uint16_t opcode, std::initializer_list<std::uint16_t> words) {
  Message m;
  m.id_code = id, m.opcode = opcode;
  for (auto w : words) m.data[m.count++] = w;
  return m;
}

// Encodes to exactly `wire` and decodes `wire` back to exactly `m`.
void expect_golden(const Message& m, const Bytes& wire) {
  EXPECT_EQ(bytes_of(encode_packet(m)), wire) << to_string(m);
  Message back;
  ASSERT_EQ(decode_packet(wire, back), PacketStatus::ok);
  EXPECT_EQ(back, m);
}

TEST(TmlSerialPacket, GoldenKppAssignment) {
  expect_golden(msg(0x0FF0, 0x205E, {0x0005}), {0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x05, 0x88});
}

TEST(TmlSerialPacket, GoldenGiveMeDataAndTakeData) {
  expect_golden(msg(0x0FF0, 0xB004, {0x0FF1, 0x025E}), {0x08, 0x0F, 0xF0, 0xB0, 0x04, 0x0F, 0xF1, 0x02, 0x5E, 0x1B});
  expect_golden(msg(0x0FF1, 0xB404, {0x0FF0, 0x025E, 0x0120}),
                {0x0A, 0x0F, 0xF1, 0xB4, 0x04, 0x0F, 0xF0, 0x02, 0x5E, 0x01, 0x20, 0x42});
}

TEST(TmlSerialPacket, GoldenTakeData2IsD5FF) {
  expect_golden(msg(0x0FF1, 0xD5FF, {0x090E, 0x8400, 0x0201}),
                {0x0A, 0x0F, 0xF1, 0xD5, 0xFF, 0x09, 0x0E, 0x84, 0x00, 0x02, 0x01, 0x7C});
  EXPECT_EQ(take_data2(master_id(255), 255, 0x090E, 0x02018400, true), msg(0x0FF1, 0xD5FF, {0x090E, 0x8400, 0x0201}));
}

TEST(TmlSerialPacket, Rs485AddressingOfExample2) {
  // Host 255 and drive 1 on RS-485: ID code 0010, sender 0FF0 (HOST = 0).
  EXPECT_EQ(host_sender_code(Link::rs485, 255), 0x0FF0);
  EXPECT_EQ(host_sender_code(Link::rs232, 255), 0x0FF1);
  const Message q = give_me_data(axis_id_code(1), host_sender_code(Link::rs485, 255), 0x025E, false);
  expect_golden(q, {0x08, 0x00, 0x10, 0xB0, 0x04, 0x0F, 0xF0, 0x02, 0x5E, 0x2B});
  const Message a = take_data(axis_id_code(255), axis_id_code(1), 0x025E, 0x0120, false);
  EXPECT_EQ(a, msg(0x0FF0, 0xB404, {0x0010, 0x025E, 0x0120}));
  EXPECT_EQ(check_host_message(Link::rs485, q), LinkCheck::ok);
}

TEST(TmlSerialPacket, ChecksumIsSumModulo256) {
  const Bytes b{0xFF, 0xFF, 0x03};
  EXPECT_EQ(checksum(b), 0x01);
  EXPECT_EQ(checksum({}), 0x00);
}

TEST(TmlSerialPacket, DecodeErrors) {
  Message m;
  Bytes good{0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x05, 0x88};
  Bytes bad = good;
  bad.back() = 0x89;
  EXPECT_EQ(decode_packet(bad, m), PacketStatus::bad_checksum);
  EXPECT_EQ(decode_packet({}, m), PacketStatus::too_short);
  EXPECT_EQ(decode_packet(Bytes{0x05, 0, 0, 0, 0, 0, 5}, m), PacketStatus::bad_length);
  EXPECT_EQ(decode_packet(Bytes{0x0E, 0, 0}, m), PacketStatus::bad_length);
  EXPECT_EQ(decode_packet(Bytes(good.begin(), good.end() - 1), m), PacketStatus::size_mismatch);
}

TEST(TmlSerialPacket, UnknownOpcodeDecodesAsGenericMessage) {
  const Message odd = msg(0x0010, 0x7ABC, {1, 2, 3, 4});
  const Packet p = encode_packet(odd);
  EXPECT_EQ(p.size, 14);
  Message back;
  ASSERT_EQ(decode_packet(p.view(), back), PacketStatus::ok);
  EXPECT_EQ(back, odd);
  EXPECT_EQ(classify(back).kind, Kind::generic);
}

TEST(TmlSerialTiming, ElevenBitsPerByte) {
  const ByteTiming slow(9600), fast(115200);
  EXPECT_EQ(slow.byte_ns(), 1'145'833);        // 11 / 9600 s
  EXPECT_EQ(slow.duration_ns(8), 9'166'667);   // the KPP=5 packet
  EXPECT_EQ(fast.byte_ns(), 95'486);           // 11 / 115200 s
  EXPECT_EQ(fast.duration_ns(8), 763'889);
  EXPECT_EQ(fast.duration_ns(115200), 11'000'000'000);  // no drift over a long burst
  EXPECT_EQ(slow.end_of(1000, 0), 1000 + 1'145'833);
  EXPECT_THROW(ByteTiming(0), std::invalid_argument);
}

TEST(TmlSerialTiming, LineSendsBackToBack) {
  std::vector<std::int64_t> ends;
  LineTx tx(9600, [&](std::uint8_t, std::int64_t t) { ends.push_back(t); });
  const Bytes two{1, 2};
  EXPECT_EQ(tx.send(two, 0), 2'291'667);
  EXPECT_EQ(tx.send(std::uint8_t{3}, 1'000'000), 2'291'667 + 1'145'833);  // waits for the line
  EXPECT_EQ(tx.send(std::uint8_t{4}, 10'000'000), 10'000'000 + 1'145'833);  // idle line: starts now
  EXPECT_EQ(ends, (std::vector<std::int64_t>{1'145'833, 2'291'667, 3'437'500, 11'145'833}));
}

TEST(TmlSerialReceiver, RolesReadIdleBytesDifferently) {
  std::vector<RxEventKind> host_events, drive_events;
  SerialReceiver host(Role::host, [&](const RxEvent& e) { host_events.push_back(e.kind); });
  SerialReceiver drive(Role::drive, [&](const RxEvent& e) { drive_events.push_back(e.kind); });
  for (const std::uint8_t b : {kAckByte, kSyncByte, std::uint8_t{0xFF}, std::uint8_t{0x01}}) {
    host.on_byte(b, 0);
    drive.on_byte(b, 0);
  }
  using K = RxEventKind;
  EXPECT_EQ(host_events, (std::vector<K>{K::ack, K::sync, K::junk, K::bad_length}));
  EXPECT_EQ(drive_events, (std::vector<K>{K::sync, K::sync, K::sync, K::bad_length}));
  EXPECT_EQ(host.stats().acks, 1u);
  EXPECT_EQ(drive.stats().syncs, 3u);
}

TEST(TmlSerialReceiver, PacketsAndBadChecksums) {
  std::vector<RxEvent> events;
  SerialReceiver rx(Role::drive, [&](const RxEvent& e) { events.push_back(e); });
  Bytes wire{0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x05, 0x87};  // bad checksum
  const Packet good = encode_packet(msg(0x0FF0, 0x205E, {5}));
  wire.insert(wire.end(), good.bytes.begin(), good.bytes.begin() + good.size);
  for (std::size_t i = 0; i < wire.size(); ++i) rx.on_byte(wire[i], static_cast<std::int64_t>(i) * 10);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].kind, RxEventKind::bad_checksum);
  EXPECT_EQ(events[1].kind, RxEventKind::message);
  EXPECT_EQ(events[1].message, msg(0x0FF0, 0x205E, {5}));
  EXPECT_EQ(events[1].t_ns, 150);
  EXPECT_EQ(rx.stats().bad_checksums, 1u);
  EXPECT_EQ(rx.stats().messages, 1u);
  EXPECT_FALSE(rx.in_packet());
}

// A host and one drive joined by a timed byte wire (each byte arrives at the end of its stop
// bits); `drop` loses bytes on the way. The drive answers GiveMeData/GiveMeData2 from `value`.
struct Rig {
  struct Byte {
    std::int64_t t;
    bool to_drive;
    std::uint8_t b;
  };

  Rig(Link link, std::uint32_t baud = 9600, std::uint8_t axis = 255, std::uint8_t groups = 1)
      : drive_axis(axis),
        host({link, baud}, [this](std::uint8_t b, std::int64_t t) { put({t, true, b}, host_tx); },
             [this](const HostEvent& e) { events.push_back(e); }),
        drive({link, axis, groups, baud}, [this](std::uint8_t b, std::int64_t t) { put({t, false, b}, drive_tx); },
              [this](const Message& m, std::int64_t t) { on_drive_message(m, t); }) {}

  void put(const Byte& x, std::vector<std::uint8_t>& log) {
    const std::size_t index = log.size();
    log.push_back(x.b);
    if (!(drop && drop(x, index))) pending.push_back(x);
  }

  void on_drive_message(const Message& m, std::int64_t t) {
    delivered.push_back(m);
    if (!answer) return;
    const Classified c = classify(m);
    if (c.kind == Kind::give_me_data) drive.send(take_data(c.sender, axis_id_code(drive_axis), c.address, value, c.wide), t);
    if (c.kind == Kind::give_me_data2) drive.send(take_data2(c.sender, drive_axis, c.address, value, c.wide), t);
  }

  // Delivers bytes and runs the host's timeouts in time order up to `until`.
  void run(std::int64_t until) {
    for (;;) {
      const auto it = std::min_element(pending.begin(), pending.end(), [](auto& a, auto& b) { return a.t < b.t; });
      const std::int64_t next_byte = it == pending.end() ? INT64_MAX : it->t;
      const std::int64_t deadline = host.next_deadline();
      if (std::min(next_byte, deadline) > until) return;
      if (next_byte <= deadline) {
        const Byte x = *it;
        pending.erase(it);
        if (x.to_drive) drive.on_byte(x.b, x.t);
        else host.on_byte(x.b, x.t);
      } else {
        host.poll(deadline);
      }
    }
  }

  std::vector<HostEventKind> kinds() const {
    std::vector<HostEventKind> k;
    for (const auto& e : events) k.push_back(e.kind);
    return k;
  }

  std::uint8_t drive_axis;
  std::function<bool(const Byte&, std::size_t index)> drop;
  bool answer = true;
  std::uint32_t value = 0x0120;
  std::vector<Byte> pending;
  Bytes host_tx, drive_tx;
  std::vector<HostEvent> events;
  std::vector<Message> delivered;
  SerialHostLink host;
  SerialDriveLink drive;
};

constexpr std::int64_t kSecond = 1'000'000'000;
const Message kKpp5 = msg(0x0FF0, 0x205E, {5});
const Bytes kKpp5Wire{0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x05, 0x88};

Bytes concat(std::initializer_list<Bytes> parts) {
  Bytes all;
  for (const auto& p : parts) all.insert(all.end(), p.begin(), p.end());
  return all;
}

TEST(TmlSerialLink, TypeAIsAcknowledgedAfterItsLastByte) {
  for (const std::uint32_t baud : {9600u, 115200u}) {
    Rig rig(Link::rs232, baud);
    ASSERT_EQ(rig.host.send(kKpp5, 0), SendStatus::ok);
    EXPECT_EQ(rig.host.send(kKpp5, 0), SendStatus::busy);
    rig.run(kSecond);
    EXPECT_EQ(rig.host_tx, kKpp5Wire);
    EXPECT_EQ(rig.drive_tx, Bytes{kAckByte});
    ASSERT_EQ(rig.kinds(), std::vector<HostEventKind>{HostEventKind::acked});
    // 8 bytes to the drive, then the 'O' back: 9 byte times.
    EXPECT_EQ(rig.events[0].t_ns, baud == 9600 ? 9'166'667 + 1'145'833 : 763'889 + 95'486);
    EXPECT_TRUE(rig.host.idle());
    ASSERT_EQ(rig.delivered.size(), 1u);
    EXPECT_EQ(rig.delivered[0], kKpp5);
  }
}

TEST(TmlSerialLink, GiveMeDataIsAcknowledgedThenAnswered) {
  Rig rig(Link::rs232);
  ASSERT_EQ(rig.host.send(give_me_data(axis_id_code(255), host_id_code(255), 0x025E, false), 0), SendStatus::ok);
  rig.run(kSecond);
  const Bytes take{0x0A, 0x0F, 0xF1, 0xB4, 0x04, 0x0F, 0xF0, 0x02, 0x5E, 0x01, 0x20, 0x42};
  EXPECT_EQ(rig.drive_tx, concat({{kAckByte}, take}));
  ASSERT_EQ(rig.kinds(), std::vector<HostEventKind>{HostEventKind::answer});
  EXPECT_EQ(classify(rig.events[0].message).value, 0x0120u);
  const ByteTiming bt(9600);  // request, then 'O', then the answer right behind it
  EXPECT_EQ(rig.events[0].t_ns, bt.duration_ns(10) + bt.byte_ns() + bt.duration_ns(12));
}

TEST(TmlSerialLink, MissingAnswerTimesOut) {
  Rig rig(Link::rs232);
  rig.answer = false;
  ASSERT_EQ(rig.host.send(give_me_data(axis_id_code(255), host_id_code(255), 0x025E, false), 0), SendStatus::ok);
  rig.run(kSecond);
  ASSERT_EQ(rig.kinds(), std::vector<HostEventKind>{HostEventKind::answer_timeout});
  const ByteTiming bt(9600);
  EXPECT_EQ(rig.events[0].t_ns, bt.duration_ns(10) + bt.byte_ns() + 100'000'000);
}

TEST(TmlSerialLink, BadChecksumGetsNoAckAndIsCounted) {
  Rig rig(Link::rs232);
  const Bytes wire{0x06, 0x0F, 0xF0, 0x20, 0x5E, 0x00, 0x05, 0x89};  // checksum off by one
  for (std::size_t i = 0; i < wire.size(); ++i) rig.drive.on_byte(wire[i], static_cast<std::int64_t>(i));
  EXPECT_TRUE(rig.drive_tx.empty());
  EXPECT_EQ(rig.drive.rx_stats().bad_checksums, 1u);
  EXPECT_TRUE(rig.delivered.empty());
  // The next good packet is taken and acknowledged.
  for (std::size_t i = 0; i < kKpp5Wire.size(); ++i) rig.drive.on_byte(kKpp5Wire[i], 100);
  EXPECT_EQ(rig.drive_tx, Bytes{kAckByte});
  EXPECT_EQ(rig.drive.stats().acks_sent, 1u);
}

TEST(TmlSerialLink, Rs232LostAckIsRecoveredWithSyncAndResend) {
  Rig rig(Link::rs232);
  rig.drop = [](const Rig::Byte& x, std::size_t i) { return !x.to_drive && i == 0; };  // the first 'O'
  ASSERT_EQ(rig.host.send(kKpp5, 0), SendStatus::ok);
  rig.run(kSecond);
  EXPECT_EQ(rig.host_tx, concat({kKpp5Wire, {kSyncByte}, kKpp5Wire}));
  EXPECT_EQ(rig.drive_tx, (Bytes{kAckByte, kSyncByte, kAckByte}));
  EXPECT_EQ(rig.kinds(), (std::vector<HostEventKind>{HostEventKind::resent, HostEventKind::acked}));
  EXPECT_EQ(rig.delivered.size(), 2u);  // the drive did execute the first copy too
  // The SYNC byte left 2 ms after the packet's checksum byte.
  const ByteTiming bt(9600);
  EXPECT_EQ(rig.events[0].t_ns, bt.duration_ns(8) + 2'000'000 + 2 * bt.byte_ns());  // SYNC out, echo back
}

TEST(TmlSerialLink, Rs232LostByteIsRecoveredWithSyncBytes) {
  Rig rig(Link::rs232);
  rig.drop = [](const Rig::Byte& x, std::size_t i) { return x.to_drive && i == 3; };  // opcode high byte
  ASSERT_EQ(rig.host.send(kKpp5, 0), SendStatus::ok);
  rig.run(kSecond);
  // The first SYNC completes the broken packet (bad checksum, no ack), the second is echoed.
  EXPECT_EQ(rig.host_tx, concat({kKpp5Wire, {kSyncByte, kSyncByte}, kKpp5Wire}));
  EXPECT_EQ(rig.drive.rx_stats().bad_checksums, 1u);
  EXPECT_EQ(rig.drive_tx, (Bytes{kSyncByte, kAckByte}));
  EXPECT_EQ(rig.kinds(), (std::vector<HostEventKind>{HostEventKind::resent, HostEventKind::acked}));
  EXPECT_EQ(rig.delivered.size(), 1u);
}

TEST(TmlSerialLink, Rs232DeadDriveBreaksTheLinkAfter15Syncs) {
  Rig rig(Link::rs232);
  rig.drop = [](const Rig::Byte& x, std::size_t) { return !x.to_drive; };
  ASSERT_EQ(rig.host.send(kKpp5, 0), SendStatus::ok);
  rig.run(10 * kSecond);
  EXPECT_EQ(rig.host_tx, concat({kKpp5Wire, Bytes(15, kSyncByte)}));
  ASSERT_EQ(rig.kinds(), std::vector<HostEventKind>{HostEventKind::link_broken});
  const ByteTiming bt(9600);
  EXPECT_EQ(rig.events[0].t_ns, bt.duration_ns(8) + 2'000'000 + 15 * (bt.byte_ns() + 2'000'000));
  EXPECT_TRUE(rig.host.broken());
  EXPECT_EQ(rig.host.send(kKpp5, 20 * kSecond), SendStatus::link_broken);
  rig.host.reset();
  EXPECT_EQ(rig.host.send(kKpp5, 20 * kSecond), SendStatus::ok);
}

TEST(TmlSerialLink, Rs485LostAckSends15SyncBytesThenResends) {
  Rig rig(Link::rs485, 9600, 1);
  rig.drop = [](const Rig::Byte& x, std::size_t i) { return !x.to_drive && i == 0; };
  const Message kpp_axis1 = msg(0x0010, 0x205E, {5});
  ASSERT_EQ(rig.host.send(kpp_axis1, 0), SendStatus::ok);
  rig.run(kSecond);
  const Bytes wire = bytes_of(encode_packet(kpp_axis1));
  EXPECT_EQ(rig.host_tx, concat({wire, Bytes(15, kSyncByte), wire}));
  EXPECT_EQ(rig.drive_tx, (Bytes{kAckByte, kAckByte}));  // RS-485 drives do not echo SYNC
  EXPECT_EQ(rig.kinds(), (std::vector<HostEventKind>{HostEventKind::resent, HostEventKind::acked}));
  const ByteTiming bt(9600);
  EXPECT_EQ(rig.events[0].t_ns, bt.duration_ns(8) + 2'000'000 + bt.duration_ns(15) + 2'000'000);
}

TEST(TmlSerialLink, Rs485DeadDriveBreaksAfterOneResend) {
  Rig rig(Link::rs485, 9600, 1);
  rig.drop = [](const Rig::Byte& x, std::size_t) { return !x.to_drive; };
  const Message kpp_axis1 = msg(0x0010, 0x205E, {5});
  ASSERT_EQ(rig.host.send(kpp_axis1, 0), SendStatus::ok);
  rig.run(kSecond);
  const Bytes wire = bytes_of(encode_packet(kpp_axis1));
  EXPECT_EQ(rig.host_tx, concat({wire, Bytes(15, kSyncByte), wire}));
  EXPECT_EQ(rig.kinds(), (std::vector<HostEventKind>{HostEventKind::resent, HostEventKind::link_broken}));
}

TEST(TmlSerialLink, Rs485GroupBroadcastIsNotAcknowledged) {
  Rig rig(Link::rs485, 9600, 1, 0x01);
  const Message to_group1 = msg(group_id_code(1), 0x205E, {5});
  EXPECT_FALSE(acknowledged(Link::rs485, to_group1));
  EXPECT_TRUE(acknowledged(Link::rs232, to_group1));
  ASSERT_EQ(rig.host.send(to_group1, 0), SendStatus::ok);
  EXPECT_TRUE(rig.host.idle());
  rig.run(kSecond);
  EXPECT_TRUE(rig.drive_tx.empty());
  ASSERT_EQ(rig.delivered.size(), 1u);
  ASSERT_EQ(rig.kinds(), std::vector<HostEventKind>{HostEventKind::sent_unacknowledged});
  EXPECT_EQ(rig.events[0].t_ns, ByteTiming(9600).duration_ns(8));
  // A group the drive is not in, and another axis: not taken, not acknowledged.
  ASSERT_EQ(rig.host.send(msg(group_id_code(2), 0x205E, {5}), 2 * kSecond), SendStatus::ok);
  ASSERT_EQ(rig.host.send(msg(axis_id_code(1), 0x205E, {5}), 2 * kSecond), SendStatus::ok);
  rig.run(3 * kSecond);
  EXPECT_EQ(rig.delivered.size(), 2u);
  EXPECT_EQ(rig.drive.stats().not_for_us, 1u);
  EXPECT_EQ(rig.drive_tx, Bytes{kAckByte});
}

TEST(TmlSerialLink, Rs485RefusesWhatTheSeedForbids) {
  Rig rig(Link::rs485, 9600, 1);
  const Message to_group = give_me_data2(group_id_code(1), axis_id_code(255), 0x022A, false);
  EXPECT_EQ(check_host_message(Link::rs485, to_group), LinkCheck::request_to_group_on_rs485);
  EXPECT_EQ(check_host_message(Link::rs232, to_group), LinkCheck::ok);
  EXPECT_EQ(rig.host.send(to_group, 0), SendStatus::not_allowed);
  const Message host_bit = give_me_data(axis_id_code(1), host_id_code(255), 0x022A, false);
  EXPECT_EQ(check_host_message(Link::rs485, host_bit), LinkCheck::host_bit_on_rs485);
  EXPECT_EQ(check_host_message(Link::rs485, take_data2(master_id(255), 1, 0x090E, 0, false)),
            LinkCheck::type_c_on_rs485);
  EXPECT_EQ(check_host_message(Link::rs232, give_me_data(group_id_code(1), host_id_code(255), 0x022A, false)),
            LinkCheck::give_me_data_to_group);
  EXPECT_TRUE(rig.host_tx.empty());
}

// Found in review: every drive on an RS-485 line takes axis 0 (seed ch. 2) and each answered
// it with 'O', so the 'O's collided; a request to axis 0 had every drive answer at once.
TEST(TmlSerialLink, Rs485AxisZeroIsNotAcknowledgedAndTakesNoRequests) {
  Rig rig(Link::rs485, 9600, 1);
  const Message to_all = msg(axis_id_code(0), 0x205E, {5});
  EXPECT_FALSE(acknowledged(Link::rs485, to_all));
  EXPECT_TRUE(acknowledged(Link::rs232, to_all));
  ASSERT_EQ(rig.host.send(to_all, 0), SendStatus::ok);
  EXPECT_TRUE(rig.host.idle());
  rig.run(kSecond);
  EXPECT_TRUE(rig.drive_tx.empty());  // delivered, not acknowledged
  ASSERT_EQ(rig.delivered.size(), 1u);
  ASSERT_EQ(rig.kinds(), std::vector<HostEventKind>{HostEventKind::sent_unacknowledged});
  const Message ask_all = give_me_data(axis_id_code(0), axis_id_code(255), 0x025E, false);
  EXPECT_EQ(check_host_message(Link::rs485, ask_all), LinkCheck::request_to_axis_0_on_rs485);
  EXPECT_EQ(check_host_message(Link::rs232, give_me_data(axis_id_code(0), host_id_code(255), 0x025E, false)),
            LinkCheck::ok);
  EXPECT_EQ(rig.host.send(ask_all, 2 * kSecond), SendStatus::not_allowed);
}

// Found in review: a packet whose ID code has bits 15–13 or 3–1 set (zero by chapter 2) was
// acknowledged and delivered; id_of() of 0x2050 and 0x005E is 5.
TEST(TmlSerialLink, AMalformedIdCodeIsDroppedWithoutAcknowledgement) {
  for (const Link link : {Link::rs232, Link::rs485}) {
    Rig rig(link, 9600, 5);
    for (const std::uint16_t id : {0x2050, 0x005E}) {
      const Packet p = encode_packet(msg(id, 0x205E, {77}));
      for (const std::uint8_t b : p.view()) rig.drive.on_byte(b, 0);
    }
    EXPECT_TRUE(rig.drive_tx.empty()) << to_string(link);
    EXPECT_TRUE(rig.delivered.empty()) << to_string(link);
    EXPECT_EQ(rig.drive.stats().invalid_id_codes, 2u) << to_string(link);
  }
}

// Found in review: the host took any TakeData/TakeData2 as the answer; an unsolicited SR32
// TakeData2 arriving before the TakeData of ?KPP was reported as its answer.
TEST(TmlSerialLink, OnlyTheMatchingTakeDataAnswersARequest) {
  Rig rig(Link::rs232);
  rig.answer = false;
  ASSERT_EQ(rig.host.send(give_me_data(axis_id_code(255), host_id_code(255), 0x025E, false), 0), SendStatus::ok);
  rig.run(20'000'000);  // the 'O' is in
  rig.drive.send(take_data2(0x0FF1, 255, 0x090E, 0x02018400, true), 21'000'000);           // type C
  rig.drive.send(take_data(0x0FF1, 0x0FF0, 0x022A, 0x0002, false), 21'000'000);            // another address
  rig.drive.send(take_data(0x0FF1, 0x0FF0, 0x025E, 0x0120, false), 21'000'000);            // the answer
  rig.run(kSecond);
  ASSERT_EQ(rig.kinds(), (std::vector<HostEventKind>{HostEventKind::unsolicited, HostEventKind::unsolicited,
                                                     HostEventKind::answer}));
  EXPECT_EQ(classify(rig.events[2].message).value, 0x0120u);
  // GiveMeData2 of SR32 (B205) is answered by a 32-bit TakeData2 (D5xx) of SRL, not by TakeData.
  ASSERT_EQ(rig.host.send(give_me_data2(axis_id_code(255), host_id_code(255), 0x090E, true), 2 * kSecond),
            SendStatus::ok);
  rig.run(2 * kSecond + 20'000'000);
  rig.drive.send(take_data(0x0FF1, 0x0FF0, 0x090E, 0x8400, false), 2 * kSecond + 21'000'000);
  rig.drive.send(take_data2(0x0FF1, 255, 0x090E, 0x8400, false), 2 * kSecond + 21'000'000);  // 16-bit
  rig.drive.send(take_data2(0x0FF1, 255, 0x090E, 0x02018400, true), 2 * kSecond + 21'000'000);
  rig.run(3 * kSecond);
  ASSERT_EQ(rig.events.size(), 6u);
  EXPECT_EQ(rig.events[3].kind, HostEventKind::unsolicited);
  EXPECT_EQ(rig.events[4].kind, HostEventKind::unsolicited);
  EXPECT_EQ(rig.events[5].kind, HostEventKind::answer);
  EXPECT_EQ(classify(rig.events[5].message).value, 0x02018400u);
}

TEST(TmlSerialLink, Rs232UnsolicitedTakeData2ReachesTheHost) {
  Rig rig(Link::rs232);
  rig.drive.send(take_data2(master_id(255), 255, 0x090E, 0x02018400, true), 0);
  rig.run(kSecond);
  EXPECT_EQ(rig.drive_tx, (Bytes{0x0A, 0x0F, 0xF1, 0xD5, 0xFF, 0x09, 0x0E, 0x84, 0x00, 0x02, 0x01, 0x7C}));
  ASSERT_EQ(rig.kinds(), std::vector<HostEventKind>{HostEventKind::unsolicited});
  EXPECT_EQ(classify(rig.events[0].message).value, 0x02018400u);
  EXPECT_TRUE(rig.host_tx.empty());  // the host does not acknowledge type C
}

}  // namespace
}  // namespace omnitwin::tml
