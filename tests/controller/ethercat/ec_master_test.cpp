// Tests controller/ethercat/ec_master: the master core against A's EscChain of four of B's
// DriveSlaves (models/ethercat/omnitwin_drive.xml) in-process — scan and identity, station
// addresses, the PDO mapping read over CoE against the ESI, all slaves to OP, the expected
// WKC every cycle, process data both ways, a slave powered off (WKC drop found and reported)
// and on again (brought back to OP), SDO aborts reported, lost frames counted, an unknown
// device refused by name, DC registers written; the whole segment cut off (frames never
// back) or powered off (WKC 0): OP left, lost frames and WKC errors counted, and back.
#include "controller/ethercat/ec_master.hpp"

#include <gtest/gtest.h>

#include <algorithm>

#include "bus_emulators/ethercat/device/ec_sii.hpp"
#include "ec_bench.hpp"

using namespace omnitwin::controller::ethercat;
using ecbench::Bench;

namespace {
bool has_event(const EcMaster& m, const std::string& part) {
  return std::any_of(m.events().begin(), m.events().end(), [&](const std::string& e) { return e.find(part) != std::string::npos; });
}
std::string events(const EcMaster& m) {
  std::string s = std::string("phase ") + to_string(m.phase()) + "\n";
  for (int i = 0; i < m.slave_count(); ++i)
    s += "slave " + std::to_string(i) + " step " + to_string(m.slave(i).step) + " al " + to_string(m.slave(i).al_state) +
         " code " + std::to_string(m.slave(i).al_code) + "\n";
  for (const auto& e : m.events()) s += e + "\n";
  return s;
}
}  // namespace

TEST(EcMaster, FirstTickCountsSlavesWithBrd) {
  Bench b;
  b.master->tick(0);
  ASSERT_TRUE(b.sent);
  // EtherCAT header: length 14, type 1; BRD, index 1, ADP 0, ADO 0x0000, 2 bytes, WKC 0
  const std::vector<std::uint8_t> golden{0x0E, 0x10, 0x07, 0x01, 0x00, 0x00, 0x00, 0x00,
                                         0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00};
  EXPECT_EQ(b.frame, golden);
  ASSERT_TRUE(b.chain.process(b.frame, 0));
  EXPECT_EQ(omnitwin::ethercat::get_u16(b.frame.data() + 14), 4);  // WKC = slave count
}

TEST(EcMaster, ScanFindsFourSlavesWithTheirIdentity) {
  Bench b;
  ASSERT_TRUE(b.run_until([&] { return b.master->phase() >= MasterPhase::configure; })) << b.master->error();
  ASSERT_EQ(b.master->slave_count(), 4);
  for (int i = 0; i < 4; ++i) {
    const SlaveStatus& s = b.master->slave(i);
    EXPECT_EQ(s.station, 0x1001 + i);
    EXPECT_EQ(b.chain.esc(i).station_address(), 0x1001 + i);
    EXPECT_EQ(s.sii.vendor, b.devices[0].vendor_id);
    EXPECT_EQ(s.sii.product, b.devices[0].product_code);
    EXPECT_EQ(s.sii.revision, b.devices[0].revision);
    EXPECT_EQ(s.sii.serial, static_cast<std::uint32_t>(100 + i));
    ASSERT_NE(s.esi, nullptr);
    EXPECT_EQ(s.esi->name, b.devices[0].name);
  }
}

TEST(EcMaster, PdoMappingReadOverCoeMatchesTheEsi) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error() << "\n" << events(*b.master);
  const auto& d = b.devices[0];
  for (int i = 0; i < 4; ++i) {
    const SlaveStatus& s = b.master->slave(i);
    EXPECT_TRUE(s.pdo_from_coe);
    std::vector<const omnitwin::ethercat::EsiPdo*> rx, tx;
    for (const auto& p : d.rx_pdos) if (p.sm == 2) rx.push_back(&p);
    for (const auto& p : d.tx_pdos) if (p.sm == 3) tx.push_back(&p);
    ASSERT_EQ(s.rx_pdos.size(), rx.size());
    ASSERT_EQ(s.tx_pdos.size(), tx.size());
    for (std::size_t k = 0; k < rx.size(); ++k) {
      EXPECT_EQ(s.rx_pdos[k].index, rx[k]->index);
      ASSERT_EQ(s.rx_pdos[k].entries.size(), rx[k]->entries.size());
      for (std::size_t e = 0; e < rx[k]->entries.size(); ++e) {
        EXPECT_EQ(s.rx_pdos[k].entries[e].index, rx[k]->entries[e].index);
        EXPECT_EQ(s.rx_pdos[k].entries[e].bits, rx[k]->entries[e].bit_length);
      }
    }
    for (std::size_t k = 0; k < tx.size(); ++k) {
      EXPECT_EQ(s.tx_pdos[k].index, tx[k]->index);
      EXPECT_EQ(s.tx_pdos[k].bits(), tx[k]->bit_size());
    }
    EXPECT_EQ(s.out_bytes, b.slaves[i]->output_bytes());
    EXPECT_EQ(s.in_bytes, b.slaves[i]->input_bytes());
  }
}

// A reply saying that 255 PDOs are assigned to SM2 (a corrupted or hostile slave): the master
// reads the entries, falls back to the SII's PDOs when they abort, and reaches OP. An 8-bit
// loop index used to wrap at 255 and queue reads until memory ran out (fuzz/ec_master_fuzz).
TEST(EcMaster, AnAssignmentCountOf255EndsAndTheSlaveStillReachesOp) {
  Bench b(1);
  int patched = 0;
  b.tamper = [&](std::vector<std::uint8_t>& f) {
    // The expedited upload response of 0x1C12:00 (command 0x4F, index, subindex, one byte).
    const std::uint8_t head[] = {0x4F, 0x12, 0x1C, 0x00};
    auto at = std::search(f.begin(), f.end(), std::begin(head), std::end(head));
    if (at == f.end() || at + 4 == f.end()) return;
    *(at + 4) = 0xFF;
    ++patched;
  };
  ASSERT_TRUE(b.to_op(20000)) << b.master->error() << "\n" << events(*b.master);
  EXPECT_EQ(patched, 1);
  const SlaveStatus& s = b.master->slave(0);
  EXPECT_FALSE(s.pdo_from_coe);
  EXPECT_GE(b.master->stats().sdo_failed, 1u);
  EXPECT_EQ(s.out_bytes, b.slaves[0]->output_bytes());
  EXPECT_EQ(s.in_bytes, b.slaves[0]->input_bytes());
}

