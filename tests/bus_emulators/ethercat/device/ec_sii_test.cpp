// Tests bus_emulators/ethercat/device/ec_sii: the SII EEPROM word image built from the shipped
// drive ESI — configuration-area checksum (golden CRC-8), identity, mailbox words, protocols,
// size/version, and a walk over the categories (strings, general with CoE details, FMMU,
// SyncManagers, TxPDO/RxPDO, DC) up to the end marker.
#include "bus_emulators/ethercat/device/ec_sii.hpp"

#include <gtest/gtest.h>

#include <map>
#include <string>

namespace omnitwin::ethercat {
namespace {

DeviceDescription drive_desc() {
  return load_esi(std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/omnitwin_drive.xml").at(0);
}

std::uint8_t byte_at(const std::vector<std::uint16_t>& w, std::size_t word, std::size_t b) {
  const std::size_t a = word * 2 + b;
  return static_cast<std::uint8_t>(w[a / 2] >> (8 * (a % 2)));
}

TEST(EcSii, Crc8GoldenValues) {
  // Computed independently (Python, bitwise MSB-first, poly 0x07, init 0xFF).
  const std::uint8_t cfg[14] = {0x08, 0x0E, 0x00, 0xCC, 0x00, 0x00, 0, 0, 0, 0, 0, 0, 0, 0};
  EXPECT_EQ(sii_crc8(cfg), 0x3C);
  const std::uint8_t with_alias[14] = {0x08, 0x0E, 0x00, 0xCC, 0x00, 0x00, 0, 0, 0x34, 0x12, 0, 0, 0, 0};
  EXPECT_EQ(sii_crc8(with_alias), 0xCB);
  const std::string check = "123456789";
  EXPECT_EQ(sii_crc8({reinterpret_cast<const std::uint8_t*>(check.data()), check.size()}), 0xFB);
}

TEST(EcSii, HeaderWords) {
  const auto w = build_sii(drive_desc(), 0x1234, 0xCAFEBABE);
  ASSERT_EQ(w.size(), 1024u);  // 2048 bytes
  EXPECT_EQ(w[0], 0x0E08);
  EXPECT_EQ(w[1], 0xCC00);
  EXPECT_EQ(w[4], 0x1234);     // configured station alias
  EXPECT_EQ(w[7], 0x00CB);     // checksum in the low byte
  EXPECT_EQ(w[sii::vendor_id], 0x0F1C);
  EXPECT_EQ(w[sii::vendor_id + 1], 0x0000);
  EXPECT_EQ(w[sii::product_code], 0x0402);
  EXPECT_EQ(w[sii::revision], 0x0000);
  EXPECT_EQ(w[sii::revision + 1], 0x0001);
  EXPECT_EQ(w[sii::serial], 0xBABE);
  EXPECT_EQ(w[sii::serial + 1], 0xCAFE);
  EXPECT_EQ(w[sii::mbx_rx_offset], 0x1000);
  EXPECT_EQ(w[sii::mbx_rx_size], 128);
  EXPECT_EQ(w[sii::mbx_tx_offset], 0x1080);
  EXPECT_EQ(w[sii::mbx_tx_size], 128);
  EXPECT_EQ(w[sii::mbx_protocols], sii::proto_coe);
  EXPECT_EQ(w[sii::size], 15);  // 16 KiBit − 1
  EXPECT_EQ(w[sii::version], 1);
  EXPECT_EQ(build_sii(drive_desc())[7], 0x003C);
}

TEST(EcSii, CategoryWalk) {
  const auto w = build_sii(drive_desc());
  std::map<std::uint16_t, std::pair<std::size_t, std::size_t>> cats;  // type → (first data word, words)
  std::vector<std::uint16_t> order;
  std::size_t at = sii::first_category;
  while (at < w.size() && w[at] != sii::cat_end) {
    cats[w[at]] = {at + 2, w[at + 1]};
    order.push_back(w[at]);
    at += 2 + w[at + 1];
  }
  ASSERT_LT(at, w.size());
  EXPECT_EQ(w[at], 0xFFFF);
  EXPECT_EQ(order, (std::vector<std::uint16_t>{10, 30, 40, 41, 50, 51, 60}));

  // Strings: string 1 is the device name (the general category's name index says so).
  const auto [s0, sn] = cats[sii::cat_strings];
  const std::size_t first = byte_at(w, s0, 0);
  EXPECT_GT(first, 3u);
  const std::size_t len1 = byte_at(w, s0, 1);
  std::string name1;
  for (std::size_t i = 0; i < len1; ++i) name1 += static_cast<char>(byte_at(w, s0, 2 + i));
  EXPECT_EQ(name1, "omnitwin drive 1-axis");

  const auto [g0, gn] = cats[sii::cat_general];
  EXPECT_EQ(gn, 16u);
  EXPECT_EQ(byte_at(w, g0, 3), 1);         // name index
  EXPECT_EQ(byte_at(w, g0, 5), 0x2F);      // CoE: SDO, SDO info, PDO assign, PDO config, complete access
  EXPECT_EQ(byte_at(w, g0, 9), 1);         // DS402 channels
  EXPECT_EQ(byte_at(w, g0, 11) & 0x02, 0); // LRW supported

  const auto [f0, fn] = cats[sii::cat_fmmu];
  EXPECT_EQ(byte_at(w, f0, 0), 1);
  EXPECT_EQ(byte_at(w, f0, 1), 2);
  EXPECT_EQ(byte_at(w, f0, 2), 3);

  const auto [m0, mn] = cats[sii::cat_syncm];
  ASSERT_EQ(mn, 16u);  // 4 SMs × 8 bytes
  EXPECT_EQ(w[m0 + 0], 0x1000);
  EXPECT_EQ(w[m0 + 1], 128);
  EXPECT_EQ(byte_at(w, m0, 4), 0x26);
  EXPECT_EQ(byte_at(w, m0, 7), 1);         // type mailbox out
  EXPECT_EQ(w[m0 + 8], 0x1100);            // SM2
  EXPECT_EQ(w[m0 + 9], 18);                // RxPDO 0x1600: 144 bits
  EXPECT_EQ(byte_at(w, m0 + 8, 4), 0x64);
  EXPECT_EQ(byte_at(w, m0 + 8, 7), 3);
  EXPECT_EQ(w[m0 + 13], 24);               // SM3: TxPDO 0x1A00: 192 bits
  EXPECT_EQ(byte_at(w, m0 + 12, 7), 4);

  const auto [t0, tn] = cats[sii::cat_txpdo];
  EXPECT_EQ(w[t0], 0x1A00);
  EXPECT_EQ(byte_at(w, t0, 2), 9);         // entries
  EXPECT_EQ(byte_at(w, t0, 3), 3);         // SM3
  EXPECT_EQ(w[t0 + 4], 0x6041);            // first entry index
  EXPECT_EQ(byte_at(w, t0 + 4, 2), 0);     // subindex
  EXPECT_EQ(byte_at(w, t0 + 4, 4), 0x06);  // UNSIGNED16
  EXPECT_EQ(byte_at(w, t0 + 4, 5), 16);    // bits
  const std::size_t second = t0 + 4 + 9 * 4;  // next PDO header after 9 entries
  EXPECT_EQ(w[second], 0x1A01);
  EXPECT_EQ(byte_at(w, second, 3), 0xFF);  // not assigned by default

  const auto [r0, rn] = cats[sii::cat_rxpdo];
  EXPECT_EQ(w[r0], 0x1600);
  EXPECT_EQ(byte_at(w, r0, 3), 2);         // SM2
  EXPECT_EQ(w[r0 + 4 + 4], 0x607A);        // second entry
  EXPECT_EQ(byte_at(w, r0 + 8, 4), 0x04);  // INTEGER32

  const auto [d0, dn] = cats[sii::cat_dc];
  EXPECT_EQ(dn, 24u);                      // two op modes × 24 bytes
  EXPECT_EQ(w[d0 + 7], 0x0300);            // AssignActivate of op mode "DC"
}

TEST(EcSii, TooSmallEepromIsAnError) {
  auto d = drive_desc();
  d.eeprom_bytes = 128;
  EXPECT_THROW(build_sii(d), EsiError);
}

}  // namespace
}  // namespace omnitwin::ethercat
