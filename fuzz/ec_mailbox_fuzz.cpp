// libFuzzer target for the EtherCAT mailbox path of a slave: bus_emulators/ethercat/device
// (ec_mailbox header codec, ec_coe SDO server and SDO information service, ec_od, ec_slave's
// mailbox pump) behind the ESC's SM0/SM1 mailbox handshake (ethercat/ec_esc, ec_sm).
//
// One DriveSlave (models/ethercat/omnitwin_drive.xml) is built and brought to PRE-OP by the
// set-up master (ec_fuzz_master.hpp: station address, SM0/SM1, AL control 2) through
// datagrams; every other restart uses 32-byte mailboxes so that transfers are segmented. Each input is cut into SM0-sized pieces (at most kMaxWrites; the last one padded
// with zeros); every piece is one mailbox write (FPWR of the whole SM0 area), after which the
// master reads SM1 (FPRD) and lets the firmware cycle until no reply is left. CoE state carries
// across inputs (a segmented transfer may span inputs as well as pieces of one input); every
// kEpoch inputs the slave is rebuilt at t = 0 and brought up again. A failed check writes the
// inputs since that restart (the failing one last) to ./ec_mailbox_history-<pid>; replay with
// `EC_FUZZ_REPLAY=that-file ./ec_mailbox_fuzz any-input-file`. The first bytes of each input
// also go through the header codec directly.
// Properties checked (trap on failure; ASan/UBSan check memory and UB):
//  - decode_mailbox_header: nullopt exactly below 6 bytes; encode gives the same 6 bytes back
//    (apart from the reserved bit 7 of byte 5); encode_mailbox_error writes a decodable error;
//  - a mailbox write into an empty SM0 is always taken (WKC 1), the slave stays in PRE-OP
//    without error, SM0 is empty again afterwards;
//  - every reply read from SM1 has a valid header whose length fits SM1, type CoE or mailbox
//    error, counter 1..7; an error reply is service 1 with a
//    known detail code; a CoE reply carries an SDO request (abort), SDO response or SDO
//    information service; the reply queue drains within a bounded number of cycles.
//
//   ./ec_mailbox_fuzz -max_total_time=60 fuzz/corpus/ec_mailbox
#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "bus_emulators/ethercat/device/ec_mailbox.hpp"
#include "bus_emulators/ethercat/device/ec_slave.hpp"
#include "bus_emulators/ethercat/ec_chain.hpp"
#include "bus_emulators/ethercat/ec_registers.hpp"
#include "fuzz/ec_fuzz_master.hpp"

using namespace omnitwin::ethercat;

namespace {

constexpr std::uint64_t kEpoch = 1024;  // inputs between restarts
constexpr std::size_t kMaxWrites = 8;   // mailbox writes per input
constexpr int kMaxDrain = 200;          // SM1 reads per write before the queue must be empty

fuzz::History& history() {
  static fuzz::History h("./ec_mailbox_");
  return h;
}

#define CHECK(cond) EC_FUZZ_CHECK(history(), cond)

struct Rig {
  DeviceDescription desc = fuzz::shipped_device("omnitwin_drive.xml");
  std::unique_ptr<DriveSlave> slave;
  std::unique_ptr<EscChain> chain;
  SimTime t = 0;
  std::uint64_t inputs = 0;
  std::uint8_t epoch = 0;
  std::uint16_t station = fuzz::kFirstStation;
  SyncManager out{}, in{};

  Rig() { restart(0); }

  // A new slave (fresh ESC, object dictionary and CoE server) at t = 0, brought to PRE-OP with
  // the ESI's mailbox size (even tags) or with 32-byte mailboxes (odd tags: most uploads and
  // downloads are then segmented, SDO information replies fragmented).
  void restart(std::uint8_t tag) {
    epoch = tag;
    history().restart(tag);
    t = 0;
    chain = std::make_unique<EscChain>();
    DriveSlaveConfig cfg;
    cfg.axes = 1;
    slave = std::make_unique<DriveSlave>(desc, cfg);
    chain->add(&slave->esc());
    fuzz::Master m(*chain, t);
    m.bring_up(0, *slave, AlState::preop, tag % 2 == 0 ? 0 : 32);
    out = slave->esc().sm(0);
    in = slave->esc().sm(1);
    CHECK(out.enabled && out.mailbox() && out.ecat_writes() && out.length >= 16);
    CHECK(in.enabled && in.mailbox() && !in.ecat_writes() && in.length >= 16);
  }

