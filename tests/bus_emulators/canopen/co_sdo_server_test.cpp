// Tests bus_emulators/canopen/co_sdo_server: the SDO server of node 5 against a small object
// dictionary built here — expedited upload/download byte for byte, segmented transfers with
// the toggle bit, block download and upload (sub-blocks, seqno errors and retransmission, CRC),
// every abort code the server sends (its own and the dictionary's), timeouts, reset and stats.
// The test plays the client by hand, frame by frame.
#include "bus_emulators/canopen/co_sdo_server.hpp"

#include <gtest/gtest.h>

#include <numeric>
#include <vector>

namespace omnitwin::canopen {
namespace {

using sdo::Payload;

constexpr std::uint8_t kNode = 5;
constexpr SimTime kMs = 1'000'000;
constexpr std::uint16_t kRw = od_access::rw, kRo = od_access::read_all;

OdEntry entry(std::uint8_t sub, std::uint16_t type, std::uint16_t bits, std::uint16_t access, std::uint64_t dflt) {
  OdEntry e;
  e.subindex = sub;
  e.data_type = type;
  e.bits = bits;
  e.access = access;
  for (int i = 0; i < (bits + 7) / 8 && i < 8; ++i) e.default_value.push_back(static_cast<std::uint8_t>(dflt >> (8 * i)));
  return e;
}

OdObject var(std::uint16_t index, OdEntry e) {
  OdObject o;
  o.index = index;
  o.data_type = e.data_type;
  o.entries.push_back(std::move(e));
  return o;
}

OdEntry string_entry(std::uint16_t type, std::size_t bytes) {
  OdEntry e = entry(0, type, static_cast<std::uint16_t>(bytes * 8), kRw, 0);
  e.default_value.assign(bytes, 0);
  return e;
}

// The dictionary of the tests.
void build(ObjectDictionary& od) {
  od.add(var(0x1000, entry(0, data_type::uint32, 32, kRo, 0x00020192)));
  od.add(var(0x2000, entry(0, data_type::uint8, 8, kRw, 0x11)));
  OdEntry limited = entry(0, data_type::uint16, 16, kRw, 100);
  limited.min = 10;
  limited.max = 1000;
  od.add(var(0x2001, limited));
  od.add(var(0x2002, entry(0, data_type::int32, 32, kRw, 0)));
  od.add(var(0x2003, string_entry(data_type::visible_string, 300)));
  od.add(var(0x2004, string_entry(data_type::octet_string, 300)));
  od.add(var(0x2005, entry(0, data_type::uint32, 32, od_access::write_all, 0)));
  od.add(var(0x2006, entry(0, data_type::uint32, 32, od_access::read_all | od_access::write_preop, 0)));
  OdObject rec;
  rec.index = 0x2007;
  rec.object_code = 9;
  rec.entries = {entry(0, data_type::uint8, 8, kRo, 2), entry(1, data_type::uint16, 16, kRw, 0x0102),
                 entry(2, data_type::uint32, 32, kRw, 0x03040506)};
  od.add(rec);
  OdObject hooked = var(0x2008, entry(0, data_type::uint32, 32, kRw, 0));
  hooked.check = [](const OdObject&, std::uint8_t, std::span<const std::uint8_t> d) {
    return get_u32(d.data()) > 5000 ? SdoAbort::value_too_high : SdoAbort::none;
  };
  od.add(hooked);
  od.add(var(0x2009, string_entry(data_type::octet_string, 2000)));
  od.add(var(0x200A, entry(0, data_type::uint64, 64, kRw, 0)));
  od.add(var(0x200B, string_entry(data_type::visible_string, 7)));
}

std::vector<std::uint8_t> pattern(std::size_t n, std::uint8_t seed = 0) {
  std::vector<std::uint8_t> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<std::uint8_t>(seed + i * 7 + (i >> 3));
  return v;
}

class SdoServerTest : public ::testing::Test {
 protected:
  SdoServerTest() { build(od); }

  SdoServer make(SdoServerConfig cfg = {}) {
    return SdoServer(od, kNode, [this](const can::Frame& f, SimTime at) {
      sent.push_back(f);
      times.push_back(at);
      return true;
    }, cfg);
  }

  // One request frame (8 bytes) from the client at t.
  void req(SdoServer& s, Payload p, OdState st = OdState::preop) { s.on_frame(sdo::make_frame(0x605, p), t, st); }
  Payload reply(std::size_t i) const { return sent.at(i).data; }
  Payload last() const { return sent.back().data; }
  std::vector<std::uint8_t> value(std::uint16_t index, std::uint8_t sub = 0) {
    const OdEntry* e = od.entry(index, sub);
    return {e->data(), e->data() + e->bytes()};
  }
  static Payload abort_of(std::uint16_t index, std::uint8_t sub, SdoAbort a) { return sdo::encode_abort({index, sub, a}); }
  SdoAbort last_abort() const {
    sdo::Abort a;
    return sdo::decode_abort(last(), a) == sdo::FrameStatus::ok ? a.code : SdoAbort::none;
  }

