// Tests controller/canopen/co_sdo_client: the master's SDO client against the real SDO server
// of bus_emulators/canopen in process (frames carried through a queue, 10 µs apart) — every
// transfer mode both ways, a 300-byte VISIBLE_STRING and OCTET_STRING, lost and corrupted
// frames in block transfers, aborts from the server, client timeouts, cancel, several nodes at
// once, and the completion callback.
#include "controller/canopen/co_sdo_client.hpp"

#include <gtest/gtest.h>

#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/canopen/co_sdo_server.hpp"

namespace omnitwin::controller::canopen {
namespace {

namespace co = omnitwin::canopen;
using co::ObjectDictionary;
using co::OdEntry;
using co::OdObject;
using co::OdState;

constexpr SimTime kUs = 1'000, kMs = 1'000'000;

OdObject var(std::uint16_t index, std::uint16_t type, std::size_t bytes, std::uint16_t access = co::od_access::rw) {
  OdEntry e;
  e.data_type = type;
  e.bits = static_cast<std::uint16_t>(bytes * 8);
  e.access = access;
  e.default_value.assign(bytes, 0);
  OdObject o;
  o.index = index;
  o.data_type = type;
  o.entries.push_back(std::move(e));
  return o;
}

void build(ObjectDictionary& od) {
  od.add(var(0x1000, co::data_type::uint32, 4, co::od_access::read_all));
  od.add(var(0x2000, co::data_type::uint8, 1));
  od.add(var(0x2001, co::data_type::uint16, 2));
  od.add(var(0x2002, co::data_type::uint32, 4));
  od.add(var(0x2003, co::data_type::visible_string, 300));
  od.add(var(0x2004, co::data_type::octet_string, 300));
  od.add(var(0x200A, co::data_type::uint64, 8));
  od.add(var(0x2009, co::data_type::octet_string, 2000));
}

std::vector<std::uint8_t> pattern(std::size_t n, std::uint8_t seed = 0) {
  std::vector<std::uint8_t> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<std::uint8_t>(seed + i * 13 + (i >> 4));
  return v;
}

// A bus in a queue: the client and the servers of nodes 1..3 hand frames in, pump() delivers
// them in order, each 10 µs after the previous. `filter` may drop (false) or alter a frame.
struct Rig {
  struct Node {
    ObjectDictionary od;
    std::unique_ptr<co::SdoServer> server;
  };
  std::deque<can::Frame> wire;
  std::vector<can::Frame> log;
  std::function<bool(can::Frame&)> filter;
  SimTime t = 0;
  std::vector<std::unique_ptr<Node>> nodes;
  std::vector<SdoResult> results;  // from the completion callback (data copied below)
  std::vector<std::vector<std::uint8_t>> result_data;
  SdoClient client;

