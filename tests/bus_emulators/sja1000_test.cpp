// Tests bus_emulators/can/sja1000: the PeliCAN acceptance filter against the thesis's
// fig. 4-7 example and hand-computed single/dual, standard/extended register values; the
// 64-byte RX FIFO's per-message byte cost, capacity, order, release, RMC, data overrun (DOS,
// frame lost, cleared only by command) and the RI/DOI interrupt behaviour.
#include "bus_emulators/can/sja1000.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace omnitwin::can {
namespace {

Sja1000Config single(std::array<std::uint8_t, 4> acr, std::array<std::uint8_t, 4> amr) {
  Sja1000Config c;
  c.mode = Sja1000FilterMode::single;
  c.acr = acr;
  c.amr = amr;
  return c;
}

Sja1000Config dual(std::array<std::uint8_t, 4> acr, std::array<std::uint8_t, 4> amr) {
  Sja1000Config c = single(acr, amr);
  c.mode = Sja1000FilterMode::dual;
  return c;
}

Frame data8(std::uint32_t id, bool extended = false) {
  return make_data(id, {1, 2, 3, 4, 5, 6, 7, 8}, extended);
}

// Seed 002, fig. 4-7: ACR = 0000 0000 | 0101 .... | 1010 1010 | 0000 1111,
// AMR = 0000 0000 | 0111 .... | 1111 1111 | 1111 1111; ID.19, ID.18 and RTR don't care,
// data bytes don't care. Accepts identifiers 0x000..0x003, data and remote frames.
const Sja1000Config kFig47 = single({0x00, 0x50, 0xAA, 0x0F}, {0x00, 0x7F, 0xFF, 0xFF});

TEST(Sja1000Filter, ThesisFig47AcceptsExactly0x000To0x003DataAndRemote) {
  const Sja1000 ctl(kFig47);
  for (std::uint32_t id = 0; id <= 0x7FF; ++id) {
    const bool want = id <= 0x003;
    EXPECT_EQ(ctl.accept(make_data(id, {})), want) << id;
    EXPECT_EQ(ctl.accept(make_data(id, {0x02, 0x01})), want) << id;
    EXPECT_EQ(ctl.accept(data8(id)), want) << id;
    EXPECT_EQ(ctl.accept(make_remote(id)), want) << id;
    EXPECT_EQ(ctl.accept(make_remote(id, 8)), want) << id;
  }
}

TEST(Sja1000Filter, Fig47LowNibbleOfAcr1AndAmr1IsUnusedForStandardFrames) {
  // The figure gives only the upper 4 bits of ACR1/AMR1; whatever the lower ones hold (here
  // AMR1.3..0 = 0, "compare", against every ACR1.3..0), the result must not change.
  for (std::uint8_t low = 0; low < 16; ++low) {
    const Sja1000 ctl(single({0x00, static_cast<std::uint8_t>(0x50 | low), 0xAA, 0x0F},
                             {0x00, 0x70, 0xFF, 0xFF}));
    EXPECT_TRUE(ctl.accept(make_data(0x003, {9})));
    EXPECT_TRUE(ctl.accept(make_remote(0x000)));
    EXPECT_FALSE(ctl.accept(make_data(0x004, {9})));
    EXPECT_FALSE(ctl.accept(make_data(0x400, {9})));
  }
}

TEST(Sja1000Filter, Fig47ThroughReceiveCountsAcceptedAndFiltered) {
  Sja1000 ctl(kFig47);
  EXPECT_EQ(ctl.receive(make_data(0x000, {0x02, 0x01})), Sja1000::RxStatus::accepted);
  EXPECT_EQ(ctl.receive(make_remote(0x002)), Sja1000::RxStatus::accepted);
  EXPECT_EQ(ctl.receive(make_data(0x102, {2, 0, 0, 0, 0})), Sja1000::RxStatus::filtered);
  EXPECT_EQ(ctl.receive(make_remote(0x004)), Sja1000::RxStatus::filtered);
  EXPECT_EQ(ctl.stats().accepted, 2u);
  EXPECT_EQ(ctl.stats().filtered, 2u);
  EXPECT_EQ(ctl.rx_message_count(), 2);
}

TEST(Sja1000Filter, SingleStandardComparesRtrBit) {
  // ID 0x102 exactly, RTR compared: ACR1 = 010 0 ...., AMR1 = 000 0 1111.
  const Sja1000 data_only(single({0x20, 0x40, 0, 0}, {0x00, 0x0F, 0xFF, 0xFF}));
  EXPECT_TRUE(data_only.accept(make_data(0x102, {1})));
  EXPECT_FALSE(data_only.accept(make_remote(0x102)));
  const Sja1000 remote_only(single({0x20, 0x50, 0, 0}, {0x00, 0x0F, 0xFF, 0xFF}));
  EXPECT_FALSE(remote_only.accept(make_data(0x102, {1})));
  EXPECT_TRUE(remote_only.accept(make_remote(0x102)));
  EXPECT_FALSE(remote_only.accept(make_remote(0x103)));
}

TEST(Sja1000Filter, SingleStandardComparesTheFirstTwoDataBytesWhenPresent) {
  // Any identifier, data byte 1 must be 0x02 (the master as sender), byte 2 must be 0x01.
  const Sja1000 ctl(single({0, 0, 0x02, 0x01}, {0xFF, 0xFF, 0x00, 0x00}));
  EXPECT_TRUE(ctl.accept(make_data(0x702, {0x02, 0x01, 0x55})));
  EXPECT_FALSE(ctl.accept(make_data(0x702, {0x01, 0x01})));
  EXPECT_FALSE(ctl.accept(make_data(0x702, {0x02, 0x00})));
  // Bytes the message does not carry are not compared.
  EXPECT_TRUE(ctl.accept(make_data(0x702, {0x02})));
  EXPECT_FALSE(ctl.accept(make_data(0x702, {0x03})));
  EXPECT_TRUE(ctl.accept(make_data(0x702, {})));
  EXPECT_TRUE(ctl.accept(make_remote(0x702, 2)));
}

TEST(Sja1000Filter, DualStandardFilter1IncludesDataByte1Filter2OnlyTheIdentifier) {
  // Filter 1: ID 0x102, RTR don't care, data byte 1 = 0x02 (upper nibble in ACR1.3..0,
  //           lower nibble in ACR3.3..0).
  // Filter 2: ID 0x000, RTR don't care (ACR2, ACR3.7..4).
  const Sja1000 ctl(dual({0x20, 0x40, 0x00, 0x02}, {0x00, 0x10, 0x00, 0x10}));
  EXPECT_TRUE(ctl.accept(make_data(0x102, {0x02, 0, 0, 0, 0})));
  EXPECT_FALSE(ctl.accept(make_data(0x102, {0x03, 0, 0, 0, 0})));  // lower nibble differs
  EXPECT_FALSE(ctl.accept(make_data(0x102, {0x12, 0, 0, 0, 0})));  // upper nibble differs
  EXPECT_TRUE(ctl.accept(make_remote(0x102)));                     // no data byte: ID decides
  EXPECT_TRUE(ctl.accept(make_data(0x102, {})));
  EXPECT_TRUE(ctl.accept(make_data(0x000, {0x02, 0x01})));  // filter 2, data ignored
  EXPECT_TRUE(ctl.accept(make_data(0x000, {0xFF, 0xFF})));
  EXPECT_TRUE(ctl.accept(make_remote(0x000)));
  EXPECT_FALSE(ctl.accept(make_data(0x001, {0x02})));
  EXPECT_FALSE(ctl.accept(make_data(0x202, {0x02})));
}

TEST(Sja1000Filter, DualStandardFilter2RtrBitIsACR3Bit4) {
  // Filter 1: ID 0x7FF data frames (RTR 0) with data byte 1 = 0xFF;
  // filter 2: ID 0x000 remote frames only (ACR3.4 = RTR = 1).
  const Sja1000 ctl(dual({0xFF, 0xEF, 0x00, 0x1F}, {0x00, 0x00, 0x00, 0x00}));
  EXPECT_TRUE(ctl.accept(make_remote(0x000)));
  EXPECT_FALSE(ctl.accept(make_data(0x000, {1, 2})));
  EXPECT_TRUE(ctl.accept(make_data(0x7FF, {0xFF})));  // filter 1
  EXPECT_FALSE(ctl.accept(make_data(0x7FF, {0xFE})));
}

TEST(Sja1000Filter, SingleExtendedMapsAll29BitsAndRtr) {
  // 0x1ABCDEF0: ID.28..21 = D5, ID.20..13 = E6, ID.12..5 = F7, ID.4..0 = 10000 -> ACR3 = 1000 0 0..
  const std::uint32_t id = 0x1ABCDEF0;
  const Sja1000 any_rtr(single({0xD5, 0xE6, 0xF7, 0x80}, {0x00, 0x00, 0x00, 0x04}));
  EXPECT_TRUE(any_rtr.accept(data8(id, true)));
  EXPECT_TRUE(any_rtr.accept(make_remote(id, 0, true)));
  for (int b = 0; b < 29; ++b) EXPECT_FALSE(any_rtr.accept(data8(id ^ (1u << b), true))) << b;
  EXPECT_FALSE(any_rtr.accept(data8(0x7FF)));  // a standard frame is mapped differently

  const Sja1000 data_only(single({0xD5, 0xE6, 0xF7, 0x80}, {0x00, 0x00, 0x00, 0x00}));
  EXPECT_TRUE(data_only.accept(data8(id, true)));
  EXPECT_FALSE(data_only.accept(make_remote(id, 0, true)));
  // ACR3.1..0 are unused: garbage there changes nothing.
  const Sja1000 garbage(single({0xD5, 0xE6, 0xF7, 0x83}, {0x00, 0x00, 0x00, 0x00}));
  EXPECT_TRUE(garbage.accept(data8(id, true)));
}

TEST(Sja1000Filter, DualExtendedComparesId28To13OnlyInTwoFilters) {
  // Filter 1: ID.28..13 of 0x1ABCDEF0 (D5 E6); filter 2: ID.28..13 all zero.
  const Sja1000 ctl(dual({0xD5, 0xE6, 0x00, 0x00}, {0x00, 0x00, 0x00, 0x00}));
  EXPECT_TRUE(ctl.accept(data8(0x1ABCDEF0, true)));
  EXPECT_TRUE(ctl.accept(make_data(0x1ABCC000, {}, true)));  // ID.12..0 ignored
  EXPECT_TRUE(ctl.accept(make_remote(0x1ABCDFFF, 0, true)));  // same ID.28..13, RTR ignored
  EXPECT_FALSE(ctl.accept(data8(0x1ABCE000, true)));          // ID.13 differs
  EXPECT_TRUE(ctl.accept(data8(0x00001FFF, true)));           // filter 2
  EXPECT_FALSE(ctl.accept(data8(0x00002000, true)));
}

TEST(Sja1000Filter, ErrorFramesAndInvalidFramesAreNeverReceived) {
  Sja1000 ctl(Sja1000Config{});  // accept-all masks
  Frame err;
  err.kind = FrameKind::error;
  EXPECT_FALSE(ctl.accept(err));
  EXPECT_EQ(ctl.receive(err), Sja1000::RxStatus::invalid);
  Frame bad = make_data(0x10, {});
  bad.id = 0x800;  // out of range for a standard identifier
  EXPECT_EQ(ctl.receive(bad), Sja1000::RxStatus::invalid);
  EXPECT_EQ(ctl.stats().accepted + ctl.stats().filtered + ctl.stats().overruns, 0u);
}

TEST(Sja1000Fifo, MessageCostIsHeaderPlusStoredDataBytes) {
  EXPECT_EQ(sja1000_fifo_cost(data8(0x100)), 11);
  EXPECT_EQ(sja1000_fifo_cost(make_data(0x100, {})), 3);
  EXPECT_EQ(sja1000_fifo_cost(make_remote(0x100, 8)), 3);  // remote frames store no data
  EXPECT_EQ(sja1000_fifo_cost(data8(0x100, true)), 13);
  EXPECT_EQ(sja1000_fifo_cost(make_remote(0x100, 8, true)), 5);
  EXPECT_EQ(sja1000_fifo_cost(make_data(0x202, {4, 0, 0, 0, 0, 0})), 9);  // slave feedback
}

struct CapacityCase {
  Frame frame;
  int fits;
};

TEST(Sja1000Fifo, CapacityDependsOnFrameSize) {
  const std::vector<CapacityCase> cases = {
      {data8(0x100), 5},                        // 64 / 11
      {data8(0x100, true), 4},                  // 64 / 13
      {make_remote(0x100), 21},                 // 64 / 3
      {make_remote(0x100, 0, true), 12},        // 64 / 5
      {make_data(0x102, {2, 0, 0, 0, 0}), 8},   // 64 / 8: the master's command frame
  };
  for (const auto& c : cases) {
    Sja1000 ctl(Sja1000Config{});
    for (int i = 0; i < c.fits; ++i)
      ASSERT_EQ(ctl.receive(c.frame), Sja1000::RxStatus::accepted) << i;
    EXPECT_EQ(ctl.receive(c.frame), Sja1000::RxStatus::overrun) << to_string(c.frame);
    EXPECT_EQ(ctl.rx_message_count(), c.fits);
    EXPECT_EQ(ctl.fifo_bytes_used(), c.fits * sja1000_fifo_cost(c.frame));
    EXPECT_TRUE(ctl.data_overrun());
  }
}

TEST(Sja1000Fifo, FifoOrderReadReleaseAndTimestamps) {
  Sja1000 ctl(Sja1000Config{});
  EXPECT_EQ(ctl.read(), nullptr);
  EXPECT_FALSE(ctl.release());
  EXPECT_FALSE(ctl.receive_buffer_status());
  ctl.receive(make_data(0x202, {4, 0, 0, 0, 0, 1}), 1000);
  ctl.receive(make_remote(0x004), 2000);
  ctl.receive(make_data(0x1ABCDEF0, {7}, true), 3000);
  EXPECT_TRUE(ctl.receive_buffer_status());
  EXPECT_EQ(ctl.rx_message_count(), 3);
  EXPECT_EQ(ctl.fifo_bytes_used(), 9 + 3 + 6);

  ASSERT_NE(ctl.read(), nullptr);
  EXPECT_EQ(ctl.read()->frame, make_data(0x202, {4, 0, 0, 0, 0, 1}));
  EXPECT_EQ(ctl.read()->rx_time_ns, 1000u);
  EXPECT_TRUE(ctl.release());
  EXPECT_EQ(ctl.read()->frame, make_remote(0x004));
  EXPECT_EQ(ctl.read()->rx_time_ns, 2000u);
  EXPECT_EQ(ctl.fifo_bytes_used(), 3 + 6);
  EXPECT_TRUE(ctl.release());
  EXPECT_EQ(ctl.read()->frame, make_data(0x1ABCDEF0, {7}, true));
  EXPECT_TRUE(ctl.release());
  EXPECT_EQ(ctl.read(), nullptr);
  EXPECT_EQ(ctl.rx_message_count(), 0);
  EXPECT_EQ(ctl.fifo_bytes_used(), 0);
  EXPECT_FALSE(ctl.receive_buffer_status());
}

TEST(Sja1000Fifo, OverrunLosesTheNewFrameKeepsOldOnesAndLatchesUntilCleared) {
  Sja1000 ctl(Sja1000Config{});
  for (std::uint32_t i = 0; i < 5; ++i) ctl.receive(data8(0x200 + i));
  EXPECT_FALSE(ctl.data_overrun());
  EXPECT_EQ(ctl.receive(data8(0x2FF)), Sja1000::RxStatus::overrun);
  EXPECT_EQ(ctl.stats().overruns, 1u);
  EXPECT_EQ(ctl.read()->frame.id, 0x200u);  // the oldest is untouched

  // Releasing makes room (64 - 44 = 20 bytes): the next frame is stored, DOS stays set.
  EXPECT_TRUE(ctl.release());
  EXPECT_EQ(ctl.receive(data8(0x2FE)), Sja1000::RxStatus::accepted);
  EXPECT_TRUE(ctl.data_overrun());
  ctl.clear_data_overrun();
  EXPECT_FALSE(ctl.data_overrun());

  // The lost 0x2FF never appears.
  std::vector<std::uint32_t> ids;
  while (const auto* m = ctl.read()) {
    ids.push_back(m->frame.id);
    ctl.release();
  }
  EXPECT_EQ(ids, (std::vector<std::uint32_t>{0x201, 0x202, 0x203, 0x204, 0x2FE}));
}

TEST(Sja1000Fifo, SmallFrameStillFitsWhereALargeOneOverran) {
  Sja1000 ctl(Sja1000Config{});
  for (int i = 0; i < 5; ++i) ctl.receive(data8(0x100));  // 55 bytes used, 9 free
  EXPECT_EQ(ctl.receive(data8(0x100)), Sja1000::RxStatus::overrun);               // needs 11
  EXPECT_EQ(ctl.receive(make_data(0x100, {1, 2, 3, 4, 5, 6})), Sja1000::RxStatus::accepted);  // 9
  EXPECT_EQ(ctl.fifo_bytes_free(), 0);
  EXPECT_EQ(ctl.receive(make_remote(0x100)), Sja1000::RxStatus::overrun);
}

TEST(Sja1000Fifo, FilteredFramesNeverOverrun) {
  Sja1000 ctl(kFig47);
  for (int i = 0; i < 5; ++i) ctl.receive(data8(0x001));
  EXPECT_EQ(ctl.receive(data8(0x001)), Sja1000::RxStatus::overrun);
  ctl.clear_data_overrun();
  EXPECT_EQ(ctl.receive(data8(0x005)), Sja1000::RxStatus::filtered);
  EXPECT_FALSE(ctl.data_overrun());
}

TEST(Sja1000Interrupts, ReceiveInterruptIsALevelDataOverrunIsLatchedOnTheTransition) {
  Sja1000 ctl(Sja1000Config{});
  std::vector<std::uint8_t> edges;
  ctl.set_interrupt_handler([&](std::uint8_t ir) { edges.push_back(ir); });

  EXPECT_FALSE(ctl.interrupt_line());
  ctl.receive(data8(0x100));
  EXPECT_TRUE(ctl.interrupt_line());
  ctl.receive(data8(0x100));  // line already active: no new edge
  ASSERT_EQ(edges.size(), 1u);
  EXPECT_EQ(edges[0], Sja1000::kIrReceive);

  // Reading IR does not clear RI while messages remain.
  EXPECT_EQ(ctl.read_interrupt_register(), Sja1000::kIrReceive);
  EXPECT_TRUE(ctl.interrupt_line());
  while (ctl.release()) {
  }
  EXPECT_FALSE(ctl.interrupt_line());

  // Fill, overrun twice: DOI set once (DOS 0 -> 1), cleared by reading IR.
  for (int i = 0; i < 7; ++i) ctl.receive(data8(0x100));
  EXPECT_EQ(ctl.stats().overruns, 2u);
  EXPECT_EQ(ctl.read_interrupt_register(), Sja1000::kIrReceive | Sja1000::kIrDataOverrun);
  EXPECT_EQ(ctl.read_interrupt_register(), Sja1000::kIrReceive);
  ctl.receive(data8(0x100));  // DOS still set: no new DOI
  EXPECT_EQ(ctl.read_interrupt_register(), Sja1000::kIrReceive);
  ctl.clear_data_overrun();
  ctl.receive(data8(0x100));  // DOS 0 -> 1 again
  EXPECT_EQ(ctl.read_interrupt_register(), Sja1000::kIrReceive | Sja1000::kIrDataOverrun);
  EXPECT_EQ(edges.size(), 2u);  // the second edge came with the first frame after emptying
}

TEST(Sja1000Interrupts, DisabledInterruptsNeverDriveTheLine) {
  Sja1000Config c;
  c.receive_interrupt_enable = false;
  c.overrun_interrupt_enable = false;
  Sja1000 ctl(c);
  int calls = 0;
  ctl.set_interrupt_handler([&](std::uint8_t) { ++calls; });
  for (int i = 0; i < 6; ++i) ctl.receive(data8(0x100));
  EXPECT_TRUE(ctl.data_overrun());
  EXPECT_TRUE(ctl.receive_buffer_status());
  EXPECT_FALSE(ctl.interrupt_line());
  EXPECT_EQ(ctl.read_interrupt_register(), 0);
  EXPECT_EQ(calls, 0);
}

}  // namespace
}  // namespace omnitwin::can
