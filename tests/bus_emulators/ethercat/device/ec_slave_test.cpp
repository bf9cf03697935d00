// Tests bus_emulators/ethercat/device/ec_slave: DriveSlave behind its ESC, driven only through
// datagrams as a master would send them — SII identity read over the EEPROM registers, INIT →
// PRE-OP → SAFE-OP → OP with SyncManager/FMMU configuration by register writes, the firmware's
// AL refusals (0x0016 mailbox SMs, 0x001D/0x001E process-data SM lengths), CoE SDO round trips
// (expedited, segmented, complete access, PDO mapping aborts) through the SM0/SM1 mailbox
// registers, process data via LRW reaching the axis' drive::Objects and coming back, and the
// seed-001 multi-axis slave's command/status modules (card address, handshake, servo enable);
// process data only through the ESI's Outputs/Inputs SMs even when the master configures another
// SM as a buffered one, and the refusal of SAFE-OP/OP with an invalid DC SYNC0 cycle (0x0030).
#include "bus_emulators/ethercat/device/ec_slave.hpp"

#include <gtest/gtest.h>

#include <array>
#include <string>
#include <vector>

#include "bus_emulators/ethercat/device/ec_sii.hpp"
#include "bus_emulators/ethercat/ec_frame.hpp"
#include "tests/bus_emulators/ethercat/ec_register_bytes.hpp"

