// Tests controller/ethercat/ec_sii_reader: when a word-by-word SII read is complete (category
// chain and its 0xFFFF end), and the decoding of identity, mailbox, SyncManager and PDO
// categories — against a hand-built golden image and against the image B's build_sii() makes
// from models/ethercat/omnitwin_drive.xml.
#include "controller/ethercat/ec_sii_reader.hpp"

#include <gtest/gtest.h>

#include "bus_emulators/ethercat/device/ec_esi.hpp"
#include "bus_emulators/ethercat/device/ec_sii.hpp"

using namespace omnitwin::controller::ethercat;

namespace {
std::vector<std::uint16_t> golden_image() {
  std::vector<std::uint16_t> w(0x40, 0);
  w[0x08] = 0x0F1C; w[0x09] = 0x0000;   // vendor
  w[0x0A] = 0x0402; w[0x0B] = 0x0001;   // product 0x00010402
  w[0x0C] = 0x0003;                     // revision
  w[0x18] = 0x1000; w[0x19] = 128; w[0x1A] = 0x1080; w[0x1B] = 128; w[0x1C] = 0x0004;
  // strings: 1 string "ab"
  w.insert(w.end(), {10, 2, 0x0201, 0x6261});
  // general: name string 1 (byte 3), CoE details 0x23 (byte 5), flags no-LRW (byte 11)
  w.insert(w.end(), {30, 6, 0x0000, 0x0100, 0x2300, 0x0000, 0x0000, 0x0200});
  // SMs: SM2 outputs at 0x1100 control 0x64, SM3 inputs at 0x1180 control 0x20
  w.insert(w.end(), {41, 8, 0x1100, 0x0000, 0x0064, 0x0301, 0x1180, 0x0000, 0x0020, 0x0401});
  // RXPDO 0x1600, 1 entry, SM 2: 0x6040:0 16 bits
  w.insert(w.end(), {51, 8, 0x1600, 0x0201, 0x0000, 0x0000, 0x6040, 0x0000, 0x1000, 0x0000});
  w.push_back(0xFFFF);
  return w;
}
}  // namespace

TEST(EcSiiReader, ScanAsksForMoreUntilTheEndMarker) {
  const auto w = golden_image();
  std::size_t need = 0;
  EXPECT_EQ(sii_scan(std::span(w).first(0x10), &need), SiiScan::need_more);
  EXPECT_EQ(need, 0x42u);
  EXPECT_EQ(sii_scan(std::span(w).first(0x42), &need), SiiScan::need_more);
  EXPECT_EQ(need, 0x40u + 4 + 1);  // the strings category, then the next header
  EXPECT_EQ(sii_scan(std::span(w).first(w.size() - 1), &need), SiiScan::need_more);
  EXPECT_EQ(sii_scan(w, &need), SiiScan::complete);
}

TEST(EcSiiReader, ScanRejectsAChainPastTheEeprom) {
  std::vector<std::uint16_t> w(0x40, 0);
  w.insert(w.end(), {10, 0xFFF0});
  std::size_t need = 0;
  EXPECT_EQ(sii_scan(w, &need), SiiScan::malformed);
}

TEST(EcSiiReader, GoldenImageDecodes) {
  const SiiInfo s = parse_sii(golden_image());
  EXPECT_EQ(s.vendor, 0x0F1Cu);
  EXPECT_EQ(s.product, 0x00010402u);
  EXPECT_EQ(s.revision, 3u);
  EXPECT_EQ(s.mbx_out_start, 0x1000);
  EXPECT_EQ(s.mbx_in_start, 0x1080);
  EXPECT_EQ(s.mbx_in_size, 128);
  EXPECT_TRUE(s.has_coe());
  EXPECT_EQ(s.coe_details, 0x23);
  EXPECT_TRUE(s.no_lrw);
  EXPECT_EQ(s.name, "ab");
  ASSERT_EQ(s.sms.size(), 2u);
  EXPECT_EQ(s.sms[0].start, 0x1100);
  EXPECT_EQ(s.sms[0].control, 0x64);
  EXPECT_EQ(s.sms[0].type, 3);
  EXPECT_EQ(s.sms[1].type, 4);
  ASSERT_EQ(s.rx_pdos.size(), 1u);
  EXPECT_EQ(s.rx_pdos[0].index, 0x1600);
  EXPECT_EQ(s.rx_pdos[0].sm, 2);
  ASSERT_EQ(s.rx_pdos[0].entries.size(), 1u);
  EXPECT_EQ(s.rx_pdos[0].entries[0].index, 0x6040);
  EXPECT_EQ(s.rx_pdos[0].entries[0].bits, 16);
  EXPECT_TRUE(s.tx_pdos.empty());
}

TEST(EcSiiReader, DriveEsiImageMatchesTheDescription) {
  const auto devs = omnitwin::ethercat::load_esi(OMNITWIN_SOURCE_DIR "/models/ethercat/omnitwin_drive.xml");
  ASSERT_FALSE(devs.empty());
  const auto& d = devs[0];
  const auto words = omnitwin::ethercat::build_sii(d, 0, 77);
  std::size_t need = 0;
  ASSERT_EQ(sii_scan(words, &need), SiiScan::complete);
  const SiiInfo s = parse_sii(words);
  EXPECT_EQ(s.vendor, d.vendor_id);
  EXPECT_EQ(s.product, d.product_code);
  EXPECT_EQ(s.revision, d.revision);
  EXPECT_EQ(s.serial, 77u);
  EXPECT_TRUE(s.has_coe());
  const int out = d.sm_of_kind(omnitwin::ethercat::SmKind::outputs);
  ASSERT_GE(out, 0);
  ASSERT_GT(s.sms.size(), static_cast<std::size_t>(out));
  EXPECT_EQ(s.sms[out].start, d.sms[out].start);
  EXPECT_EQ(s.sms[out].type, 3);
  ASSERT_EQ(s.rx_pdos.size(), d.rx_pdos.size());
  for (std::size_t i = 0; i < d.rx_pdos.size(); ++i) {
    EXPECT_EQ(s.rx_pdos[i].index, d.rx_pdos[i].index);
    EXPECT_EQ(s.rx_pdos[i].bits(), d.rx_pdos[i].bit_size());
  }
}
