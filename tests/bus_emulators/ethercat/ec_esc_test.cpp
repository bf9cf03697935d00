// Tests bus_emulators/ethercat/ec_esc: one ESC as datagrams pass it — the WKC of every command
// kind (incl. ARMW/FRMW and refused accesses), ADP increment for position addressing, node and
// alias addressing, read-only and reset-only registers, AL control/status with the firmware's
// answers and error acknowledge, SII access through registers, mailbox full/empty refusals and
// the repeat handshake, 3-buffer process data through FMMUs, the process-data watchdog, that
// unknown commands are counted without effect, that SyncManagers outside process RAM are not
// activated (neither ECAT nor PDI reach the registers through them), and the cap on SYNC0 pulses
// per advance.
#include "bus_emulators/ethercat/ec_esc.hpp"

#include <gtest/gtest.h>

#include <iterator>
#include <random>
#include <vector>

#include "bus_emulators/ethercat/ec_registers.hpp"
#include "tests/bus_emulators/ethercat/ec_register_bytes.hpp"

namespace omnitwin::ethercat {
namespace {

struct Reply {
  std::vector<std::uint8_t> data;
  std::uint16_t wkc = 0;
  std::uint16_t adp = 0;
};

Reply xfer(Esc& e, Cmd c, std::uint16_t adp, std::uint16_t ado, std::vector<std::uint8_t> data, SimTime t = 0) {
  std::array<std::uint8_t, kMaxPdu> buf{};
  PduBuilder b(buf);
  const int off = b.add(c, 0x11, adp, ado, static_cast<std::uint16_t>(data.size()), data.data());
  const std::size_t n = b.finish();
  PduView v;
  EXPECT_EQ(parse_pdu(std::span(buf.data(), n), v), PduError::ok);
  e.process(v.datagrams[0], t);
  Reply r;
  r.data.assign(buf.begin() + off, buf.begin() + off + static_cast<std::ptrdiff_t>(data.size()));
  r.wkc = v.datagrams[0].wkc();
  r.adp = v.datagrams[0].adp();
  return r;
}

std::vector<std::uint8_t> le16(std::uint16_t v) { return {static_cast<std::uint8_t>(v), static_cast<std::uint8_t>(v >> 8)}; }
std::vector<std::uint8_t> le32(std::uint32_t v) {
  return {static_cast<std::uint8_t>(v), static_cast<std::uint8_t>(v >> 8), static_cast<std::uint8_t>(v >> 16),
          static_cast<std::uint8_t>(v >> 24)};
}
std::uint16_t u16(const Reply& r) { return get_u16(r.data.data()); }

// Writes with APWR to position 0 (the only slave).
std::uint16_t apwr(Esc& e, std::uint16_t ado, std::vector<std::uint8_t> d, SimTime t = 0) {
  return xfer(e, Cmd::apwr, 0, ado, std::move(d), t).wkc;
}
Reply aprd(Esc& e, std::uint16_t ado, std::size_t n, SimTime t = 0) {
  return xfer(e, Cmd::aprd, 0, ado, std::vector<std::uint8_t>(n, 0), t);
}

class App : public EscApplication {
 public:
  AlStatusCode answer = AlStatusCode::none;
  std::vector<std::pair<AlState, AlState>> requests;
  std::vector<std::vector<std::uint8_t>> mailboxes;
  std::vector<std::vector<std::uint8_t>> outputs;
  int sync0 = 0;
  std::vector<SimTime> sync1_at;
  AlStatusCode on_al_request(AlState from, AlState to, SimTime) override {
    requests.emplace_back(from, to);
    return answer;
  }
  void on_mailbox(std::span<const std::uint8_t> m, SimTime) override { mailboxes.emplace_back(m.begin(), m.end()); }
  void on_outputs(std::span<const std::uint8_t> o, SimTime) override { outputs.emplace_back(o.begin(), o.end()); }
  void on_sync0(SimTime) override { ++sync0; }
  void on_sync1(SimTime t) override { sync1_at.push_back(t); }
};

using ec_test::fmmu_bytes;
using ec_test::sm_bytes;

void go(Esc& e, AlState s, SimTime t = 0) { apwr(e, reg::kAlControl, le16(static_cast<std::uint16_t>(s)), t); }

TEST(EcEsc, InformationRegistersFromTheConfig) {
  EscConfig c;
  c.type = 0x11;
  c.revision = 2;
  c.build = 0x0123;
  c.fmmus = 3;
  c.sync_managers = 4;
  c.ram_kib = 8;
  Esc e(c, nullptr);
  const Reply r = aprd(e, 0x0000, 10);
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(r.data, (std::vector<std::uint8_t>{0x11, 2, 0x23, 0x01, 3, 4, 8, 0x0F, 0x0C, 0x00}));
  EXPECT_EQ(u16(aprd(e, reg::kAlStatus, 2)), 0x0001);
  EXPECT_EQ(u16(aprd(e, reg::kWatchdogDivider, 2)), 0x09C2);
  EXPECT_EQ(u16(aprd(e, reg::kWatchdogTimePd, 2)), 0x03E8);
  EXPECT_EQ(u16(aprd(e, reg::kDlStatus, 2)), 0x0001 | 0x0010 | 0x0200 | 0x0400);  // alone: port 1 closed
}

TEST(EcEsc, PositionAddressingIncrementsAdpAndCountsOnlyTheAddressed) {
  Esc e(EscConfig{}, nullptr);
  Reply r = xfer(e, Cmd::aprd, 0, 0x0000, {0, 0});
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(r.adp, 1);
  EXPECT_EQ(r.data[0], 0x11);
  r = xfer(e, Cmd::aprd, 0xFFFF, 0x0000, {0, 0});  // position 2 seen by slave 1: not us
  EXPECT_EQ(r.wkc, 0);
  EXPECT_EQ(r.adp, 0);
  EXPECT_EQ(r.data[0], 0);
  // APWR sets the station address; APRW reads the old value and writes: +3.
  EXPECT_EQ(xfer(e, Cmd::apwr, 0, reg::kStationAddress, le16(0x1001)).wkc, 1);
  r = xfer(e, Cmd::aprw, 0, reg::kStationAddress, le16(0x1002));
  EXPECT_EQ(r.wkc, 3);
  EXPECT_EQ(u16(r), 0x1001);
  EXPECT_EQ(e.station_address(), 0x1002);
}

TEST(EcEsc, NodeAddressingByStationAddressOrEnabledAlias) {
  EscConfig c;
  c.sii.assign(64, 0);
  c.sii[4] = 0x0BEE;  // configured station alias
  Esc e(c, nullptr);
  EXPECT_EQ(e.alias(), 0x0BEE);
  apwr(e, reg::kStationAddress, le16(0x1001));
  EXPECT_EQ(xfer(e, Cmd::fprd, 0x1001, 0x0000, {0}).wkc, 1);
  EXPECT_EQ(xfer(e, Cmd::fprd, 0x1002, 0x0000, {0}).wkc, 0);
  EXPECT_EQ(xfer(e, Cmd::fprd, 0x0BEE, 0x0000, {0}).wkc, 0);  // alias not enabled yet
  apwr(e, reg::kDlControlAlias, {0x01});
  EXPECT_EQ(xfer(e, Cmd::fprd, 0x0BEE, 0x0000, {0}).wkc, 1);
  EXPECT_EQ(xfer(e, Cmd::fpwr, 0x0BEE, 0x0020, {1, 2}).wkc, 1);
  const Reply r = xfer(e, Cmd::fprw, 0x1001, 0x0020, {5, 6});
  EXPECT_EQ(r.wkc, 3);
  EXPECT_EQ(r.data, (std::vector<std::uint8_t>{1, 2}));
  // The alias register is read-only for the master (written count, value kept).
  EXPECT_EQ(apwr(e, reg::kStationAlias, le16(0x1234)), 1);
  EXPECT_EQ(e.alias(), 0x0BEE);
}

TEST(EcEsc, BroadcastReadOrsAndWritesEverywhere) {
  Esc e(EscConfig{}, nullptr);
  Reply r = xfer(e, Cmd::brd, 0, 0x0000, {0x40, 0x00});
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(r.adp, 1);
  EXPECT_EQ(r.data[0], 0x51);  // 0x40 | type 0x11
  EXPECT_EQ(xfer(e, Cmd::bwr, 0, reg::kEcatEventMask, le16(0x0004)).wkc, 1);
  r = xfer(e, Cmd::brw, 0, reg::kEcatEventMask, le16(0x0100));
  EXPECT_EQ(r.wkc, 3);
  EXPECT_EQ(u16(r), 0x0104);
  EXPECT_EQ(e.read16(reg::kEcatEventMask), 0x0100);
}

TEST(EcEsc, ReadModifyWriteCommandsReadWhenAddressedElseWrite) {
  Esc e(EscConfig{}, nullptr);
  apwr(e, reg::kStationAddress, le16(0x1001));
  apwr(e, 0x0F80, le32(0x11111111));  // user RAM-like register space
  Reply r = xfer(e, Cmd::frmw, 0x1001, 0x0F80, le32(0xAAAAAAAA));
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(get_u32(r.data.data()), 0x11111111u);
  r = xfer(e, Cmd::frmw, 0x1005, 0x0F80, le32(0xBBBBBBBB));
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(e.read32(0x0F80), 0xBBBBBBBBu);
  r = xfer(e, Cmd::armw, 0xFFFF, 0x0F80, le32(0xCCCCCCCC));
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(r.adp, 0);
  EXPECT_EQ(e.read32(0x0F80), 0xCCCCCCCCu);
  r = xfer(e, Cmd::armw, 0, 0x0F80, le32(0));
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(get_u32(r.data.data()), 0xCCCCCCCCu);
}

TEST(EcEsc, ReadOnlyWritesCountButDoNotChangeAndResetOnlyRegistersAreStored) {
  Esc e(EscConfig{}, nullptr);
  EXPECT_EQ(apwr(e, reg::kType, {0x99}), 1);
  EXPECT_EQ(e.read8(reg::kType), 0x11);
  EXPECT_EQ(apwr(e, reg::kAlStatus, le16(0x0008)), 1);
  EXPECT_EQ(e.read16(reg::kAlStatus), 0x0001);
  EXPECT_EQ(apwr(e, reg::kRxErrorCounter, std::vector<std::uint8_t>(14, 0)), 1);
  EXPECT_EQ(apwr(e, reg::kRxErrorCounter, {7}), 1);
  EXPECT_EQ(e.read8(reg::kRxErrorCounter), 7);
  EXPECT_EQ(apwr(e, reg::kDcSpeedCounterStart, le16(0x1000)), 1);
  EXPECT_EQ(e.read16(reg::kDcSpeedCounterStart), 0x1000);
  EXPECT_EQ(apwr(e, reg::kDcTimeDiffFilter, {0x0C}), 1);
  EXPECT_EQ(e.read8(reg::kDcTimeDiffFilter), 0x0C);
  EXPECT_EQ(apwr(e, reg::kDcActivation, {0}), 1);
  EXPECT_EQ(apwr(e, reg::kFmmu0, std::vector<std::uint8_t>(256, 0)), 1);
  EXPECT_EQ(apwr(e, reg::kSm0, std::vector<std::uint8_t>(128, 0)), 1);
}

TEST(EcEsc, AlTransitionsLegalIllegalAndAcknowledge) {
  App app;
  Esc e(EscConfig{}, &app);
  go(e, AlState::preop);
  EXPECT_EQ(e.al_state(), AlState::preop);
  EXPECT_EQ(u16(aprd(e, reg::kAlStatus, 2)), 0x0002);
  ASSERT_EQ(app.requests.size(), 1u);
  EXPECT_EQ(app.requests[0], std::make_pair(AlState::init, AlState::preop));

  go(e, AlState::op);  // PRE-OP → OP is not a transition
  EXPECT_EQ(e.al_state(), AlState::preop);
  EXPECT_TRUE(e.al_error());
  EXPECT_EQ(u16(aprd(e, reg::kAlStatus, 2)), 0x0012);
  EXPECT_EQ(u16(aprd(e, reg::kAlStatusCode, 2)), 0x0011);
  EXPECT_EQ(app.requests.size(), 1u);  // the firmware was not asked

  go(e, AlState::safeop);  // no acknowledge: ignored while the error is pending
  EXPECT_EQ(e.al_state(), AlState::preop);
  EXPECT_EQ(app.requests.size(), 1u);

  apwr(e, reg::kAlControl, le16(0x0002 | 0x0010));  // acknowledge, stay
  EXPECT_FALSE(e.al_error());
  EXPECT_EQ(u16(aprd(e, reg::kAlStatus, 2)), 0x0002);
  EXPECT_EQ(u16(aprd(e, reg::kAlStatusCode, 2)), 0x0000);

  apwr(e, reg::kAlControl, le16(0x0007));  // unknown state
  EXPECT_EQ(e.al_status_code(), AlStatusCode::unknown_state);
  EXPECT_EQ(u16(aprd(e, reg::kAlStatus, 2)), 0x0012);
  app.answer = AlStatusCode::invalid_sm_config;
  apwr(e, reg::kAlControl, le16(0x0014));  // acknowledge + SAFE-OP; the firmware refuses
  EXPECT_EQ(e.al_state(), AlState::preop);
  EXPECT_EQ(e.al_status_code(), AlStatusCode::invalid_sm_config);
  EXPECT_EQ(u16(aprd(e, reg::kAlStatusCode, 2)), 0x0017);
  app.answer = AlStatusCode::none;
  apwr(e, reg::kAlControl, le16(0x0014));
  EXPECT_EQ(e.al_state(), AlState::safeop);
  EXPECT_FALSE(e.al_error());
  EXPECT_EQ(app.requests.back(), std::make_pair(AlState::preop, AlState::safeop));
  go(e, AlState::op);
  EXPECT_EQ(u16(aprd(e, reg::kAlStatus, 2)), 0x0008);
  // An error pending does not block INIT, and INIT acknowledges it (the slave stack's "0xX1").
  e.set_al_error(AlState::safeop, AlStatusCode::synchronization_error);
  EXPECT_EQ(u16(aprd(e, reg::kAlStatus, 2)), 0x0014);
  EXPECT_EQ(u16(aprd(e, reg::kAlStatusCode, 2)), 0x001A);
  go(e, AlState::init);
  EXPECT_EQ(e.al_state(), AlState::init);
  EXPECT_FALSE(e.al_error());
  EXPECT_EQ(u16(aprd(e, reg::kAlStatus, 2)), 0x0001);
  EXPECT_EQ(u16(aprd(e, reg::kAlStatusCode, 2)), 0x0000);
}

TEST(EcEsc, EepromReadsThroughTheInterfaceRegisters) {
  EscConfig c;
  c.sii = {0x0C80, 0x6E00, 0x0000, 0x0000, 0x0007, 0x0000, 0x0000, 0x0010,
           0x0F1C, 0x0000, 0x0001, 0x0000, 0x0002, 0x0000, 0x0003, 0x0000};
  Esc e(c, nullptr);
  EXPECT_EQ(u16(aprd(e, reg::kEepromControl, 2)) & reg::kEepromRead8, reg::kEepromRead8);
  apwr(e, reg::kEepromAddress, le32(0x0008));
  apwr(e, reg::kEepromControl, le16(reg::kEepromCmdRead));
  const Reply r = aprd(e, reg::kEepromControl, 14);
  EXPECT_EQ(get_u16(r.data.data()) & (reg::kEepromBusy | reg::kEepromErrNack | reg::kEepromCmdMask), 0);
  EXPECT_EQ(get_u32(r.data.data() + 6), 0x00000F1Cu);   // vendor id
  EXPECT_EQ(get_u32(r.data.data() + 10), 0x00000001u);  // product code (8-byte read)
  // Reading past the end: 0xFFFF.
  apwr(e, reg::kEepromAddress, le32(0x000E));
  apwr(e, reg::kEepromControl, le16(reg::kEepromCmdRead));
  EXPECT_EQ(e.read64(reg::kEepromData), 0xFFFFFFFF00000003ull);
  // Write, then reload changes the alias register.
  apwr(e, reg::kEepromAddress, le32(0x0004));
  apwr(e, reg::kEepromData, le16(0x0042));
  apwr(e, reg::kEepromControl, le16(reg::kEepromCmdWrite | reg::kEepromWriteEnable));
  EXPECT_EQ(e.eeprom().word(4), 0x0042);
  EXPECT_EQ(e.alias(), 0x0007);
  apwr(e, reg::kEepromControl, le16(reg::kEepromCmdReload));
  EXPECT_EQ(e.alias(), 0x0042);
}

// Mailbox SMs: SM0 0x1000 (write), SM1 0x1080 (read), 128 bytes.
void setup_mailbox(Esc& e) {
  apwr(e, reg::kSm0, sm_bytes(0x1000, 128, 0x26, true));
  apwr(e, reg::kSm0 + 8, sm_bytes(0x1080, 128, 0x22, true));
}

TEST(EcEsc, MailboxFullAndEmptyRefusals) {
  App app;
  Esc e(EscConfig{}, &app);
  setup_mailbox(e);
  // Reading the empty read mailbox is refused.
  EXPECT_EQ(aprd(e, 0x1080, 128).wkc, 0);
  EXPECT_EQ(e.stats().refused, 1u);
  // A whole mailbox write reaches the firmware.
  std::vector<std::uint8_t> req(128, 0);
  req[0] = 10;
  req[5] = 0x13;
  EXPECT_EQ(apwr(e, 0x1000, req), 1);
  ASSERT_EQ(app.mailboxes.size(), 1u);
  EXPECT_EQ(app.mailboxes[0], req);
  // A write that stops short of the last byte makes it full; a further write is refused.
  EXPECT_EQ(apwr(e, 0x1000, std::vector<std::uint8_t>(64, 1)), 1);
  EXPECT_EQ(apwr(e, 0x1000 + 64, std::vector<std::uint8_t>(64, 2)), 1);
  EXPECT_EQ(app.mailboxes.size(), 2u);
  // Reading the write mailbox is refused.
  EXPECT_EQ(aprd(e, 0x1000, 4).wkc, 0);

  // The firmware answers; the master reads it once; the mailbox is empty again.
  const std::vector<std::uint8_t> reply{6, 0, 0, 0, 0, 0x23, 1, 2, 3, 4, 5, 6};
  EXPECT_TRUE(e.post_mailbox(reply));
  EXPECT_EQ(e.read8(reg::kSm0 + 8 + reg::kSmStatus) & 0x08, 0x08);
  EXPECT_FALSE(e.post_mailbox(reply));  // still full
  Reply r = aprd(e, 0x1080, 128);
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(std::vector<std::uint8_t>(r.data.begin(), r.data.begin() + 12), reply);
  EXPECT_EQ(e.read8(reg::kSm0 + 8 + reg::kSmStatus) & 0x08, 0x00);
  EXPECT_EQ(aprd(e, 0x1080, 128).wkc, 0);

  // Repeat: toggle 0x080E bit 1; the reply comes back and 0x080F bit 1 follows.
  apwr(e, reg::kSm0 + 8 + reg::kSmActivate, {0x03});
  EXPECT_EQ(e.read8(reg::kSm0 + 8 + reg::kSmPdiControl) & 0x02, 0x02);
  r = aprd(e, 0x1080, 128);
  EXPECT_EQ(r.wkc, 1);
  EXPECT_EQ(std::vector<std::uint8_t>(r.data.begin(), r.data.begin() + 12), reply);
  apwr(e, reg::kSm0 + 8 + reg::kSmActivate, {0x01});
  EXPECT_EQ(e.read8(reg::kSm0 + 8 + reg::kSmPdiControl) & 0x02, 0x00);
}

// ESC Technology Section I §8.6 (fig. 26): the repeat request brings back the data the master
// last read (A), even when the firmware has meanwhile posted the next reply (B) into SM1; B
// follows once A has been read again, so no reply is lost.
TEST(EcEsc, RepeatRequestBringsBackTheLostReplyAndTheNewerOneFollows) {
  App app;
  Esc e(EscConfig{}, &app);
  setup_mailbox(e);
  const std::vector<std::uint8_t> a{4, 0, 0, 0, 0, 0x13, 0xAA, 0xAA, 0xAA, 0xAA};
  const std::vector<std::uint8_t> b{4, 0, 0, 0, 0, 0x23, 0xBB, 0xBB, 0xBB, 0xBB};
  auto head = [](const Reply& r) { return std::vector<std::uint8_t>(r.data.begin(), r.data.begin() + 10); };
  ASSERT_TRUE(e.post_mailbox(a));
  ASSERT_EQ(aprd(e, 0x1080, 128).wkc, 1);  // read, but lost on the way back
  ASSERT_TRUE(e.post_mailbox(b));          // the firmware posts the next reply
  // SOEM's repeat: the status/activate word at 0x080D with 0x080E bit 1 toggled.
  const std::uint16_t sm1 = static_cast<std::uint16_t>(e.read16(reg::kSm0 + 8 + reg::kSmStatus) ^ 0x0200);
  apwr(e, reg::kSm0 + 8 + reg::kSmStatus, le16(sm1));
  EXPECT_EQ(e.read8(reg::kSm0 + 8 + reg::kSmPdiControl) & 0x02, 0x02);  // acknowledged
  Reply r = aprd(e, 0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(head(r), a);
  EXPECT_FALSE(e.post_mailbox(a));  // B is waiting: nothing may overtake it
  r = aprd(e, 0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(head(r), b);
  EXPECT_EQ(aprd(e, 0x1080, 128).wkc, 0);
  // A second repeat now brings back B, the last data read.
  apwr(e, reg::kSm0 + 8 + reg::kSmActivate, {0x01});
  r = aprd(e, 0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(head(r), b);
}

// ESC datasheet Section II (SyncManager registers): start address, length and control can be
// written only while the SM is disabled (+0x6 bit 0 = 0); the activate byte always.
TEST(EcEsc, SyncManagerAreaCannotBeMovedWhileEnabled) {
  App app;
  Esc e(EscConfig{}, &app);
  setup_mailbox(e);
  EXPECT_EQ(apwr(e, reg::kSm0 + 8, sm_bytes(0x1400, 64, 0x26, true)), 1);  // WKC as on an ESC
  EXPECT_EQ(e.sm(1).start, 0x1080);
  EXPECT_EQ(e.sm(1).length, 128);
  EXPECT_EQ(e.sm(1).control, 0x22);
  EXPECT_TRUE(e.sm(1).enabled);
  EXPECT_EQ(u16(aprd(e, reg::kSm0 + 8, 2)), 0x1080);
  // Disabling and re-addressing in one write: the bytes before the activate byte still meet an
  // enabled SM.
  apwr(e, reg::kSm0 + 8, sm_bytes(0x1400, 64, 0x22, false));
  EXPECT_FALSE(e.sm(1).enabled);
  EXPECT_EQ(e.sm(1).start, 0x1080);
  // Disabled, it takes a new area.
  apwr(e, reg::kSm0 + 8, sm_bytes(0x1400, 64, 0x22, true));
  EXPECT_TRUE(e.sm(1).enabled);
  EXPECT_EQ(e.sm(1).start, 0x1400);
  EXPECT_EQ(e.sm(1).length, 64);
}

TEST(EcEsc, EventsReachTheIrqFieldUnderTheMask) {
  App app;
  Esc e(EscConfig{}, &app);
  setup_mailbox(e);
  go(e, AlState::preop);
  // Mask 0: events pend in 0x0210 but the IRQ field stays 0.
  EXPECT_EQ(e.read16(reg::kEcatEventRequest) & reg::kEventAlStatus, reg::kEventAlStatus);
  std::array<std::uint8_t, 32> buf{};
  auto irq_of = [&](Cmd c, std::uint16_t ado) {
    PduBuilder b(buf);
    b.add(c, 0, 0, ado, 2);
    const std::size_t n = b.finish();
    PduView v;
    parse_pdu(std::span(buf.data(), n), v);
    e.process(v.datagrams[0], 0);
    return v.datagrams[0].irq();
  };
  EXPECT_EQ(irq_of(Cmd::aprd, 0x0000), 0);
  apwr(e, reg::kEcatEventMask, le16(0x00FF));
  EXPECT_EQ(irq_of(Cmd::aprd, 0x0000) & reg::kEventAlStatus, reg::kEventAlStatus);
  EXPECT_EQ(irq_of(Cmd::aprd, reg::kAlStatus), 0);  // reading AL status acknowledges
  EXPECT_EQ(irq_of(Cmd::aprd, 0x0000), 0);
  e.post_mailbox(std::vector<std::uint8_t>{1, 2});
  EXPECT_EQ(irq_of(Cmd::aprd, 0x0000), reg::kEventSm0 << 1);  // SM1 holds a reply
  aprd(e, 0x1080, 128);
  EXPECT_EQ(irq_of(Cmd::aprd, 0x0000), 0);
  e.set_port_link(1, true);
  EXPECT_EQ(irq_of(Cmd::aprd, 0x0000), reg::kEventDlStatus);
  EXPECT_EQ(irq_of(Cmd::aprd, reg::kDlStatus), 0);
}

// Process data: SM2 outputs 0x1100 (4 bytes, watchdog trigger), SM3 inputs 0x1200 (4 bytes),
// FMMU0 logical 0x10000 → 0x1100 write, FMMU1 logical 0x10004 → 0x1200 read.
void setup_pd(Esc& e) {
  setup_mailbox(e);
  apwr(e, reg::kSm0 + 16, sm_bytes(0x1100, 4, 0x64, true));
  apwr(e, reg::kSm0 + 24, sm_bytes(0x1200, 4, 0x20, true));
  apwr(e, reg::kFmmu0, fmmu_bytes(0x10000, 4, 0, 7, 0x1100, 0, 2));
  apwr(e, reg::kFmmu0 + 16, fmmu_bytes(0x10004, 4, 0, 7, 0x1200, 0, 1));
}

Reply lrw(Esc& e, std::uint32_t addr, std::vector<std::uint8_t> d, Cmd c = Cmd::lrw, SimTime t = 0) {
  return xfer(e, c, static_cast<std::uint16_t>(addr & 0xFFFF), static_cast<std::uint16_t>(addr >> 16), std::move(d), t);
}

TEST(EcEsc, ProcessDataCountsOnlyInSafeOpAndOp) {
  App app;
  Esc e(EscConfig{}, &app);
  setup_pd(e);
  go(e, AlState::preop);
  EXPECT_EQ(lrw(e, 0x10000, std::vector<std::uint8_t>(8, 1)).wkc, 0);  // PD SMs refused in PRE-OP
  go(e, AlState::safeop);
  ASSERT_TRUE(e.write_inputs(3, std::vector<std::uint8_t>{1, 2, 3, 4}));
  Reply r = lrw(e, 0x10000, {9, 8, 7, 6, 0, 0, 0, 0});
  EXPECT_EQ(r.wkc, 3);
  EXPECT_EQ(r.data, (std::vector<std::uint8_t>{9, 8, 7, 6, 1, 2, 3, 4}));
  ASSERT_EQ(app.outputs.size(), 1u);
  EXPECT_EQ(app.outputs[0], (std::vector<std::uint8_t>{9, 8, 7, 6}));
  EXPECT_EQ(std::vector<std::uint8_t>(e.outputs().begin(), e.outputs().end()), (std::vector<std::uint8_t>{9, 8, 7, 6}));
  EXPECT_EQ(lrw(e, 0x10000, std::vector<std::uint8_t>(8, 0), Cmd::lrd).wkc, 1);
  EXPECT_EQ(lrw(e, 0x10000, std::vector<std::uint8_t>(8, 0), Cmd::lwr).wkc, 1);
  // A datagram covering only part of the image: one FMMU.
  EXPECT_EQ(lrw(e, 0x10004, std::vector<std::uint8_t>(4, 0)).wkc, 1);
  // Outside the mapping: nothing.
  EXPECT_EQ(lrw(e, 0x20000, std::vector<std::uint8_t>(4, 0)).wkc, 0);
}

// Firmware that answers outputs with inputs at once (as a drive's PDI interrupt would).
class Echo : public App {
 public:
  Esc* esc = nullptr;
  void on_outputs(std::span<const std::uint8_t> o, SimTime t) override {
    App::on_outputs(o, t);
    std::vector<std::uint8_t> in(o.begin(), o.end());
    for (auto& b : in) b = static_cast<std::uint8_t>(b + 1);
    esc->write_inputs(in);
  }
};

TEST(EcEsc, OutputsAreAppliedBeforeInputsArePlacedInOneLrw) {
  Echo app;
  Esc e(EscConfig{}, &app);
  app.esc = &e;
  setup_pd(e);
  go(e, AlState::preop);
  go(e, AlState::safeop);
  const Reply r = lrw(e, 0x10000, {1, 2, 3, 4, 0, 0, 0, 0});
  EXPECT_EQ(r.wkc, 3);
  EXPECT_EQ(r.data, (std::vector<std::uint8_t>{1, 2, 3, 4, 2, 3, 4, 5}));
}

TEST(EcEsc, ThreeBufferReadsGiveTheLastCompleteBuffer) {
  Esc e(EscConfig{}, nullptr);
  setup_pd(e);
  go(e, AlState::preop);
  go(e, AlState::safeop);
  e.write_inputs(std::vector<std::uint8_t>{1, 1, 1, 1});
  // The master reads the first half: the buffer is locked.
  Reply r = xfer(e, Cmd::aprd, 0, 0x1200, {0, 0});
  EXPECT_EQ(r.data, (std::vector<std::uint8_t>{1, 1}));
  EXPECT_EQ(e.read8(reg::kSm0 + 24 + reg::kSmStatus) & 0x40, 0x40);
  // Meanwhile the firmware writes twice: the master still finishes the buffer it began.
  e.write_inputs(std::vector<std::uint8_t>{2, 2, 2, 2});
  e.write_inputs(std::vector<std::uint8_t>{3, 3, 3, 3});
  r = xfer(e, Cmd::aprd, 0, 0x1202, {0, 0});
  EXPECT_EQ(r.data, (std::vector<std::uint8_t>{1, 1}));
  // The next read gets the newest complete buffer.
  r = xfer(e, Cmd::aprd, 0, 0x1200, {0, 0, 0, 0});
  EXPECT_EQ(r.data, (std::vector<std::uint8_t>{3, 3, 3, 3}));
  // Outputs: an incomplete write does not replace the last complete buffer.
  xfer(e, Cmd::apwr, 0, 0x1100, {5, 5, 5, 5});
  xfer(e, Cmd::apwr, 0, 0x1100, {6, 6});
  EXPECT_EQ(std::vector<std::uint8_t>(e.outputs().begin(), e.outputs().end()), (std::vector<std::uint8_t>{5, 5, 5, 5}));
  xfer(e, Cmd::apwr, 0, 0x1102, {6, 6});
  EXPECT_EQ(std::vector<std::uint8_t>(e.outputs().begin(), e.outputs().end()), (std::vector<std::uint8_t>{6, 6, 6, 6}));
}

TEST(EcEsc, WatchdogTakesOpToSafeOpAndZeroesOutputs) {
  App app;
  Esc e(EscConfig{}, &app);
  setup_pd(e);
  apwr(e, reg::kWatchdogTimePd, le16(100));  // 100 × 100 µs = 10 ms
  go(e, AlState::preop);
  go(e, AlState::safeop);
  lrw(e, 0x10000, {1, 2, 3, 4, 0, 0, 0, 0}, Cmd::lrw, 0);
  go(e, AlState::op, 0);
  for (SimTime t = 1'000'000; t <= 20'000'000; t += 1'000'000) lrw(e, 0x10000, {1, 2, 3, 4, 0, 0, 0, 0}, Cmd::lrw, t);
  EXPECT_EQ(e.al_state(), AlState::op);
  EXPECT_EQ(e.next_event_time(), 30'000'001);  // the watchdog's deadline
  e.advance(29'000'000);  // 9 ms since the last write
  EXPECT_EQ(e.al_state(), AlState::op);
  EXPECT_EQ(e.read16(reg::kWatchdogStatusPd) & 1, 1);
  e.advance(30'100'000);
  EXPECT_EQ(e.al_state(), AlState::safeop);
  EXPECT_TRUE(e.al_error());
  EXPECT_EQ(e.al_status_code(), AlStatusCode::watchdog);
  EXPECT_EQ(e.read16(reg::kAlStatus), 0x0014);
  EXPECT_EQ(e.read16(reg::kWatchdogStatusPd) & 1, 0);
  EXPECT_EQ(std::vector<std::uint8_t>(e.outputs().begin(), e.outputs().end()), (std::vector<std::uint8_t>{0, 0, 0, 0}));
  EXPECT_EQ(e.next_event_time(), kNoEscEvent);
  // Acknowledged and back to OP, process data keeps it there.
  apwr(e, reg::kAlControl, le16(0x0014), 31'000'000);
  EXPECT_FALSE(e.al_error());
  go(e, AlState::op, 31'000'000);
  lrw(e, 0x10000, {1, 2, 3, 4, 0, 0, 0, 0}, Cmd::lrw, 35'000'000);
  e.advance(44'000'000);
  EXPECT_EQ(e.al_state(), AlState::op);
  EXPECT_EQ(e.read16(reg::kWatchdogStatusPd) & 1, 1);
}

// An SM configured over the register space (3 buffers 0x0128, 0x012C, 0x0130) is not activated:
// ECAT writes through its area are plain register writes, never redirected into AL status.
TEST(EcEsc, SmOverTheRegistersIsNotActivatedForEcatAccesses) {
  for (const bool logical : {false, true}) {
    App app;
    Esc e(EscConfig{}, &app);
    go(e, AlState::preop);
    go(e, AlState::safeop);
    ASSERT_EQ(e.read16(reg::kAlStatus), 0x0004);
    apwr(e, reg::kSm0 + 16, sm_bytes(0x0128, 4, 0x24, true));  // buffered, ECAT writes
    EXPECT_FALSE(e.sm(2).enabled) << logical;
    EXPECT_EQ(e.read16(reg::kSm0 + 16), 0x0128);  // the registers keep what the master wrote
    apwr(e, reg::kFmmu0, fmmu_bytes(0x30000, 4, 0, 7, 0x0128, 0, 2));
    for (int k = 0; k < 3; ++k) {
      if (logical) {
        lrw(e, 0x30000, {0xFF, 0xFF, 0xFF, 0xFF}, Cmd::lwr);
      } else {
        apwr(e, 0x0128, {0xFF, 0xFF, 0xFF, 0xFF});
      }
    }
    EXPECT_EQ(e.read16(reg::kAlStatus), 0x0004) << logical;
    EXPECT_EQ(e.read16(reg::kAlStatusCode), 0x0000) << logical;
    EXPECT_EQ(u16(aprd(e, reg::kAlStatus, 2)), 0x0004) << logical;
    EXPECT_EQ(e.read32(0x0128), 0xFFFFFFFFu) << logical;  // written in place
    EXPECT_EQ(e.read32(0x012C), 0u) << logical;
    EXPECT_EQ(e.al_state(), AlState::safeop);
  }
}

// The PDI cannot post inputs or a mailbox reply into an SM placed over the registers.
TEST(EcEsc, SmOverTheRegistersIsNotActivatedForThePdi) {
  App app;
  Esc e(EscConfig{}, &app);
  go(e, AlState::preop);
  go(e, AlState::safeop);
  apwr(e, reg::kSm0 + 24, sm_bytes(0x0130, 2, 0x20, true));  // buffered, ECAT reads: over AL status
  apwr(e, reg::kSm0 + 8, sm_bytes(0x0130, 6, 0x02, true));   // mailbox, ECAT reads: the same
  EXPECT_FALSE(e.sm(3).enabled);
  EXPECT_FALSE(e.sm(1).enabled);
  EXPECT_FALSE(e.write_inputs(3, std::vector<std::uint8_t>{0xFF, 0xFF}));
  e.write_inputs(std::vector<std::uint8_t>{0xFF, 0xFF});
  EXPECT_FALSE(e.post_mailbox(std::vector<std::uint8_t>{0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE}));
  EXPECT_EQ(e.read16(reg::kAlStatus), 0x0004);
  EXPECT_EQ(e.read16(reg::kAlStatusCode), 0x0000);
  EXPECT_EQ(e.al_state(), AlState::safeop);
  // Moved into process RAM, the same SMs work.
  apwr(e, reg::kSm0 + 24, sm_bytes(0x1200, 2, 0x20, true));
  EXPECT_TRUE(e.sm(3).enabled);
  EXPECT_TRUE(e.write_inputs(3, std::vector<std::uint8_t>{0x12, 0x34}));
}

// All three buffers (or the mailbox) must lie inside process RAM (8 KiB: up to 0x2FFF).
TEST(EcEsc, SmPastTheEndOfRamIsNotActivated) {
  Esc e(EscConfig{}, nullptr);
  apwr(e, reg::kSm0 + 16, sm_bytes(0x2FF0, 8, 0x64, true));  // buffers up to 0x3007
  EXPECT_FALSE(e.sm(2).enabled);
  apwr(e, reg::kSm0 + 16, sm_bytes(0x2FE8, 8, 0x64, true));  // up to 0x2FFF
  EXPECT_TRUE(e.sm(2).enabled);
  apwr(e, reg::kSm0, sm_bytes(0x2FF8, 8, 0x26, true));       // mailbox: one buffer, fits
  EXPECT_TRUE(e.sm(0).enabled);
  apwr(e, reg::kSm0, sm_bytes(0x2FF8, 8, 0x26, false));      // disabled first: an enabled SM keeps its area
  apwr(e, reg::kSm0, sm_bytes(0x0FF8, 16, 0x26, true));      // starts in the registers
  EXPECT_FALSE(e.sm(0).enabled);
}

// A long jump of time delivers at most kMaxSync0PerAdvance SYNC0 pulses; the rest are dropped
// and the schedule goes on from the first boundary after t.
TEST(EcEsc, Sync0PulsesPerAdvanceAreCapped) {
  App app;
  Esc e(EscConfig{}, &app);
  apwr(e, reg::kDcSync0Cycle, le32(10'000));  // 10 µs, the minimum
  apwr(e, reg::kDcActivation, {0x03});        // start time 0: pulses at 0, 10 µs, …
  ASSERT_EQ(e.read8(reg::kDcActivationStatus) & 1, 1);
  e.advance(1'000'000'000);  // 100001 pulses due
  EXPECT_EQ(app.sync0, kMaxSync0PerAdvance);
  EXPECT_EQ(e.stats().sync0_dropped, 100'001u - static_cast<std::uint64_t>(kMaxSync0PerAdvance));
  EXPECT_EQ(e.next_event_time(), 1'000'010'000);
  e.advance(1'000'020'000);
  EXPECT_EQ(app.sync0, kMaxSync0PerAdvance + 2);
}

// SYNC1 through the registers: activation bit 2, cycle 0x09A4 after each SYNC0 pulse; status
// bits in 0x0984 and 0x098F, the next SYNC1 time in 0x0998.
TEST(EcEsc, Sync1PulsesThroughTheRegisters) {
  App app;
  Esc e(EscConfig{}, &app);
  apwr(e, reg::kDcSync0Cycle, le32(1'000'000));
  apwr(e, reg::kDcSync1Cycle, le32(300'000));
  apwr(e, reg::kDcActivation, {0x07});
  EXPECT_EQ(e.read8(reg::kDcActivationStatus), 0x03);
  for (SimTime t = 100'000; t <= 2'400'000; t += 100'000) e.advance(t);
  EXPECT_EQ(app.sync0, 3);  // 0, 1, 2 ms
  EXPECT_EQ(app.sync1_at, (std::vector<SimTime>{300'000, 1'300'000, 2'300'000}));
  EXPECT_EQ(e.read8(reg::kDcSync1Status), 0x01);
}

TEST(EcEsc, UnknownCommandsAreCountedAndLeftAlone) {
  Esc e(EscConfig{}, nullptr);
  std::array<std::uint8_t, 32> buf{};
  PduBuilder b(buf);
  b.add(Cmd::aprd, 0, 0, 0, 2);
  const std::size_t n = b.finish();
  buf[2] = 0x2F;  // no such command
  PduView v;
  ASSERT_EQ(parse_pdu(std::span(buf.data(), n), v), PduError::ok);
  e.process(v.datagrams[0], 0);
  EXPECT_EQ(v.datagrams[0].wkc(), 0);
  EXPECT_EQ(v.datagrams[0].adp(), 0);
  EXPECT_EQ(e.stats().malformed, 1u);
  EXPECT_EQ(e.stats().datagrams, 1u);
  // NOP does nothing either.
  EXPECT_EQ(xfer(e, Cmd::nop, 0, 0, {0}).wkc, 0);
  // A register access running past the end of memory is cut, not a crash.
  EXPECT_EQ(xfer(e, Cmd::aprd, 0, 0xFFF0, std::vector<std::uint8_t>(64, 0)).wkc, 1);
}

TEST(EcEsc, RandomDatagramsAndWildConfigurationsStayInBounds) {
  // Random commands, addresses and data, biased towards the SM/FMMU/AL/DC registers so that
  // SyncManagers and FMMUs get wild areas (past the RAM, overlapping, 3-buffer past the end).
  App app;
  EscConfig c;
  c.ram_kib = 1;
  c.sii.assign(16, 0x1234);
  Esc e(c, &app);
  std::mt19937 rng(12345);
  const std::uint16_t hot[] = {0x0120, 0x0502, 0x0504, 0x0600, 0x0610, 0x0800, 0x0808, 0x0810, 0x0818,
                               0x0900, 0x0910, 0x0920, 0x0930, 0x0981, 0x0990, 0x09A0, 0x1000, 0x13F0, 0xFFF0};
  std::array<std::uint8_t, kMaxPdu> buf{};
  const int rounds = 20000;
  for (int k = 0; k < rounds; ++k) {
    const auto cmd = static_cast<std::uint8_t>(rng() % 18);
    const std::uint16_t ado = (rng() % 4 != 0) ? static_cast<std::uint16_t>(hot[rng() % std::size(hot)] + rng() % 16)
                                               : static_cast<std::uint16_t>(rng());
    const std::uint16_t adp = (rng() % 2 == 0) ? 0 : static_cast<std::uint16_t>(rng());
    const auto len = static_cast<std::uint16_t>(rng() % 300);
    std::vector<std::uint8_t> data(len);
    for (auto& b : data) b = static_cast<std::uint8_t>(rng());
    if (k % 50 == 0) {
      e.write_inputs(data);
      e.post_mailbox(data);
    }
    PduBuilder b(buf);
    ASSERT_GE(b.add(Cmd::nop, 0, adp, ado, len, data.data()), 0);
    const std::size_t n = b.finish();
    buf[2] = cmd;
    PduView v;
    ASSERT_EQ(parse_pdu(std::span(buf.data(), n), v), PduError::ok);
    e.process(v.datagrams[0], static_cast<SimTime>(k) * 1000);
    ASSERT_LE(v.datagrams[0].wkc(), 3);
  }
  e.advance(static_cast<SimTime>(rounds) * 1000 + 1'000'000'000);
  EXPECT_EQ(e.stats().datagrams, static_cast<std::uint64_t>(rounds));
  EXPECT_GT(e.stats().malformed, 0u);
  EXPECT_TRUE(al_state_valid(static_cast<std::uint8_t>(e.al_state())));
}

TEST(EcEsc, PowerCycleRestoresPowerOnState) {
  Esc e(EscConfig{}, nullptr);
  setup_pd(e);
  apwr(e, reg::kStationAddress, le16(0x1001));
  go(e, AlState::preop);
  e.power_cycle(5'000);
  EXPECT_EQ(e.station_address(), 0);
  EXPECT_EQ(e.al_state(), AlState::init);
  EXPECT_FALSE(e.sm(0).enabled);
  EXPECT_FALSE(e.fmmu(0).active);
  EXPECT_EQ(e.local_time(5'000), 0);
}

}  // namespace
}  // namespace omnitwin::ethercat