// A mapping may say an entry is up to 255 bits wide (a corrupted reply did, in
// fuzz/ec_master_fuzz): reading and writing it as an integer touch its low 64 bits only. Shifts
// by 64 or more used to be undefined; on x86 they wrapped and copied bit 0 into bit 64.
TEST(EcMaster, AnEntryWiderThan64BitsIsReadAndWrittenInItsLow64Bits) {
  Bench b(1);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  ASSERT_GE(b.master->lrw_bytes(), 10u);
  const EntryLocation wide{0, 80, true};
  b.master->write_entry(EntryLocation{64, 16, true}, 0x5A5A);
  b.master->write_entry(wide, 1);
  EXPECT_EQ(b.master->read_entry(EntryLocation{64, 16, true}, false), 0);  // zeros above bit 63
  EXPECT_EQ(b.master->read_entry(wide, false), 1);
  b.master->write_entry(EntryLocation{64, 1, true}, 1);
  EXPECT_EQ(b.master->read_entry(wide, false), 1);  // bit 64 is not folded into bit 0
  EXPECT_EQ(b.master->read_entry(EntryLocation{0, 64, true}, true), 1);
}

// The tick's frame as it came back with every LRW cut to no data, its lengths and header
// consistent (a slave or a wire that shortens a datagram); false when it held no LRW.
bool cut_lrw(std::vector<std::uint8_t>& f) {
  omnitwin::ethercat::PduView v;
  if (omnitwin::ethercat::parse_pdu(f, v) != omnitwin::ethercat::PduError::ok) return false;
  std::vector<std::uint8_t> out(f.size());
  omnitwin::ethercat::PduBuilder pb(out);
  bool cut = false;
  for (std::size_t i = 0; i < v.count; ++i) {
    const auto& d = v.datagrams[i];
    const bool lrw = d.cmd() == omnitwin::ethercat::Cmd::lrw;
    cut = cut || lrw;
    pb.add(d.cmd(), d.index(), d.adp(), d.ado(), lrw ? 0 : d.length(), d.data());
  }
  out.resize(pb.finish());
  omnitwin::ethercat::PduView w;
  if (omnitwin::ethercat::parse_pdu(out, w) != omnitwin::ethercat::PduError::ok) return false;
  for (std::size_t i = 0; i < v.count; ++i) {
    w.datagrams[i].set_wkc(v.datagrams[i].wkc());
    w.datagrams[i].set_irq(v.datagrams[i].irq());
  }
  f = out;
  return cut;
}

// A reply whose datagram lost its data (length 0, the frame otherwise well formed) is not this
// frame's answer: the master used to copy the image's inputs from past its end (ASan, found in
// review). It is counted as a stray frame and the cycle as not returned.
TEST(EcMaster, AReplyWhoseDatagramCameBackShorterIsNotTaken) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  ASSERT_FALSE(b.master->image_in_own_frames());
  const auto stray = b.master->stats().stray_frames;
  const auto cycles = b.master->stats().cycles;
  int cut = 0;
  b.tamper = [&](std::vector<std::uint8_t>& f) { cut += cut_lrw(f) ? 1 : 0; };
  for (int i = 0; i < 5; ++i) b.step();
  EXPECT_EQ(cut, 5);
  EXPECT_EQ(b.master->stats().stray_frames, stray + 5);
  EXPECT_EQ(b.master->stats().cycles, cycles);
  b.tamper = nullptr;
  for (int i = 0; i < 5; ++i) b.step();
  EXPECT_EQ(b.master->stats().cycles, cycles + 5);
}

// The slave count is the WKC of one broadcast read: a corrupted 0xFFFF used to become 65535
// slaves (133 MB, station addresses wrapping past 0xFFFF, then a misleading SII timeout; found in
// review). Beyond 4096 the master stops and says why.
TEST(EcMaster, ACountBeyondWhatTheMasterAddressesStopsIt) {
  Bench b(2);
  b.tamper = [](std::vector<std::uint8_t>& f) {
    omnitwin::ethercat::PduView v;
    if (omnitwin::ethercat::parse_pdu(f, v) != omnitwin::ethercat::PduError::ok) return;
    for (std::size_t i = 0; i < v.count; ++i)
      if (v.datagrams[i].cmd() == omnitwin::ethercat::Cmd::brd) v.datagrams[i].set_wkc(0xFFFF);
  };
  b.step();
  EXPECT_EQ(b.master->phase(), MasterPhase::failed);
  EXPECT_NE(b.master->error().find("counted 65535 slaves, more than the 4096"), std::string::npos) << b.master->error();
  EXPECT_EQ(b.master->slave_count(), 0);
}

TEST(EcMaster, AllReachOpAndEveryCycleHasTheExpectedWkc) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error() << "\n" << events(*b.master);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(b.chain.esc(i).al_state(), omnitwin::ethercat::AlState::op);
  EXPECT_EQ(b.master->stats().expected_wkc, 12);  // 2 × 4 with outputs + 4 with inputs
  const auto cycles = b.master->stats().cycles;
  for (int k = 0; k < 500; ++k) {
    b.step();
    ASSERT_EQ(b.master->stats().last_wkc, 12) << "cycle " << k;
  }
  EXPECT_EQ(b.master->stats().cycles, cycles + 500);
  EXPECT_EQ(b.master->stats().wkc_errors, 0u);
  EXPECT_EQ(b.master->stats().lost_frames, 0u);
  EXPECT_TRUE(b.master->operational());
}

TEST(EcMaster, ProcessDataTravelsBothWays) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  const auto tv = b.master->find_entry(2, 0x60FF, 0);
  ASSERT_TRUE(tv.has_value());
  EXPECT_TRUE(tv->output);
  EXPECT_EQ(tv->bits, 32);
  b.master->write_entry(*tv, -4321);
  for (int k = 0; k < 5; ++k) b.step();
  EXPECT_EQ(b.slaves[2]->axis(0).objects().target_velocity, -4321);
  EXPECT_EQ(b.slaves[1]->axis(0).objects().target_velocity, 0);
  const auto pa = b.master->find_entry(3, 0x6064, 0);
  ASSERT_TRUE(pa.has_value());
  EXPECT_FALSE(pa->output);
  b.step();
  EXPECT_EQ(b.master->read_entry(*pa, true), b.slaves[3]->axis(0).objects().position_actual);
  const auto sw = b.master->find_entry(0, 0x6041, 0);
  ASSERT_TRUE(sw.has_value());
  EXPECT_EQ(b.master->read_entry(*sw, false), b.slaves[0]->axis(0).objects().statusword);
}