  // Segmented upload of index:sub through the initiate and every segment; toggles checked.
  std::vector<std::uint8_t> segmented_upload(SdoServer& s, std::uint16_t index, std::uint8_t sub) {
    req(s, sdo::encode_initiate_upload({index, sub}));
    sdo::Initiate m;
    EXPECT_EQ(sdo::decode_initiate(last(), m), sdo::FrameStatus::ok);
    EXPECT_FALSE(m.expedited);
    std::vector<std::uint8_t> out;
    for (bool toggle = false;; toggle = !toggle) {
      req(s, sdo::encode_upload_segment_request(toggle));
      sdo::Segment g;
      EXPECT_EQ(sdo::decode_segment(last(), g), sdo::FrameStatus::ok);
      EXPECT_EQ(g.toggle, toggle);
      out.insert(out.end(), g.data.begin(), g.data.begin() + g.len);
      if (g.last || out.size() > 4096) break;
    }
    EXPECT_EQ(out.size(), m.size);
    return out;
  }

  // Segmented download of `data` (size indicated) to index:sub; returns the last reply.
  void segmented_download(SdoServer& s, std::uint16_t index, std::uint8_t sub, const std::vector<std::uint8_t>& data,
                          OdState st = OdState::preop) {
    sdo::Initiate m;
    m.index = index;
    m.sub = sub;
    m.sized = true;
    m.size = static_cast<std::uint32_t>(data.size());
    req(s, sdo::encode_initiate_download(m), st);
    if (last()[0] != 0x60) return;
    bool toggle = false;
    for (std::size_t at = 0; at < data.size() || at == 0; toggle = !toggle) {
      sdo::Segment g;
      g.toggle = toggle;
      g.len = static_cast<std::uint8_t>(std::min<std::size_t>(7, data.size() - at));
      g.last = at + g.len == data.size();
      std::copy_n(data.begin() + static_cast<std::ptrdiff_t>(at), g.len, g.data.begin());
      req(s, sdo::encode_segment(g), st);
      if (last()[0] != (toggle ? 0x30 : 0x20)) return;
      at += g.len;
      if (g.last) return;
    }
  }

  // Sends the segments of `data` from byte `from` as one sub-block of `count` segments,
  // seqno 1..count (the one with the last byte has c = 1); `skip` (1-based) is left out.
  void send_sub_block(SdoServer& s, const std::vector<std::uint8_t>& data, std::size_t from, int count, int skip = 0) {
    for (int q = 1; q <= count; ++q) {
      const std::size_t at = from + static_cast<std::size_t>(q - 1) * 7;
      if (at >= data.size() && !(data.empty() && at == 0)) break;
      sdo::BlockSegment g;
      g.seqno = static_cast<std::uint8_t>(q);
      const std::size_t n = std::min<std::size_t>(7, data.size() - at);
      g.last = at + n == data.size();
      std::copy_n(data.begin() + static_cast<std::ptrdiff_t>(at), n, g.data.begin());
      if (q != skip) req(s, sdo::encode_block_segment(g));
      if (g.last) break;
    }
  }