  explicit Rig(SdoClientConfig ccfg = {}, co::SdoServerConfig scfg = {})
      : client([this](const can::Frame& f, SimTime) { return queue(f); }, ccfg,
               [this](const SdoResult& r) {
                 results.push_back(r);
                 result_data.emplace_back(r.data.begin(), r.data.end());
               }) {
    for (std::uint8_t id = 1; id <= 3; ++id) {
      auto n = std::make_unique<Node>();
      build(n->od);
      n->server = std::make_unique<co::SdoServer>(n->od, id, [this](const can::Frame& f, SimTime) { return queue(f); },
                                                  scfg);
      nodes.push_back(std::move(n));
    }
  }
  bool queue(const can::Frame& f) {
    wire.push_back(f);
    return true;
  }
  Node& node(int id) { return *nodes.at(static_cast<std::size_t>(id - 1)); }
  // Delivers frames until the wire is empty (or `limit` frames).
  void pump(int limit = 100000) {
    while (!wire.empty() && limit-- > 0) {
      can::Frame f = wire.front();
      wire.pop_front();
      t += 10 * kUs;
      if (filter && !filter(f)) continue;
      log.push_back(f);
      client.on_frame(f, t);
      for (auto& n : nodes) n->server->on_frame(f, t, OdState::preop);
    }
  }
  std::vector<std::uint8_t> value(int id, std::uint16_t index) {
    const OdEntry* e = node(id).od.entry(index, 0);
    return {e->data(), e->data() + e->bytes()};
  }
  // Frames with this first byte sent to (0x600 + id) or from (0x580 + id) the server.
  int count(std::uint32_t cob, std::uint8_t b0, std::uint8_t mask = 0xFF) const {
    int n = 0;
    for (const auto& f : log) n += f.id == cob && (f.data[0] & mask) == b0;
    return n;
  }
};

std::vector<std::uint8_t> padded(const std::vector<std::uint8_t>& v, std::size_t n) {
  auto out = v;
  out.resize(n, 0);
  return out;
}

TEST(SdoClient, ExpeditedUpload) {
  Rig rig;
  const std::vector<std::uint8_t> v{0x92, 0x01, 0x02, 0x00};
  ASSERT_EQ(rig.node(2).od.write(0x2002, 0, OdState::preop, v), co::SdoAbort::none);
  ASSERT_EQ(rig.client.upload(2, 0x2002, 0, rig.t), SdoStart::ok);
  EXPECT_TRUE(rig.client.busy(2));
  EXPECT_EQ(rig.wire.front().id, 0x602u);
  EXPECT_EQ(rig.wire.front().data[0], 0x40);
  rig.pump();
  ASSERT_EQ(rig.results.size(), 1u);
  EXPECT_EQ(rig.results[0].status, SdoStatus::done);
  EXPECT_TRUE(rig.results[0].upload);
  EXPECT_EQ(rig.results[0].node, 2);
  EXPECT_EQ(rig.result_data[0], v);
  const SdoResult* r = rig.client.result(2);
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->status, SdoStatus::done);
  EXPECT_EQ(std::vector<std::uint8_t>(r->data.begin(), r->data.end()), v);
  EXPECT_FALSE(rig.client.busy(2));
  EXPECT_EQ(rig.log.size(), 2u);
}

TEST(SdoClient, ExpeditedDownloadOfOneTwoAndFourBytes) {
  Rig rig;
  ASSERT_EQ(rig.client.download(1, 0x2000, 0, std::vector<std::uint8_t>{0x7E}, rig.t), SdoStart::ok);
  EXPECT_EQ(rig.wire.front().data, (std::array<std::uint8_t, 8>{0x2F, 0x00, 0x20, 0x00, 0x7E, 0, 0, 0}));
  rig.pump();
  ASSERT_EQ(rig.client.download(1, 0x2001, 0, std::vector<std::uint8_t>{0x34, 0x12}, rig.t), SdoStart::ok);
  EXPECT_EQ(rig.wire.front().data[0], 0x2B);
  rig.pump();
  ASSERT_EQ(rig.client.download(1, 0x2002, 0, std::vector<std::uint8_t>{1, 2, 3, 4}, rig.t), SdoStart::ok);
  EXPECT_EQ(rig.wire.front().data[0], 0x23);
  rig.pump();
  ASSERT_EQ(rig.results.size(), 3u);
  for (const auto& r : rig.results) EXPECT_EQ(r.status, SdoStatus::done);
  EXPECT_EQ(rig.value(1, 0x2000), (std::vector<std::uint8_t>{0x7E}));
  EXPECT_EQ(rig.value(1, 0x2001), (std::vector<std::uint8_t>{0x34, 0x12}));
  EXPECT_EQ(rig.value(1, 0x2002), (std::vector<std::uint8_t>{1, 2, 3, 4}));
  EXPECT_EQ(rig.log.size(), 6u);
}

TEST(SdoClient, SegmentedOnRequestEvenForFourBytes) {
  Rig rig;
  ASSERT_EQ(rig.client.download(1, 0x2002, 0, std::vector<std::uint8_t>{9, 8, 7, 6}, rig.t, TransferMode::segmented),
            SdoStart::ok);
  EXPECT_EQ(rig.wire.front().data, (std::array<std::uint8_t, 8>{0x21, 0x02, 0x20, 0x00, 4, 0, 0, 0}));
  rig.pump();
  EXPECT_EQ(rig.client.result(1)->status, SdoStatus::done);
  EXPECT_EQ(rig.value(1, 0x2002), (std::vector<std::uint8_t>{9, 8, 7, 6}));
  EXPECT_EQ(rig.count(0x601, 0x00 | (3 << 1) | 1), 1);  // one segment: toggle 0, 4 bytes, c
}

TEST(SdoClient, SegmentedStringBothWays) {
  Rig rig;
  std::string text;
  while (text.size() < 300) text += "omnitwin SDO segmented transfer; ";
  text.resize(300);
  const std::vector<std::uint8_t> v(text.begin(), text.end());
  ASSERT_EQ(rig.client.download(3, 0x2003, 0, v, rig.t), SdoStart::ok);
  EXPECT_EQ(rig.wire.front().data, (std::array<std::uint8_t, 8>{0x21, 0x03, 0x20, 0x00, 0x2C, 0x01, 0, 0}));
  rig.pump();
  ASSERT_EQ(rig.client.result(3)->status, SdoStatus::done);
  EXPECT_EQ(rig.value(3, 0x2003), v);
  EXPECT_EQ(rig.count(0x603, 0x00, 0xE0), 43);  // 43 download segments
  ASSERT_EQ(rig.client.upload(3, 0x2003, 0, rig.t), SdoStart::ok);
  rig.pump();
  const SdoResult* r = rig.client.result(3);
  ASSERT_EQ(r->status, SdoStatus::done);
  EXPECT_EQ(std::string(r->data.begin(), r->data.end()), text);
  EXPECT_EQ(rig.node(3).server->stats().segments, 86u);
}

TEST(SdoClient, ShortAndEmptyStringDownloads) {
  Rig rig;
  const std::string s = "twin";  // 4 bytes: expedited, the string's rest zeroed by the OD
  ASSERT_EQ(rig.client.download(1, 0x2003, 0, std::vector<std::uint8_t>(s.begin(), s.end()), rig.t), SdoStart::ok);
  EXPECT_EQ(rig.wire.front().data[0], 0x23);
  rig.pump();
  EXPECT_EQ(rig.client.result(1)->status, SdoStatus::done);
  EXPECT_EQ(rig.value(1, 0x2003), padded({'t', 'w', 'i', 'n'}, 300));
  // An empty download: segmented with size 0, one segment without data.
  ASSERT_EQ(rig.client.download(1, 0x2003, 0, std::vector<std::uint8_t>{}, rig.t), SdoStart::ok);
  rig.pump();
  EXPECT_EQ(rig.client.result(1)->status, SdoStatus::done);
  EXPECT_EQ(rig.value(1, 0x2003), std::vector<std::uint8_t>(300, 0));
  EXPECT_EQ(rig.count(0x601, 0x0F), 1);  // toggle 0, n = 7, c
}

TEST(SdoClient, BlockOctetStringBothWays) {
  Rig rig;
  const auto v = pattern(300, 17);
  ASSERT_EQ(rig.client.download(2, 0x2004, 0, v, rig.t, TransferMode::block), SdoStart::ok);
  EXPECT_EQ(rig.wire.front().data, (std::array<std::uint8_t, 8>{0xC6, 0x04, 0x20, 0x00, 0x2C, 0x01, 0, 0}));
  rig.pump();
  ASSERT_EQ(rig.client.result(2)->status, SdoStatus::done);
  EXPECT_EQ(rig.value(2, 0x2004), v);
  EXPECT_EQ(rig.node(2).server->stats().downloads, 1u);
  EXPECT_EQ(rig.node(2).server->stats().block_segments, 43u);
  ASSERT_EQ(rig.client.upload(2, 0x2004, 0, rig.t, TransferMode::block), SdoStart::ok);
  EXPECT_EQ(rig.wire.front().data, (std::array<std::uint8_t, 8>{0xA4, 0x04, 0x20, 0x00, 127, 0, 0, 0}));
  rig.pump();
  const SdoResult* r = rig.client.result(2);
  ASSERT_EQ(r->status, SdoStatus::done);
  EXPECT_EQ(r->mode, TransferMode::block);
  EXPECT_EQ(std::vector<std::uint8_t>(r->data.begin(), r->data.end()), v);
  EXPECT_EQ(rig.node(2).server->stats().uploads, 1u);
  EXPECT_EQ(rig.count(0x602, 0xA1), 1);  // our end response
}

TEST(SdoClient, BlockTransfersInSmallSubBlocks) {
  SdoClientConfig ccfg;
  ccfg.blksize = 4;
  co::SdoServerConfig scfg;
  scfg.blksize = 3;
  Rig rig(ccfg, scfg);
  const auto v = pattern(300, 3);
  ASSERT_EQ(rig.client.download(1, 0x2003, 0, v, rig.t, TransferMode::block), SdoStart::ok);
  rig.pump();
  ASSERT_EQ(rig.client.result(1)->status, SdoStatus::done);
  EXPECT_EQ(rig.value(1, 0x2003), v);
  EXPECT_EQ(rig.node(1).server->stats().blocks, 15u);  // 43 segments in threes
  ASSERT_EQ(rig.client.upload(1, 0x2003, 0, rig.t, TransferMode::block), SdoStart::ok);
  rig.pump();
  const SdoResult* r = rig.client.result(1);
  ASSERT_EQ(r->status, SdoStatus::done);
  EXPECT_EQ(std::vector<std::uint8_t>(r->data.begin(), r->data.end()), v);
  EXPECT_EQ(rig.node(1).server->stats().blocks, 15u + 11u);  // 43 segments in fours
}

TEST(SdoClient, BlockDownloadRecoversFromALostSegment) {
  co::SdoServerConfig scfg;
  scfg.blksize = 10;
  Rig rig({}, scfg);
  bool dropped = false;
  rig.filter = [&](can::Frame& f) {
    // Segment 4 of the second sub-block vanishes (once).
    if (!dropped && f.id == 0x601 && f.data[0] == 4 && rig.node(1).server->stats().blocks == 1) {
      dropped = true;
      return false;
    }
    return true;
  };
  const auto v = pattern(300, 8);
  ASSERT_EQ(rig.client.download(1, 0x2004, 0, v, rig.t, TransferMode::block), SdoStart::ok);
  rig.pump();
  EXPECT_TRUE(dropped);
  ASSERT_EQ(rig.client.result(1)->status, SdoStatus::done);
  EXPECT_EQ(rig.value(1, 0x2004), v);
  EXPECT_EQ(rig.client.stats().retransmitted, 7u);  // seqno 4..10 of that sub-block
  EXPECT_EQ(rig.count(0x581, 0xA2), 5);             // 10, 3 (short), then the 30 left in tens
}

TEST(SdoClient, BlockUploadRecoversFromALostSegment) {
  Rig rig;
  const auto v = pattern(300, 21);
  ASSERT_EQ(rig.node(1).od.write(0x2004, 0, OdState::preop, v), co::SdoAbort::none);
  bool dropped = false;
  rig.filter = [&](can::Frame& f) {
    if (!dropped && f.id == 0x581 && f.data[0] == 30) return dropped = true, false;
    return true;
  };
  ASSERT_EQ(rig.client.upload(1, 0x2004, 0, rig.t, TransferMode::block), SdoStart::ok);
  rig.pump();
  EXPECT_TRUE(dropped);
  const SdoResult* r = rig.client.result(1);
  ASSERT_EQ(r->status, SdoStatus::done);
  EXPECT_EQ(std::vector<std::uint8_t>(r->data.begin(), r->data.end()), v);
  // The first ack named seqno 29; the server sent the rest again from there.
  EXPECT_EQ(rig.count(0x601, 0xA2), 2);
  EXPECT_EQ(rig.node(1).server->stats().block_segments, 43u + 14u);
}

TEST(SdoClient, CorruptedBlockDataIsACrcAbortFromTheServer) {
  Rig rig;
  bool corrupted = false;
  rig.filter = [&](can::Frame& f) {
    if (!corrupted && f.id == 0x601 && f.data[0] == 7) {
      f.data[3] ^= 0x40;
      corrupted = true;
    }
    return true;
  };
  const auto v = pattern(100, 1);
  ASSERT_EQ(rig.client.download(1, 0x2004, 0, v, rig.t, TransferMode::block), SdoStart::ok);
  rig.pump();
  const SdoResult* r = rig.client.result(1);
  ASSERT_EQ(r->status, SdoStatus::aborted);
  EXPECT_TRUE(r->server_abort);
  EXPECT_EQ(r->code, co::sdo::abort_crc);
  EXPECT_EQ(rig.value(1, 0x2004), std::vector<std::uint8_t>(300, 0));
  EXPECT_EQ(rig.client.stats().aborts_received, 1u);
}

TEST(SdoClient, CorruptedBlockUploadIsACrcAbortFromTheClient) {
  Rig rig;
  ASSERT_EQ(rig.node(1).od.write(0x2004, 0, OdState::preop, pattern(50)), co::SdoAbort::none);
  rig.filter = [&](can::Frame& f) {
    if (f.id == 0x581 && f.data[0] == 2) f.data[1] ^= 0x01;
    return true;
  };
  ASSERT_EQ(rig.client.upload(1, 0x2004, 0, rig.t, TransferMode::block), SdoStart::ok);
  rig.pump();
  const SdoResult* r = rig.client.result(1);
  ASSERT_EQ(r->status, SdoStatus::aborted);
  EXPECT_FALSE(r->server_abort);
  EXPECT_EQ(r->code, co::sdo::abort_crc);
  EXPECT_EQ(rig.count(0x601, 0x80), 1);
  EXPECT_FALSE(rig.node(1).server->busy());  // our abort ended the server's transfer
}

TEST(SdoClient, ServerAbortsAreReported) {
  Rig rig;
  ASSERT_EQ(rig.client.upload(1, 0x3000, 0, rig.t), SdoStart::ok);
  rig.pump();
  ASSERT_EQ(rig.results.size(), 1u);
  EXPECT_EQ(rig.results[0].status, SdoStatus::aborted);
  EXPECT_EQ(rig.results[0].code, co::SdoAbort::no_object);
  EXPECT_TRUE(rig.results[0].server_abort);
  ASSERT_EQ(rig.client.download(1, 0x1000, 0, std::vector<std::uint8_t>{1, 2, 3, 4}, rig.t, TransferMode::block),
            SdoStart::ok);
  rig.pump();
  EXPECT_EQ(rig.client.result(1)->code, co::SdoAbort::read_only);
  ASSERT_EQ(rig.client.upload(1, 0x2009, 0, rig.t, TransferMode::block), SdoStart::ok);
  rig.pump();
  EXPECT_EQ(rig.client.result(1)->code, co::SdoAbort::out_of_memory);
  EXPECT_EQ(rig.client.stats().aborted, 3u);
  EXPECT_EQ(rig.client.stats().aborts_sent, 0u);
}

TEST(SdoClient, ClientTimeoutSendsAnAbort) {
  Rig rig;
  rig.filter = [&](can::Frame& f) { return f.id != 0x581; };  // the server's answers are lost
  ASSERT_EQ(rig.client.upload(1, 0x2003, 0, 5 * kMs), SdoStart::ok);
  rig.pump();
  EXPECT_TRUE(rig.node(1).server->busy());
  rig.client.on_time(5 * kMs + 999 * kMs);
  EXPECT_TRUE(rig.results.empty());
  rig.client.on_time(5 * kMs + 1000 * kMs);
  ASSERT_EQ(rig.results.size(), 1u);
  EXPECT_EQ(rig.results[0].status, SdoStatus::aborted);
  EXPECT_EQ(rig.results[0].code, co::SdoAbort::timeout);
  EXPECT_FALSE(rig.results[0].server_abort);
  ASSERT_EQ(rig.wire.size(), 1u);
  EXPECT_EQ(rig.wire.front().data, co::sdo::encode_abort({0x2003, 0, co::SdoAbort::timeout}));
  rig.pump();
  EXPECT_FALSE(rig.node(1).server->busy());
  rig.client.on_time(10'000 * kMs);
  EXPECT_EQ(rig.results.size(), 1u);  // reported once
  EXPECT_EQ(rig.client.stats().timeouts, 1u);
}

TEST(SdoClient, BlockDownloadTimesOutWithoutAck) {
  Rig rig;
  rig.filter = [&](can::Frame& f) { return !(f.id == 0x581 && f.data[0] == 0xA2); };
  ASSERT_EQ(rig.client.download(1, 0x2004, 0, pattern(40), rig.t, TransferMode::block), SdoStart::ok);
  rig.pump();
  EXPECT_TRUE(rig.client.busy(1));
  rig.client.on_time(rig.t + 1000 * kMs);
  EXPECT_EQ(rig.client.result(1)->code, co::SdoAbort::timeout);
  EXPECT_FALSE(rig.client.busy(1));
}

TEST(SdoClient, OneTransferPerNodeSeveralNodesAtOnce) {
  Rig rig;
  const auto a = pattern(300, 1), b = pattern(300, 2);
  ASSERT_EQ(rig.client.download(1, 0x2004, 0, a, rig.t, TransferMode::block), SdoStart::ok);
  EXPECT_EQ(rig.client.upload(1, 0x1000, 0, rig.t), SdoStart::busy);
  ASSERT_EQ(rig.client.download(2, 0x2004, 0, b, rig.t), SdoStart::ok);
  ASSERT_EQ(rig.client.upload(3, 0x2003, 0, rig.t, TransferMode::block), SdoStart::ok);
  rig.pump();
  EXPECT_EQ(rig.results.size(), 3u);
  EXPECT_EQ(rig.value(1, 0x2004), a);
  EXPECT_EQ(rig.value(2, 0x2004), b);
  EXPECT_EQ(rig.client.result(3)->status, SdoStatus::done);
  EXPECT_EQ(rig.client.result(3)->data.size(), 300u);
  EXPECT_EQ(rig.client.stats().done, 3u);
}

TEST(SdoClient, ChannelsRunOutAndAreReused) {
  SdoClientConfig cfg;
  cfg.channels = 2;
  Rig rig(cfg);
  ASSERT_EQ(rig.client.upload(1, 0x1000, 0, rig.t), SdoStart::ok);
  ASSERT_EQ(rig.client.upload(2, 0x1000, 0, rig.t), SdoStart::ok);
  EXPECT_EQ(rig.client.upload(3, 0x1000, 0, rig.t), SdoStart::no_channel);
  rig.pump();
  ASSERT_EQ(rig.client.upload(3, 0x1000, 0, rig.t), SdoStart::ok);  // takes node 1's channel
  rig.pump();
  EXPECT_EQ(rig.client.result(1), nullptr);
  ASSERT_NE(rig.client.result(2), nullptr);
  EXPECT_EQ(rig.client.result(3)->status, SdoStatus::done);
}

TEST(SdoClient, StartErrors) {
  SdoClientConfig cfg;
  cfg.max_object_bytes = 64;
  Rig rig(cfg);
  EXPECT_EQ(rig.client.upload(0, 0x1000, 0, rig.t), SdoStart::bad_node);
  EXPECT_EQ(rig.client.upload(128, 0x1000, 0, rig.t), SdoStart::bad_node);
  EXPECT_EQ(rig.client.download(1, 0x2004, 0, pattern(65), rig.t), SdoStart::too_long);
  EXPECT_TRUE(rig.wire.empty());
  // An upload longer than our buffer is aborted by us.
  ASSERT_EQ(rig.client.upload(1, 0x2004, 0, rig.t), SdoStart::ok);
  rig.pump();
  EXPECT_EQ(rig.client.result(1)->code, co::SdoAbort::out_of_memory);
  EXPECT_FALSE(rig.client.result(1)->server_abort);
  EXPECT_FALSE(rig.node(1).server->busy());
  EXPECT_THROW(SdoClient(SendFn{}), std::invalid_argument);
  SdoClientConfig bad;
  bad.blksize = 0;
  EXPECT_THROW(SdoClient([](const can::Frame&, SimTime) { return true; }, bad), std::invalid_argument);
}

TEST(SdoClient, CancelAbortsBothSides) {
  Rig rig;
  ASSERT_EQ(rig.client.upload(1, 0x2003, 0, rig.t), SdoStart::ok);
  rig.pump(3);  // initiate, response, first segment request
  EXPECT_TRUE(rig.node(1).server->busy());
  EXPECT_TRUE(rig.client.cancel(1, rig.t, co::SdoAbort::general));
  EXPECT_FALSE(rig.client.cancel(1, rig.t));
  rig.pump();
  EXPECT_FALSE(rig.node(1).server->busy());
  EXPECT_EQ(rig.client.result(1)->status, SdoStatus::aborted);
  EXPECT_EQ(rig.client.result(1)->code, co::SdoAbort::general);
  EXPECT_GE(rig.client.stats().ignored, 1u);  // the segment answered after the cancel
}

TEST(SdoClient, UnexpectedResponseAborts) {
  Rig rig;
  ASSERT_EQ(rig.client.upload(1, 0x2002, 0, rig.t), SdoStart::ok);
  rig.wire.clear();
  // A download response where an upload response belongs.
  rig.client.on_frame(co::sdo::make_frame(0x581, co::sdo::encode_initiate_download_response({0x2002, 0})), rig.t);
  EXPECT_EQ(rig.client.result(1)->code, co::SdoAbort::invalid_command);
  ASSERT_EQ(rig.wire.size(), 1u);
  EXPECT_EQ(rig.wire.front().data, co::sdo::encode_abort({0x2002, 0, co::SdoAbort::invalid_command}));
  // A toggle error in a segmented upload.
  rig.wire.clear();
  ASSERT_EQ(rig.client.upload(1, 0x2003, 0, rig.t), SdoStart::ok);
  co::sdo::Initiate m;
  m.index = 0x2003;
  m.sized = true;
  m.size = 300;
  rig.client.on_frame(co::sdo::make_frame(0x581, co::sdo::encode_initiate_upload_response(m)), rig.t);
  co::sdo::Segment g;
  g.toggle = true;
  g.len = 7;
  rig.client.on_frame(co::sdo::make_frame(0x581, co::sdo::encode_segment(g)), rig.t);
  EXPECT_EQ(rig.client.result(1)->code, co::SdoAbort::toggle);
}

}  // namespace
}  // namespace omnitwin::controller::canopen