TEST(EcMaster, PoweredOffSlaveIsFoundAndBroughtBackToOp) {
  EcMasterConfig cfg;
  cfg.probe_every_ns = 10'000'000;
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.chain.set_powered(2, false, b.t);
  for (int k = 0; k < 20; ++k) b.step();
  EXPECT_GT(b.master->stats().wkc_errors, 0u);
  EXPECT_LT(b.master->stats().last_wkc, 12);
  EXPECT_FALSE(b.master->operational());
  EXPECT_TRUE(has_event(*b.master, "slave 3 (station 0x1003) lost")) << events(*b.master);
  EXPECT_EQ(b.master->slave(2).step, SlaveStep::offline);
  EXPECT_GE(b.master->stats().slaves_lost, 1u);
  EXPECT_FALSE(b.master->segment_lost()) << "one slave missing is not the segment";
  EXPECT_EQ(b.master->stats().segment_losses, 0u);
  b.chain.set_powered(2, true, b.t);
  ASSERT_TRUE(b.run_until([&] { return b.master->operational(); }, 20000)) << events(*b.master);
  EXPECT_EQ(b.chain.esc(2).station_address(), 0x1003);
  EXPECT_EQ(b.chain.esc(2).al_state(), omnitwin::ethercat::AlState::op);
  EXPECT_GE(b.master->slave(2).recoveries, 1u);
  EXPECT_TRUE(has_event(*b.master, "slave 3 (station 0x1003) back in OP")) << events(*b.master);
  const auto errors = b.master->stats().wkc_errors;
  for (int k = 0; k < 100; ++k) b.step();
  EXPECT_EQ(b.master->stats().wkc_errors, errors);
  EXPECT_EQ(b.master->stats().last_wkc, 12);
}

TEST(EcMaster, SdoUploadOfAMissingObjectReportsTheAbortCode) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  std::optional<SdoResult> got;
  const auto id = b.master->sdo_upload(1, 0x2345, 0, [&](const SdoResult& r) { got = r; });
  ASSERT_NE(id, 0u);
  EXPECT_EQ(b.master->sdo_pending(1), 1u);
  ASSERT_TRUE(b.run_until([&] { return got.has_value(); }, 2000));
  EXPECT_EQ(got->id, id);
  EXPECT_EQ(got->status, SdoStatus::aborted);
  EXPECT_EQ(got->abort_code, 0x06020000u);
  EXPECT_EQ(b.master->sdo_pending(1), 0u);
  EXPECT_TRUE(has_event(*b.master, "0x06020000"));
  EXPECT_EQ(b.master->stats().wkc_errors, 0u);  // served between cycles without disturbing them
}

TEST(EcMaster, SdoUploadAndDownloadRoundTrip) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  std::optional<SdoResult> down, up;
  b.master->sdo_download(0, 0x6081, 0, value_bytes(12345, 4), [&](const SdoResult& r) { down = r; });
  b.master->sdo_upload(0, 0x6081, 0, [&](const SdoResult& r) { up = r; });
  ASSERT_TRUE(b.run_until([&] { return up.has_value(); }, 2000));
  EXPECT_EQ(down->status, SdoStatus::done);
  EXPECT_EQ(up->status, SdoStatus::done);
  EXPECT_EQ(bytes_value(up->data, false), 12345);
  EXPECT_EQ(b.slaves[0]->axis(0).objects().profile_velocity, 12345u);
}

TEST(EcMaster, LostFramesAreCountedAndConfigurationStillCompletes) {
  Bench b;
  for (int k = 0; k < 30; ++k) b.step();
  b.drop_next = 3;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  EXPECT_EQ(b.master->stats().lost_frames, 3u);
  b.drop_next = 2;
  for (int k = 0; k < 10; ++k) b.step();
  EXPECT_EQ(b.master->stats().lost_frames, 5u);
  EXPECT_TRUE(b.master->operational());
}

TEST(EcMaster, StartupSdoIsWrittenBeforeOp) {
  EcMasterConfig cfg;
  cfg.startup.push_back(StartupSdo{-1, 0x6060, 0, {9}});
  cfg.startup.push_back(StartupSdo{1, 0x6081, 0, value_bytes(777, 4)});
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  for (int i = 0; i < 4; ++i) EXPECT_EQ(b.slaves[i]->axis(0).objects().mode, 9);
  EXPECT_EQ(b.slaves[1]->axis(0).objects().profile_velocity, 777u);
  EXPECT_NE(b.slaves[0]->axis(0).objects().profile_velocity, 777u);
}

// Found in review: a start-up SDO for a slave beyond the count was silently never written.
TEST(EcMaster, AStartupSdoNamingASlaveBeyondTheCountFailsAfterTheCount) {
  EcMasterConfig cfg;
  cfg.startup.push_back(StartupSdo{4, 0x6060, 0, {9}});
  Bench b(4, cfg);
  for (int k = 0; k < 3; ++k) b.step();
  EXPECT_EQ(b.master->phase(), MasterPhase::failed);
  EXPECT_EQ(b.master->error(), "start-up SDO 0x6060:0 names slave 5, but the bus has 4 slave(s)");
}

TEST(EcMaster, UnknownDeviceIsRefusedByPositionAndIdentity) {
  auto devs = ecbench::drive_esi();
  devs[0].product_code ^= 0x1;
  Bench b(4, {}, devs);
  b.run_until([&] { return b.master->phase() == MasterPhase::failed; }, 5000);
  ASSERT_EQ(b.master->phase(), MasterPhase::failed);
  EXPECT_NE(b.master->error().find("slave 1 (vendor 0x"), std::string::npos) << b.master->error();
  EXPECT_NE(b.master->error().find("matches no ESI"), std::string::npos);
}

TEST(EcMaster, ExpectedSlaveCountMismatchFails) {
  EcMasterConfig cfg;
  cfg.expected_slaves = 5;
  Bench b(4, cfg);
  for (int k = 0; k < 3; ++k) b.step();
  EXPECT_EQ(b.master->phase(), MasterPhase::failed);
  EXPECT_EQ(b.master->error(), "found 4 slaves, the configuration expects 5");
}

TEST(EcMaster, DistributedClocksAreConfigured) {
  EcMasterConfig cfg;
  cfg.dc = true;
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error() << "\n" << events(*b.master);
  for (int i = 0; i < 4; ++i) {
    EXPECT_TRUE(b.master->slave(i).dc);
    EXPECT_EQ(b.chain.esc(i).read32(0x09A0), 1'000'000u);
    EXPECT_EQ(b.chain.esc(i).read8(0x0981) & 0x03, 0x03);
  }
  EXPECT_EQ(b.master->slave(0).dc_delay_ns, 0);
  EXPECT_GT(b.master->slave(3).dc_delay_ns, b.master->slave(1).dc_delay_ns);
  for (int k = 0; k < 100; ++k) b.step();
  EXPECT_EQ(b.master->stats().wkc_errors, 0u);
}