  ObjectDictionary od;
  std::vector<can::Frame> sent;
  std::vector<SimTime> times;
  SimTime t = 10 * kMs;
};

// ---- expedited ---------------------------------------------------------------------------------

TEST_F(SdoServerTest, ExpeditedUploadIsByteExact) {
  SdoServer s = make();
  req(s, {0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0});
  ASSERT_EQ(sent.size(), 1u);
  EXPECT_EQ(sent[0].id, 0x585u);
  EXPECT_EQ(sent[0].dlc, 8);
  EXPECT_EQ(reply(0), (Payload{0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00}));
  EXPECT_EQ(times[0], t);
  req(s, {0x40, 0x00, 0x20, 0x00, 0, 0, 0, 0});
  EXPECT_EQ(reply(1), (Payload{0x4F, 0x00, 0x20, 0x00, 0x11, 0, 0, 0}));
  req(s, {0x40, 0x07, 0x20, 0x01, 0, 0, 0, 0});
  EXPECT_EQ(reply(2), (Payload{0x4B, 0x07, 0x20, 0x01, 0x02, 0x01, 0, 0}));
  EXPECT_EQ(s.stats().uploads, 3u);
  EXPECT_EQ(s.stats().requests, 3u);
  EXPECT_FALSE(s.busy());
}

TEST_F(SdoServerTest, ExpeditedDownloadWithSizeIsByteExact) {
  SdoServer s = make();
  req(s, {0x2B, 0x01, 0x20, 0x00, 0x34, 0x01, 0xEE, 0xEE});
  EXPECT_EQ(last(), (Payload{0x60, 0x01, 0x20, 0x00, 0, 0, 0, 0}));
  EXPECT_EQ(od.entry(0x2001, 0)->as_int(), 0x134);
  req(s, {0x23, 0x02, 0x20, 0x00, 0xFE, 0xFF, 0xFF, 0xFF});
  EXPECT_EQ(last(), (Payload{0x60, 0x02, 0x20, 0x00, 0, 0, 0, 0}));
  EXPECT_EQ(od.entry(0x2002, 0)->as_int(), -2);
  EXPECT_EQ(s.stats().downloads, 2u);
}

TEST_F(SdoServerTest, ExpeditedDownloadWithoutSizeTakesTheEntrysLength) {
  SdoServer s = make();
  req(s, {0x22, 0x00, 0x20, 0x00, 0x5A, 0x77, 0x77, 0x77});  // u8: one byte of four
  EXPECT_EQ(last()[0], 0x60);
  EXPECT_EQ(value(0x2000), (std::vector<std::uint8_t>{0x5A}));
  req(s, {0x22, 0x07, 0x20, 0x02, 1, 2, 3, 4});
  EXPECT_EQ(last()[0], 0x60);
  EXPECT_EQ(od.entry(0x2007, 2)->as_int(), 0x04030201);
}

TEST_F(SdoServerTest, ExpeditedLengthErrors) {
  SdoServer s = make();
  req(s, {0x2F, 0x01, 0x20, 0x00, 0x20, 0, 0, 0});  // 1 byte into a u16
  EXPECT_EQ(last(), abort_of(0x2001, 0, SdoAbort::too_short));
  req(s, {0x23, 0x01, 0x20, 0x00, 0x20, 0, 0, 0});  // 4 bytes into a u16
  EXPECT_EQ(last(), abort_of(0x2001, 0, SdoAbort::too_long));
  EXPECT_EQ(static_cast<std::uint32_t>(last_abort()), 0x06070012u);
  EXPECT_EQ(od.entry(0x2001, 0)->as_int(), 100);
}

// ---- the dictionary's abort codes -----------------------------------------------------------------

TEST_F(SdoServerTest, DictionaryAbortCodes) {
  SdoServer s = make();
  req(s, sdo::encode_initiate_upload({0x3000, 0}));
  EXPECT_EQ(last(), abort_of(0x3000, 0, SdoAbort::no_object));
  EXPECT_EQ(last()[7], 0x06);  // 0x06020000 little-endian
  req(s, sdo::encode_initiate_upload({0x2007, 5}));
  EXPECT_EQ(last(), abort_of(0x2007, 5, SdoAbort::no_subindex));
  req(s, {0x23, 0x00, 0x10, 0x00, 1, 2, 3, 4});
  EXPECT_EQ(last(), abort_of(0x1000, 0, SdoAbort::read_only));
  req(s, sdo::encode_initiate_upload({0x2005, 0}));
  EXPECT_EQ(last(), abort_of(0x2005, 0, SdoAbort::write_only));
  req(s, {0x2B, 0x01, 0x20, 0x00, 0xE9, 0x03, 0, 0});  // 1001 > max 1000
  EXPECT_EQ(last(), abort_of(0x2001, 0, SdoAbort::value_range));
  req(s, {0x2B, 0x01, 0x20, 0x00, 0x09, 0x00, 0, 0});  // 9 < min 10
  EXPECT_EQ(last(), abort_of(0x2001, 0, SdoAbort::value_range));
  req(s, {0x23, 0x08, 0x20, 0x00, 0x89, 0x13, 0, 0});  // 5001: the check hook
  EXPECT_EQ(last(), abort_of(0x2008, 0, SdoAbort::value_too_high));
  req(s, {0x23, 0x06, 0x20, 0x00, 1, 0, 0, 0}, OdState::op);  // writable in PRE-OP only
  EXPECT_EQ(last(), abort_of(0x2006, 0, SdoAbort::state));
  req(s, {0x23, 0x06, 0x20, 0x00, 1, 0, 0, 0}, OdState::preop);
  EXPECT_EQ(last()[0], 0x60);
  EXPECT_EQ(s.stats().aborts_sent, 8u);
  EXPECT_EQ(s.stats().aborts_with(SdoAbort::value_range), 2u);
  EXPECT_EQ(s.stats().aborts_with(SdoAbort::state), 1u);
  EXPECT_EQ(s.stats().aborts_with(SdoAbort::toggle), 0u);
  EXPECT_EQ(od.entry(0x2001, 0)->as_int(), 100);
  EXPECT_EQ(od.entry(0x2008, 0)->as_int(), 0);
}

TEST_F(SdoServerTest, SegmentedDownloadChecksTheObjectAtTheInitiate) {
  SdoServer s = make();
  segmented_download(s, 0x1000, 0, pattern(4));
  EXPECT_EQ(last(), abort_of(0x1000, 0, SdoAbort::read_only));
  segmented_download(s, 0x2003, 0, pattern(301));
  EXPECT_EQ(last(), abort_of(0x2003, 0, SdoAbort::too_long));
  segmented_download(s, 0x200A, 0, pattern(6));
  EXPECT_EQ(last(), abort_of(0x200A, 0, SdoAbort::too_short));
  segmented_download(s, 0x2006, 0, pattern(4), OdState::op);
  EXPECT_EQ(last(), abort_of(0x2006, 0, SdoAbort::state));
  EXPECT_FALSE(s.busy());
}

// ---- segmented ----------------------------------------------------------------------------------

TEST_F(SdoServerTest, SegmentedUploadOfAStringWithToggles) {
  const auto text = pattern(300, 3);
  ASSERT_EQ(od.write(0x2003, 0, OdState::preop, text), SdoAbort::none);
  SdoServer s = make();
  EXPECT_EQ(segmented_upload(s, 0x2003, 0), text);
  ASSERT_EQ(sent.size(), 1u + 43u);
  EXPECT_EQ(reply(0), (Payload{0x41, 0x03, 0x20, 0x00, 0x2C, 0x01, 0, 0}));
  EXPECT_EQ(reply(1)[0], 0x00);  // toggle 0, 7 bytes
  EXPECT_EQ(reply(2)[0], 0x10);  // toggle 1, 7 bytes
  EXPECT_EQ(sent.back().data[0], 0x00 | (1 << 1) | 1);  // 43rd segment: toggle 0, 6 bytes (n = 1), c
  EXPECT_FALSE(s.busy());
  EXPECT_EQ(s.stats().segments, 43u);
}

TEST_F(SdoServerTest, SegmentedUploadOfAnEightByteNumber) {
  SdoServer s = make();
  ASSERT_EQ(od.write(0x200A, 0, OdState::preop, pattern(8)), SdoAbort::none);
  EXPECT_EQ(segmented_upload(s, 0x200A, 0), pattern(8));
}

TEST_F(SdoServerTest, SegmentedDownloadWritesTheDictionaryOnceAtTheEnd) {
  int writes = 0;
  od.find(0x2004)->after_write = [&](OdObject&, std::uint8_t) { ++writes; };
  SdoServer s = make();
  const auto data = pattern(300, 9);
  sdo::Initiate m;
  m.index = 0x2004;
  m.sized = true;
  m.size = 300;
  req(s, sdo::encode_initiate_download(m));
  EXPECT_EQ(last(), (Payload{0x60, 0x04, 0x20, 0x00, 0, 0, 0, 0}));
  bool toggle = false;
  for (std::size_t at = 0; at < 300; at += 7, toggle = !toggle) {
    EXPECT_EQ(writes, 0);
    sdo::Segment g;
    g.toggle = toggle;
    g.len = static_cast<std::uint8_t>(std::min<std::size_t>(7, 300 - at));
    g.last = at + g.len == 300;
    std::copy_n(data.begin() + static_cast<std::ptrdiff_t>(at), g.len, g.data.begin());
    req(s, sdo::encode_segment(g));
    EXPECT_EQ(last(), (Payload{static_cast<std::uint8_t>(toggle ? 0x30 : 0x20), 0, 0, 0, 0, 0, 0, 0}));
  }
  EXPECT_EQ(writes, 1);
  EXPECT_EQ(value(0x2004), data);
  EXPECT_EQ(s.stats().downloads, 1u);
}

TEST_F(SdoServerTest, SegmentedDownloadWithoutSizeAndShorterString) {
  SdoServer s = make();
  ASSERT_EQ(od.write(0x2003, 0, OdState::preop, pattern(300, 1)), SdoAbort::none);
  req(s, {0x20, 0x03, 0x20, 0x00, 0, 0, 0, 0});  // size not indicated
  EXPECT_EQ(last()[0], 0x60);
  req(s, {0x00, 'h', 'e', 'l', 'l', 'o', ',', ' '});
  req(s, {0x10 | (4 << 1) | 1, 'C', 'A', 'N', 0, 0, 0, 0});
  EXPECT_EQ(last()[0], 0x30);
  const auto v = value(0x2003);
  EXPECT_EQ(std::string(v.begin(), v.begin() + 10), "hello, CAN");
  EXPECT_EQ(v[10], 0);  // the rest of the string zeroed by the dictionary
}

TEST_F(SdoServerTest, ToggleErrorsAbortBothDirections) {
  SdoServer s = make();
  req(s, sdo::encode_initiate_upload({0x2003, 0}));
  req(s, sdo::encode_upload_segment_request(false));
  req(s, sdo::encode_upload_segment_request(false));  // should have been 1
  EXPECT_EQ(last(), abort_of(0x2003, 0, SdoAbort::toggle));
  EXPECT_FALSE(s.busy());
  sdo::Initiate m;
  m.index = 0x2004;
  m.sized = true;
  m.size = 20;
  req(s, sdo::encode_initiate_download(m));
  req(s, {0x10, 1, 2, 3, 4, 5, 6, 7});  // first segment must have toggle 0
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::toggle));
  EXPECT_EQ(static_cast<std::uint32_t>(last_abort()), 0x05030000u);
  EXPECT_EQ(s.stats().aborts_with(SdoAbort::toggle), 2u);
}

