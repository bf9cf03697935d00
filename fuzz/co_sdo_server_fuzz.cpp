// libFuzzer target for the CANopen SDO server: bus_emulators/canopen (co_sdo frame layer,
// co_sdo_server) over a small object dictionary (ethercat/device/ec_od) built here.
//
// Each input builds a fresh server (so every finding replays from its one input): the first
// byte picks the configuration (blksize 1..127, buffer 16/64/1024 bytes, CRC on/off), then the
// input is read as 10-byte records [op][flags][8 data bytes]:
//   op % 4 == 0: a frame on 0x605 — DLC 8 when flags bit 4 is set, else flags & 0x0F (0..15);
//                remote when flags bits 7..6 are both set; the OD in OP when flags bit 5 is set;
//   op % 4 == 1: the same bytes on a COB-ID or format the server must ignore;
//   op % 4 == 2: time advances by (u32 of the data) µs, then on_time;
//   op % 4 == 3: reset() when flags == 0x5A; else one whole transfer by our SDO client
//                (controller/canopen/co_sdo_client) to the server: object, direction, mode
//                (expedited/segmented/block) and length from the data bytes, and optionally
//                one frame of the exchange corrupted (XOR) or dropped; then time runs out so
//                that both sides end (a transfer a raw request left running is reset first).
// Properties checked (trap on failure; ASan/UBSan check memory and UB):
//  - every frame the server sends is a standard 8-byte data frame on 0x585 at the current time;
//    at most 127 frames answer one request (one sub-block), at most one answers a time step;
//  - frames on other COB-IDs, extended and (at most) remote frames produce nothing and are not
//    counted as requests;
//  - every abort (byte 0 = 0x80; no segment has seqno 0) carries a known CiA 301 code, the
//    server is idle after it, and stats().aborts_sent counts exactly the aborts seen;
//  - a transfer is never left running once cfg.timeout_ns passed since the last request;
//  - after reset() the server is idle; the value limits of the dictionary always hold;
//  - a client transfer always ends (completion reported exactly once); untouched by the fuzzer
//    it ends done, or aborted by the server with the dictionary's verdict, never by a protocol
//    error; done uploads hold the entry's bytes, done downloads are in the entry.
//
//   ./co_sdo_server_fuzz -max_total_time=60 fuzz/corpus/co_sdo_server
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <span>
#include <vector>

#include "bus_emulators/canopen/co_sdo.hpp"
#include "bus_emulators/canopen/co_sdo_server.hpp"
#include "controller/canopen/co_sdo_client.hpp"

using namespace omnitwin::canopen;

namespace {

#define CHECK(cond)                                                            \
  do {                                                                         \
    if (!(cond)) {                                                             \
      std::fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond); \
      __builtin_trap();                                                        \
    }                                                                          \
  } while (0)

constexpr std::uint8_t kNode = 5;
constexpr SimTime kTimeout = 5'000'000;  // [ns]