TEST(EcMaster, FramesThatComeBackTooLateAreSurvived) {
  for (int every : {7, 11, 13, 17, 23}) {
    EcMasterConfig cfg;
    cfg.dc = true;
    cfg.startup.push_back(StartupSdo{-1, 0x6060, 0, {9}});
    Bench b(4, cfg);
    b.late_every = every;
    ASSERT_TRUE(b.to_op(60000)) << "every " << every << ": " << b.master->error() << "\n" << events(*b.master);
    EXPECT_GT(b.master->stats().lost_frames, 0u);
  }
}

TEST(EcMaster, PdoRemappingThroughStartupSdosIsReadBackAndLaidOut) {
  // Assign RxPDO 0x1601 (controlword + target position) instead of 0x1600.
  EcMasterConfig cfg;
  cfg.startup.push_back(StartupSdo{-1, 0x1C12, 0, {0}});
  cfg.startup.push_back(StartupSdo{-1, 0x1C12, 1, {0x01, 0x16}});
  cfg.startup.push_back(StartupSdo{-1, 0x1C12, 0, {1}});
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error() << "\n" << events(*b.master);
  const SlaveStatus& s = b.master->slave(0);
  ASSERT_EQ(s.rx_pdos.size(), 1u);
  EXPECT_EQ(s.rx_pdos[0].index, 0x1601);
  EXPECT_EQ(s.out_bytes, 6u);
  EXPECT_EQ(b.master->stats().expected_wkc, 12);
  EXPECT_FALSE(b.master->find_entry(0, 0x60FF, 0).has_value());
  const auto tp = b.master->find_entry(1, 0x607A, 0);
  ASSERT_TRUE(tp.has_value());
  b.master->write_entry(*tp, 98765);
  for (int k = 0; k < 5; ++k) b.step();
  EXPECT_EQ(b.slaves[1]->axis(0).objects().target_position, 98765);
  EXPECT_EQ(b.master->stats().wkc_errors, 0u);
}

TEST(EcMaster, SlaveFallingToSafeOpWithAnErrorIsReportedAndBroughtBack) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.chain.esc(1).set_al_error(omnitwin::ethercat::AlState::safeop, omnitwin::ethercat::AlStatusCode::watchdog);
  ASSERT_TRUE(b.run_until([&] { return has_event(*b.master, "left OP"); }, 200)) << events(*b.master);
  EXPECT_TRUE(has_event(*b.master,
                        "slave 2 (station 0x1002) left OP: state SAFE-OP + error, AL status code 0x001B (sync manager watchdog)"))
      << events(*b.master);
  EXPECT_EQ(b.master->slave(1).al_code, 0x001B);
  ASSERT_TRUE(b.run_until([&] { return b.master->operational(); }, 5000)) << events(*b.master);
  EXPECT_EQ(b.chain.esc(1).al_state(), omnitwin::ethercat::AlState::op);
  EXPECT_FALSE(b.chain.esc(1).al_error());
  EXPECT_EQ(b.master->slave(1).recoveries, 1u);
  EXPECT_EQ(b.master->stats().slaves_lost, 0u);
}

// Issue 20: a master that stalls longer than the process-data watchdog (100 ms) trips every
// drive to SAFE-OP + 0x001B. The drives' firmware deactivates their output SM then, so the next
// cycle's WKC is 4 (inputs only) instead of 12 — a master supervising by WKC alone notices. Ours
// reads the AL status, reports 0x001B and brings the slaves back to OP, WKC 12 again.
TEST(EcMaster, AStalledMasterSeesTheWatchdogInTheWkcAndBringsTheSlavesBack) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  for (int k = 0; k < 20; ++k) b.step();
  ASSERT_EQ(b.master->stats().last_wkc, 12);
  b.paused = 150;  // 150 ms without a frame
  for (int k = 0; k < 150; ++k) b.step();
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(b.chain.esc(i).al_state(), omnitwin::ethercat::AlState::safeop);
    EXPECT_EQ(b.chain.esc(i).al_status_code(), omnitwin::ethercat::AlStatusCode::watchdog);
  }
  b.step();  // the first cycle after the stall
  EXPECT_EQ(b.master->stats().last_wkc, 4) << "the output SM of a slave in SAFE-OP + error takes no writes";
  ASSERT_TRUE(b.run_until([&] { return has_event(*b.master, "AL status code 0x001B"); }, 200)) << events(*b.master);
  ASSERT_TRUE(b.run_until([&] { return b.master->operational() && b.master->stats().last_wkc == 12; }, 5000))
      << events(*b.master);
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(b.chain.esc(i).al_state(), omnitwin::ethercat::AlState::op);
    EXPECT_FALSE(b.chain.esc(i).al_error());
    EXPECT_EQ(b.master->slave(i).recoveries, 1u);
  }
  EXPECT_GT(b.master->stats().wkc_errors, 0u);
}

// Issue 20: a drive fault reaches the master as a CoE emergency: the slave's SM1 event shows in
// the cyclic frame's IRQ field, the master reads the mailbox, logs "emergency 0x8611 (following
// error)" once, and the fault reset's "error reset" 0x0000 after it. The WKC stays 12 meanwhile.
TEST(EcMaster, ADriveFaultArrivesAsOneEmergencyAndItsResetAsAnother) {
  Bench b;
  ASSERT_TRUE(b.to_op()) << b.master->error();
  for (int k = 0; k < 20; ++k) b.step();
  EXPECT_EQ(b.master->stats().emergencies, 0u);
  b.slaves[2]->axis(0).raise_fault(omnitwin::drive::kErrorFollowing);
  ASSERT_TRUE(b.run_until([&] { return b.master->stats().emergencies >= 1; }, 100)) << events(*b.master);
  for (int k = 0; k < 50; ++k) b.step();
  EXPECT_EQ(b.master->stats().emergencies, 1u) << events(*b.master);
  EXPECT_EQ(b.master->slave(2).emergencies, 1u);
  EXPECT_EQ(b.master->slave(2).last_emergency, 0x8611);
  EXPECT_EQ(b.master->slave(2).last_error_register, 0x21);
  EXPECT_TRUE(has_event(*b.master, "slave 3 (station 0x1003) emergency 0x8611 (following error), error register 0x21"))
      << events(*b.master);
  const auto cw = b.master->find_entry(2, 0x6040, 0);
  ASSERT_TRUE(cw.has_value());
  b.master->write_entry(*cw, 0x0080);  // fault reset
  ASSERT_TRUE(b.run_until([&] { return b.master->stats().emergencies >= 2; }, 200)) << events(*b.master);
  EXPECT_EQ(b.master->slave(2).last_emergency, 0x0000);
  EXPECT_TRUE(has_event(*b.master, "emergency 0x0000 (error reset or no error)")) << events(*b.master);
  EXPECT_EQ(b.master->stats().last_wkc, 12);
  EXPECT_EQ(b.master->slave(0).emergencies, 0u);
}