TEST_F(SdoServerTest, SegmentedDownloadLengthMismatch) {
  SdoServer s = make();
  sdo::Initiate m;
  m.index = 0x2004;
  m.sized = true;
  m.size = 10;
  req(s, sdo::encode_initiate_download(m));
  req(s, {0x00, 1, 2, 3, 4, 5, 6, 7});
  req(s, {0x10 | 1, 1, 2, 3, 4, 5, 6, 7});  // 14 > 10
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::length_mismatch));
  req(s, sdo::encode_initiate_download(m));
  req(s, {0x00 | 1, 1, 2, 3, 4, 5, 6, 7});  // ends at 7 < 10
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::length_mismatch));
  EXPECT_EQ(static_cast<std::uint32_t>(last_abort()), 0x06070010u);
  EXPECT_EQ(value(0x2004), std::vector<std::uint8_t>(300, 0));
}

TEST_F(SdoServerTest, OutOfMemoryBeyondTheBuffer) {
  SdoServer s = make();
  req(s, sdo::encode_initiate_upload({0x2009, 0}));  // 2000 bytes > 1024
  EXPECT_EQ(last(), abort_of(0x2009, 0, SdoAbort::out_of_memory));
  segmented_download(s, 0x2009, 0, pattern(1500));
  EXPECT_EQ(last(), abort_of(0x2009, 0, SdoAbort::out_of_memory));
  // Size not indicated: aborted when the data outgrows the buffer.
  req(s, {0x20, 0x09, 0x20, 0x00, 0, 0, 0, 0});
  bool toggle = false;
  int segments = 0;
  while (last()[0] != 0x80 && segments < 300) {
    req(s, {static_cast<std::uint8_t>(toggle ? 0x10 : 0x00), 1, 2, 3, 4, 5, 6, 7});
    toggle = !toggle;
    ++segments;
  }
  EXPECT_EQ(last(), abort_of(0x2009, 0, SdoAbort::out_of_memory));
  EXPECT_EQ(segments, 1024 / 7 + 1);
  sdo::BlockInitiate b;
  b.index = 0x2009;
  b.sized = true;
  b.size = 1025;
  req(s, sdo::encode_block_download_initiate(b));
  EXPECT_EQ(last(), abort_of(0x2009, 0, SdoAbort::out_of_memory));
  b.blksize = 10;
  req(s, sdo::encode_block_upload_initiate(b));
  EXPECT_EQ(last(), abort_of(0x2009, 0, SdoAbort::out_of_memory));
  EXPECT_EQ(static_cast<std::uint32_t>(last_abort()), 0x05040005u);
}

