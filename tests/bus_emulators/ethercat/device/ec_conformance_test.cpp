// Conformance-style tests of the emulated EtherCAT drive (DriveSlave behind its Esc, two of them
// on an EscChain), walked the way ETG's public descriptions of slave conformance testing lay
// them out: every AL state request from every state, the error flag and its acknowledge; the
// mailbox and process-data SyncManager checks of each transition; what each state does to the
// process data and its working counter (SAFE-OP, SAFE-OP + error after a watchdog trip, OP);
// a master that stalls past the watchdog and recovers by WKC and AL status alone; FMMUs laid
// out as KickCAT does it (outputs and inputs at the same logical address, LWR and LRD); mailbox
// edge cases (full, empty, unknown type, oversized length, repeated counter, the SM1 repeat
// handshake, an emergency between an SDO request and its answer); DC settings (SYNC0 cycle
// below the minimum, a sync mode that disagrees with the activation). Only datagrams go in, as
// from a master; expectations come from the ETG.1000 rules (facts/ethercat.md) and the slave's
// documented choices (docs/protocols/ethercat-states.md), not from reading the code.
#include "bus_emulators/ethercat/device/ec_slave.hpp"

#include <gtest/gtest.h>

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/ethercat/ec_chain.hpp"
#include "bus_emulators/ethercat/ec_frame.hpp"
#include "tests/bus_emulators/ethercat/ec_register_bytes.hpp"