// A segment whose per-slave configuration datagrams do not fit one frame (32 drives) reaches
// OP: each slave's datagrams go whole into a frame or wait for the next one. Before, slave
// 21's EEPROM read was cut off the frame and the start-up failed with an EEPROM read error.
// One image of 32 × 42 bytes still fits one LRW; the expected WKC is 3 × 32.
TEST(EcMaster, ASegmentLargerThanOneFramesConfigurationReachesOp) {
  Bench b(32);
  ASSERT_TRUE(b.to_op(200000)) << b.master->error() << "\n" << events(*b.master);
  for (int k = 0; k < 50; ++k) b.step();
  EXPECT_EQ(b.master->stats().last_wkc, 96);
  EXPECT_EQ(b.master->stats().wkc_errors, 0u);
}

// 70 drives: more station addresses than one frame chains APWRs (64), so the address phase
// takes two frames. Before, the APWRs of slaves 64… were silently left out, the phase went on,
// and slave 64 timed out reading its EEPROM at an address it never had. Their image (70 × 24
// bytes overlapped) then takes two LRW frames per cycle, and every drive gets its WKC.
TEST(EcMaster, SeventyDrivesAreAddressedOverTwoFramesAndCycleInTwo) {
  Bench b(70);
  ASSERT_TRUE(b.to_op(200000)) << b.master->error() << "\n" << events(*b.master);
  for (int i = 0; i < 70; ++i) EXPECT_EQ(b.slaves[static_cast<std::size_t>(i)]->esc().station_address(), 0x1001 + i);
  EXPECT_EQ(b.master->cyclic_frames(), 2);
  EXPECT_TRUE(b.master->image_in_own_frames());
  const auto sent = b.master->stats().frames_sent;
  for (int k = 0; k < 20; ++k) b.step();
  EXPECT_GE(b.master->stats().frames_sent - sent, 40u);  // the image's two frames every tick
  EXPECT_EQ(b.master->stats().last_wkc, 210);
  EXPECT_EQ(b.master->stats().wkc_errors, 0u);
}

TEST(EcMaster, MultiAxisSlaveOfSeed001ReachesOp) {
  const auto multi = omnitwin::ethercat::load_esi(OMNITWIN_SOURCE_DIR "/models/ethercat/omnitwin_multiaxis.xml");
  ASSERT_FALSE(multi.empty());
  omnitwin::ethercat::DriveSlave slave(multi[0], omnitwin::ethercat::DriveSlaveConfig{});
  omnitwin::ethercat::EscChain chain;
  chain.add(&slave.esc());
  EcMasterConfig cfg;
  cfg.devices = multi;
  std::vector<std::uint8_t> frame;
  EcMaster m(cfg, [&](std::span<const std::uint8_t> pdu) {
    frame.assign(pdu.begin(), pdu.end());
    return true;
  });
  SimTime t = 0;
  for (int k = 0; k < 20000 && !m.operational() && m.phase() != MasterPhase::failed; ++k, t += 1'000'000) {
    slave.cycle(t);
    chain.advance(t);
    frame.clear();
    m.tick(t);
    if (!frame.empty() && chain.process(frame, t)) m.on_frame(frame, t);
  }
  ASSERT_TRUE(m.operational()) << m.error() << "\n" << events(m);
  EXPECT_EQ(m.slave(0).out_bytes, slave.output_bytes());
  EXPECT_EQ(m.slave(0).in_bytes, slave.input_bytes());
  EXPECT_EQ(m.stats().expected_wkc, 3);
  EXPECT_EQ(m.slave(0).esi->product_code, 0x00000801u);
}

// Every status module of a multi-axis segment sits at its own slave's place in the image: an
// idle slot k reports card k + 1 (the slot driven by `commanded` reports card 3).
void expect_modules_at_their_slaves(const EcMaster& m, int commanded = -1) {
  for (int p = 0; p < m.slave_count(); ++p) {
    const auto& s = m.slave(p);
    for (std::uint32_t k = 0; k < s.in_bytes / 12; ++k) {
      const std::uint8_t card = m.image()[s.in_offset + 12 * k];
      EXPECT_EQ(card, p == commanded && k == 0 ? 3 : k + 1) << "slave " << p << " slot " << k;
    }
  }
}