namespace omnitwin::ethercat {
namespace {

using Bytes = std::vector<std::uint8_t>;
constexpr std::uint16_t kStation = 0x1001;
constexpr std::uint32_t kLogical = 0x00010000;

DeviceDescription load(const std::string& name) {
  return load_esi(std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/" + name).at(0);
}

// A minimal test master: one datagram per frame, straight into the slave's ESC.
class Master {
 public:
  explicit Master(DriveSlave& s) : slave_(s) {}
  struct Result {
    Bytes data;
    std::uint16_t wkc = 0;
  };
  Result exchange(Cmd cmd, std::uint16_t adp, std::uint16_t ado, const Bytes& data) {
    std::array<std::uint8_t, kMaxPdu> buf{};
    PduBuilder b(buf);
    const int off = b.add(cmd, 0x42, adp, ado, static_cast<std::uint16_t>(data.size()), data.data());
    EXPECT_GE(off, 0);
    const std::size_t n = b.finish();
    PduView v;
    EXPECT_EQ(parse_pdu(std::span<std::uint8_t>(buf.data(), n), v), PduError::ok);
    t += 100'000;
    slave_.esc().process(v.datagrams[0], t);
    Result r;
    r.data.assign(v.datagrams[0].data(), v.datagrams[0].data() + v.datagrams[0].length());
    r.wkc = v.datagrams[0].wkc();
    return r;
  }
  std::uint16_t fpwr(std::uint16_t ado, const Bytes& d) { return exchange(Cmd::fpwr, kStation, ado, d).wkc; }
  Result fprd(std::uint16_t ado, std::size_t n) { return exchange(Cmd::fprd, kStation, ado, Bytes(n, 0)); }
  std::uint16_t read16(std::uint16_t ado) {
    auto r = fprd(ado, 2);
    return get_u16(r.data.data());
  }
  Result lrw(const Bytes& d) {
    std::array<std::uint8_t, kMaxPdu> buf{};
    PduBuilder b(buf);
    b.add_logical(Cmd::lrw, 7, kLogical, static_cast<std::uint16_t>(d.size()), d.data());
    const std::size_t n = b.finish();
    PduView v;
    EXPECT_EQ(parse_pdu(std::span<std::uint8_t>(buf.data(), n), v), PduError::ok);
    t += 100'000;
    slave_.esc().process(v.datagrams[0], t);
    return {Bytes(v.datagrams[0].data(), v.datagrams[0].data() + v.datagrams[0].length()), v.datagrams[0].wkc()};
  }
  static Bytes sm(std::uint16_t start, std::uint16_t len, std::uint8_t control, bool enable) {
    return ec_test::sm_bytes(start, len, control, enable);
  }
  static Bytes fmmu(std::uint32_t logical, std::uint16_t len, std::uint16_t phys, std::uint8_t type) {
    return ec_test::fmmu_bytes(logical, len, phys, type);
  }
  // Writes AL control and returns AL status (state | 0x10 error).
  std::uint16_t request(std::uint16_t state) {
    fpwr(0x0120, {static_cast<std::uint8_t>(state), 0});
    return read16(0x0130);
  }
  void set_address() { exchange(Cmd::apwr, 0, 0x0010, {kStation & 0xFF, kStation >> 8}); }
  // A master resizing SM2/SM3 disables them first: an enabled SM keeps its start, length and
  // control (only its activate byte takes writes).
  void disable_pd_sms() {
    fpwr(0x0816, {0});
    fpwr(0x081E, {0});
  }
  void mailbox_sms(std::uint16_t mbx = 128) {
    fpwr(0x0800, sm(0x1000, mbx, 0x26, true));
    fpwr(0x0808, sm(0x1080, mbx, 0x22, true));
  }
  void pd_sms(std::uint16_t out_start, std::uint16_t out_len, std::uint16_t in_start, std::uint16_t in_len) {
    fpwr(0x0810, sm(out_start, out_len, 0x64, true));
    fpwr(0x0818, sm(in_start, in_len, 0x20, true));
    fpwr(0x0600, fmmu(kLogical, out_len, out_start, 2));
    fpwr(0x0610, fmmu(kLogical + out_len, in_len, in_start, 1));
  }
  // One mailbox request (SM0) and its reply (SM1), with the firmware cycle in between.
  Bytes mailbox(const Bytes& request, std::uint16_t mbx = 128) {
    Bytes m = request;
    m.resize(mbx, 0);
    EXPECT_EQ(fpwr(0x1000, m), 1);
    slave_.cycle(t);
    auto r = fprd(0x1080, mbx);
    EXPECT_EQ(r.wkc, 1) << "no reply in SM1";
    return r.data;
  }
  Bytes sdo(std::uint8_t cmd, std::uint16_t index, std::uint8_t sub, std::uint32_t d4 = 0, const Bytes& extra = {}) {
    Bytes m(16, 0);
    put_u16(m.data(), static_cast<std::uint16_t>(10 + extra.size()));
    counter_ = next_mailbox_counter(counter_);
    m[5] = static_cast<std::uint8_t>(3 | (counter_ << 4));
    put_u16(m.data() + 6, 0x2000);
    m[8] = cmd;
    put_u16(m.data() + 9, index);
    m[11] = sub;
    put_u32(m.data() + 12, d4);
    for (const std::uint8_t b : extra) m.push_back(b);
    return mailbox(m);
  }
  Bytes segment(std::uint8_t cmd) {
    Bytes m(16, 0);
    m[0] = 10;
    counter_ = next_mailbox_counter(counter_);
    m[5] = static_cast<std::uint8_t>(3 | (counter_ << 4));
    put_u16(m.data() + 6, 0x2000);
    m[8] = cmd;
    return mailbox(m);
  }
  // SOEM's repeat request after a lost SM1 read: 0x080D/0x080E written back with 0x080E bit 1
  // toggled.
  void repeat_request() {
    const auto st = static_cast<std::uint16_t>(read16(0x080D) ^ 0x0200);
    fpwr(0x080D, {static_cast<std::uint8_t>(st), static_cast<std::uint8_t>(st >> 8)});
  }
  std::uint32_t sdo_abort(std::uint8_t cmd, std::uint16_t index, std::uint8_t sub, std::uint32_t d4 = 0) {
    auto r = sdo(cmd, index, sub, d4);
    EXPECT_EQ(r[8], 0x80);
    return get_u32(r.data() + 12);
  }
  SimTime t = 0;

 private:
  DriveSlave& slave_;
  std::uint8_t counter_ = 0;
};

class EcSlave : public ::testing::Test {
 protected:
  EcSlave() : slave(load("omnitwin_drive.xml"), config()), m(slave) {}
  static DriveSlaveConfig config() {
    DriveSlaveConfig c;
    c.serial = 77;
    return c;
  }
  void to_preop() {
    m.set_address();
    m.mailbox_sms();
    ASSERT_EQ(m.request(2), 2);
  }
  void to_op() {
    to_preop();
    m.pd_sms(0x1100, 18, 0x1180, 24);
    ASSERT_EQ(m.request(4), 4);
    ASSERT_EQ(m.request(8), 8);
  }
  DriveSlave slave;
  Master m;
};

TEST_F(EcSlave, SiiIdentityOverEepromRegisters) {
  m.set_address();
  auto read_word_pair = [&](std::uint32_t word) {
    Bytes a(4, 0);
    put_u32(a.data(), word);
    m.fpwr(0x0504, a);
    m.fpwr(0x0502, {0x00, 0x01});  // read command
    auto r = m.fprd(0x0508, 4);
    return get_u32(r.data.data());
  };
  EXPECT_EQ(read_word_pair(sii::vendor_id), 0x00000F1Cu);
  EXPECT_EQ(read_word_pair(sii::product_code), 0x00000402u);
  EXPECT_EQ(read_word_pair(sii::serial), 77u);
  EXPECT_EQ(slave.esc().config().sii, build_sii(slave.description(), 0, 77));
  EXPECT_EQ(slave.app(), SlaveApp::cia402);
  EXPECT_EQ(slave.axes(), 1);
}

TEST_F(EcSlave, InitToOpWithRegisterWrites) {
  to_op();
  EXPECT_EQ(slave.esc().al_state(), AlState::op);
  EXPECT_EQ(slave.esc().sm(2).length, 18);
  EXPECT_EQ(slave.esc().sm(3).length, 24);
  EXPECT_TRUE(slave.esc().fmmu(0).active);
  EXPECT_EQ(slave.rx_layout().size(), 7u);
  EXPECT_EQ(slave.tx_layout().size(), 9u);
  EXPECT_EQ(slave.output_bytes(), 18u);
  EXPECT_EQ(slave.input_bytes(), 24u);
}

TEST_F(EcSlave, MailboxSmCheckedOnInitToPreop) {
  m.set_address();
  m.fpwr(0x0800, Master::sm(0x1000, 128, 0x26, true));
  m.fpwr(0x0808, Master::sm(0x1080, 128, 0x22, false));  // SM1 not enabled
  EXPECT_EQ(m.request(2), 0x11);                          // INIT + error
  EXPECT_EQ(m.read16(0x0134), 0x0016);
  EXPECT_EQ(slave.stats().al_refused, 1u);
  m.mailbox_sms();
  EXPECT_EQ(m.request(0x12), 2);  // acknowledged and retried
}

TEST_F(EcSlave, WrongSm2LengthRefusesSafeop) {
  to_preop();
  m.pd_sms(0x1100, 16, 0x1180, 24);  // RxPDO 0x1600 needs 18 bytes
  EXPECT_EQ(m.request(4), 0x12);
  EXPECT_EQ(m.read16(0x0134), 0x001D);
  m.disable_pd_sms();
  m.pd_sms(0x1100, 18, 0x1180, 20);
  EXPECT_EQ(m.request(0x14), 0x12);
  EXPECT_EQ(m.read16(0x0134), 0x001E);
  m.disable_pd_sms();
  m.pd_sms(0x1100, 18, 0x1180, 24);
  EXPECT_EQ(m.request(0x14), 4);
}

TEST_F(EcSlave, ProcessDataReachesTheDriveAndComesBack) {
  to_op();
  Bytes out(18 + 24, 0);
  put_u16(out.data(), 0x0006);                    // controlword
  put_u32(out.data() + 2, 123456);                // target position
  put_u32(out.data() + 6, static_cast<std::uint32_t>(-5678));  // target velocity
  put_u16(out.data() + 10, 250);                  // target torque
  out[12] = 9;                                    // mode CSV
  put_u32(out.data() + 14, 42);                   // velocity offset
  auto r = m.lrw(out);
  EXPECT_EQ(r.wkc, 3);
  slave.cycle(m.t);
  auto& o = slave.axis(0).objects();
  EXPECT_EQ(o.controlword, 0x0006);
  EXPECT_EQ(o.target_position, 123456);
  EXPECT_EQ(o.target_velocity, -5678);
  EXPECT_EQ(o.target_torque, 250);
  EXPECT_EQ(o.mode, 9);
  EXPECT_EQ(o.velocity_offset, 42);
  EXPECT_EQ(slave.stats().outputs_applied, 1u);

  // The drive steps (the twin's part), the firmware packs its objects into the inputs.
  for (int i = 0; i < 3; ++i) slave.axis(0).step(m.t + i * 1'000'000, drive::Feedback{});
  o.position_actual = 4242;
  o.following_error_actual = -7;
  slave.cycle(m.t);
  r = m.lrw(out);
  EXPECT_EQ(r.wkc, 3);
  const std::uint8_t* in = r.data.data() + 18;
  EXPECT_EQ(get_u16(in), o.statusword);
  EXPECT_EQ(drive::decode_statusword(get_u16(in)), drive::State::ready_to_switch_on);
  EXPECT_EQ(static_cast<std::int32_t>(get_u32(in + 2)), 4242);
  EXPECT_EQ(static_cast<std::int8_t>(in[12]), o.mode_display);
  EXPECT_EQ(static_cast<std::int32_t>(get_u32(in + 18)), -7);
}

TEST_F(EcSlave, SdoThroughMailboxRegisters) {
  to_preop();
  // Expedited upload of the identity's serial number, then a download and its effect.
  auto r = m.sdo(0x40, 0x1018, 4);
  EXPECT_EQ(r[8], 0x43);
  EXPECT_EQ(get_u32(r.data() + 12), 77u);
  r = m.sdo(0x2F, 0x6098, 0, 17);
  EXPECT_EQ(r[8], 0x60);
  EXPECT_EQ(slave.axis(0).objects().homing_method, 17);
  // Normal upload of the device name.
  r = m.sdo(0x40, 0x1008, 0);
  EXPECT_EQ(r[8], 0x41);
  EXPECT_EQ(std::string(r.begin() + 16, r.begin() + 16 + 21), "omnitwin drive 1-axis");
  // Complete access upload of the TxPDO mapping (9 entries): 2 + 36 bytes.
  r = m.sdo(0x50, 0x1A00, 0);
  EXPECT_EQ(r[8], 0x51);
  EXPECT_EQ(get_u32(r.data() + 12), 38u);
  EXPECT_EQ(get_u32(r.data() + 18), 0x60410010u);
  // Unsupported mode → value range; unknown object.
  EXPECT_EQ(m.sdo_abort(0x2F, 0x6060, 0, 2), 0x06090030u);
  EXPECT_EQ(m.sdo_abort(0x40, 0x6999, 0), 0x06020000u);
}

TEST_F(EcSlave, RepeatedMailboxWriteThroughTheEsc) {
  to_preop();
  Bytes req(128, 0);
  req[0] = 10;
  req[5] = 3 | (5 << 4);  // counter 5
  put_u16(req.data() + 6, 0x2000);
  req[8] = 0x2F;          // download 1 byte: homing method
  put_u16(req.data() + 9, 0x6098);
  req[12] = 21;
  ASSERT_EQ(m.fpwr(0x1000, req), 1);
  slave.axis(0).objects().homing_method = 3;  // changed locally after the first execution
  ASSERT_EQ(m.fpwr(0x1000, req), 1);          // the master repeats (it lost the WKC)
  slave.cycle(m.t);
  auto r = m.fprd(0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(r.data[8], 0x60);
  EXPECT_EQ(slave.axis(0).objects().homing_method, 3);  // not executed twice
  slave.cycle(m.t);
  EXPECT_EQ(m.fprd(0x1080, 128).wkc, 0);                 // no stale duplicate in SM1
  ASSERT_EQ(m.fpwr(0x1000, req), 1);                     // repeat after the reply was read: answered again
  slave.cycle(m.t);
  auto again = m.fprd(0x1080, 128);
  ASSERT_EQ(again.wkc, 1);
  EXPECT_EQ(Bytes(again.data.begin() + 6, again.data.begin() + 16), Bytes(r.data.begin() + 6, r.data.begin() + 16));
  EXPECT_EQ(slave.axis(0).objects().homing_method, 3);
  EXPECT_EQ(slave.coe().stats().repeats, 2u);
}

// ESC Technology Section I §8.6: a repeat request brings back the reply the master lost, even
// when the firmware has posted the next one (here the second fragment of an SDO information
// object list) into SM1 meanwhile; that one follows, nothing is lost.
TEST_F(EcSlave, RepeatRequestBringsBackALostFragmentBeforeTheNextOne) {
  to_preop();
  Bytes q(128, 0);  // SDO information: get object list, all objects
  put_u16(q.data(), 8);
  q[5] = 3 | (1 << 4);
  put_u16(q.data() + 6, 0x8000);
  q[8] = 0x01;
  put_u16(q.data() + 12, 1);
  ASSERT_EQ(m.fpwr(0x1000, q), 1);
  slave.cycle(m.t);
  const auto first = m.fprd(0x1080, 128);  // lost on its way back to the master
  ASSERT_EQ(first.wkc, 1);
  ASSERT_EQ(first.data[8], 0x82);          // object list response, more fragments follow
  const std::uint16_t left = get_u16(first.data.data() + 10);
  ASSERT_GE(left, 1);
  slave.cycle(m.t);                        // the firmware posts the next fragment
  m.repeat_request();
  const auto again = m.fprd(0x1080, 128);
  ASSERT_EQ(again.wkc, 1);
  EXPECT_EQ(again.data, first.data);
  slave.cycle(m.t);
  const auto next = m.fprd(0x1080, 128);
  ASSERT_EQ(next.wkc, 1);
  EXPECT_EQ(get_u16(next.data.data() + 10), left - 1);
}

// The same with an emergency queued behind a lost SDO reply: the reply comes back first, then
// the emergency.
TEST_F(EcSlave, RepeatRequestBringsBackALostSdoReplyBeforeAQueuedEmergency) {
  to_preop();
  const Bytes reply = m.sdo(0x40, 0x1018, 4);  // read, but lost on its way back
  ASSERT_EQ(reply[8], 0x43);
  slave.axis(0).objects().error_code = drive::kErrorFollowing;
  slave.cycle(m.t);                             // the emergency goes into SM1
  m.repeat_request();
  const auto again = m.fprd(0x1080, 128);
  ASSERT_EQ(again.wkc, 1);
  EXPECT_EQ(again.data, reply);
  const auto emcy = m.fprd(0x1080, 128);
  ASSERT_EQ(emcy.wkc, 1);
  EXPECT_EQ(get_u16(emcy.data.data() + 6) >> 12, 1);  // emergency service
  EXPECT_EQ(get_u16(emcy.data.data() + 8), drive::kErrorFollowing);
  EXPECT_EQ(m.fprd(0x1080, 128).wkc, 0);
}

// ETG.1000.6: the mailbox starts in PRE-OP. As SSC slaves do, the firmware keeps SM0/SM1
// deactivated (0x0807 bit 0) until INIT → PRE-OP passes, and again from every return to INIT:
// a master's mailbox accesses in INIT get WKC 0 and no SDO is served.
TEST_F(EcSlave, MailboxStaysClosedUntilPreopIsAccepted) {
  m.set_address();
  m.mailbox_sms();
  ASSERT_EQ(m.read16(0x0130), 1);
  Bytes req(128, 0);  // download 0x6060 = 8 (CSP)
  req[0] = 10;
  req[5] = 3 | (6 << 4);
  put_u16(req.data() + 6, 0x2000);
  req[8] = 0x2F;
  put_u16(req.data() + 9, 0x6060);
  req[12] = 8;
  const auto mode = slave.axis(0).objects().mode;
  ASSERT_NE(mode, 8);
  EXPECT_EQ(m.fprd(0x0807, 1).data[0] & 0x01, 0x01);
  EXPECT_EQ(m.fprd(0x080F, 1).data[0] & 0x01, 0x01);
  EXPECT_EQ(m.fpwr(0x1000, req), 0);
  slave.cycle(m.t);
  EXPECT_EQ(m.fprd(0x1080, 128).wkc, 0);
  EXPECT_EQ(slave.axis(0).objects().mode, mode);
  // PRE-OP opens the mailbox; a reply left unread in SM1 is dropped on the way back to INIT.
  ASSERT_EQ(m.request(2), 2);
  EXPECT_EQ(m.fprd(0x080F, 1).data[0] & 0x01, 0x00);
  ASSERT_EQ(m.fpwr(0x1000, req), 1);
  EXPECT_EQ(slave.axis(0).objects().mode, 8);
  ASSERT_EQ(m.request(1), 1);
  EXPECT_EQ(m.fprd(0x1080, 128).wkc, 0);
  EXPECT_EQ(m.fpwr(0x1000, req), 0);
  ASSERT_EQ(m.request(2), 2);
  EXPECT_EQ(m.fprd(0x1080, 128).wkc, 0);
  // After a power cycle the mailbox is closed again.
  slave.power_cycle(m.t);
  m.set_address();
  m.mailbox_sms();
  EXPECT_EQ(m.fpwr(0x1000, req), 0);
  ASSERT_EQ(m.request(2), 2);
  EXPECT_EQ(m.sdo(0x40, 0x1018, 4)[8], 0x43);
}

TEST_F(EcSlave, SegmentedUploadThroughSmallMailbox) {
  m.set_address();
  m.mailbox_sms(32);  // 32-byte mailboxes: the 21-byte name needs segments
  ASSERT_EQ(m.request(2), 2);
  Bytes req(16, 0);
  req[0] = 10;
  req[5] = 3 | (1 << 4);
  put_u16(req.data() + 6, 0x2000);
  req[8] = 0x40;
  put_u16(req.data() + 9, 0x1008);
  auto r = m.mailbox(req, 32);
  ASSERT_EQ(r[8], 0x41);
  EXPECT_EQ(get_u32(r.data() + 12), 21u);
  std::string name(r.begin() + 16, r.begin() + 6 + get_u16(r.data()));
  EXPECT_EQ(name.size(), 16u);
  Bytes seg(16, 0);
  seg[0] = 10;
  seg[5] = 3 | (2 << 4);
  put_u16(seg.data() + 6, 0x2000);
  seg[8] = 0x60;
  r = m.mailbox(seg, 32);
  EXPECT_EQ(r[8], 0x00 | (2 << 1) | 1);  // toggle 0, 2 unused bytes, last
  name.append(r.begin() + 9, r.begin() + 14);
  EXPECT_EQ(name, "omnitwin drive 1-axis");
}

TEST_F(EcSlave, PdoMappingRulesAndSizes) {
  to_preop();
  EXPECT_EQ(m.sdo_abort(0x23, 0x1600, 1, 0x60410010), 0x06010003u);  // sub 0 not 0
  ASSERT_EQ(m.sdo(0x2F, 0x1600, 0, 0)[8], 0x60);                      // disable the mapping
  EXPECT_EQ(m.sdo_abort(0x23, 0x1600, 1, 0x60650020), 0x06040041u);   // 0x6065 not mappable
  EXPECT_EQ(m.sdo_abort(0x23, 0x1600, 1, 0x60410010), 0x06040041u);   // statusword is a TxPDO object
  EXPECT_EQ(m.sdo_abort(0x23, 0x1600, 1, 0x70000010), 0x06020000u);   // no such object
  ASSERT_EQ(m.sdo(0x23, 0x1600, 1, 0x60400010)[8], 0x60);             // controlword
  ASSERT_EQ(m.sdo(0x23, 0x1600, 2, 0x60FF0020)[8], 0x60);             // target velocity
  ASSERT_EQ(m.sdo(0x2F, 0x1600, 0, 2)[8], 0x60);
  EXPECT_EQ(slave.output_bytes(), 6u);
  EXPECT_EQ(m.sdo_abort(0x2B, 0x1C12, 1, 0x1A00), 0x06010003u);        // assignment: sub 0 first
  ASSERT_EQ(m.sdo(0x2F, 0x1C12, 0, 0)[8], 0x60);
  EXPECT_EQ(m.sdo_abort(0x2B, 0x1C12, 1, 0x1A00), 0x06090030u);        // a TxPDO in the RxPDO list
  ASSERT_EQ(m.sdo(0x2B, 0x1C12, 1, 0x1600)[8], 0x60);
  ASSERT_EQ(m.sdo(0x2F, 0x1C12, 0, 1)[8], 0x60);
  m.pd_sms(0x1100, 18, 0x1180, 24);
  EXPECT_EQ(m.request(4), 0x12);  // SM2 still 18 bytes: refused
  EXPECT_EQ(m.read16(0x0134), 0x001D);
  m.disable_pd_sms();
  m.pd_sms(0x1100, 6, 0x1180, 24);
  EXPECT_EQ(m.request(0x14), 4);
  EXPECT_EQ(slave.rx_layout().size(), 2u);
  // SAFE-OP: the mapping is frozen.
  EXPECT_EQ(m.sdo_abort(0x2F, 0x1600, 0, 0), 0x08000022u);
  ASSERT_EQ(m.request(8), 8);
  Bytes out(6 + 24, 0);
  put_u16(out.data(), 0x0006);
  put_u32(out.data() + 2, 999);
  EXPECT_EQ(m.lrw(out).wkc, 3);
  slave.cycle(m.t);
  EXPECT_EQ(slave.axis(0).objects().target_velocity, 999);
}

TEST_F(EcSlave, LeavingOpDisablesTheDrive) {
  to_op();
  Bytes out(42, 0);
  put_u16(out.data(), 0x000F);
  m.lrw(out);
  slave.cycle(m.t);
  EXPECT_EQ(slave.axis(0).objects().controlword, 0x000F);
  ASSERT_EQ(m.request(4), 4);
  EXPECT_EQ(slave.axis(0).objects().controlword, 0x0000);
  slave.cycle(m.t);
  EXPECT_EQ(slave.axis(0).objects().controlword, 0x0000);  // outputs not applied in SAFE-OP
}

TEST_F(EcSlave, Sync0DrivesTheCycleWhenDcIsActive) {
  to_op();
  Bytes cyc(4, 0);
  put_u32(cyc.data(), 1'000'000);  // SYNC0 every 1 ms
  m.fpwr(0x09A0, cyc);
  Bytes start(8, 0);
  put_u64(start.data(), static_cast<std::uint64_t>(slave.esc().system_time(m.t) + 2'000'000));
  m.fpwr(0x0990, start);
  m.fpwr(0x0980, {0x00, 0x03});    // AssignActivate 0x0300: cyclic unit + SYNC0
  ASSERT_TRUE(slave.sync0_driven());
  Bytes out(42, 0);
  put_u16(out.data(), 0x0006);
  put_u32(out.data() + 6, 321);
  m.lrw(out);
  const auto cycles = slave.stats().cycles;
  slave.cycle(m.t);                // mailbox only: the process data wait for SYNC0
  EXPECT_EQ(slave.stats().cycles, cycles);
  EXPECT_EQ(slave.axis(0).objects().target_velocity, 0);
  slave.esc().advance(m.t + 3'500'000);
  EXPECT_GE(slave.stats().cycles, cycles + 1);
  EXPECT_EQ(slave.axis(0).objects().target_velocity, 321);
}

// The master configures SM1 as a buffered master-read SM (lower index than SM3) and SM0 as a
// buffered master-write SM: the firmware still exchanges process data through SM2/SM3 only.
TEST_F(EcSlave, ProcessDataOnlyThroughTheEsiSyncManagers) {
  to_preop();
  m.fpwr(0x0800, Master::sm(0x1400, 18, 0x64, true));  // SM0: buffered, master writes
  m.fpwr(0x0808, Master::sm(0x1500, 24, 0x20, true));  // SM1: buffered, master reads
  m.pd_sms(0x1100, 18, 0x1180, 24);
  ASSERT_EQ(m.request(4), 4);
  ASSERT_EQ(m.request(8), 8);
  auto& o = slave.axis(0).objects();
  o.position_actual = 4242;
  Bytes out(18 + 24, 0);
  put_u16(out.data(), 0x0006);
  put_u32(out.data() + 6, 321);  // target velocity
  m.lrw(out);
  slave.cycle(m.t);
  EXPECT_EQ(o.target_velocity, 321);  // from SM2, not from the never-written SM0
  EXPECT_EQ(slave.stats().outputs_applied, 1u);
  const auto r = m.lrw(out);
  EXPECT_EQ(r.wkc, 3);
  EXPECT_EQ(static_cast<std::int32_t>(get_u32(r.data.data() + 18 + 2)), 4242);  // inputs in SM3
  EXPECT_EQ(slave.esc().sm_unit(1).latest(), -1);  // nothing was posted into SM1
}

// SYNC0 activated with a 1 ns cycle: the ESC gives no pulses and the firmware refuses SAFE-OP
// with 0x0030 (invalid DC SYNC configuration); a valid cycle is then accepted.
TEST_F(EcSlave, InvalidSync0CycleRefusesSafeop) {
  to_preop();
  m.pd_sms(0x1100, 18, 0x1180, 24);
  Bytes cyc(4, 0);
  put_u32(cyc.data(), 1);
  m.fpwr(0x09A0, cyc);
  m.fpwr(0x0980, {0x00, 0x03});
  EXPECT_EQ(m.fprd(0x0984, 1).data[0] & 1, 0);  // SYNC0 not activated
  EXPECT_FALSE(slave.sync0_driven());
  const auto cycles = slave.stats().cycles;
  slave.esc().advance(m.t + 1'000'000);
  EXPECT_EQ(slave.stats().cycles, cycles);  // no pulses ran the firmware
  EXPECT_EQ(m.request(4), 0x12);
  EXPECT_EQ(m.read16(0x0134), 0x0030);
  put_u32(cyc.data(), 1'000'000);
  m.fpwr(0x09A0, cyc);
  EXPECT_EQ(m.fprd(0x0984, 1).data[0] & 1, 1);
  EXPECT_TRUE(slave.sync0_driven());
  EXPECT_EQ(m.request(0x14), 4);
}

TEST_F(EcSlave, WatchdogDropToSafeopDisablesTheDrive) {
  to_op();
  Bytes out(42, 0);
  put_u16(out.data(), 0x000F);
  m.lrw(out);
  slave.cycle(m.t);
  EXPECT_EQ(slave.axis(0).objects().controlword, 0x000F);
  slave.esc().advance(m.t + 500'000'000);  // no process data for 500 ms (watchdog 100 ms)
  EXPECT_EQ(slave.esc().al_state(), AlState::safeop);
  EXPECT_EQ(slave.esc().al_status_code(), AlStatusCode::watchdog);
  slave.cycle(m.t + 500'000'000);
  EXPECT_EQ(slave.axis(0).objects().controlword, 0x0000);
}

TEST_F(EcSlave, PowerCycleRestoresDefaults) {
  to_preop();
  ASSERT_EQ(m.sdo(0x2F, 0x1600, 0, 0)[8], 0x60);
  ASSERT_EQ(m.sdo(0x2F, 0x6098, 0, 1)[8], 0x60);
  EXPECT_EQ(slave.output_bytes(), 0u);
  slave.power_cycle(m.t);
  EXPECT_EQ(slave.esc().al_state(), AlState::init);
  EXPECT_EQ(slave.output_bytes(), 18u);
  EXPECT_EQ(slave.axis(0).objects().homing_method, 35);
  EXPECT_EQ(slave.od().entry(0x1018, 4)->as_int(), 77);
  to_op();
}

TEST_F(EcSlave, CycleHookRunsBetweenOutputsAndInputs) {
  to_op();
  std::vector<SimTime> calls;
  std::int32_t seen_target = 0;
  slave.set_cycle_hook([&](SimTime t) {
    calls.push_back(t);
    seen_target = slave.axis(0).objects().target_velocity;  // outputs already unpacked
    slave.axis(0).objects().position_actual = 777;         // packed right after
  });
  Bytes out(42, 0);
  put_u32(out.data() + 6, 55);
  m.lrw(out);
  slave.cycle(m.t);
  ASSERT_EQ(calls.size(), 1u);
  EXPECT_EQ(calls[0], m.t);
  EXPECT_EQ(seen_target, 55);
  auto r = m.lrw(out);
  EXPECT_EQ(static_cast<std::int32_t>(get_u32(r.data.data() + 18 + 2)), 777);
}

TEST_F(EcSlave, BootIsRefused) {
  m.set_address();
  EXPECT_EQ(m.request(3), 0x11);
  EXPECT_EQ(m.read16(0x0134), 0x0013);
}

// ---- seed 001 multi-axis slave -----------------------------------------------------------

class EcMultiAxis : public ::testing::Test {
 protected:
  EcMultiAxis() : slave(load("omnitwin_multiaxis.xml"), config()), m(slave) {}
  static DriveSlaveConfig config() {
    DriveSlaveConfig c;
    c.axes = 2;
    return c;
  }
  void to_op() {
    m.set_address();
    m.mailbox_sms();
    ASSERT_EQ(m.request(2), 2);
    m.pd_sms(0x1100, 24, 0x1200, 24);
    ASSERT_EQ(m.request(4), 4);
    ASSERT_EQ(m.request(8), 8);
  }
  // One bus cycle: LRW with the command modules, firmware, drive step.
  Bytes cycle(const Bytes& commands) {
    Bytes d = commands;
    d.resize(48, 0);
    auto r = m.lrw(d);
    EXPECT_EQ(r.wkc, 3);
    slave.cycle(m.t);
    for (int a = 0; a < slave.axes(); ++a) slave.axis(a).step(m.t, drive::Feedback{});
    m.t += 1'000'000;
    return Bytes(r.data.begin() + 24, r.data.end());
  }
  static void module(Bytes& cmds, int slot, std::uint16_t header, std::uint16_t control, std::int32_t v1, std::int32_t v2 = 0) {
    cmds.resize(48, 0);
    put_u16(cmds.data() + 12 * slot, header);
    put_u16(cmds.data() + 12 * slot + 2, control);
    put_u32(cmds.data() + 12 * slot + 4, static_cast<std::uint32_t>(v1));
    put_u32(cmds.data() + 12 * slot + 8, static_cast<std::uint32_t>(v2));
  }
  DriveSlave slave;
  Master m;
};

TEST_F(EcMultiAxis, LayoutFollowsFittedCards) {
  EXPECT_EQ(slave.app(), SlaveApp::multiaxis);
  EXPECT_EQ(slave.axes(), 2);
  EXPECT_EQ(slave.output_bytes(), 24u);  // two 12-byte command modules
  EXPECT_EQ(slave.input_bytes(), 24u);
  // The SII assigns only the fitted cards' PDOs.
  const auto& w = slave.esc().config().sii;
  std::size_t at = sii::first_category;
  int assigned = 0;
  while (w[at] != sii::cat_end) {
    if (w[at] == sii::cat_rxpdo) {
      for (std::size_t p = at + 2; p < at + 2 + w[at + 1]; p += 4 + 4 * (w[p + 1] & 0xFF))
        if ((w[p + 1] >> 8) == 2) ++assigned;
    }
    at += 2 + w[at + 1];
  }
  EXPECT_EQ(assigned, 2);
  DriveSlaveConfig bad;
  bad.axes = 9;
  EXPECT_THROW(DriveSlave(load("omnitwin_multiaxis.xml"), bad), EsiError);
}

TEST_F(EcMultiAxis, ModeHandshakeServoEnableAndStatus) {
  to_op();
  // Card 1: position mode requested with the handshake bit, servo enabled.
  Bytes cmds;
  module(cmds, 0, 0x0001 | (1 << 8) | 0x8000, 0x0001, 0);
  module(cmds, 1, 0x0002, 0x0000, 0);
  Bytes st(24, 0);
  for (int i = 0; i < 100 && (get_u16(st.data() + 2) & 0x0001) == 0; ++i) st = cycle(cmds);
  st = cycle(cmds);
  const std::uint16_t h0 = get_u16(st.data()), s0 = get_u16(st.data() + 2);
  EXPECT_EQ(h0 & 0xFF, 1);           // card address
  EXPECT_EQ((h0 >> 8) & 0x7F, 1);    // position mode active
  EXPECT_EQ(h0 & 0x8000, 0x8000);    // handshake echoed
  EXPECT_EQ(s0 & 0x0001, 0x0001);    // servo enabled
  EXPECT_EQ(s0 & 0x0002, 0);         // no alarm
  EXPECT_EQ(slave.axis(0).state(), drive::State::operation_enabled);
  EXPECT_EQ(slave.axis(0).objects().mode_display, 8);  // CSP
  const std::uint16_t h1 = get_u16(st.data() + 12), s1 = get_u16(st.data() + 14);
  EXPECT_EQ(h1 & 0xFF, 2);
  EXPECT_EQ(s1 & 0x0001, 0);         // card 2 not enabled
  EXPECT_NE(slave.axis(1).state(), drive::State::operation_enabled);
  // Position command reaches the drive; actual position and following error come back.
  module(cmds, 0, 0x0001 | (1 << 8) | 0x8000, 0x0001, 50, 0);
  st = cycle(cmds);
  EXPECT_EQ(slave.axis(0).objects().target_position, 50);
  slave.axis(0).objects().position_actual = 48;
  slave.axis(0).objects().following_error_actual = 2;
  slave.cycle(m.t);
  auto r = m.lrw(Bytes(48, 0));
  EXPECT_EQ(static_cast<std::int32_t>(get_u32(r.data.data() + 24 + 4)), 48);
  EXPECT_EQ(static_cast<std::int32_t>(get_u32(r.data.data() + 24 + 8)), 2);
}

TEST_F(EcMultiAxis, HomingModeHomesTheCard) {
  to_op();
  Bytes cmds;
  module(cmds, 1, 0x0002 | (3 << 8) | 0x8000, 0x0001, 0);  // slot 1 → card 2, homing, enable
  Bytes st(24, 0);
  for (int i = 0; i < 200 && (get_u16(st.data() + 14) & 0x0010) == 0; ++i) st = cycle(cmds);
  EXPECT_EQ((get_u16(st.data() + 12) >> 8) & 0x7F, 3);
  EXPECT_TRUE(slave.axis(1).homed());
  EXPECT_EQ(get_u16(st.data() + 14) & 0x0010, 0x0010);  // homing done
  EXPECT_FALSE(slave.axis(0).homed());
}

TEST_F(EcMultiAxis, AlarmResetClearsAFault) {
  to_op();
  Bytes cmds;
  module(cmds, 0, 0x0001, 0x0001, 0);
  for (int i = 0; i < 5; ++i) cycle(cmds);
  slave.axis(0).raise_fault();
  // The drive's fault reaction takes its own number of periods; the status lags by one cycle.
  Bytes st(24, 0);
  for (int i = 0; i < 50 && !(get_u16(st.data() + 2) & 0x0002); ++i) st = cycle(cmds);
  EXPECT_EQ(get_u16(st.data() + 2) & 0x0002, 0x0002);  // alarm
  EXPECT_EQ(get_u16(st.data() + 2) & 0x0001, 0);       // not enabled
  module(cmds, 0, 0x0001, 0x0001 | 0x0002, 0);          // reset (rising edge) with enable
  for (int i = 0; i < 50 && !(get_u16(st.data() + 2) & 0x0001); ++i) st = cycle(cmds);
  EXPECT_EQ(get_u16(st.data() + 2) & 0x0002, 0);
  EXPECT_EQ(get_u16(st.data() + 2) & 0x0001, 0x0001);    // enabled again
  EXPECT_EQ(slave.axis(0).state(), drive::State::operation_enabled);
}

TEST_F(EcMultiAxis, WrongCardAddressIsReported) {
  to_op();
  Bytes cmds;
  module(cmds, 0, 0x0007, 0x0001, 0);  // card 7 is not fitted
  auto st = cycle(cmds);
  st = cycle(cmds);
  EXPECT_EQ(get_u16(st.data() + 2) & 0x0040, 0x0040);
  EXPECT_EQ(get_u16(st.data()) & 0xFF, 1);
  EXPECT_GE(slave.stats().address_errors, 1u);
  EXPECT_NE(slave.axis(0).state(), drive::State::operation_enabled);
}

TEST_F(EcMultiAxis, ParametersBoundToTheAxis) {
  m.set_address();
  m.mailbox_sms();
  ASSERT_EQ(m.request(2), 2);
  EXPECT_EQ(m.sdo(0x2F, 0x8010, 1, 34)[8], 0x60);  // card 2 homing method
  EXPECT_EQ(slave.axis(1).objects().homing_method, 34);
  EXPECT_EQ(m.sdo_abort(0x2F, 0x1600, 0, 0), 0x06010002u);  // fixed mapping
}

// Issue 20: the objects a CiA 402 master writes or reads before OP. 0x60C2 (interpolation time
// period) takes the CSP/CSV period in PRE-OP; its index must be a power of ten from µs to s.
TEST_F(EcSlave, InterpolationTimePeriodIsWritableBeforeOp) {
  to_preop();
  auto up = [&](std::uint8_t sub) { return m.sdo(0x40, 0x60C2, sub)[12]; };
  EXPECT_EQ(up(0), 2);
  EXPECT_EQ(up(1), 1);
  EXPECT_EQ(static_cast<std::int8_t>(up(2)), -3);  // 1 ms
  EXPECT_EQ(m.sdo(0x2F, 0x60C2, 1, 2)[8], 0x60);   // 2 × 10^-3 s
  EXPECT_EQ(m.sdo(0x2F, 0x60C2, 2, 0xFD)[8], 0x60);
  EXPECT_EQ(up(1), 2);
  EXPECT_EQ(m.sdo_abort(0x2F, 0x60C2, 2, 0xF9), 0x06090030u);  // 10^-7 s: out of range
  EXPECT_EQ(static_cast<std::int8_t>(up(2)), -3);
}

// 0x608F/0x6091/0x6092 tell a master the counts per revolution and the gear: position units
// are motor counts, so 0x608F · 0x6091 / 0x6092 = 1. They are read-only.
TEST(EcSlaveFactors, EncoderResolutionGearAndFeedFollowTheDriveConfiguration) {
  DriveSlaveConfig c;
  c.drive.counts_per_rev = 4096;
  c.drive.gear_ratio = 2.5;
  DriveSlave slave(load("omnitwin_drive.xml"), c);
  auto v = [&](std::uint16_t i, std::uint8_t s) { return slave.od().entry(i, s)->as_int(); };
  EXPECT_EQ(v(0x608F, 1), 4096);
  EXPECT_EQ(v(0x608F, 2), 1);
  EXPECT_EQ(v(0x6091, 1), 5);
  EXPECT_EQ(v(0x6091, 2), 2);
  EXPECT_EQ(v(0x6092, 1), 4096 * 5);
  EXPECT_EQ(v(0x6092, 2), 2);
  const std::array<std::uint8_t, 4> d{1, 0, 0, 0};
  EXPECT_EQ(slave.od().write(0x6091, 1, OdState::preop, d), SdoAbort::read_only);
  slave.power_cycle(0);
  EXPECT_EQ(v(0x6091, 1), 5);  // still the configuration's, not the ESI default
}

// 0x1C32/0x1C33 (ETG.1020): free run until SYNC0 is activated, then DC SYNC0 with the SYNC0
// cycle; SM-synchronous mode is refused; a DC mode written without SYNC0 refuses SAFE-OP
// (0x0030); in OP each SYNC0 pulse without a new output buffer counts as an SM event missed,
// and "get cycle time" = 2 clears the counters.
TEST_F(EcSlave, SmSynchronisationParametersFollowTheDcModel) {
  to_preop();
  auto up16 = [&](std::uint16_t i, std::uint8_t s) { return get_u16(m.sdo(0x40, i, s).data() + 12); };
  auto up32 = [&](std::uint16_t i, std::uint8_t s) { return get_u32(m.sdo(0x40, i, s).data() + 12); };
  EXPECT_EQ(up16(0x1C32, 1), 0);       // free run
  EXPECT_EQ(up16(0x1C32, 4), 0x0005);  // free run and DC SYNC0 supported
  EXPECT_EQ(up32(0x1C32, 5), DcClock::kMinSyncCycleNs);
  EXPECT_EQ(m.sdo_abort(0x2B, 0x1C32, 1, 1), 0x06090030u);  // SM-synchronous: not supported
  EXPECT_EQ(m.sdo(0x2B, 0x1C32, 1, 2)[8], 0x60);
  EXPECT_EQ(m.sdo(0x2B, 0x1C33, 1, 2)[8], 0x60);
  m.pd_sms(0x1100, 18, 0x1180, 24);
  EXPECT_EQ(m.request(4), 0x12);  // DC mode written, SYNC0 not active
  EXPECT_EQ(m.read16(0x0134), 0x0030);
  Bytes cyc(4, 0);
  put_u32(cyc.data(), 1'000'000);
  m.fpwr(0x09A0, cyc);
  m.fpwr(0x0980, {0x00, 0x03});
  ASSERT_TRUE(slave.sync0_driven());
  EXPECT_EQ(m.request(0x14), 4);
  ASSERT_EQ(m.request(8), 8);
  // OP: one output buffer per 1 ms SYNC0 pulse, then three pulses without one.
  const SimTime t0 = m.t;
  Bytes out(42, 0);
  for (int k = 1; k <= 5; ++k) {
    m.lrw(out);
    slave.esc().advance(t0 + k * 1'000'000 + 500'000);
    m.t = t0 + k * 1'000'000 + 500'000;
  }
  const auto missed_before = slave.sync_params(true).sm_missed;
  EXPECT_EQ(missed_before, 0);
  slave.esc().advance(m.t + 3'000'000);
  m.t += 3'000'000;
  EXPECT_EQ(slave.sync_params(true).sm_missed, missed_before + 3);
  EXPECT_EQ(slave.sync_params(true).sync_error, 1);
  EXPECT_EQ(slave.sync_params(false).sm_missed, missed_before + 3);
  // Over SDO (each mailbox exchange here takes 100 µs of bus time, so a pulse may pass).
  EXPECT_EQ(up16(0x1C32, 1), 2);
  EXPECT_EQ(up32(0x1C32, 2), 1'000'000u);
  EXPECT_EQ(up32(0x1C32, 10), 1'000'000u);
  EXPECT_GE(up16(0x1C33, 11), missed_before + 3);
  EXPECT_EQ(m.sdo(0x2B, 0x1C32, 8, 2)[8], 0x60);  // clear the counters (both objects)
  EXPECT_LE(slave.sync_params(true).sm_missed, 1);
  EXPECT_LE(slave.sync_params(false).sm_missed, 1);
  EXPECT_EQ(slave.sync_params(true).get_cycle, 0);
}

// Issue 20: a following-error fault sends exactly one CoE emergency 0x8611 through SM1 (error
// register generic + device profile, axis 1), and the fault reset one "error reset" 0x0000.
TEST_F(EcSlave, FollowingErrorSendsOneEmergencyAndTheResetClearsIt) {
  to_op();
  Bytes out(42, 0);
  m.lrw(out);
  slave.cycle(m.t);
  EXPECT_EQ(m.fprd(0x1080, 128).wkc, 0);  // nothing in SM1
  for (int k = 1; k <= 5; ++k) slave.axis(0).step(m.t - 10'000'000 + k * 1'000'000, {});  // power-up
  slave.axis(0).raise_fault(drive::kErrorFollowing);
  for (int k = 1; k <= 20; ++k) slave.axis(0).step(m.t + k * 1'000'000, {});  // fault reaction → fault
  ASSERT_EQ(slave.axis(0).objects().error_code, drive::kErrorFollowing);
  ASSERT_EQ(slave.axis(0).state(), drive::State::fault);
  for (int k = 0; k < 3; ++k) slave.cycle(m.t + k);  // the code is signalled once, not per cycle
  auto r = m.fprd(0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(get_u16(r.data.data()), 10);              // mailbox length
  EXPECT_EQ(r.data[5] & 0x0F, 3);                     // CoE
  EXPECT_EQ(get_u16(r.data.data() + 6) >> 12, 1);     // emergency service
  EXPECT_EQ(get_u16(r.data.data() + 8), 0x8611);
  EXPECT_EQ(r.data[10], 0x21);                        // generic | device profile
  EXPECT_EQ(r.data[11], 1);                           // axis 1
  EXPECT_EQ(slave.od().entry(0x1001, 0)->as_int(), 0x21);
  slave.cycle(m.t + 10);
  EXPECT_EQ(m.fprd(0x1080, 128).wkc, 0) << "exactly one emergency";
  // Fault reset through the process data (controlword bit 7).
  put_u16(out.data(), 0x0080);
  m.lrw(out);
  slave.cycle(m.t);
  slave.axis(0).step(m.t + 30'000'000, {});
  ASSERT_EQ(slave.axis(0).objects().error_code, 0);
  slave.cycle(m.t + 1);
  r = m.fprd(0x1080, 128);
  ASSERT_EQ(r.wkc, 1);
  EXPECT_EQ(get_u16(r.data.data() + 6) >> 12, 1);
  EXPECT_EQ(get_u16(r.data.data() + 8), 0x0000);
  EXPECT_EQ(r.data[10], 0x00);
  EXPECT_EQ(slave.od().entry(0x1001, 0)->as_int(), 0);
  EXPECT_EQ(slave.stats().emergencies, 2u);
  EXPECT_EQ(slave.coe().stats().emergencies, 2u);
}

}  // namespace
}  // namespace omnitwin::ethercat
