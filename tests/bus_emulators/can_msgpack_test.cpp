// Tests bus_emulators/can/can_msgpack: byte-identical encoding to python-can 4.1's
// pack_message(), round trips for every frame kind, python-can's defaults on decode, and
// a status (never a crash) for every kind of bad datagram.
#include "bus_emulators/can/can_msgpack.hpp"

#include <gtest/gtest.h>
#include <msgpack.hpp>

#include <functional>
#include <string>
#include <vector>

namespace omnitwin::can::msgpack_wire {
namespace {

std::vector<std::uint8_t> from_hex(const std::string& h) {
  std::vector<std::uint8_t> v;
  for (std::size_t i = 0; i + 1 < h.size(); i += 2) v.push_back(static_cast<std::uint8_t>(std::stoul(h.substr(i, 2), nullptr, 16)));
  return v;
}

DecodeStatus dec(const std::vector<std::uint8_t>& b, Decoded* out = nullptr) {
  Decoded d;
  const DecodeStatus s = decode(b, d);
  if (out) *out = d;
  return s;
}

// Builds a msgpack map from (key, packing function) pairs, for hand-made datagrams.
struct MapBuilder {
  msgpack::sbuffer buf;
  msgpack::packer<msgpack::sbuffer> pk{buf};
  explicit MapBuilder(std::uint32_t n) { pk.pack_map(n); }
  msgpack::packer<msgpack::sbuffer>& key(const std::string& k) {
    pk.pack(k);
    return pk;
  }
  std::vector<std::uint8_t> bytes() const {
    return {reinterpret_cast<const std::uint8_t*>(buf.data()), reinterpret_cast<const std::uint8_t*>(buf.data()) + buf.size()};
  }
};

// A complete, valid python-can map with one field replaced by the caller.
std::vector<std::uint8_t> python_map(const std::string& replace_key, const std::function<void(msgpack::packer<msgpack::sbuffer>&)>& value) {
  MapBuilder m(11);
  auto field = [&](const std::string& k, const std::function<void(msgpack::packer<msgpack::sbuffer>&)>& def) {
    auto& pk = m.key(k);
    if (k == replace_key) value(pk);
    else def(pk);
  };
  field("timestamp", [](auto& p) { p.pack_double(1.0); });
  field("arbitration_id", [](auto& p) { p.pack_uint32(0x123); });
  field("is_extended_id", [](auto& p) { p.pack_false(); });
  field("is_remote_frame", [](auto& p) { p.pack_false(); });
  field("is_error_frame", [](auto& p) { p.pack_false(); });
  field("channel", [](auto& p) { p.pack_nil(); });
  field("dlc", [](auto& p) { p.pack_uint8(2); });
  field("data", [](auto& p) { p.pack_bin(2); p.pack_bin_body("\x01\x02", 2); });
  field("is_fd", [](auto& p) { p.pack_false(); });
  field("bitrate_switch", [](auto& p) { p.pack_false(); });
  field("error_state_indicator", [](auto& p) { p.pack_false(); });
  return m.bytes();
}

TEST(CanMsgpack, EncodingIsByteIdenticalToPythonCan) {
  // /usr/bin/python3: can.interfaces.udp_multicast.utils.pack_message(can.Message(
  //   timestamp=1.5, arbitration_id=0x123, is_extended_id=False, data=[1, 2, 3])).hex()
  const auto py_std = from_hex(
      "8ba974696d657374616d70cb3ff8000000000000ae6172626974726174696f6e5f6964cd0123ae69735f657874656e64"
      "65645f6964c2af69735f72656d6f74655f6672616d65c2ae69735f6572726f725f6672616d65c2a76368616e6e656cc0"
      "a3646c6303a464617461c403010203a569735f6664c2ae626974726174655f737769746368c2b56572726f725f737461"
      "74655f696e64696361746f72c2");
  EXPECT_EQ(encode(make_data(0x123, {1, 2, 3}), 1.5), py_std);
  // ... Message(timestamp=0.0, arbitration_id=0x1ABCDEF0, is_extended_id=True,
  //             is_remote_frame=True, dlc=4)
  const auto py_rtr = from_hex(
      "8ba974696d657374616d70cb0000000000000000ae6172626974726174696f6e5f6964ce1abcdef0ae69735f657874656e"
      "6465645f6964c3af69735f72656d6f74655f6672616d65c3ae69735f6572726f725f6672616d65c2a76368616e6e656c"
      "c0a3646c6304a464617461c400a569735f6664c2ae626974726174655f737769746368c2b56572726f725f7374617465"
      "5f696e64696361746f72c2");
  EXPECT_EQ(encode(make_remote(0x1ABCDEF0, 4, true), 0.0), py_rtr);

  Decoded d;
  ASSERT_EQ(dec(py_std, &d), DecodeStatus::ok);
  EXPECT_EQ(d.frame, make_data(0x123, {1, 2, 3}));
  EXPECT_DOUBLE_EQ(d.timestamp, 1.5);
  ASSERT_EQ(dec(py_rtr, &d), DecodeStatus::ok);
  EXPECT_EQ(d.frame, make_remote(0x1ABCDEF0, 4, true));
}

TEST(CanMsgpack, EveryFrameKindRoundTrips) {
  Frame err;
  err.kind = FrameKind::error;
  err.id = 0x004;  // CAN_ERR_CTRL
  err.dlc = 8;
  err.data = {0, 0x04, 0, 0, 0, 0, 0x80, 0};
  const Frame frames[] = {make_data(0x000, {}),
                          make_data(0x000, {0x02, 0x00}),
                          make_data(0x7FF, {1, 2, 3, 4, 5, 6, 7, 8}),
                          make_data(0x1FFFFFFF, {0xFF}, true),
                          make_data(0x0, {}, true),
                          make_remote(0x701, 1),
                          make_remote(0x12345, 8, true),
                          err};
  for (const Frame& f : frames) {
    const auto bytes = encode(f, 12.25);
    EXPECT_LE(bytes.size(), kMaxEncodedSize);
    Decoded d;
    ASSERT_EQ(dec(bytes, &d), DecodeStatus::ok) << to_string(f);
    EXPECT_EQ(d.frame, f) << to_string(f) << " came back as " << to_string(d.frame);
    EXPECT_DOUBLE_EQ(d.timestamp, 12.25);
    if (f.kind == FrameKind::error) {
      EXPECT_EQ(d.frame.data, f.data);  // the error detail bytes survive
    }
  }
}

TEST(CanMsgpack, EncodeRefusesInvalidFramesAndSmallBuffers) {
  Frame bad = make_data(0x100, {1});
  bad.id = 0x800;  // standard id out of range
  std::array<std::uint8_t, kMaxEncodedSize> buf{};
  EXPECT_EQ(encode(bad, 0.0, buf), 0u);
  EXPECT_THROW(encode(bad, 0.0), std::invalid_argument);
  Frame long_dlc = make_data(0x100, {1});
  long_dlc.dlc = 9;
  EXPECT_EQ(encode(long_dlc, 0.0, buf), 0u);
  EXPECT_EQ(encode(make_data(0x1FFFFFFF, {1, 2, 3, 4, 5, 6, 7, 8}, true), 0.0).size(), 164u);  // the largest
  std::array<std::uint8_t, 40> small{};
  EXPECT_EQ(encode(make_data(1, {1}), 0.0, small), 0u);
}

TEST(CanMsgpack, MissingKeysTakePythonCanDefaults) {
  MapBuilder m(2);
  m.key("arbitration_id").pack_uint32(0x10);
  m.key("data").pack_bin(1);
  m.pk.pack_bin_body("\x07", 1);
  Decoded d;
  ASSERT_EQ(dec(m.bytes(), &d), DecodeStatus::ok);
  EXPECT_TRUE(d.frame.extended);  // python-can's Message(is_extended_id=True) default
  EXPECT_EQ(d.frame.dlc, 1);      // dlc defaults to len(data)
  EXPECT_EQ(d.frame.data[0], 7);
  EXPECT_EQ(d.frame.kind, FrameKind::data);

  MapBuilder nil_dlc(3);
  nil_dlc.key("is_extended_id").pack_false();
  nil_dlc.key("dlc").pack_nil();
  nil_dlc.key("data").pack_nil();
  ASSERT_EQ(dec(nil_dlc.bytes(), &d), DecodeStatus::ok);
  EXPECT_EQ(d.frame, make_data(0, {}));
}

TEST(CanMsgpack, DataMayBeAnArrayOfIntegers) {
  auto b = python_map("data", [](auto& p) { p.pack_array(2); p.pack_uint8(0x20); p.pack_uint8(0x02); });
  Decoded d;
  ASSERT_EQ(dec(b, &d), DecodeStatus::ok);
  EXPECT_EQ(d.frame, make_data(0x123, {0x20, 0x02}));
  EXPECT_EQ(dec(python_map("data", [](auto& p) { p.pack_array(2); p.pack_uint16(256); p.pack_uint8(1); })), DecodeStatus::bad_type);
  EXPECT_EQ(dec(python_map("data", [](auto& p) { p.pack_array(2); p.pack_int8(-1); p.pack_uint8(1); })), DecodeStatus::bad_type);
  EXPECT_EQ(dec(python_map("data", [](auto& p) { p.pack_array(2); p.pack_nil(); p.pack_uint8(1); })), DecodeStatus::bad_type);
  EXPECT_EQ(dec(python_map("data", [](auto& p) { p.pack_array(2); p.pack_array(0); p.pack_uint8(1); })), DecodeStatus::malformed);
}

TEST(CanMsgpack, IdentifierOutOfRangeIsBadId) {
  EXPECT_EQ(dec(python_map("arbitration_id", [](auto& p) { p.pack_uint32(0x800); })), DecodeStatus::bad_id);
  EXPECT_EQ(dec(python_map("arbitration_id", [](auto& p) { p.pack_int32(-1); })), DecodeStatus::bad_id);
  EXPECT_EQ(dec(python_map("arbitration_id", [](auto& p) { p.pack_uint64(0x100000123ull); })), DecodeStatus::bad_id);
  // 29-bit limit for extended frames.
  MapBuilder m(3);
  m.key("arbitration_id").pack_uint32(0x20000000);
  m.key("is_extended_id").pack_true();
  m.key("data").pack_nil();
  EXPECT_EQ(dec(m.bytes()), DecodeStatus::bad_id);
}

TEST(CanMsgpack, WrongDlcIsReported) {
  EXPECT_EQ(dec(python_map("dlc", [](auto& p) { p.pack_uint8(3); })), DecodeStatus::wrong_dlc);   // 2 data bytes
  EXPECT_EQ(dec(python_map("dlc", [](auto& p) { p.pack_uint8(9); })), DecodeStatus::wrong_dlc);
  EXPECT_EQ(dec(python_map("dlc", [](auto& p) { p.pack_int8(-1); })), DecodeStatus::wrong_dlc);
  EXPECT_EQ(dec(python_map("data", [](auto& p) { p.pack_bin(9); p.pack_bin_body("123456789", 9); })), DecodeStatus::wrong_dlc);
  EXPECT_EQ(dec(python_map("data", [](auto& p) { p.pack_bin(65); p.pack_bin_body(std::string(65, 'x').data(), 65); })),
            DecodeStatus::wrong_dlc);
}

TEST(CanMsgpack, InvalidFlagCombinationsAndFdAreRejected) {
  // A remote frame may not carry data (python-can's check).
  EXPECT_EQ(dec(python_map("is_remote_frame", [](auto& p) { p.pack_true(); })), DecodeStatus::invalid_flags);
  MapBuilder m(3);
  m.key("is_remote_frame").pack_true();
  m.key("is_error_frame").pack_true();
  m.key("data").pack_nil();
  EXPECT_EQ(dec(m.bytes()), DecodeStatus::invalid_flags);
  EXPECT_EQ(dec(python_map("bitrate_switch", [](auto& p) { p.pack_true(); })), DecodeStatus::invalid_flags);
  EXPECT_EQ(dec(python_map("error_state_indicator", [](auto& p) { p.pack_true(); })), DecodeStatus::invalid_flags);
  EXPECT_EQ(dec(python_map("is_fd", [](auto& p) { p.pack_true(); })), DecodeStatus::fd_unsupported);
}

TEST(CanMsgpack, WrongTypesAndUnknownKeysAreRejected) {
  EXPECT_EQ(dec(python_map("arbitration_id", [](auto& p) { p.pack(std::string("0x123")); })), DecodeStatus::bad_type);
  EXPECT_EQ(dec(python_map("is_extended_id", [](auto& p) { p.pack_uint8(1); })), DecodeStatus::bad_type);
  EXPECT_EQ(dec(python_map("timestamp", [](auto& p) { p.pack(std::string("now")); })), DecodeStatus::bad_type);
  EXPECT_EQ(dec(python_map("data", [](auto& p) { p.pack(std::string("\x01\x02")); })), DecodeStatus::bad_type);
  EXPECT_EQ(dec(python_map("data", [](auto& p) { p.pack_map(0); })), DecodeStatus::malformed);
  // channel: anything scalar is accepted (python-can passes it through).
  Decoded d;
  EXPECT_EQ(dec(python_map("channel", [](auto& p) { p.pack(std::string("vcan0")); }), &d), DecodeStatus::ok);
  EXPECT_EQ(dec(python_map("channel", [](auto& p) { p.pack_uint8(3); })), DecodeStatus::ok);
  // timestamp: ints and floats (python-can replaces it on receive anyway).
  EXPECT_EQ(dec(python_map("timestamp", [](auto& p) { p.pack_int8(-5); }), &d), DecodeStatus::ok);
  EXPECT_DOUBLE_EQ(d.timestamp, -5.0);

  MapBuilder unknown(2);
  unknown.key("arbitration_id").pack_uint8(1);
  unknown.key("is_rx").pack_true();  // a Message() argument, but pack_message never sends it
  EXPECT_EQ(dec(unknown.bytes()), DecodeStatus::unknown_key);
  MapBuilder dup(2);
  dup.key("dlc").pack_uint8(0);
  dup.key("dlc").pack_uint8(0);
  EXPECT_EQ(dec(dup.bytes()), DecodeStatus::unknown_key);
  MapBuilder int_key(1);
  int_key.pk.pack_uint8(1);
  int_key.pk.pack_uint8(1);
  EXPECT_EQ(dec(int_key.bytes()), DecodeStatus::unknown_key);
}

TEST(CanMsgpack, MalformedDatagramsGiveAStatusNotACrash) {
  EXPECT_EQ(dec({}), DecodeStatus::malformed);
  EXPECT_EQ(dec({0xc1}), DecodeStatus::malformed);                     // never-used byte
  EXPECT_EQ(dec({0x93, 0x01, 0x02, 0x03}), DecodeStatus::malformed);   // array at top level
  EXPECT_EQ(dec({0x2a}), DecodeStatus::malformed);                     // a bare integer
  EXPECT_EQ(dec({0x80, 0x80}), DecodeStatus::malformed);               // two maps
  EXPECT_EQ(dec({0xdf, 0xff, 0xff, 0xff, 0xff}), DecodeStatus::malformed);  // map32 of 2^32-1 entries
  EXPECT_EQ(dec({0x81, 0xa4, 'd', 'a', 't', 'a', 0xc6, 0xff, 0xff, 0xff, 0xff}), DecodeStatus::malformed);  // bin32, no body
  EXPECT_EQ(dec({0x81, 0xa7, 'c', 'h', 'a', 'n', 'n', 'e', 'l', 0xc9, 0xff, 0xff, 0xff, 0xff, 0x01}),
            DecodeStatus::malformed);  // ext32 of 2^32-1 bytes (msgpack-cxx throws inside)
  EXPECT_EQ(dec(std::vector<std::uint8_t>(kMaxDatagramSize + 1, 0x80)), DecodeStatus::malformed);

  // Every proper prefix of a valid datagram is malformed; trailing bytes are too.
  const auto good = encode(make_data(0x181, {1, 2, 3, 4}, false), 3.0);
  for (std::size_t n = 0; n < good.size(); ++n)
    EXPECT_EQ(dec(std::vector<std::uint8_t>(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n))), DecodeStatus::malformed) << n;
  auto extra = good;
  extra.push_back(0xc0);
  EXPECT_EQ(dec(extra), DecodeStatus::malformed);
  // Flipping any single byte never crashes, and what still decodes is a valid frame.
  for (std::size_t i = 0; i < good.size(); ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      auto b = good;
      b[i] ^= static_cast<std::uint8_t>(1u << bit);
      Decoded d;
      if (dec(b, &d) == DecodeStatus::ok) {
        EXPECT_TRUE(d.frame.valid()) << i << ":" << bit;
      }
    }
  }
}

TEST(CanMsgpack, StatusesHaveNames) {
  EXPECT_STREQ(to_string(DecodeStatus::wrong_dlc), "wrong DLC");
  EXPECT_STREQ(to_string(DecodeStatus::ok), "ok");
}

}  // namespace
}  // namespace omnitwin::can::msgpack_wire
