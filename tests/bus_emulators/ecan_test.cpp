// Tests bus_emulators/can/ecan: F2812 eCAN mailbox matching with and without local acceptance
// masks (AME, LAM, LAMI, IDE), the receive priority from mailbox 31 down, overwrite with RML
// when OPC is clear, fall-through and loss when OPC is set, RMP/RML clearing, the per-mailbox
// interrupt callback, and remote frames against transmit mailboxes (AAM).
#include "bus_emulators/can/ecan.hpp"

#include <gtest/gtest.h>

#include <stdexcept>
#include <utility>
#include <vector>

namespace omnitwin::can {
namespace {

using Boxes = std::array<EcanMailboxConfig, Ecan::kMailboxes>;

Boxes boxes(std::initializer_list<std::pair<int, EcanMailboxConfig>> set) {
  Boxes b{};
  for (const auto& [n, cfg] : set) b[static_cast<std::size_t>(n)] = cfg;
  return b;
}

TEST(EcanMatch, WithoutMaskIdentifierAndFormatMustBeEqual) {
  Ecan ecan(boxes({{5, ecan_rx_mailbox(0x202)}}));
  EXPECT_EQ(ecan.receive(make_data(0x203, {1})).status, Ecan::RxStatus::no_match);
  EXPECT_EQ(ecan.receive(make_data(0x202, {1}, true)).status, Ecan::RxStatus::no_match);
  const auto r = ecan.receive(make_data(0x202, {4, 0, 0, 0, 0, 7}), 123);
  EXPECT_EQ(r.status, Ecan::RxStatus::stored);
  EXPECT_EQ(r.mailbox, 5);
  EXPECT_EQ(ecan.rmp(), 1u << 5);
  EXPECT_EQ(ecan.read(5).frame, make_data(0x202, {4, 0, 0, 0, 0, 7}));
  EXPECT_EQ(ecan.read(5).rx_time_ns, 123u);
  EXPECT_EQ(ecan.stats().stored, 1u);
  EXPECT_EQ(ecan.stats().unmatched, 2u);
}

TEST(EcanMatch, ExtendedMailboxComparesAll29Bits) {
  Ecan ecan(boxes({{0, ecan_rx_mailbox(0x1ABCDEF0, true)}}));
  for (int b = 0; b < 29; ++b)
    EXPECT_EQ(ecan.receive(make_data(0x1ABCDEF0 ^ (1u << b), {}, true)).status,
              Ecan::RxStatus::no_match) << b;
  EXPECT_EQ(ecan.receive(make_data(0x1ABCDEF0, {}, true)).status, Ecan::RxStatus::stored);
}

TEST(EcanMatch, LocalAcceptanceMaskMakesBitsDontCareAndStoresTheReceivedId) {
  // Speed feedback 0x2xx addressed to anyone: ID 0x200, low 8 bits don't care.
  Ecan ecan(boxes({{10, ecan_rx_mailbox(0x200, false, 0x0FF)}}));
  EXPECT_TRUE(ecan.mailbox(10).ame);
  EXPECT_EQ(ecan.mailbox(10).lam, 0x0FFu << 18);
  EXPECT_EQ(ecan.receive(make_data(0x302, {})).status, Ecan::RxStatus::no_match);
  EXPECT_EQ(ecan.receive(make_data(0x202, {4})).status, Ecan::RxStatus::stored);
  EXPECT_EQ(ecan.read(10).frame.id, 0x202u);  // the received identifier, not MSGID's
  ecan.clear_rmp(10);
  EXPECT_EQ(ecan.receive(make_data(0x2FF, {8})).status, Ecan::RxStatus::stored);
  EXPECT_EQ(ecan.read(10).frame.id, 0x2FFu);
}

TEST(EcanMatch, MaskIgnoredWithoutAme) {
  EcanMailboxConfig m = ecan_rx_mailbox(0x200);
  m.lam = ecan_lam_standard(0x7FF);  // would accept anything, but AME is clear
  Ecan ecan(boxes({{1, m}}));
  EXPECT_EQ(ecan.receive(make_data(0x201, {})).status, Ecan::RxStatus::no_match);
  EXPECT_EQ(ecan.receive(make_data(0x200, {})).status, Ecan::RxStatus::stored);
}

TEST(EcanMatch, LamiAcceptsBothFormatsComparingBits28To18ForStandardFrames) {
  // Extended mailbox whose bits 28..18 hold standard ID 0x202; only those bits compared for
  // standard frames; all 29 for extended ones.
  EcanMailboxConfig m;
  m.enabled = true;
  m.direction = EcanDirection::receive;
  m.id = 0x202u << 18 | 0x155;
  m.extended = true;
  m.ame = true;
  m.lam = 0;
  m.lami = true;
  Ecan both(boxes({{7, m}}));
  EXPECT_EQ(both.receive(make_data(0x202, {})).status, Ecan::RxStatus::stored);
  both.clear_rmp(7);
  EXPECT_EQ(both.receive(make_data(0x203, {})).status, Ecan::RxStatus::no_match);
  EXPECT_EQ(both.receive(make_data(0x202u << 18, {}, true)).status, Ecan::RxStatus::no_match);
  EXPECT_EQ(both.receive(make_data(0x202u << 18 | 0x155, {}, true)).status,
            Ecan::RxStatus::stored);

  m.lami = false;  // now IDE must match: standard frames rejected
  Ecan ext_only(boxes({{7, m}}));
  EXPECT_EQ(ext_only.receive(make_data(0x202, {})).status, Ecan::RxStatus::no_match);
  EXPECT_EQ(ext_only.receive(make_data(0x202u << 18 | 0x155, {}, true)).status,
            Ecan::RxStatus::stored);
}

TEST(EcanMatch, DisabledMailboxesTakeNothing) {
  EcanMailboxConfig m = ecan_rx_mailbox(0x102);
  m.enabled = false;
  Ecan ecan(boxes({{31, m}, {2, ecan_rx_mailbox(0x102)}}));
  EXPECT_EQ(ecan.receive(make_data(0x102, {2})).mailbox, 2);
}

TEST(EcanPriority, HighestNumberedMatchingMailboxWins) {
  Ecan ecan(boxes({{3, ecan_rx_mailbox(0x102)},
                   {20, ecan_rx_mailbox(0x100, false, 0x0FF)},
                   {12, ecan_rx_mailbox(0x102)}}));
  const auto r = ecan.receive(make_data(0x102, {2, 0, 0, 0, 0}));
  EXPECT_EQ(r.mailbox, 20);
  EXPECT_EQ(ecan.rmp(), 1u << 20);
}

TEST(EcanOverwrite, FullMailboxWithoutOpcIsOverwrittenWithRmlEvenIfALowerOneIsFree) {
  Ecan ecan(boxes({{3, ecan_rx_mailbox(0x102)}, {20, ecan_rx_mailbox(0x102)}}));
  EXPECT_EQ(ecan.receive(make_data(0x102, {1})).mailbox, 20);
  const auto r = ecan.receive(make_data(0x102, {2}));
  EXPECT_EQ(r.status, Ecan::RxStatus::overwritten);
  EXPECT_EQ(r.mailbox, 20);
  EXPECT_EQ(ecan.read(20).frame.data[0], 2);  // the newest message
  EXPECT_TRUE(ecan.pending(20));
  EXPECT_TRUE(ecan.lost(20));
  EXPECT_FALSE(ecan.pending(3));
  EXPECT_EQ(ecan.stats().overwritten, 1u);

  ecan.clear_rmp(20);  // the CPU acknowledges: RMP and RML clear
  EXPECT_EQ(ecan.rmp(), 0u);
  EXPECT_EQ(ecan.rml(), 0u);
  EXPECT_EQ(ecan.receive(make_data(0x102, {3})).status, Ecan::RxStatus::stored);
}

TEST(EcanOverwrite, OpcPassesTheFrameToTheNextMatchingMailboxThenLosesIt) {
  // Mailboxes 20 and 3 both protected: the third frame is lost, nothing is flagged.
  Ecan ecan(boxes({{3, ecan_rx_mailbox(0x102, false, 0, true)},
                   {20, ecan_rx_mailbox(0x102, false, 0, true)}}));
  EXPECT_EQ(ecan.receive(make_data(0x102, {1})).mailbox, 20);
  EXPECT_EQ(ecan.receive(make_data(0x102, {2})).mailbox, 3);
  const auto r = ecan.receive(make_data(0x102, {3}));
  EXPECT_EQ(r.status, Ecan::RxStatus::lost);
  EXPECT_EQ(r.mailbox, -1);
  EXPECT_EQ(ecan.read(20).frame.data[0], 1);
  EXPECT_EQ(ecan.read(3).frame.data[0], 2);
  EXPECT_EQ(ecan.rml(), 0u);
  EXPECT_EQ(ecan.stats().lost, 1u);
  EXPECT_EQ(ecan.stats().stored, 2u);
}

TEST(EcanOverwrite, OpcFallThroughEndsInAnUnprotectedMailboxWhichIsOverwritten) {
  Ecan ecan(boxes({{3, ecan_rx_mailbox(0x102)}, {20, ecan_rx_mailbox(0x102, false, 0, true)}}));
  ecan.receive(make_data(0x102, {1}));  // -> 20
  ecan.receive(make_data(0x102, {2}));  // 20 protected -> 3
  const auto r = ecan.receive(make_data(0x102, {3}));
  EXPECT_EQ(r.status, Ecan::RxStatus::overwritten);
  EXPECT_EQ(r.mailbox, 3);
  EXPECT_EQ(ecan.read(20).frame.data[0], 1);
  EXPECT_EQ(ecan.read(3).frame.data[0], 3);
  EXPECT_EQ(ecan.rml(), 1u << 3);
}

TEST(EcanInterrupt, CallbackPerStoredFrameOnlyForMailboxesWithMim) {
  EcanMailboxConfig quiet = ecan_rx_mailbox(0x302);
  quiet.mim = false;
  Ecan ecan(boxes({{4, ecan_rx_mailbox(0x202)}, {6, quiet}}));
  std::vector<std::pair<int, bool>> calls;
  ecan.set_interrupt_handler([&](int n, bool overwritten) { calls.emplace_back(n, overwritten); });
  ecan.receive(make_data(0x202, {4}));
  ecan.receive(make_data(0x202, {4}));  // overwrite
  ecan.receive(make_data(0x302, {8}));  // stored, but MIM clear
  ecan.receive(make_data(0x502, {16}));  // no match
  EXPECT_EQ(calls, (std::vector<std::pair<int, bool>>{{4, false}, {4, true}}));
  EXPECT_TRUE(ecan.pending(6));
}

TEST(EcanRemote, RemoteFramesGoToReceiveMailboxesLikeDataFrames) {
  // The master's detection answers: remote frames 0x004/0x008/0x010/0x020 into one masked box.
  Ecan ecan(boxes({{15, ecan_rx_mailbox(0x000, false, 0x03C)}}));
  const auto r = ecan.receive(make_remote(0x008));
  EXPECT_EQ(r.status, Ecan::RxStatus::stored);
  EXPECT_EQ(ecan.read(15).frame, make_remote(0x008));
  EXPECT_EQ(ecan.receive(make_remote(0x040)).status, Ecan::RxStatus::no_match);
}

TEST(EcanRemote, TransmitMailboxAnswersMatchingRemoteFramesAndStopsTheSearch) {
  EcanMailboxConfig tx;
  tx.enabled = true;
  tx.direction = EcanDirection::transmit;
  tx.id = 0x002;
  tx.aam = true;
  Ecan ecan(boxes({{30, tx}, {1, ecan_rx_mailbox(0x002)}}));
  const auto r = ecan.receive(make_remote(0x002));
  EXPECT_EQ(r.status, Ecan::RxStatus::auto_answer);
  EXPECT_EQ(r.mailbox, 30);
  EXPECT_EQ(ecan.trs(), 1u << 30);
  EXPECT_EQ(ecan.rmp(), 0u);  // the lower receive mailbox did not get it
  ecan.clear_trs(30);
  EXPECT_EQ(ecan.trs(), 0u);
  // Data frames pass transmit mailboxes by.
  EXPECT_EQ(ecan.receive(make_data(0x002, {1})).mailbox, 1);

  tx.aam = false;
  Ecan no_aam(boxes({{30, tx}, {1, ecan_rx_mailbox(0x002)}}));
  EXPECT_EQ(no_aam.receive(make_remote(0x002)).status, Ecan::RxStatus::ignored);
  EXPECT_EQ(no_aam.rmp(), 0u);
  EXPECT_EQ(no_aam.trs(), 0u);
}

TEST(EcanSetup, RejectsIdentifiersOutOfRangeAndInvalidFrames) {
  EcanMailboxConfig bad = ecan_rx_mailbox(0x7FF);
  bad.id = 0x800;
  EXPECT_THROW(Ecan(boxes({{0, bad}})), std::invalid_argument);
  Ecan ecan(boxes({{0, ecan_rx_mailbox(0, false, 0x7FF)}}));
  Frame err;
  err.kind = FrameKind::error;
  EXPECT_EQ(ecan.receive(err).status, Ecan::RxStatus::invalid);
  EXPECT_EQ(ecan.rmp(), 0u);
}

}  // namespace
}  // namespace omnitwin::can