// ---- protocol errors, client abort, timeout, reset ------------------------------------------------

TEST_F(SdoServerTest, UnknownOrMisplacedCommandsAbort) {
  SdoServer s = make();
  req(s, {0xE0, 0x00, 0x20, 0x00, 0, 0, 0, 0});  // CCS 7
  EXPECT_EQ(last(), abort_of(0x2000, 0, SdoAbort::invalid_command));
  req(s, {0x60, 0x00, 0x20, 0x00, 0, 0, 0, 0});  // upload segment without a transfer
  EXPECT_EQ(last(), abort_of(0x2000, 0, SdoAbort::invalid_command));
  req(s, {0x00, 1, 2, 3, 4, 5, 6, 7});  // download segment without a transfer
  EXPECT_EQ(last_abort(), SdoAbort::invalid_command);
  req(s, {0xA3, 0, 0, 0, 0, 0, 0, 0});  // block upload start without an initiate
  EXPECT_EQ(last_abort(), SdoAbort::invalid_command);
  // A running segmented upload is aborted by an unexpected initiate.
  req(s, sdo::encode_initiate_upload({0x2003, 0}));
  req(s, sdo::encode_initiate_upload({0x2004, 0}));
  EXPECT_EQ(last(), abort_of(0x2003, 0, SdoAbort::invalid_command));
  EXPECT_FALSE(s.busy());
  EXPECT_EQ(static_cast<std::uint32_t>(last_abort()), 0x05040001u);
}

TEST_F(SdoServerTest, ShortFramesAbortWithInvalidCommand) {
  SdoServer s = make();
  s.on_frame(can::make_data(0x605, {0x40, 0x00, 0x10, 0x00}), t, OdState::preop);
  EXPECT_EQ(last(), abort_of(0x1000, 0, SdoAbort::invalid_command));
  s.on_frame(can::make_data(0x605, {0x40}), t, OdState::preop);
  EXPECT_EQ(last(), abort_of(0, 0, SdoAbort::invalid_command));
  req(s, sdo::encode_initiate_upload({0x2003, 0}));
  s.on_frame(can::make_data(0x605, {0x60}), t, OdState::preop);
  EXPECT_EQ(last(), abort_of(0x2003, 0, SdoAbort::invalid_command));
  EXPECT_FALSE(s.busy());
}

TEST_F(SdoServerTest, OtherFramesAreIgnored) {
  SdoServer s = make();
  s.on_frame(sdo::make_frame(0x606, sdo::encode_initiate_upload({0x1000, 0})), t, OdState::preop);
  s.on_frame(sdo::make_frame(0x585, sdo::encode_initiate_upload({0x1000, 0})), t, OdState::preop);
  s.on_frame(can::make_remote(0x605, 8), t, OdState::preop);
  can::Frame x = sdo::make_frame(0x605, sdo::encode_initiate_upload({0x1000, 0}));
  x.extended = true;
  s.on_frame(x, t, OdState::preop);
  EXPECT_TRUE(sent.empty());
  EXPECT_EQ(s.stats().requests, 0u);
}

TEST_F(SdoServerTest, ClientAbortDropsTheTransferSilently) {
  SdoServer s = make();
  req(s, sdo::encode_initiate_upload({0x2003, 0}));
  req(s, sdo::encode_upload_segment_request(false));
  const auto n = sent.size();
  req(s, sdo::encode_abort({0x2003, 0, SdoAbort::general}));
  EXPECT_EQ(sent.size(), n);
  EXPECT_FALSE(s.busy());
  EXPECT_EQ(s.stats().aborts_received, 1u);
  req(s, sdo::encode_upload_segment_request(true));  // the transfer is gone
  EXPECT_EQ(last_abort(), SdoAbort::invalid_command);
}

TEST_F(SdoServerTest, StalledTransferTimesOut) {
  SdoServer s = make();
  req(s, sdo::encode_initiate_upload({0x2003, 0}));
  t += 600 * kMs;
  req(s, sdo::encode_upload_segment_request(false));  // activity restarts the timer
  const auto n = sent.size();
  s.on_time(t + 999 * kMs);
  EXPECT_EQ(sent.size(), n);
  EXPECT_TRUE(s.busy());
  s.on_time(t + 1000 * kMs);
  EXPECT_EQ(last(), abort_of(0x2003, 0, SdoAbort::timeout));
  EXPECT_EQ(times.back(), t + 1000 * kMs);
  EXPECT_FALSE(s.busy());
  EXPECT_EQ(s.stats().timeouts, 1u);
  s.on_time(t + 5000 * kMs);  // idle: nothing more
  EXPECT_EQ(sent.size(), n + 1);
  EXPECT_EQ(static_cast<std::uint32_t>(last_abort()), 0x05040000u);
}