namespace omnitwin::ethercat {
namespace {

using Bytes = std::vector<std::uint8_t>;
constexpr std::uint32_t kLogical = 0x00010000;
constexpr std::uint16_t kOut = 18, kIn = 24;  // the drive ESI's default PDO sizes [bytes]

struct Reply {
  Bytes data;
  std::uint16_t wkc = 0;
};

// N drives on a line and a master that sends one datagram per frame (t += 100 µs each); every
// exchange is followed by one firmware cycle of each slave (mailbox replies, outputs, inputs).
class Segment {
 public:
  explicit Segment(int n = 2) {
    const auto esi = load_esi(std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/omnitwin_drive.xml").at(0);
    for (int i = 0; i < n; ++i) {
      DriveSlaveConfig c;
      c.serial = static_cast<std::uint32_t>(i + 1);
      slaves.push_back(std::make_unique<DriveSlave>(esi, c));
      chain.add(&slaves.back()->esc());
    }
    for (int i = 0; i < n; ++i)  // station addresses 0x1001…
      exchange(Cmd::apwr, static_cast<std::uint16_t>(0 - i), 0x0010,
               {static_cast<std::uint8_t>(0x01 + i), 0x10});
  }
  int size() const { return static_cast<int>(slaves.size()); }
  static std::uint16_t station(int i) { return static_cast<std::uint16_t>(0x1001 + i); }

  Reply exchange(Cmd cmd, std::uint16_t adp, std::uint16_t ado, const Bytes& data) {
    buf_.fill(0);
    PduBuilder b(buf_);
    EXPECT_GE(b.add(cmd, 1, adp, ado, static_cast<std::uint16_t>(data.size()), data.data()), 0);
    return send(b.finish());
  }
  Reply logical(Cmd cmd, std::uint32_t addr, const Bytes& data) {
    buf_.fill(0);
    PduBuilder b(buf_);
    b.add_logical(cmd, 1, addr, static_cast<std::uint16_t>(data.size()), data.data());
    return send(b.finish());
  }
  std::uint16_t fpwr(int i, std::uint16_t ado, const Bytes& d) { return exchange(Cmd::fpwr, station(i), ado, d).wkc; }
  Reply fprd(int i, std::uint16_t ado, std::size_t n) { return exchange(Cmd::fprd, station(i), ado, Bytes(n, 0)); }
  std::uint16_t read16(int i, std::uint16_t ado) { return get_u16(fprd(i, ado, 2).data.data()); }
  // AL control write; returns AL status (state | 0x10 error).
  std::uint16_t request(int i, std::uint16_t control) {
    fpwr(i, 0x0120, {static_cast<std::uint8_t>(control), static_cast<std::uint8_t>(control >> 8)});
    return read16(i, 0x0130);
  }
  void advance(SimTime dt) {
    t += dt;
    chain.advance(t);
    for (auto& s : slaves) s->cycle(t);
  }

  static Bytes sm(std::uint16_t start, std::uint16_t len, std::uint8_t control, bool enable) {
    return ec_test::sm_bytes(start, len, control, enable);
  }
  static Bytes fmmu(std::uint32_t logical, std::uint16_t len, std::uint16_t phys, std::uint8_t type) {
    return ec_test::fmmu_bytes(logical, len, phys, type);
  }
  // One SM block as a master reprogramming it writes it: disabled first (an enabled SM keeps its
  // start, length and control), then the new block.
  void write_sm(int i, std::uint16_t reg, const Bytes& block) {
    Bytes off = block;
    off[6] = 0;
    fpwr(i, reg, off);
    fpwr(i, reg, block);
  }
  void mailbox_sms(int i) {
    write_sm(i, 0x0800, sm(0x1000, 128, 0x26, true));
    write_sm(i, 0x0808, sm(0x1080, 128, 0x22, true));
  }
  // SM2/SM3 and FMMUs: slave i's outputs at kLogical + i·kOut, inputs after all outputs.
  void pd_sms(int i) {
    write_sm(i, 0x0810, sm(0x1100, kOut, 0x64, true));
    write_sm(i, 0x0818, sm(0x1180, kIn, 0x20, true));
    fpwr(i, 0x0600, fmmu(kLogical + kOut * i, kOut, 0x1100, 2));
    fpwr(i, 0x0610, fmmu(kLogical + kOut * size() + kIn * i, kIn, 0x1180, 1));
  }
  bool to_preop(int i) {
    mailbox_sms(i);
    return request(i, 2) == 2;
  }
  bool to_safeop(int i) {
    if (!to_preop(i)) return false;
    pd_sms(i);
    return request(i, 4) == 4;
  }
  bool to_op(int i) { return to_safeop(i) && request(i, 8) == 8; }
  bool all_to_op() {
    bool ok = true;
    for (int i = 0; i < size(); ++i) ok = to_op(i) && ok;
    return ok;
  }
  Reply lrw(const Bytes& out) {
    Bytes d(static_cast<std::size_t>((kOut + kIn) * size()), 0);
    std::copy(out.begin(), out.end(), d.begin());
    return logical(Cmd::lrw, kLogical, d);
  }
  std::uint16_t expected_wkc() const { return static_cast<std::uint16_t>(3 * size()); }

  EscChain chain;
  std::vector<std::unique_ptr<DriveSlave>> slaves;
  SimTime t = 0;

 private:
  std::array<std::uint8_t, kMaxPdu> buf_{};
  Reply send(std::size_t n) {
    t += 100'000;
    EXPECT_TRUE(chain.process(std::span<std::uint8_t>(buf_.data(), n), t));
    PduView v;
    EXPECT_EQ(parse_pdu(std::span<std::uint8_t>(buf_.data(), n), v), PduError::ok);
    Reply r{Bytes(v.datagrams[0].data(), v.datagrams[0].data() + v.datagrams[0].length()), v.datagrams[0].wkc()};
    for (auto& s : slaves) s->cycle(t);
    return r;
  }
};

// ---- AL state machine ------------------------------------------------------------------------

enum : std::uint16_t { INIT = 1, PREOP = 2, BOOT = 3, SAFEOP = 4, OP = 8 };

// Every request (the five states and an undefined value) from every state the master can reach,
// on a freshly configured slave each time: legal steps are taken (BOOT is refused by this
// firmware with 0x0013), illegal ones leave the state with the error flag and 0x0011, an
// undefined state gives 0x0012.
TEST(EcConformance, EveryAlRequestFromEveryState) {
  struct Case {
    std::uint16_t from, req, state;
    std::uint16_t code;  // 0: accepted
  };
  const Case cases[] = {
      {INIT, INIT, INIT, 0},        {INIT, PREOP, PREOP, 0},       {INIT, BOOT, INIT, 0x0013},
      {INIT, SAFEOP, INIT, 0x0011}, {INIT, OP, INIT, 0x0011},      {INIT, 5, INIT, 0x0012},
      {PREOP, INIT, INIT, 0},       {PREOP, PREOP, PREOP, 0},      {PREOP, BOOT, PREOP, 0x0011},
      {PREOP, SAFEOP, SAFEOP, 0},   {PREOP, OP, PREOP, 0x0011},    {PREOP, 5, PREOP, 0x0012},
      {SAFEOP, INIT, INIT, 0},      {SAFEOP, PREOP, PREOP, 0},     {SAFEOP, BOOT, SAFEOP, 0x0011},
      {SAFEOP, SAFEOP, SAFEOP, 0},  {SAFEOP, OP, OP, 0},           {SAFEOP, 5, SAFEOP, 0x0012},
      {OP, INIT, INIT, 0},          {OP, PREOP, PREOP, 0},         {OP, BOOT, OP, 0x0011},
      {OP, SAFEOP, SAFEOP, 0},      {OP, OP, OP, 0},               {OP, 5, OP, 0x0012},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE("from " + std::to_string(c.from) + " request " + std::to_string(c.req));
    Segment seg(1);
    switch (c.from) {
      case PREOP: ASSERT_TRUE(seg.to_preop(0)); break;
      case SAFEOP: ASSERT_TRUE(seg.to_safeop(0)); break;
      case OP: ASSERT_TRUE(seg.to_op(0)); break;
      default: break;
    }
    seg.mailbox_sms(0);  // every SM the firmware checks is valid: only the AL rules decide
    seg.pd_sms(0);
    const std::uint16_t st = seg.request(0, c.req);
    EXPECT_EQ(st & 0x0F, c.state);
    EXPECT_EQ((st & 0x10) != 0, c.code != 0);
    EXPECT_EQ(seg.read16(0, 0x0134), c.code);
    if (c.code != 0) {  // the acknowledge clears the flag and the code
      EXPECT_EQ(seg.request(0, static_cast<std::uint16_t>(c.from | 0x10)), c.from);
      EXPECT_EQ(seg.read16(0, 0x0134), 0);
    }
  }
}

// With the error flag set, requests without the acknowledge are ignored, except INIT, which
// acknowledges the error as the bit does (Beckhoff's slave stack; the flag and the old code used
// to stay, so a master that wrote 0x0001 and then PRE-OP found its request ignored).
TEST(EcConformance, TheErrorFlagHoldsUntilAcknowledgedOrInit) {
  Segment seg(1);
  ASSERT_TRUE(seg.to_safeop(0));
  EXPECT_EQ(seg.request(0, OP | 0x00), OP);
  EXPECT_EQ(seg.request(0, BOOT), OP | 0x10);  // refused: error flag
  EXPECT_EQ(seg.request(0, SAFEOP), OP | 0x10);  // ignored without the ack
  EXPECT_EQ(seg.read16(0, 0x0134), 0x0011);
  EXPECT_EQ(seg.request(0, INIT), INIT);  // INIT is taken and clears the flag and the code
  EXPECT_EQ(seg.read16(0, 0x0134), 0x0000);
  EXPECT_EQ(seg.request(0, PREOP), PREOP) << "no acknowledge needed any more";
}

// ---- SyncManager checks of the transitions ---------------------------------------------------

// INIT → PRE-OP needs SM0 (master writes) and SM1 (master reads) as enabled mailboxes of at
// least 16 bytes that do not overlap; anything else is 0x0016.
TEST(EcConformance, MailboxSyncManagerChecksOfInitToPreop) {
  struct Bad {
    const char* what;
    Bytes sm0, sm1;
  };
  const Bad bad[] = {
      {"SM0 disabled", Segment::sm(0x1000, 128, 0x26, false), Segment::sm(0x1080, 128, 0x22, true)},
      {"SM1 disabled", Segment::sm(0x1000, 128, 0x26, true), Segment::sm(0x1080, 128, 0x22, false)},
      {"SM0 read direction", Segment::sm(0x1000, 128, 0x22, true), Segment::sm(0x1080, 128, 0x22, true)},
      {"SM1 write direction", Segment::sm(0x1000, 128, 0x26, true), Segment::sm(0x1080, 128, 0x26, true)},
      {"SM0 buffered", Segment::sm(0x1000, 128, 0x24, true), Segment::sm(0x1080, 128, 0x22, true)},
      {"SM0 8 bytes", Segment::sm(0x1000, 8, 0x26, true), Segment::sm(0x1080, 128, 0x22, true)},
      {"overlap", Segment::sm(0x1000, 128, 0x26, true), Segment::sm(0x1040, 128, 0x22, true)},
  };
  for (const Bad& b : bad) {
    SCOPED_TRACE(b.what);
    Segment seg(1);
    seg.fpwr(0, 0x0800, b.sm0);
    seg.fpwr(0, 0x0808, b.sm1);
    EXPECT_EQ(seg.request(0, PREOP), INIT | 0x10);
    EXPECT_EQ(seg.read16(0, 0x0134), 0x0016);
    seg.mailbox_sms(0);
    EXPECT_EQ(seg.request(0, PREOP | 0x10), PREOP);  // fixed and acknowledged
  }
}

// PRE-OP → SAFE-OP needs SM2 (buffered, master writes, RxPDO length) → else 0x001D, and SM3
// (buffered, master reads, TxPDO length) → else 0x001E; a buffered SM takes three buffers of
// its length, which must not reach another SM (SM2's into SM3 or a mailbox: 0x001D; SM3's into
// a mailbox: 0x001E; found by a protocol review: SM2's second buffer overwrote the inputs).
TEST(EcConformance, ProcessDataSyncManagerChecksOfPreopToSafeop) {
  struct Bad {
    const char* what;
    std::uint16_t reg;
    Bytes sm;
    std::uint16_t code;
  };
  const Bad bad[] = {
      {"SM2 disabled", 0x0810, Segment::sm(0x1100, kOut, 0x64, false), 0x001D},
      {"SM2 wrong length", 0x0810, Segment::sm(0x1100, kOut - 2, 0x64, true), 0x001D},
      {"SM2 mailbox", 0x0810, Segment::sm(0x1100, kOut, 0x66, true), 0x001D},
      {"SM2 read direction", 0x0810, Segment::sm(0x1100, kOut, 0x60, true), 0x001D},
      {"SM3 disabled", 0x0818, Segment::sm(0x1180, kIn, 0x20, false), 0x001E},
      {"SM3 wrong length", 0x0818, Segment::sm(0x1180, kIn + 2, 0x20, true), 0x001E},
      {"SM3 write direction", 0x0818, Segment::sm(0x1180, kIn, 0x24, true), 0x001E},
      {"SM3 inside SM2's three buffers", 0x0818, Segment::sm(0x1100 + 2 * kOut, kIn, 0x20, true), 0x001D},
      {"SM3's three buffers over a mailbox", 0x0818, Segment::sm(0x1080 - kIn, kIn, 0x20, true), 0x001E},
  };
  for (const Bad& b : bad) {
    SCOPED_TRACE(b.what);
    Segment seg(1);
    ASSERT_TRUE(seg.to_preop(0));
    seg.pd_sms(0);
    seg.write_sm(0, b.reg, b.sm);
    EXPECT_EQ(seg.request(0, SAFEOP), PREOP | 0x10);
    EXPECT_EQ(seg.read16(0, 0x0134), b.code);
    seg.pd_sms(0);
    EXPECT_EQ(seg.request(0, SAFEOP | 0x10), SAFEOP);
  }
}

// ---- process data per state ------------------------------------------------------------------

// The WKC of one LRW over two drives in each state, and whether outputs reach the drive:
// PRE-OP 0 (no process data below SAFE-OP); SAFE-OP 6 (outputs taken, not applied); OP 6
// (applied); SAFE-OP + error after a watchdog trip 2 (the output SM is deactivated: inputs
// only); acknowledged 6 again; OP again 6. 0x0807 shows the deactivation to the master.
TEST(EcConformance, WorkingCounterAndOutputsStateByState) {
  Segment seg(2);
  Bytes out(2 * kOut, 0);
  put_u16(out.data(), 0x0006);  // slave 1's controlword
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(seg.to_preop(i));
    seg.pd_sms(i);
  }
  EXPECT_EQ(seg.lrw(out).wkc, 0);
  EXPECT_EQ(seg.fprd(0, 0x0817, 1).data[0] & 1, 1);  // SM2 deactivated by the PDI in PRE-OP
  for (int i = 0; i < 2; ++i) ASSERT_EQ(seg.request(i, SAFEOP), SAFEOP);
  EXPECT_EQ(seg.fprd(0, 0x0817, 1).data[0] & 1, 0);
  EXPECT_EQ(seg.lrw(out).wkc, 6);
  EXPECT_EQ(seg.slaves[0]->axis(0).objects().controlword, 0);  // not applied in SAFE-OP
  for (int i = 0; i < 2; ++i) ASSERT_EQ(seg.request(i, OP), OP);
  EXPECT_EQ(seg.lrw(out).wkc, 6);
  EXPECT_EQ(seg.slaves[0]->axis(0).objects().controlword, 0x0006);  // applied in OP
  // No frame for 150 ms (watchdog 100 ms): SAFE-OP + 0x001B, outputs to their safe state.
  seg.advance(150'000'000);
  EXPECT_EQ(seg.read16(0, 0x0130), SAFEOP | 0x10);
  EXPECT_EQ(seg.read16(0, 0x0134), 0x001B);
  EXPECT_EQ(seg.read16(0, 0x0440) & 1, 0);  // watchdog status: expired
  EXPECT_EQ(seg.fprd(0, 0x0442, 1).data[0], 1);  // process-data watchdog counter
  EXPECT_EQ(seg.fprd(0, 0x0817, 1).data[0] & 1, 1);
  EXPECT_EQ(seg.slaves[0]->axis(0).objects().controlword, 0);
  EXPECT_EQ(seg.lrw(out).wkc, 2);  // inputs of both, no outputs
  ASSERT_EQ(seg.request(0, SAFEOP | 0x10), SAFEOP);  // slave 1 acknowledged, slave 2 not yet
  EXPECT_EQ(seg.lrw(out).wkc, 4);
  ASSERT_EQ(seg.request(1, SAFEOP | 0x10), SAFEOP);
  EXPECT_EQ(seg.lrw(out).wkc, 6);
  for (int i = 0; i < 2; ++i) ASSERT_EQ(seg.request(i, OP), OP);
  EXPECT_EQ(seg.lrw(out).wkc, 6);
}

// A master we did not write supervises by WKC and AL status, as SOEM's example check does: it
// stalls for 150 ms, sees the WKC drop below the expected 6, reads each slave's AL status
// (SAFE-OP + error, 0x001B), acknowledges it and requests OP (one AL control write, 0x0018),
// and has the expected WKC again.
TEST(EcConformance, AStalledMasterRecoversByWkcAndAlStatusAlone) {
  Segment seg(2);
  ASSERT_TRUE(seg.all_to_op());
  const Bytes out(2 * kOut, 0);
  for (int k = 0; k < 10; ++k) {
    ASSERT_EQ(seg.lrw(out).wkc, seg.expected_wkc());
    seg.advance(900'000);
  }
  seg.advance(150'000'000);
  const std::uint16_t wkc = seg.lrw(out).wkc;
  ASSERT_LT(wkc, seg.expected_wkc());
  int recovered = 0;
  for (int i = 0; i < seg.size(); ++i) {
    const std::uint16_t st = seg.read16(i, 0x0130);
    if (st == OP) continue;
    EXPECT_EQ(st, SAFEOP | 0x10);
    EXPECT_EQ(seg.read16(i, 0x0134), 0x001B);
    EXPECT_EQ(seg.request(i, OP | 0x10), OP);
    ++recovered;
  }
  EXPECT_EQ(recovered, 2);
  EXPECT_EQ(seg.lrw(out).wkc, seg.expected_wkc());
}

// ---- FMMUs ---------------------------------------------------------------------------------

// KickCAT maps a slave's outputs (write FMMU) and inputs (read FMMU) both at logical address 0
// and moves them with separate LWR and LRD: each counts once per slave.
TEST(EcConformance, OutputAndInputFmmusAtTheSameLogicalAddress) {
  Segment seg(1);
  ASSERT_TRUE(seg.to_preop(0));
  seg.fpwr(0, 0x0810, Segment::sm(0x1100, kOut, 0x64, true));
  seg.fpwr(0, 0x0818, Segment::sm(0x1180, kIn, 0x20, true));
  seg.fpwr(0, 0x0600, Segment::fmmu(0, kOut, 0x1100, 2));
  seg.fpwr(0, 0x0610, Segment::fmmu(0, kIn, 0x1180, 1));
  ASSERT_EQ(seg.request(0, SAFEOP), SAFEOP);
  ASSERT_EQ(seg.request(0, OP), OP);
  Bytes out(kOut, 0);
  put_u16(out.data(), 0x0006);
  seg.slaves[0]->axis(0).objects().position_actual = 0x12345;
  EXPECT_EQ(seg.logical(Cmd::lwr, 0, out).wkc, 1);
  seg.advance(1'000'000);
  const Reply in = seg.logical(Cmd::lrd, 0, Bytes(kIn, 0));
  EXPECT_EQ(in.wkc, 1);
  EXPECT_EQ(get_u32(in.data.data() + 2), 0x12345u);  // statusword, then position actual
  EXPECT_EQ(seg.slaves[0]->axis(0).objects().controlword, 0x0006);
}

// A bit-granular FMMU (logical and physical start bit 4, one bit) over plain process RAM: an
// LWR moves that one bit and leaves the others, an LRD reads it back at its logical bit.
TEST(EcConformance, BitGranularFmmuMovesOnlyItsBit) {
  Segment seg(1);
  ASSERT_TRUE(seg.to_safeop(0));
  seg.fpwr(0, 0x1400, {0xFF});
  // Logical bits 4 … 4 onto physical bit 4, read and write.
  seg.fpwr(0, 0x0620, ec_test::fmmu_bytes(0x00020000, 1, 4, 4, 0x1400, 4, 3));
  EXPECT_EQ(seg.logical(Cmd::lwr, 0x00020000, {0x00}).wkc, 1);
  EXPECT_EQ(seg.fprd(0, 0x1400, 1).data[0], 0xEF);
  seg.fpwr(0, 0x1400, {0x10});
  const Reply r = seg.logical(Cmd::lrd, 0x00020000, {0x00});
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(r.data[0], 0x10);
}

// ---- mailbox ---------------------------------------------------------------------------------

Bytes sdo_upload(std::uint16_t index, std::uint8_t sub, std::uint8_t counter) {
  Bytes m(128, 0);
  put_u16(m.data(), 10);
  m[5] = static_cast<std::uint8_t>(0x03 | (counter << 4));
  put_u16(m.data() + 6, 0x2000);
  m[8] = 0x40;
  put_u16(m.data() + 9, index);
  m[11] = sub;
  return m;
}

// A full write mailbox and an empty read mailbox refuse the access (WKC 0); an unknown mailbox
// type gets a mailbox error reply (0x0002 unsupported protocol), a length beyond the SM one
// 0x0008 invalid size; an SDO to a missing object the abort 0x06020000.
TEST(EcConformance, MailboxFullEmptyUnknownTypeAndBadLength) {
  Segment seg(1);
  ASSERT_TRUE(seg.to_preop(0));
  EXPECT_EQ(seg.fprd(0, 0x1080, 128).wkc, 0);  // empty
  Bytes unknown(128, 0);
  put_u16(unknown.data(), 4);
  unknown[5] = 0x1E;  // type 14 (reserved), counter 1
  EXPECT_EQ(seg.fpwr(0, 0x1000, unknown), 1);
  Reply r = seg.fprd(0, 0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(r.data[5] & 0x0F, 0);  // mailbox error
  EXPECT_EQ(get_u16(r.data.data() + 8), 0x0002);
  Bytes oversized = sdo_upload(0x1000, 0, 2);
  put_u16(oversized.data(), 500);
  EXPECT_EQ(seg.fpwr(0, 0x1000, oversized), 1);
  r = seg.fprd(0, 0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(get_u16(r.data.data() + 8), 0x0008);
  EXPECT_EQ(seg.fpwr(0, 0x1000, sdo_upload(0x5FFF, 0, 3)), 1);
  r = seg.fprd(0, 0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(r.data[8], 0x80);
  EXPECT_EQ(get_u32(r.data.data() + 12), 0x06020000u);
  // Full: the firmware is not given a cycle between two writes here, the second is refused.
  std::array<std::uint8_t, kMaxPdu> buf{};
  PduBuilder b(buf);
  const Bytes m1 = sdo_upload(0x1000, 0, 4), m2 = sdo_upload(0x1000, 0, 5);
  b.add(Cmd::fpwr, 1, Segment::station(0), 0x1000, 128, m1.data());
  b.add(Cmd::fpwr, 2, Segment::station(0), 0x1080, 0, nullptr);
  const std::size_t n = b.finish();
  ASSERT_TRUE(seg.chain.process(std::span<std::uint8_t>(buf.data(), n), seg.t + 1));
  // SM1 holds the reply to m1 (not read yet): SM0 takes m2, but its reply waits.
  EXPECT_EQ(seg.fpwr(0, 0x1000, m2), 1);
  EXPECT_EQ(seg.fprd(0, 0x1080, 128).wkc, 1);
}

// The same counter twice is a repeat: answered, never executed again. A lost reply is asked for
// again with the SM1 repeat request (0x080E bit 1): the slave puts the last reply back.
TEST(EcConformance, RepeatedCounterAndTheRepeatHandshake) {
  Segment seg(1);
  ASSERT_TRUE(seg.to_preop(0));
  EXPECT_EQ(seg.fpwr(0, 0x1000, sdo_upload(0x1018, 1, 1)), 1);
  const Reply first = seg.fprd(0, 0x1080, 128);
  ASSERT_EQ(first.wkc, 1);
  EXPECT_EQ(seg.fpwr(0, 0x1000, sdo_upload(0x1018, 1, 1)), 1);  // same counter
  const Reply again = seg.fprd(0, 0x1080, 128);
  ASSERT_EQ(again.wkc, 1);
  EXPECT_EQ(std::vector<std::uint8_t>(again.data.begin() + 6, again.data.end()),
            std::vector<std::uint8_t>(first.data.begin() + 6, first.data.end()));
  EXPECT_EQ(seg.slaves[0]->coe().stats().repeats, 1u);
  // Repeat handshake: toggle the request bit; the ESC acknowledges in 0x080F and refills SM1.
  EXPECT_EQ(seg.fprd(0, 0x1080, 128).wkc, 0);
  EXPECT_EQ(seg.fpwr(0, 0x080E, {0x03}), 1);
  EXPECT_EQ(seg.fprd(0, 0x080F, 1).data[0] & 0x02, 0x02);
  const Reply repeated = seg.fprd(0, 0x1080, 128);
  ASSERT_EQ(repeated.wkc, 1);
  EXPECT_EQ(repeated.data, again.data);
}

// An emergency that arrives between an SDO request and its answer sits in SM1 first; the SDO
// answer follows it, unchanged.
TEST(EcConformance, AnEmergencyBetweenAnSdoRequestAndItsAnswer) {
  Segment seg(1);
  ASSERT_TRUE(seg.to_op(0));
  auto& axis = seg.slaves[0]->axis(0);
  for (int k = 1; k <= 5; ++k) axis.step(k * 1'000'000, {});
  axis.raise_fault(drive::kErrorExternal);
  axis.step(6'000'000, {});
  ASSERT_EQ(axis.objects().error_code, drive::kErrorExternal);
  seg.advance(1'000);  // the firmware cycle queues the emergency
  EXPECT_EQ(seg.fpwr(0, 0x1000, sdo_upload(0x1018, 2, 1)), 1);
  Reply r = seg.fprd(0, 0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(get_u16(r.data.data() + 6) >> 12, 1);  // emergency
  EXPECT_EQ(get_u16(r.data.data() + 8), drive::kErrorExternal);
  EXPECT_EQ(r.data[10], 0x01 | drive::error_class_bit(drive::kErrorExternal));
  r = seg.fprd(0, 0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(get_u16(r.data.data() + 6) >> 12, 3);  // SDO response
  EXPECT_EQ(get_u32(r.data.data() + 12), 0x00000402u);  // product code
}

// ---- distributed clocks ------------------------------------------------------------------------

// SYNC0 activated with a cycle below the minimum is not activated (0x0981 reads 0) and SAFE-OP
// is refused with 0x0030; a DC sync mode written to 0x1C32 without SYNC0 is refused the same
// way; with a valid cycle the slave reaches OP and 0x1C32 reports it.
TEST(EcConformance, DcSettingsTheSlaveRefuses) {
  Segment seg(1);
  ASSERT_TRUE(seg.to_preop(0));
  seg.pd_sms(0);
  Bytes cyc(4, 0);
  put_u32(cyc.data(), DcClock::kMinSyncCycleNs - 1);
  seg.fpwr(0, 0x09A0, cyc);
  seg.fpwr(0, 0x0980, {0x00, 0x03});
  EXPECT_EQ(seg.fprd(0, 0x0981, 1).data[0], 0x03);  // requested…
  EXPECT_EQ(seg.fprd(0, 0x0984, 1).data[0] & 1, 0);  // …but SYNC0 not active
  EXPECT_EQ(seg.request(0, SAFEOP), PREOP | 0x10);
  EXPECT_EQ(seg.read16(0, 0x0134), 0x0030);
  seg.fpwr(0, 0x0980, {0x00, 0x00});  // DC off, but the master says DC SYNC0 in 0x1C32
  Bytes sdo(128, 0);
  put_u16(sdo.data(), 10);
  sdo[5] = 0x13;
  put_u16(sdo.data() + 6, 0x2000);
  sdo[8] = 0x2B;
  put_u16(sdo.data() + 9, 0x1C32);
  sdo[11] = 1;
  put_u16(sdo.data() + 12, 2);
  EXPECT_EQ(seg.fpwr(0, 0x1000, sdo), 1);
  EXPECT_EQ(seg.fprd(0, 0x1080, 128).data[8], 0x60);
  EXPECT_EQ(seg.request(0, SAFEOP | 0x10), PREOP | 0x10);
  EXPECT_EQ(seg.read16(0, 0x0134), 0x0030);
  put_u32(cyc.data(), 1'000'000);
  seg.fpwr(0, 0x09A0, cyc);
  seg.fpwr(0, 0x0980, {0x00, 0x03});
  EXPECT_EQ(seg.request(0, SAFEOP | 0x10), SAFEOP);
  EXPECT_EQ(seg.request(0, OP), OP);
  EXPECT_EQ(seg.slaves[0]->sync_params(true).sync_mode, 2);
  EXPECT_EQ(seg.slaves[0]->sync_params(false).sync_mode, 2);  // not written: follows SYNC0
}

}  // namespace
}  // namespace omnitwin::ethercat
