// Tests bus_emulators/ethercat/device/ec_coe: the CoE SDO server on the shipped drive's object
// dictionary, request by request — expedited, normal and segmented upload and download round
// trips (golden command bytes, toggle and last-segment bits), the abort codes provoked by bad
// requests, complete access, repeated requests recognised by the mailbox counter, SDO
// information (fragmented object list, object and entry description, error) and mailbox error
// replies. Round trips through the ESC's mailbox registers are in ec_slave_test.cpp.
#include "bus_emulators/ethercat/device/ec_coe.hpp"

#include <gtest/gtest.h>

#include <numeric>
#include <string>
#include <vector>

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::ethercat {
namespace {

using Bytes = std::vector<std::uint8_t>;

class EcCoe : public ::testing::Test {
 protected:
  void SetUp() override {
    od.add_from_esi(load_esi(std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/omnitwin_drive.xml").at(0));
    OdObject big;  // a 300-byte parameter block: segmented transfers
    big.index = 0x2200;
    big.name = "Block";
    OdEntry e;
    e.name = "Block";
    e.data_type = coe_type::octet_string;
    e.bits = 300 * 8;
    e.access = od_access::rw;
    big.entries.push_back(e);
    od.add(big);
    OdObject wo;
    wo.index = 0x2001;
    wo.name = "Password";
    OdEntry w;
    w.data_type = coe_type::uint32;
    w.bits = 32;
    w.access = od_access::write_all;
    wo.entries.push_back(w);
    od.add(wo);
    OdObject lim;
    lim.index = 0x2002;
    lim.name = "Gain";
    OdEntry l;
    l.data_type = coe_type::int16;
    l.bits = 16;
    l.access = od_access::rw;
    l.min = 0;
    l.max = 100;
    lim.entries.push_back(l);
    od.add(lim);
    CoeServerConfig cfg;
    cfg.complete_access = true;
    cfg.mailbox_size = 128;
    server = std::make_unique<CoeServer>(od, cfg);
  }

  // One SDO request: CoE service 2, command, index, subindex, 4 data bytes, extra data.
  Bytes sdo(std::uint8_t cmd, std::uint16_t index, std::uint8_t sub, std::uint32_t d4 = 0, const Bytes& extra = {}) {
    Bytes m(16, 0);
    put_u16(m.data(), static_cast<std::uint16_t>(10 + extra.size()));
    m[5] = static_cast<std::uint8_t>(3 | (next_counter() << 4));
    put_u16(m.data() + 6, 0x2000);
    m[8] = cmd;
    put_u16(m.data() + 9, index);
    m[11] = sub;
    put_u32(m.data() + 12, d4);
    for (const std::uint8_t b : extra) m.push_back(b);
    return m;
  }
  // A segment request (download: cmd + data padded to 7; upload: cmd only).
  Bytes segment(std::uint8_t cmd, const Bytes& data = {}) {
    const std::size_t n = std::max<std::size_t>(data.size(), 7);
    Bytes m(6 + 3 + n, 0);
    put_u16(m.data(), static_cast<std::uint16_t>(3 + n));
    m[5] = static_cast<std::uint8_t>(3 | (next_counter() << 4));
    put_u16(m.data() + 6, 0x2000);
    m[8] = cmd;
    std::copy(data.begin(), data.end(), m.begin() + 9);
    return m;
  }
  Bytes info(std::uint8_t opcode, const Bytes& body) {
    Bytes m(6 + 6 + body.size(), 0);
    put_u16(m.data(), static_cast<std::uint16_t>(6 + body.size()));
    m[5] = static_cast<std::uint8_t>(3 | (next_counter() << 4));
    put_u16(m.data() + 6, 0x8000);
    m[8] = opcode;
    std::copy(body.begin(), body.end(), m.begin() + 12);
    return m;
  }
  std::uint8_t next_counter() { return counter = next_mailbox_counter(counter); }
  // Sends one mailbox; returns every reply produced.
  std::vector<Bytes> send(const Bytes& m, OdState s = OdState::preop) {
    server->on_mailbox(m, s);
    std::vector<Bytes> out;
    while (server->has_reply()) {
      auto f = server->front();
      out.emplace_back(f.begin(), f.end());
      server->pop();
    }
    return out;
  }
  Bytes one(const Bytes& m, OdState s = OdState::preop) {
    auto r = send(m, s);
    EXPECT_EQ(r.size(), 1u);
    return r.empty() ? Bytes(16, 0) : r[0];
  }
  static std::uint32_t abort_code(const Bytes& r) {
    EXPECT_EQ(r[8], 0x80) << "not an abort";
    EXPECT_EQ(get_u16(r.data() + 6) >> 12, 2);  // abort travels in an SDO request service
    return get_u32(r.data() + 12);
  }
  std::uint32_t abort_of(const Bytes& m, OdState s = OdState::preop) { return abort_code(one(m, s)); }

  ObjectDictionary od;
  std::unique_ptr<CoeServer> server;
  std::uint8_t counter = 0;
};

// An empty value (an octet string of 0 bits) cannot go expedited (1-4 bytes): the normal
// initiate response, 0x41 with size 0 (it was 0x53, which set the complete-access bit; found
// by a protocol review).
TEST_F(EcCoe, AnEmptyValueIsANormalUploadOfSizeZero) {
  OdObject o;
  o.index = 0x2202;
  OdEntry e;
  e.data_type = coe_type::octet_string;
  e.bits = 0;
  e.access = od_access::rw;
  o.entries.push_back(e);
  od.add(o);
  auto r = one(sdo(0x40, 0x2202, 0));
  EXPECT_EQ(r[8], 0x41) << "normal initiate, size indicated";
  EXPECT_EQ(get_u16(r.data() + 9), 0x2202);
  EXPECT_EQ(get_u32(r.data() + 12), 0u);
}

TEST_F(EcCoe, ExpeditedUploadAndDownload) {
  auto r = one(sdo(0x40, 0x6065, 0));
  EXPECT_EQ(get_u16(r.data()), 10);       // mailbox length
  EXPECT_EQ(r[5] & 0x0F, 3);              // CoE
  EXPECT_EQ(get_u16(r.data() + 6) >> 12, 3);
  EXPECT_EQ(r[8], 0x43);                  // expedited, 4 bytes
  EXPECT_EQ(get_u16(r.data() + 9), 0x6065);
  EXPECT_EQ(get_u32(r.data() + 12), 10000u);
  r = one(sdo(0x40, 0x6060, 0));
  EXPECT_EQ(r[8], 0x4F);                  // 1 byte
  r = one(sdo(0x40, 0x6040, 0));
  EXPECT_EQ(r[8], 0x4B);                  // 2 bytes

  r = one(sdo(0x2B, 0x6040, 0, 0x000F));  // download 2 bytes
  EXPECT_EQ(r[8], 0x60);
  EXPECT_EQ(get_u16(r.data() + 9), 0x6040);
  EXPECT_EQ(od.entry(0x6040, 0)->as_int(), 0x000F);
  r = one(sdo(0x22, 0x6098, 0, 0x11));    // size not indicated: the entry's size
  EXPECT_EQ(r[8], 0x60);
  EXPECT_EQ(od.entry(0x6098, 0)->as_int(), 0x11);
}

TEST_F(EcCoe, NormalUploadAndDownload) {
  auto r = one(sdo(0x40, 0x1008, 0));
  const std::string name = "omnitwin drive 1-axis";
  EXPECT_EQ(r[8], 0x41);
  EXPECT_EQ(get_u32(r.data() + 12), name.size());
  EXPECT_EQ(get_u16(r.data()), 10 + name.size());
  EXPECT_EQ(std::string(r.begin() + 16, r.begin() + 16 + static_cast<std::ptrdiff_t>(name.size())), name);

  Bytes block(40);
  std::iota(block.begin(), block.end(), 1);
  r = one(sdo(0x21, 0x2200, 0, 40, block));
  EXPECT_EQ(r[8], 0x60);
  EXPECT_EQ(od.entry(0x2200, 0)->data()[39], 40);
  EXPECT_EQ(od.entry(0x2200, 0)->data()[40], 0);  // octet string: the rest zeroed
}

TEST_F(EcCoe, SegmentedDownloadThenUpload) {
  Bytes block(300);
  for (std::size_t i = 0; i < block.size(); ++i) block[i] = static_cast<std::uint8_t>(i * 7 + 3);
  // Initiate: as much as fits (128 − 16 = 112 bytes).
  auto r = one(sdo(0x21, 0x2200, 0, 300, Bytes(block.begin(), block.begin() + 112)));
  EXPECT_EQ(r[8], 0x60);
  std::size_t at = 112;
  std::uint8_t toggle = 0;
  while (at < block.size()) {
    const std::size_t n = std::min<std::size_t>(119, block.size() - at);
    const bool last = at + n == block.size();
    r = one(segment(static_cast<std::uint8_t>((toggle << 4) | (last ? 1 : 0)),
                    Bytes(block.begin() + static_cast<std::ptrdiff_t>(at), block.begin() + static_cast<std::ptrdiff_t>(at + n))));
    EXPECT_EQ(r[8], 0x20 | (toggle << 4));
    at += n;
    toggle ^= 1;
  }
  EXPECT_EQ(Bytes(od.entry(0x2200, 0)->data(), od.entry(0x2200, 0)->data() + 300), block);

  r = one(sdo(0x40, 0x2200, 0));
  ASSERT_EQ(r[8], 0x41);
  EXPECT_EQ(get_u32(r.data() + 12), 300u);
  Bytes got(r.begin() + 16, r.begin() + 6 + get_u16(r.data()));
  EXPECT_EQ(got.size(), 112u);
  toggle = 0;
  for (int guard = 0; guard < 10; ++guard) {
    r = one(segment(static_cast<std::uint8_t>(0x60 | (toggle << 4))));
    EXPECT_EQ((r[8] >> 4) & 1, toggle);
    EXPECT_EQ(r[8] & 0xE0, 0x00);
    got.insert(got.end(), r.begin() + 9, r.begin() + 6 + get_u16(r.data()));
    toggle ^= 1;
    if (r[8] & 1) break;
  }
  EXPECT_EQ(got, block);
}

TEST_F(EcCoe, ShortLastSegmentUsesUnusedBytes) {
  // 112 bytes in the initiate + 5 in one last segment of 7 bytes with n = 2 unused.
  Bytes block(117, 0x5A);
  one(sdo(0x21, 0x2200, 0, 117, Bytes(block.begin(), block.begin() + 112)));
  auto r = one(segment(0x00 | (2 << 1) | 1, Bytes(5, 0x5A)));
  EXPECT_EQ(r[8], 0x20);
  EXPECT_EQ(od.entry(0x2200, 0)->data()[116], 0x5A);
  // Upload of a 117-byte object: 112 bytes in the initiate, then one last segment of 5 bytes
  // padded to 7 with n = 2 unused.
  OdObject o;
  o.index = 0x2201;
  OdEntry e;
  e.data_type = coe_type::octet_string;
  e.bits = 117 * 8;
  e.access = od_access::rw;
  e.default_value.assign(117, 0x33);
  o.entries.push_back(e);
  od.add(o);
  auto init = one(sdo(0x40, 0x2201, 0));
  EXPECT_EQ(get_u32(init.data() + 12), 117u);
  auto s1 = one(segment(0x60));
  EXPECT_EQ(s1[8], 0x05);               // toggle 0, n = 2, last
  EXPECT_EQ(get_u16(s1.data()), 10);    // minimum segment size
  EXPECT_EQ(s1[9], 0x33);
  EXPECT_EQ(s1[13], 0x33);
  EXPECT_EQ(s1[14], 0x00);
  EXPECT_EQ(abort_of(segment(0x70)), 0x05040001u);  // transfer over
}

TEST_F(EcCoe, AbortCodes) {
  EXPECT_EQ(abort_of(sdo(0x40, 0x5555, 0)), 0x06020000u);                    // object does not exist
  EXPECT_EQ(abort_of(sdo(0x40, 0x6040, 7)), 0x06090011u);                    // subindex missing
  EXPECT_EQ(abort_of(sdo(0x40, 0x2001, 0)), 0x06010001u);                    // write-only
  EXPECT_EQ(abort_of(sdo(0x2B, 0x6041, 0, 1)), 0x06010002u);                 // read-only
  EXPECT_EQ(abort_of(sdo(0x23, 0x6040, 0, 1)), 0x06070012u);                 // 4 bytes to a u16: too long
  EXPECT_EQ(abort_of(sdo(0x2F, 0x6040, 0, 1)), 0x06070013u);                 // 1 byte to a u16: too short
  EXPECT_EQ(abort_of(sdo(0x2B, 0x2002, 0, 101)), 0x06090030u);               // value range
  EXPECT_EQ(abort_of(sdo(0x2F, 0x1600, 0, 0), OdState::safeop), 0x08000022u);// mapping writable in PRE-OP only
  EXPECT_EQ(abort_of(sdo(0xE0, 0x6040, 0)), 0x05040001u);                    // unknown command specifier
  EXPECT_EQ(abort_of(segment(0x60)), 0x05040001u);                           // upload segment, no transfer
  // Toggle bit not alternated.
  one(sdo(0x21, 0x2200, 0, 300, Bytes(112, 1)));
  EXPECT_EQ(abort_of(segment(0x10, Bytes(119, 2))), 0x05030000u);
  // Length mismatch: the last segment ends before the declared size.
  one(sdo(0x21, 0x2200, 0, 300, Bytes(112, 1)));
  EXPECT_EQ(abort_of(segment(0x01, Bytes(20, 2))), 0x06070010u);
  // Complete access where it is not advertised.
  CoeServerConfig cfg;
  cfg.complete_access = false;
  server = std::make_unique<CoeServer>(od, cfg);
  EXPECT_EQ(abort_of(sdo(0x50, 0x1C12, 0)), 0x06010000u);
  EXPECT_GE(server->stats().aborts, 1u);
}

TEST_F(EcCoe, CompleteAccess) {
  auto r = one(sdo(0x50, 0x1018, 0));  // complete access upload from subindex 0
  ASSERT_EQ(r[8], 0x51);
  EXPECT_EQ(get_u32(r.data() + 12), 18u);
  EXPECT_EQ(r[16], 4);                  // subindex 0, padded to 16 bits
  EXPECT_EQ(r[17], 0);
  EXPECT_EQ(get_u32(r.data() + 18), 0x00000F1Cu);
  EXPECT_EQ(get_u32(r.data() + 22), 0x00000402u);
  // Complete access download of the RxPDO assignment: 0x1601 only.
  r = one(sdo(0x31, 0x1C12, 0, 4, Bytes{1, 0, 0x01, 0x16}));
  EXPECT_EQ(r[8], 0x60);
  EXPECT_EQ(od.entry(0x1C12, 1)->as_int(), 0x1601);
}

// Complete access to a VAR is refused with 0x06010000 (see ObjectDictionary::read_complete); a
// segmented one at its initiate, before any segment is taken.
TEST_F(EcCoe, CompleteAccessToAVarIsRefused) {
  EXPECT_EQ(abort_of(sdo(0x50, 0x1000, 0)), 0x06010000u);
  EXPECT_EQ(abort_of(sdo(0x31, 0x6081, 0, 4, Bytes{0x10, 0x27, 0, 0})), 0x06010000u);
  EXPECT_EQ(abort_of(sdo(0x31, 0x2200, 0, 300, Bytes(112, 1))), 0x06010000u);
}

TEST_F(EcCoe, RepeatedCounterIsAnsweredAgainNotExecuted) {
  int writes = 0;
  od.find(0x6098)->after_write = [&](OdObject&, std::uint8_t) { ++writes; };
  const Bytes req = sdo(0x2F, 0x6098, 0, 1);
  const auto first = one(req);
  const auto again = one(req);  // same counter: the master lost the reply
  EXPECT_EQ(first, again);
  EXPECT_EQ(writes, 1);
  EXPECT_EQ(server->stats().repeats, 1u);
  one(sdo(0x2F, 0x6098, 0, 2));  // next counter: executed
  EXPECT_EQ(writes, 2);
  EXPECT_EQ(od.entry(0x6098, 0)->as_int(), 2);
}

TEST_F(EcCoe, RepeatWhileTheReplyIsUnreadAddsNoDuplicate) {
  const Bytes req = sdo(0x40, 0x6065, 0);
  server->on_mailbox(req, OdState::preop);
  server->on_mailbox(req, OdState::preop);  // reply still queued
  EXPECT_EQ(send(Bytes(req.begin(), req.end()), OdState::preop).size(), 1u);  // one reply in all
  server->on_mailbox(req, OdState::preop, true);  // the caller's SM1 still holds it
  EXPECT_FALSE(server->has_reply());
  EXPECT_EQ(server->stats().repeats, 3u);
}

TEST_F(EcCoe, SdoInfoObjectListIsFragmented) {
  auto r = send(info(0x01, Bytes{1, 0}));  // list type 1: all objects
  ASSERT_GT(r.size(), 1u);
  std::vector<std::uint16_t> indices;
  for (std::size_t i = 0; i < r.size(); ++i) {
    const auto& m = r[i];
    EXPECT_EQ(get_u16(m.data() + 6) >> 12, 8);
    EXPECT_EQ(m[8] & 0x7F, 0x02);
    EXPECT_EQ((m[8] & 0x80) != 0, i + 1 < r.size());  // incomplete while fragments follow
    EXPECT_EQ(get_u16(m.data() + 10), r.size() - 1 - i);
    const std::size_t end = 6 + get_u16(m.data());
    std::size_t at = 12;
    if (i == 0) {
      EXPECT_EQ(get_u16(m.data() + 12), 1);  // list type, first fragment only
      at = 14;
    }
    for (; at + 1 < end; at += 2) indices.push_back(get_u16(m.data() + at));
  }
  ASSERT_EQ(indices.size(), od.objects().size());
  for (std::size_t i = 0; i < indices.size(); ++i) EXPECT_EQ(indices[i], od.objects()[i].index);

  auto c = send(info(0x01, Bytes{0, 0}));  // list type 0: counts per list
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(get_u16(c[0].data() + 14), od.objects().size());
  EXPECT_GT(get_u16(c[0].data() + 16), 0);  // RxPDO-mappable objects
  EXPECT_GT(get_u16(c[0].data() + 18), 0);  // TxPDO-mappable objects
}

TEST_F(EcCoe, SdoInfoDescriptions) {
  auto r = send(info(0x03, Bytes{0x18, 0x10}));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0][8], 0x04);
  EXPECT_EQ(get_u16(r[0].data() + 12), 0x1018);
  EXPECT_EQ(r[0][16], 4);   // max subindex
  EXPECT_EQ(r[0][17], 9);   // RECORD
  EXPECT_EQ(std::string(r[0].begin() + 18, r[0].end()), "Identity");

  r = send(info(0x05, Bytes{0x40, 0x60, 0, 0}));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0][8], 0x06);
  EXPECT_EQ(get_u16(r[0].data() + 12), 0x6040);
  EXPECT_EQ(get_u16(r[0].data() + 16), coe_type::uint16);
  EXPECT_EQ(get_u16(r[0].data() + 18), 16);
  EXPECT_EQ(get_u16(r[0].data() + 20), od_access::rw | od_access::rxpdo);
  EXPECT_EQ(std::string(r[0].begin() + 22, r[0].end()), "Controlword");

  r = send(info(0x03, Bytes{0x55, 0x55}));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0][8], 0x07);
  EXPECT_EQ(get_u32(r[0].data() + 12), 0x06020000u);
  r = send(info(0x05, Bytes{0x40, 0x60, 9, 0}));
  EXPECT_EQ(get_u32(r[0].data() + 12), 0x06090011u);
}

TEST_F(EcCoe, MailboxErrors) {
  Bytes foe(16, 0);
  foe[0] = 10;
  foe[5] = 4 | (1 << 4);  // FoE
  auto r = one(foe);
  EXPECT_EQ(r[5] & 0x0F, 0);
  EXPECT_EQ(get_u16(r.data() + 6), 0x0001);
  EXPECT_EQ(get_u16(r.data() + 8), static_cast<std::uint16_t>(MailboxError::unsupported_protocol));
  Bytes lying(16, 0);
  lying[0] = 200;  // longer than the mailbox
  lying[5] = 3 | (2 << 4);
  r = one(lying);
  EXPECT_EQ(get_u16(r.data() + 8), static_cast<std::uint16_t>(MailboxError::invalid_size));
  Bytes emergency(16, 0);
  emergency[0] = 10;
  emergency[5] = 3 | (3 << 4);
  put_u16(emergency.data() + 6, 0x1000);  // service 1 from the master
  r = one(emergency);
  EXPECT_EQ(get_u16(r.data() + 8), static_cast<std::uint16_t>(MailboxError::service_not_supported));
  EXPECT_EQ(server->stats().mailbox_errors, 3u);
}

}  // namespace
}  // namespace omnitwin::ethercat