TEST_F(SdoServerTest, ConfiguredTimeoutAndReset) {
  SdoServerConfig cfg;
  cfg.timeout_ns = 50 * kMs;
  SdoServer s = make(cfg);
  req(s, sdo::encode_initiate_upload({0x2003, 0}));
  s.reset();
  EXPECT_FALSE(s.busy());
  const auto n = sent.size();
  s.on_time(t + 60 * kMs);
  EXPECT_EQ(sent.size(), n);  // nothing to time out after reset
  req(s, sdo::encode_initiate_upload({0x2003, 0}));
  s.on_time(t + 50 * kMs);
  EXPECT_EQ(last_abort(), SdoAbort::timeout);
}

TEST_F(SdoServerTest, ConstructionChecksItsArguments) {
  SendFn send = [](const can::Frame&, SimTime) { return true; };
  EXPECT_THROW(SdoServer(od, 0, send), std::invalid_argument);
  EXPECT_THROW(SdoServer(od, 128, send), std::invalid_argument);
  SdoServerConfig cfg;
  cfg.blksize = 0;
  EXPECT_THROW(SdoServer(od, 1, send, cfg), std::invalid_argument);
  EXPECT_THROW(SdoServer(od, 1, SendFn{}), std::invalid_argument);
  SdoServer s(od, 127, send);
  EXPECT_EQ(s.rx_cob(), 0x67Fu);
  EXPECT_EQ(s.tx_cob(), 0x5FFu);
}

// ---- block download --------------------------------------------------------------------------------

TEST_F(SdoServerTest, BlockDownloadInSubBlocksWithCrc) {
  SdoServerConfig cfg;
  cfg.blksize = 10;
  SdoServer s = make(cfg);
  const auto data = pattern(300, 5);
  sdo::BlockInitiate b;
  b.index = 0x2004;
  b.crc = b.sized = true;
  b.size = 300;
  req(s, sdo::encode_block_download_initiate(b));
  EXPECT_EQ(last(), (Payload{0xA4, 0x04, 0x20, 0x00, 10, 0, 0, 0}));
  // 43 segments: sub-blocks of 10, 10, 10, 10, 3.
  std::size_t from = 0;
  for (int block = 0; block < 5; ++block) {
    const auto n = sent.size();
    send_sub_block(s, data, from, 10);
    ASSERT_EQ(sent.size(), n + 1) << "one ack per sub-block";
    const int count = block < 4 ? 10 : 3;
    EXPECT_EQ(last(), (Payload{0xA2, static_cast<std::uint8_t>(count), 10, 0, 0, 0, 0, 0}));
    from += static_cast<std::size_t>(count) * 7;
  }
  EXPECT_EQ(value(0x2004), std::vector<std::uint8_t>(300, 0));  // not written before the end
  req(s, sdo::encode_block_end({sdo::block_unused(300), sdo::crc16(data)}));
  EXPECT_EQ(last(), (Payload{0xA1, 0, 0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(value(0x2004), data);
  EXPECT_EQ(s.stats().downloads, 1u);
  EXPECT_EQ(s.stats().blocks, 5u);
  EXPECT_EQ(s.stats().block_segments, 43u);
  EXPECT_FALSE(s.busy());
}

TEST_F(SdoServerTest, BlockDownloadCrcError) {
  SdoServer s = make();
  const auto data = pattern(20, 1);
  sdo::BlockInitiate b;
  b.index = 0x2004;
  b.crc = b.sized = true;
  b.size = 20;
  req(s, sdo::encode_block_download_initiate(b));
  send_sub_block(s, data, 0, 127);
  EXPECT_EQ(last(), (Payload{0xA2, 3, 127, 0, 0, 0, 0, 0}));
  req(s, sdo::encode_block_end({1, static_cast<std::uint16_t>(sdo::crc16(data) ^ 0x0100)}));
  EXPECT_EQ(last(), abort_of(0x2004, 0, sdo::abort_crc));
  EXPECT_EQ(static_cast<std::uint32_t>(last_abort()), 0x05040004u);
  EXPECT_EQ(value(0x2004), std::vector<std::uint8_t>(300, 0));
  EXPECT_EQ(s.stats().aborts_with(sdo::abort_crc), 1u);
}

TEST_F(SdoServerTest, BlockDownloadWithoutCrcIgnoresTheField) {
  SdoServer s = make();
  const auto data = pattern(8, 2);
  sdo::BlockInitiate b;
  b.index = 0x200A;
  b.crc = false;  // the client does not support CRC
  b.sized = true;
  b.size = 8;
  req(s, sdo::encode_block_download_initiate(b));
  EXPECT_EQ(last()[0], 0xA4);  // the server still says it would
  send_sub_block(s, data, 0, 127);
  req(s, sdo::encode_block_end({6, 0xDEAD}));
  EXPECT_EQ(last()[0], 0xA1);
  EXPECT_EQ(value(0x200A), data);
}

TEST_F(SdoServerTest, BlockDownloadWrongSeqnoIsAckedWithTheLastGoodOne) {
  SdoServerConfig cfg;
  cfg.blksize = 5;
  SdoServer s = make(cfg);
  const auto data = pattern(60, 7);  // 9 segments
  sdo::BlockInitiate b;
  b.index = 0x2004;
  b.crc = b.sized = true;
  b.size = 60;
  req(s, sdo::encode_block_download_initiate(b));
  send_sub_block(s, data, 0, 5, 3);  // segment 3 lost: 4 and 5 arrive out of order
  EXPECT_EQ(last(), (Payload{0xA2, 2, 5, 0, 0, 0, 0, 0}));
  send_sub_block(s, data, 14, 5);  // resumes at byte 14 with seqno 1
  EXPECT_EQ(last(), (Payload{0xA2, 5, 5, 0, 0, 0, 0, 0}));
  send_sub_block(s, data, 49, 5);  // two segments, the last with c = 1
  EXPECT_EQ(last(), (Payload{0xA2, 2, 5, 0, 0, 0, 0, 0}));
  req(s, sdo::encode_block_end({sdo::block_unused(60), sdo::crc16(data)}));
  EXPECT_EQ(last()[0], 0xA1);
  const auto v = value(0x2004);
  EXPECT_EQ(std::vector<std::uint8_t>(v.begin(), v.begin() + 60), data);
  EXPECT_EQ(v[60], 0);
}

TEST_F(SdoServerTest, BlockDownloadLostLastSegmentIsRetransmitted) {
  SdoServer s = make();
  sdo::BlockInitiate b;
  b.index = 0x200B;
  b.sized = true;
  b.size = 7;
  req(s, sdo::encode_block_download_initiate(b));
  // Segment 1 lost, a segment with c = 1 arrives as seqno 2: discarded, acked with 0.
  req(s, {0x82, 1, 2, 3, 4, 5, 6, 7});
  EXPECT_EQ(last(), (Payload{0xA2, 0, 127, 0, 0, 0, 0, 0}));
  EXPECT_TRUE(s.busy());
  req(s, {0x81, 'a', 'b', 'c', 'd', 'e', 'f', 'g'});
  EXPECT_EQ(last(), (Payload{0xA2, 1, 127, 0, 0, 0, 0, 0}));
  req(s, sdo::encode_block_end({0, 0}));  // CRC not in use: the client did not ask for it
  EXPECT_EQ(last()[0], 0xA1);
  EXPECT_EQ(value(0x200B), (std::vector<std::uint8_t>{'a', 'b', 'c', 'd', 'e', 'f', 'g'}));
}

TEST_F(SdoServerTest, BlockDownloadInvalidSeqnoAborts) {
  SdoServerConfig cfg;
  cfg.blksize = 4;
  SdoServer s = make(cfg);
  sdo::BlockInitiate b;
  b.index = 0x2004;
  b.sized = true;
  b.size = 50;
  req(s, sdo::encode_block_download_initiate(b));
  req(s, {0x05, 1, 2, 3, 4, 5, 6, 7});  // seqno 5 > blksize 4
  EXPECT_EQ(last(), abort_of(0x2004, 0, sdo::abort_invalid_seqno));
  req(s, sdo::encode_block_download_initiate(b));
  req(s, {0x00, 1, 2, 3, 4, 5, 6, 7});  // seqno 0
  EXPECT_EQ(last(), abort_of(0x2004, 0, sdo::abort_invalid_seqno));
  EXPECT_EQ(static_cast<std::uint32_t>(last_abort()), 0x05040003u);
  // 0x80 in a sub-block is the client's abort, not a segment.
  req(s, sdo::encode_block_download_initiate(b));
  const auto n = sent.size();
  req(s, sdo::encode_abort({0x2004, 0, SdoAbort::general}));
  EXPECT_EQ(sent.size(), n);
  EXPECT_FALSE(s.busy());
}

TEST_F(SdoServerTest, BlockDownloadSizeMismatchAtTheEnd) {
  SdoServer s = make();
  const auto data = pattern(14);
  sdo::BlockInitiate b;
  b.index = 0x2004;
  b.sized = true;
  b.size = 12;
  req(s, sdo::encode_block_download_initiate(b));
  send_sub_block(s, data, 0, 127);
  req(s, sdo::encode_block_end({0, 0}));  // 14 bytes, 12 announced
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::length_mismatch));
  // Segments beyond the announced size abort at once.
  b.size = 7;
  req(s, sdo::encode_block_download_initiate(b));
  req(s, {0x01, 1, 2, 3, 4, 5, 6, 7});
  req(s, {0x02, 1, 2, 3, 4, 5, 6, 7});
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::length_mismatch));
}