// Issue 17, item 4: seed 001's 100 axes (12 slaves of 8 cards and one of 4, 12 bytes per card
// each way) are 2,400 image bytes, more than a frame holds; laid out overlapped (each slave's
// outputs and inputs on one logical range) they are 1,200 and cycle in one LRW at 100 µs. Every
// status module lands at its own slave's place (an idle slot k reports card k + 1), and a
// command written for the last slave's first slot reaches that slave alone.
TEST(EcMaster, AHundredAxesCycleInOneOverlappedLrwAndEachModuleLandsAtItsSlave) {
  ecbench::MultiAxisSegment seg(100, 100'000);
  ASSERT_EQ(seg.slaves.size(), 13u);
  ASSERT_TRUE(seg.to_op(400000)) << seg.master->error() << "\n" << events(*seg.master);
  EXPECT_TRUE(seg.master->image_overlapped());
  EXPECT_EQ(seg.master->lrw_bytes(), 1200u);
  EXPECT_EQ(seg.master->output_bytes(), 1200u);
  // The last slave, slot 0: card 3, velocity mode with the handshake bit toggled.
  const auto& last = seg.master->slave(12);
  ASSERT_EQ(last.out_bytes, 48u);
  auto img = seg.master->image();
  img[last.out_offset] = 3;
  img[last.out_offset + 1] = 0x82;  // mode 2, handshake bit 15
  for (int k = 0; k < 200; ++k) seg.step();
  EXPECT_EQ(seg.master->stats().last_wkc, 39);  // 3 per slave: outputs written, inputs read
  EXPECT_EQ(seg.master->stats().wkc_errors, 0u);
  EXPECT_EQ(seg.master->stats().lost_frames, 0u);
  expect_modules_at_their_slaves(*seg.master, 12);
  EXPECT_EQ(seg.master->image()[last.in_offset + 1] & 0x7F, 2);  // card 3 runs velocity mode
}

// Forced to the separate layout, the same segment's 2,400 bytes do not fit one frame: they
// are cut at a slave boundary into two LRW frames of their own per cycle (7 slaves of 192
// bytes in the first, 5 more and the 4-card slave in the second) behind the tick's frame (DC's
// FRMW), and every module still lands at its slave.
TEST(EcMaster, AHundredAxesLaidOutSeparatelyCycleInTwoFrames) {
  EcMasterConfig cfg;
  cfg.image_layout = ImageLayout::separate;
  ecbench::MultiAxisSegment seg(100, 100'000, cfg);
  ASSERT_TRUE(seg.to_op(400000)) << seg.master->error() << "\n" << events(*seg.master);
  EXPECT_FALSE(seg.master->image_overlapped());
  EXPECT_EQ(seg.master->cyclic_frames(), 2);
  EXPECT_EQ(seg.master->lrw_bytes(), 2400u);
  EXPECT_EQ(seg.master->slave(7).out_logical, 1344u);  // the second frame starts with slave 7
  EXPECT_EQ(seg.master->slave(7).in_logical, 1344u + 5 * 96 + 48);
  const auto& last = seg.master->slave(12);
  auto img = seg.master->image();
  img[last.out_offset] = 3;
  img[last.out_offset + 1] = 0x82;  // mode 2, handshake bit 15
  for (int k = 0; k < 200; ++k) seg.step();
  EXPECT_EQ(seg.n_more, 2u) << "the tick's frame, then the image's two";
  EXPECT_EQ(seg.master->stats().last_wkc, 39);  // the sum over both frames
  EXPECT_EQ(seg.master->stats().wkc_errors, 0u);
  EXPECT_EQ(seg.master->stats().lost_frames, 0u);
  expect_modules_at_their_slaves(*seg.master, 12);
  EXPECT_EQ(seg.master->image()[last.in_offset + 1] & 0x7F, 2);  // card 3 runs velocity mode
}

// 200 axes (25 slaves) do not fit one frame even overlapped (2,400 bytes): 15 slaves ride in
// one frame, 10 in a second one. The log says so. It also needs the DC set-up in
// several frames: 3 datagrams per slave for 25 slaves are more than the 64 a frame chains, and
// before, the last slaves' datagrams were cut off and the master waited in phase dc forever.
// Every slave gets the same SYNC0 start time.
TEST(EcMaster, TwoHundredAxesOverlappedTakeTwoFramesPerCycle) {
  ecbench::MultiAxisSegment seg(200, 1'000'000);
  ASSERT_TRUE(seg.to_op(40000)) << seg.master->error() << "\n" << events(*seg.master);
  const std::uint64_t start = seg.slaves[0]->esc().read64(0x0990);
  EXPECT_GT(start, 0u);
  for (const auto& sl : seg.slaves) EXPECT_EQ(sl->esc().read64(0x0990), start);
  EXPECT_TRUE(seg.master->image_overlapped());
  EXPECT_EQ(seg.master->cyclic_frames(), 2);
  EXPECT_EQ(seg.master->slave(15).out_logical, 15u * 96);
  for (int k = 0; k < 50; ++k) seg.step();
  EXPECT_EQ(seg.master->stats().last_wkc, 75);
  EXPECT_EQ(seg.master->stats().wkc_errors, 0u);
  expect_modules_at_their_slaves(*seg.master);
  EXPECT_NE(events(*seg.master).find("overlapped in 2400 bytes, in 2 frames of its own"), std::string::npos)
      << events(*seg.master);
}

// Seed 001's 100 axes at 100 µs lose their segment for 15 ms and get it back: every slave is
// in OP again within 1 s (10,000 cycles). Before, it took 9.1 s: one slave's PDO-mapping reads
// got no room beside the 1,200-byte image, because every idle mailbox polled first on the SM1
// event that slave's own pending reply kept raising, and the slaves were always served in the
// same order. Transfers now go before polls, and the order turns by one each frame.
TEST(EcMaster, ALostHundredAxisSegmentIsBackInOpWithinASecond) {
  ecbench::MultiAxisSegment seg(100, 100'000);
  ASSERT_TRUE(seg.to_op(400000)) << seg.master->error();
  for (int k = 0; k < 100; ++k) seg.step();
  seg.drop_all = 150;
  for (int k = 0; k < 150; ++k) seg.step();
  ASSERT_TRUE(seg.master->segment_lost());
  int k = 0;
  for (; k < 10'000 && !seg.master->operational(); ++k) seg.step();
  EXPECT_TRUE(seg.master->operational()) << events(*seg.master);
  EXPECT_FALSE(seg.master->segment_lost());
  EXPECT_EQ(seg.master->stats().segment_returns, 1u);
  for (int j = 0; j < 100; ++j) seg.step();
  EXPECT_EQ(seg.master->stats().last_wkc, 39);
}

// A cap on the frames per cycle refuses an image that needs more, naming both numbers.
TEST(EcMaster, AnImageNeedingMoreFramesThanAllowedIsRefused) {
  EcMasterConfig cfg;
  cfg.image_layout = ImageLayout::separate;
  cfg.max_cyclic_frames = 1;
  ecbench::MultiAxisSegment seg(100, 100'000, cfg);
  EXPECT_FALSE(seg.to_op(400000));
  EXPECT_EQ(seg.master->phase(), MasterPhase::failed);
  EXPECT_NE(seg.master->error().find("process image of 2400 bytes needs 2 frames, more than max_cyclic_frames 1"),
            std::string::npos)
      << seg.master->error();
}

// The image's second frame lost three times: three lost frames and three WKC errors whose
// WKC is the first frame's share (15 slaves × 3); the segment is not silent (the first frame came back), the
// AL status reads find every slave in OP, and the next complete cycles are clean again.
TEST(EcMaster, ALostFurtherFrameCostsItsShareOfTheWkcNotTheSegment) {
  ecbench::MultiAxisSegment seg(200, 1'000'000);
  ASSERT_TRUE(seg.to_op(40000)) << seg.master->error();
  for (int k = 0; k < 20; ++k) seg.step();
  const auto before = seg.master->stats();
  seg.drop_last = 3;
  for (int k = 0; k < 4; ++k) seg.step();  // the fourth tick notices the third loss
  EXPECT_EQ(seg.master->stats().lost_frames - before.lost_frames, 3u);
  EXPECT_EQ(seg.master->stats().wkc_errors - before.wkc_errors, 3u);
  EXPECT_FALSE(seg.master->segment_lost());
  for (int k = 0; k < 300; ++k) seg.step();
  EXPECT_EQ(seg.master->stats().wkc_errors - before.wkc_errors, 3u);
  EXPECT_EQ(seg.master->stats().last_wkc, 75);
  EXPECT_TRUE(seg.master->operational()) << events(*seg.master);
  EXPECT_EQ(seg.master->stats().slaves_lost, 0u);
  EXPECT_NE(events(*seg.master).find("WKC 45 instead of 75 for 3 cycles (frame lost)"), std::string::npos)
      << events(*seg.master);
}

TEST(EcMaster, PoweredOffDcSlaveRejoinsDistributedClocks) {
  EcMasterConfig cfg;
  cfg.dc = true;
  cfg.probe_every_ns = 10'000'000;
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  for (int k = 0; k < 50; ++k) b.step();
  b.chain.set_powered(3, false, b.t);
  for (int k = 0; k < 30; ++k) b.step();
  EXPECT_EQ(b.master->slave(3).step, SlaveStep::offline);
  b.chain.set_powered(3, true, b.t);
  EXPECT_EQ(b.chain.esc(3).read8(0x0981), 0);  // power-on state: SYNC0 off
  ASSERT_TRUE(b.run_until([&] { return b.master->operational(); }, 20000)) << events(*b.master);
  EXPECT_TRUE(has_event(*b.master, "slave 4 (station 0x1004) rejoins distributed clocks")) << events(*b.master);
  EXPECT_EQ(b.chain.esc(3).read8(0x0981) & 0x03, 0x03);
  EXPECT_EQ(b.chain.esc(3).read32(0x09A0), 1'000'000u);
  // right after rejoining its system time is within microseconds of the reference's, and the
  // FRMW 0x0910 every cycle lets the ESC's drift control close the rest
  auto diff = [&] { return std::llabs(static_cast<long long>(b.chain.esc(3).system_time(b.t) - b.chain.esc(0).system_time(b.t))); };
  EXPECT_LT(diff(), 20'000);
  for (int k = 0; k < 500; ++k) b.step();
  EXPECT_LT(diff(), 100);
  EXPECT_EQ(b.master->stats().last_wkc, 12);
}

namespace {
// A mailbox-less digital I/O slave (no CoE): 1 output byte at SM0, 2 input bytes at SM1.
struct IoApp : omnitwin::ethercat::EscApplication {
  std::vector<std::uint8_t> outputs;
  omnitwin::ethercat::AlStatusCode on_al_request(omnitwin::ethercat::AlState, omnitwin::ethercat::AlState,
                                                 omnitwin::ethercat::SimTime) override {
    return omnitwin::ethercat::AlStatusCode::none;
  }
  void on_mailbox(std::span<const std::uint8_t>, omnitwin::ethercat::SimTime) override {}
  void on_outputs(std::span<const std::uint8_t> o, omnitwin::ethercat::SimTime) override { outputs.assign(o.begin(), o.end()); }
};
omnitwin::ethercat::DeviceDescription io_device() {
  namespace ec = omnitwin::ethercat;
  ec::DeviceDescription d;
  d.vendor_id = 0x00000F1C;
  d.product_code = 0x00001010;
  d.name = "io 8/16";
  d.sms = {{0x1000, 0, 0x64, true, ec::SmKind::outputs}, {0x1100, 0, 0x20, true, ec::SmKind::inputs}};
  d.rx_pdos = {{0x1600, "out", 0, true, true, {{0x7000, 1, 8, "out", "USINT"}}}};
  d.tx_pdos = {{0x1A00, "in", 1, true, true, {{0x6000, 1, 16, "in", "UINT"}}}};
  return d;
}
}  // namespace

TEST(EcMaster, SlaveWithoutCoeIsLaidOutFromItsSiiPdoCategories) {
  namespace ec = omnitwin::ethercat;
  const ec::DeviceDescription io = io_device();
  IoApp app;
  ec::EscConfig ecfg;
  ecfg.sii = ec::build_sii(io);
  ec::Esc esc(ecfg, &app);
  auto devs = ecbench::drive_esi();
  ec::DriveSlave drive(devs[0], ec::DriveSlaveConfig{});
  ec::EscChain chain;
  chain.add(&esc);
  chain.add(&drive.esc());
  EcMasterConfig cfg;
  cfg.devices = devs;
  cfg.devices.push_back(io);
  std::vector<std::uint8_t> frame;
  EcMaster m(cfg, [&](std::span<const std::uint8_t> pdu) {
    frame.assign(pdu.begin(), pdu.end());
    return true;
  });
  SimTime t = 0;
  auto step = [&] {
    drive.cycle(t);
    const std::uint8_t in[2] = {0x34, 0x12};
    esc.write_inputs(in);
    chain.advance(t);
    frame.clear();
    m.tick(t);
    if (!frame.empty() && chain.process(frame, t)) m.on_frame(frame, t);
    t += 1'000'000;
  };
  for (int k = 0; k < 20000 && !m.operational() && m.phase() != MasterPhase::failed; ++k) step();
  ASSERT_TRUE(m.operational()) << m.error() << "\n" << events(m);
  EXPECT_FALSE(m.slave(0).sii.has_coe());
  EXPECT_FALSE(m.slave(0).pdo_from_coe);
  EXPECT_TRUE(m.slave(1).pdo_from_coe);
  EXPECT_EQ(m.slave(0).out_bytes, 1u);
  EXPECT_EQ(m.slave(0).in_bytes, 2u);
  EXPECT_EQ(m.stats().expected_wkc, 6);
  EXPECT_EQ(m.slave(1).out_offset, 1u);  // outputs of both slaves first, then the inputs
  EXPECT_EQ(m.slave(0).in_offset, 1u + m.slave(1).out_bytes);
  const auto out = m.find_entry(0, 0x7000, 1);
  ASSERT_TRUE(out.has_value());
  m.write_entry(*out, 0xA5);
  for (int k = 0; k < 3; ++k) step();
  EXPECT_EQ(app.outputs, std::vector<std::uint8_t>{0xA5});
  EXPECT_EQ(m.read_entry(*m.find_entry(0, 0x6000, 1), false), 0x1234);
  EXPECT_EQ(m.stats().last_wkc, 6);
  EXPECT_EQ(m.sdo_upload(0, 0x1000, 0), 0u);  // no mailbox: refused
}

TEST(EcMaster, SegmentCutOffLeavesOpAfterTheConfiguredCyclesAndCountsEveryLostCycle) {
  EcMasterConfig cfg;
  cfg.segment_loss_cycles = 5;
  cfg.segment_loss_ns = 0;  // the cycle count alone (1 ms cycles)
  cfg.probe_every_ns = 10'000'000;
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  for (int k = 0; k < 20; ++k) b.step();
  const EcMasterStats before = b.master->stats();
  ASSERT_EQ(before.wkc_errors, 0u);
  b.drop_next = 1'000'000;  // the segment vanishes: no frame comes back
  b.step();                 // this cycle's frame goes out and is lost
  for (int k = 0; k < 4; ++k) b.step();
  EXPECT_TRUE(b.master->operational()) << "4 lost cycles are below the limit of 5";
  EXPECT_EQ(b.master->stats().lost_frames - before.lost_frames, 4u);
  EXPECT_EQ(b.master->stats().wkc_errors, 4u);
  b.step();
  EXPECT_TRUE(b.master->segment_lost()) << events(*b.master);
  EXPECT_FALSE(b.master->operational());
  EXPECT_EQ(b.master->stop_reason(),
            "segment lost: 5 consecutive cycles without a valid WKC; leaving OP, drives stopped");
  EXPECT_TRUE(has_event(*b.master, "segment lost: 5 consecutive cycles")) << events(*b.master);
  EXPECT_EQ(b.master->stats().segment_losses, 1u);
  EXPECT_EQ(b.master->stats().slaves_lost, 4u);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(b.master->slave(i).step, SlaveStep::offline);
  for (int k = 0; k < 100; ++k) b.step();
  EXPECT_EQ(b.master->stats().lost_frames - before.lost_frames, 105u);
  EXPECT_EQ(b.master->stats().wkc_errors, 105u) << "every cycle whose frame never returned is a WKC error";
  EXPECT_EQ(b.master->stats().cycles, before.cycles);
  EXPECT_EQ(b.master->stats().segment_losses, 1u) << "one loss, logged once";
}

// At short cycles a host stall of a few ms is not a lost segment: 10 silent cycles of 100 µs
// (1 ms) keep the master in OP, 10 ms (segment_loss_ns, the default) do not.
TEST(EcMaster, AtShortCyclesTheSegmentIsLostOnlyAfterSegmentLossNs) {
  EcMasterConfig cfg;
  cfg.cycle_ns = 100'000;
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op(200000)) << b.master->error();
  for (int k = 0; k < 20; ++k) b.step();
  b.drop_next = 20;  // 2 ms without an answer
  for (int k = 0; k < 40; ++k) b.step();
  EXPECT_FALSE(b.master->segment_lost()) << events(*b.master);
  EXPECT_TRUE(b.master->operational());
  EXPECT_EQ(b.master->stats().segment_losses, 0u);
  b.drop_next = 1'000'000;
  for (int k = 0; k < 99; ++k) b.step();  // 99 × 100 µs: still short of 10 ms
  EXPECT_FALSE(b.master->segment_lost());
  b.step();
  b.step();
  EXPECT_TRUE(b.master->segment_lost()) << events(*b.master);
}

TEST(EcMaster, LostSegmentComesBackThroughTheOfflineProbes) {
  EcMasterConfig cfg;
  cfg.segment_loss_cycles = 3;
  cfg.segment_loss_ns = 0;  // the cycle count alone (1 ms cycles)
  cfg.probe_every_ns = 10'000'000;
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.drop_next = 200;
  for (int k = 0; k < 200; ++k) b.step();
  ASSERT_TRUE(b.master->segment_lost()) << events(*b.master);
  ASSERT_TRUE(b.run_until([&] { return b.master->operational(); }, 20000)) << events(*b.master);
  EXPECT_FALSE(b.master->segment_lost());
  EXPECT_EQ(b.master->stats().segment_losses, 1u);
  EXPECT_EQ(b.master->stats().segment_returns, 1u);
  EXPECT_GE(b.master->stats().recoveries, 4u);
  EXPECT_TRUE(has_event(*b.master, "segment back: all 4 slaves in OP again")) << events(*b.master);
  EXPECT_FALSE(b.master->stop_reason().empty()) << "why it left OP stays on record";
  const auto errors = b.master->stats().wkc_errors;
  for (int k = 0; k < 100; ++k) b.step();
  EXPECT_EQ(b.master->stats().wkc_errors, errors);
  EXPECT_EQ(b.master->stats().last_wkc, 12);
}

TEST(EcMaster, PoweredOffSegmentIsLostAndBackWhenPoweredOn) {
  EcMasterConfig cfg;
  cfg.segment_loss_cycles = 4;
  cfg.segment_loss_ns = 0;  // the cycle count alone (1 ms cycles)
  cfg.probe_every_ns = 10'000'000;
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  for (int i = 0; i < 4; ++i) b.chain.set_powered(i, false, b.t);
  ASSERT_TRUE(b.run_until([&] { return b.master->segment_lost(); }, 20)) << events(*b.master);
  EXPECT_EQ(b.master->stats().lost_frames, 4u) << "no slave powered: nothing comes back";
  EXPECT_EQ(b.master->stats().wkc_errors, 4u);
  EXPECT_FALSE(b.master->operational());
  for (int i = 0; i < 4; ++i) b.chain.set_powered(i, true, b.t);
  ASSERT_TRUE(b.run_until([&] { return b.master->operational(); }, 20000)) << events(*b.master);
  EXPECT_EQ(b.master->stats().segment_returns, 1u);
}

TEST(EcMaster, FramesComingBackUntouchedAreASilentSegmentToo) {
  EcMasterConfig cfg;
  cfg.segment_loss_cycles = 4;
  cfg.segment_loss_ns = 0;  // the cycle count alone (1 ms cycles)
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  // A link closed right at the master's port: every frame returns as sent, WKC 0.
  for (int k = 0; k < 4; ++k) {
    b.t += b.cycle;
    b.sent = false;
    b.master->tick(b.t);
    ASSERT_TRUE(b.sent);
    b.master->on_frame(b.frame, b.t + 50'000);
  }
  EXPECT_TRUE(b.master->segment_lost()) << events(*b.master);
  EXPECT_EQ(b.master->stats().lost_frames, 0u);
  EXPECT_EQ(b.master->stats().last_wkc, 0);
  EXPECT_EQ(b.master->stats().wkc_errors, 4u);
  EXPECT_FALSE(b.master->operational());
}

TEST(EcMaster, SegmentWatchOffKeepsCountingButNeverLeavesOp) {
  EcMasterConfig cfg;
  cfg.segment_loss_cycles = 0;
  Bench b(4, cfg);
  ASSERT_TRUE(b.to_op()) << b.master->error();
  b.drop_next = 50;
  for (int k = 0; k < 51; ++k) b.step();  // the 50th lost frame is noticed by the 51st tick
  EXPECT_FALSE(b.master->segment_lost());
  EXPECT_EQ(b.master->stats().segment_losses, 0u);
  EXPECT_EQ(b.master->stats().wkc_errors, 50u);
  EXPECT_TRUE(b.master->stop_reason().empty());
}