  // One reply as read from SM1.
  void check_reply(const std::uint8_t* r) {
    const auto h = decode_mailbox_header({r, in.length});
    CHECK(h.has_value());
    CHECK(kMailboxHeaderSize + h->length <= in.length);
    CHECK(h->counter >= 1 && h->counter <= 7);
    if (h->type == static_cast<std::uint8_t>(MailboxType::error)) {
      CHECK(h->length == 4 && get_u16(r + 6) == 0x0001);
      const std::uint16_t code = get_u16(r + 8);
      CHECK(code >= 0x0001 && code <= 0x0008);
      CHECK(to_string(static_cast<MailboxError>(code)) != nullptr);
      return;
    }
    CHECK(h->type == static_cast<std::uint8_t>(MailboxType::coe));
    CHECK(h->length >= 2);
    const std::uint16_t service = get_u16(r + 6) >> 12;
    CHECK(service == coe::svc_sdo_request || service == coe::svc_sdo_response || service == coe::svc_sdo_info);
    if (service == coe::svc_sdo_request) {  // an abort: command 0x80, index, sub, u32 code
      CHECK(h->length >= 10 && r[8] == 0x80);
    }
  }

  // One whole SM0 write of `piece` (zero-padded), then SM1 drained.
  void write_mailbox(std::span<const std::uint8_t> piece) {
    fuzz::Master m(*chain, t);
    std::vector<std::uint8_t> mbx(out.length, 0);
    std::copy_n(piece.begin(), std::min(piece.size(), mbx.size()), mbx.begin());
    CHECK(m.fpwr(station, out.start, mbx.data(), out.length) == 1);
    Esc& e = slave->esc();
    CHECK(!e.sm_unit(0).full());
    CHECK(e.al_state() == AlState::preop && !e.al_error());
    std::vector<std::uint8_t> reply(in.length, 0);
    int empty_reads = 0;
    for (int i = 0; i < kMaxDrain; ++i) {
      const int wkc = m.fprd(station, in.start, reply.data(), in.length);
      CHECK(wkc == 0 || wkc == 1);
      if (wkc == 1) {
        check_reply(reply.data());
        empty_reads = 0;
        CHECK(!e.sm_unit(1).full());
      } else if (++empty_reads == 2) {
        CHECK(!slave->coe().has_reply());
        return;
      }
      t += 1'000'000;
      slave->cycle(t);
    }
    CHECK(false);  // the queue did not drain
  }
};

// The header codec on the input's first bytes.
void check_header_codec(const std::uint8_t* data, std::size_t size) {
  const auto h = decode_mailbox_header({data, size});
  CHECK(h.has_value() == (size >= kMailboxHeaderSize));
  if (!h) return;
  CHECK(h->channel <= 63 && h->priority <= 3 && h->type <= 15 && h->counter <= 7);
  std::uint8_t enc[kMailboxHeaderSize];
  encode_mailbox_header(*h, enc);
  CHECK(std::memcmp(enc, data, 5) == 0 && enc[5] == (data[5] & 0x7F));
  const std::uint8_t next = next_mailbox_counter(h->counter);
  CHECK(next >= 1 && next <= 7 && next != h->counter);
  std::uint8_t err[10];
  const auto code = static_cast<MailboxError>(1 + data[0] % 8);
  CHECK(encode_mailbox_error(code, next, {err, 9}) == 0);
  CHECK(encode_mailbox_error(code, next, err) == 10);
  const auto eh = decode_mailbox_header(err);
  CHECK(eh && eh->length == 4 && eh->type == 0 && eh->counter == next && get_u16(err + 6) == 1 &&
        get_u16(err + 8) == static_cast<std::uint16_t>(code));
}

// One input: the header codec, then up to kMaxWrites mailbox writes.
void one_input(Rig& rig, const std::uint8_t* data, std::size_t size) {
  history().record(data, size);
  check_header_codec(data, size);
  const std::size_t piece = rig.out.length;
  for (std::size_t off = 0, n = 0; n < kMaxWrites && (off < size || n == 0); off += piece, ++n) {
    const std::size_t len = off < size ? std::min(piece, size - off) : 0;
    rig.write_mailbox({data + off, len});
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static Rig rig;
  fuzz::replay_recorded(history(), rig, one_input);  // EC_FUZZ_REPLAY: a recorded failure first
  if (++rig.inputs % kEpoch == 0) rig.restart(static_cast<std::uint8_t>(rig.epoch + 1));
  one_input(rig, data, size);
  return 0;
}