TEST_F(SdoServerTest, BlockDownloadEndExpectedAfterTheLastAck) {
  SdoServer s = make();
  sdo::BlockInitiate b;
  b.index = 0x2004;
  req(s, sdo::encode_block_download_initiate(b));
  req(s, {0x81, 1, 2, 3, 4, 5, 6, 7});
  EXPECT_EQ(last()[0], 0xA2);
  req(s, sdo::encode_initiate_upload({0x2004, 0}));  // not the end request
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::invalid_command));
}

// ---- block upload -----------------------------------------------------------------------------------

TEST_F(SdoServerTest, BlockUploadWithCrcAndRetransmission) {
  const auto data = pattern(100, 4);  // 15 segments
  ASSERT_EQ(od.write(0x2004, 0, OdState::preop, data), SdoAbort::none);
  SdoServer s = make();
  sdo::BlockInitiate b;
  b.index = 0x2004;
  b.crc = true;
  b.blksize = 6;
  b.pst = 0;
  req(s, sdo::encode_block_upload_initiate(b));
  EXPECT_EQ(last(), (Payload{0xC6, 0x04, 0x20, 0x00, 0x2C, 0x01, 0, 0}));  // size 300: the whole entry
  sent.clear();
  req(s, sdo::encode_block_upload_start());
  ASSERT_EQ(sent.size(), 6u);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(reply(i)[0], i + 1);
    EXPECT_EQ(reply(i)[1], data[i * 7]);
  }
  // Ack only 4 of 6: the next sub-block starts at byte 28.
  sent.clear();
  req(s, sdo::encode_block_ack({4, 6}));
  ASSERT_EQ(sent.size(), 6u);
  EXPECT_EQ(reply(0)[0], 1);
  EXPECT_EQ(reply(0)[1], data[28]);
  std::vector<std::uint8_t> got(data.begin(), data.begin() + 28);
  for (int guard = 0; guard < 100; ++guard) {
    // Collect the segments just sent, ack them all (with a new, smaller blksize).
    bool end = false;
    for (const auto& f : sent) {
      got.insert(got.end(), f.data.begin() + 1, f.data.end());
      end = end || (f.data[0] & 0x80);
    }
    const auto n = static_cast<std::uint8_t>(sent.size());
    sent.clear();
    req(s, sdo::encode_block_ack({n, 5}));
    if (end) break;
    EXPECT_LE(sent.size(), 5u);
  }
  ASSERT_EQ(sent.size(), 1u);
  sdo::BlockEnd e;
  ASSERT_EQ(sdo::decode_block_end(last(), e), sdo::FrameStatus::ok);
  EXPECT_EQ(e.unused, sdo::block_unused(300));
  got.resize(got.size() - e.unused);
  std::vector<std::uint8_t> whole(300, 0);
  std::copy(data.begin(), data.end(), whole.begin());
  EXPECT_EQ(got, whole);
  EXPECT_EQ(e.crc, sdo::crc16(whole));
  EXPECT_TRUE(s.busy());
  req(s, sdo::encode_block_end_response());
  EXPECT_FALSE(s.busy());
  EXPECT_EQ(s.stats().uploads, 1u);
}