OdObject var(std::uint16_t index, std::uint16_t type, std::size_t bytes, std::uint16_t access) {
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

// Objects of every size class and access kind: u8, u16 with limits, u32 read-only,
// write-only and PRE-OP-only, u64, strings of 7, 40 and 300 bytes, a record.
void build(ObjectDictionary& od) {
  od.add(var(0x1000, data_type::uint32, 4, od_access::read_all));
  od.add(var(0x2000, data_type::uint8, 1, od_access::rw));
  OdObject limited = var(0x2001, data_type::uint16, 2, od_access::rw);
  limited.entries[0].default_value = {100, 0};
  limited.entries[0].min = 10;
  limited.entries[0].max = 1000;
  od.add(limited);
  od.add(var(0x2002, data_type::uint32, 4, od_access::write_all));
  od.add(var(0x2003, data_type::uint32, 4, od_access::read_all | od_access::write_preop));
  od.add(var(0x2004, data_type::uint64, 8, od_access::rw));
  od.add(var(0x2005, data_type::visible_string, 7, od_access::rw));
  od.add(var(0x2006, data_type::octet_string, 40, od_access::rw));
  od.add(var(0x2007, data_type::octet_string, 300, od_access::rw));
  OdObject rec = var(0x2008, data_type::uint8, 1, od_access::read_all);
  rec.object_code = 9;
  rec.entries[0].default_value = {2};
  OdEntry s1;
  s1.subindex = 1;
  s1.data_type = data_type::uint16;
  s1.bits = 16;
  s1.access = od_access::rw;
  s1.default_value = {0, 0};
  rec.entries.push_back(s1);
  s1.subindex = 2;
  s1.data_type = data_type::visible_string;
  s1.bits = 8 * 20;
  s1.default_value.assign(20, 0);
  rec.entries.push_back(s1);
  od.add(rec);
}

bool known_abort(std::uint32_t code) {
  const auto a = static_cast<SdoAbort>(code);
  return a == sdo::abort_crc || a == sdo::abort_invalid_seqno ||
         std::strcmp(omnitwin::ethercat::to_string(a), "unknown abort code") != 0;
}

struct Rig {
  ObjectDictionary od;
  SimTime t = 0, last_request = 0;
  int sent_now = 0;
  std::uint64_t aborts_seen = 0;
  bool abort_now = false;
  SdoServer* server = nullptr;
  bool capture = false;  // server frames go to the client (op 3)
  std::deque<omnitwin::can::Frame> to_client, to_server;

  // Checks one frame the server hands out.
  bool on_send(const omnitwin::can::Frame& f, SimTime at) {
    CHECK(f.id == 0x580u + kNode && !f.extended && f.kind == omnitwin::can::FrameKind::data && f.dlc == 8);
    CHECK(at == t);
    ++sent_now;
    if (f.data[0] == 0x80) {
      CHECK(known_abort(get_u32(f.data.data() + 4)));
      ++aborts_seen;
      abort_now = true;
    }
    if (capture) to_client.push_back(f);
    return true;
  }

  void request(const omnitwin::can::Frame& f, OdState st) {
    sent_now = 0;
    abort_now = false;
    const auto before = server->stats().requests;
    server->on_frame(f, t, st);
    const bool taken = server->stats().requests != before;
    if (taken) last_request = t;
    CHECK(taken || sent_now == 0);
    CHECK(sent_now <= sdo::kMaxBlockSize);
    if (abort_now) CHECK(!server->busy());
  }
};


namespace cc = omnitwin::controller::canopen;

struct ObjectRef {
  std::uint16_t index;
  std::uint8_t sub;
};
constexpr ObjectRef kObjects[] = {{0x1000, 0}, {0x2000, 0}, {0x2001, 0}, {0x2002, 0}, {0x2003, 0}, {0x2004, 0},
                                  {0x2005, 0}, {0x2006, 0}, {0x2007, 0}, {0x2008, 1}, {0x2008, 2}, {0x3000, 0}};

// One client transfer driven to its end (see the header); d = the record's 8 data bytes.
void client_transfer(Rig& rig, cc::SdoClient& client, const std::vector<cc::SdoResult>& results,
                     const std::uint8_t* d) {
  const ObjectRef o = kObjects[d[0] % std::size(kObjects)];
  const bool up = d[1] & 1;
  const auto mode = static_cast<cc::TransferMode>((d[1] >> 1) % 3);
  std::vector<std::uint8_t> bytes(d[2] + ((d[3] & 1) ? 256u : 0u));
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<std::uint8_t>(d[0] + 3 * i);
  const int mutate_at = d[4];  // frame ordinal of the exchange, 0 = none
  const std::uint8_t mask = d[5] | 1, at_byte = d[6] % 8;
  const bool drop = d[7] & 1;
  const std::size_t before = results.size();
  if (rig.server->busy()) rig.server->reset();  // a raw request left a transfer running
  const auto st = up ? client.upload(kNode, o.index, o.sub, rig.t, mode)
                     : client.download(kNode, o.index, o.sub, bytes, rig.t, mode);
  CHECK(st == cc::SdoStart::ok);
  bool mutated = false;
  int ordinal = 0;
  // Alternately one frame to the server and one to the client; one may be corrupted or lost.
  auto deliver = [&](std::deque<omnitwin::can::Frame>& q, bool to_server) {
    if (q.empty()) return;
    omnitwin::can::Frame f = q.front();
    q.pop_front();
    rig.t += 10'000;
    if (++ordinal == mutate_at) {
      mutated = true;
      if (drop) return;
      f.data[at_byte] ^= mask;
    }
    if (to_server) {
      CHECK(f.id == 0x600u + kNode && f.dlc == 8);
      rig.request(f, OdState::preop);
    } else {
      client.on_frame(f, rig.t);
    }
  };
  rig.capture = true;
  for (int round = 0; round < 2; ++round) {
    for (int n = 0; n < 4000 && (!rig.to_server.empty() || !rig.to_client.empty()); ++n) {
      deliver(rig.to_server, true);
      deliver(rig.to_client, false);
    }
    if (round == 0 && client.busy(kNode)) {
      // Stalled (a frame was lost or the server waits): let both time out, then deliver.
      rig.t += 2 * kTimeout;
      client.on_time(rig.t);
      rig.sent_now = 0;
      rig.abort_now = false;
      rig.server->on_time(rig.t);
    }
  }
  rig.capture = false;
  rig.to_client.clear();
  rig.to_server.clear();
  CHECK(!client.busy(kNode));
  CHECK(results.size() == before + 1);
  const cc::SdoResult& r = results.back();
  CHECK(r.status == cc::SdoStatus::done || r.status == cc::SdoStatus::aborted);
  if (!mutated) CHECK(r.status == cc::SdoStatus::done || r.server_abort);
  if (r.status != cc::SdoStatus::done) return;
  const OdEntry* e = rig.od.entry(o.index, o.sub);
  // A corrupted frame can pass for success (an abort whose first byte became an initiate
  // response naming the same object: SDO has no check of its own, the CAN CRC would catch it),
  // so only an untouched exchange must have had an object to succeed on.
  if (mutated && e == nullptr) return;
  CHECK(e != nullptr);
  if (up && !mutated) CHECK(r.data.size() == e->bytes() && std::equal(r.data.begin(), r.data.end(), e->data()));
  if (!up && !mutated) CHECK(bytes.size() <= e->bytes() && std::equal(bytes.begin(), bytes.end(), e->data()));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  Rig rig;
  build(rig.od);
  SdoServerConfig cfg;
  cfg.blksize = static_cast<std::uint8_t>(1 + data[0] % 127);
  cfg.max_object_bytes = (data[0] & 0x80) ? 1024 : ((data[0] & 0x40) ? 64 : 16);
  cfg.crc = (data[0] & 0x01) != 0;
  cfg.timeout_ns = kTimeout;
  SdoServer server(rig.od, kNode, [&rig](const omnitwin::can::Frame& f, SimTime at) { return rig.on_send(f, at); },
                   cfg);
  rig.server = &server;
  std::vector<cc::SdoResult> results;
  cc::SdoClientConfig ccfg;
  ccfg.blksize = static_cast<std::uint8_t>(1 + (data[0] * 7) % 127);
  ccfg.crc = (data[0] & 0x02) != 0;
  ccfg.timeout_ns = kTimeout;
  cc::SdoClient client([&rig](const omnitwin::can::Frame& f, SimTime) { rig.to_server.push_back(f); return true; },
                       ccfg, [&results](const cc::SdoResult& r) { results.push_back(r); });

  for (std::size_t off = 1; off + 10 <= size; off += 10) {
    const std::uint8_t op = data[off] % 4, flags = data[off + 1];
    omnitwin::can::Frame f = frame11(0x600 + kNode, 8);
    std::memcpy(f.data.data(), data + off + 2, 8);
    const OdState st = (flags & 0x20) ? OdState::op : OdState::preop;
    switch (op) {
      case 0:
        if (!(flags & 0x10)) f.dlc = flags & 0x0F;
        if ((flags & 0xC0) == 0xC0) f.kind = omnitwin::can::FrameKind::remote;
        rig.request(f, st);
        break;
      case 1: {
        // Not ours: another node's request, a response, an extended ID.
        const int which = flags % 3;
        if (which == 0) f.id = 0x600 + kNode + 1;
        else if (which == 1) f.id = 0x580 + kNode;
        else f.extended = true;
        const auto before = server.stats().requests;
        rig.request(f, st);
        CHECK(server.stats().requests == before);
        break;
      }
      case 2: {
        rig.t += static_cast<SimTime>(get_u32(f.data.data())) * 1000;
        rig.sent_now = 0;
        rig.abort_now = false;
        server.on_time(rig.t);
        CHECK(rig.sent_now <= 1);
        if (rig.t - rig.last_request >= kTimeout) CHECK(!server.busy());
        break;
      }
      case 3:
        if (flags == 0x5A) {
          server.reset();
          CHECK(!server.busy());
        } else {
          client_transfer(rig, client, results, data + off + 2);
        }
        break;
    }
    CHECK(server.stats().aborts_sent == rig.aborts_seen);
    const std::int64_t v = rig.od.entry(0x2001, 0)->as_int();
    CHECK(v >= 10 && v <= 1000);
  }
  return 0;
}