TEST_F(SdoServerTest, BlockUploadOfASmallObjectWithoutCrc) {
  SdoServer s = make();
  sdo::BlockInitiate b;
  b.index = 0x1000;
  b.crc = false;
  b.blksize = 127;
  b.pst = 10;  // the protocol switch threshold is ignored: still a block upload
  req(s, sdo::encode_block_upload_initiate(b));
  EXPECT_EQ(last(), (Payload{0xC6, 0x00, 0x10, 0x00, 4, 0, 0, 0}));
  req(s, sdo::encode_block_upload_start());
  EXPECT_EQ(last(), (Payload{0x81, 0x92, 0x01, 0x02, 0x00, 0, 0, 0}));
  req(s, sdo::encode_block_ack({1, 127}));
  EXPECT_EQ(last(), (Payload{0xC1 | (3 << 2), 0, 0, 0, 0, 0, 0, 0}));  // CRC 0: not in use
  req(s, sdo::encode_block_end_response());
  EXPECT_FALSE(s.busy());
}

TEST_F(SdoServerTest, BlockUploadErrors) {
  SdoServer s = make();
  sdo::BlockInitiate b;
  b.index = 0x2004;
  b.blksize = 0;
  req(s, sdo::encode_block_upload_initiate(b));
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::invalid_block_size));
  b.blksize = 3;
  req(s, sdo::encode_block_upload_initiate(b));
  req(s, sdo::encode_block_upload_start());
  req(s, sdo::encode_block_ack({4, 3}));  // only 3 were sent
  EXPECT_EQ(last(), abort_of(0x2004, 0, sdo::abort_invalid_seqno));
  req(s, sdo::encode_block_upload_initiate(b));
  req(s, sdo::encode_block_upload_start());
  req(s, sdo::encode_block_ack({3, 0}));
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::invalid_block_size));
  EXPECT_EQ(static_cast<std::uint32_t>(last_abort()), 0x05040002u);
  req(s, sdo::encode_block_upload_initiate(b));
  req(s, sdo::encode_upload_segment_request(false));  // not the start request
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::invalid_command));
  b.index = 0x2005;
  req(s, sdo::encode_block_upload_initiate(b));
  EXPECT_EQ(last(), abort_of(0x2005, 0, SdoAbort::write_only));
}

TEST_F(SdoServerTest, BlockUploadTimesOutWaitingForTheAck) {
  SdoServer s = make();
  sdo::BlockInitiate b;
  b.index = 0x2004;
  b.blksize = 10;
  req(s, sdo::encode_block_upload_initiate(b));
  t += kMs;
  req(s, sdo::encode_block_upload_start());
  s.on_time(t + 1000 * kMs - 1);
  EXPECT_NE(last_abort(), SdoAbort::timeout);
  s.on_time(t + 1000 * kMs);
  EXPECT_EQ(last(), abort_of(0x2004, 0, SdoAbort::timeout));
}

TEST_F(SdoServerTest, StatsCountPerAbortCode) {
  SdoServer s = make();
  for (int i = 0; i < 3; ++i) req(s, sdo::encode_initiate_upload({0x3000, 0}));
  req(s, sdo::encode_initiate_upload({0x2005, 0}));
  EXPECT_EQ(s.stats().aborts_sent, 4u);
  EXPECT_EQ(s.stats().aborts_with(SdoAbort::no_object), 3u);
  EXPECT_EQ(s.stats().aborts_with(SdoAbort::write_only), 1u);
  EXPECT_EQ(s.stats().abort_code[0], 0x06020000u);
  EXPECT_EQ(s.stats().requests, 4u);
  EXPECT_EQ(s.stats().uploads, 0u);
}

}  // namespace
}  // namespace omnitwin::canopen
