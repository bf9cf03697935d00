// controller/ethercat — what the master takes from a slave's SII EEPROM image (facts/ethercat.md
// "SII EEPROM").
//
// The core reads the EEPROM word by word through the ESC's EEPROM registers (0x0502..0x050F);
// this file says when enough words have arrived (the fixed header plus the category chain up
// to its 0xFFFF end marker) and turns the words into the identity, the mailbox layout, the
// SyncManager list and the PDO categories. Pure functions over a word vector so that they can
// be tested with golden images; set-up code (allocates).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace omnitwin::controller::ethercat {

inline constexpr std::size_t kSiiMaxWords = 0x2000;  // 16 KiB: we stop reading past this

struct SiiSyncManager {
  std::uint16_t start = 0, length = 0;
  std::uint8_t control = 0, status = 0, enable = 0, type = 0;  // type: 1 mbx out, 2 mbx in, 3 outputs, 4 inputs
};

struct PdoEntryInfo {
  std::uint16_t index = 0;  // 0 = gap
  std::uint8_t sub = 0;
  std::uint8_t bits = 0;
};

struct PdoInfo {
  std::uint16_t index = 0;
  int sm = -1;
  std::vector<PdoEntryInfo> entries;
  std::uint32_t bits() const;
};

struct SiiInfo {
  std::uint32_t vendor = 0, product = 0, revision = 0, serial = 0;
  std::uint16_t mbx_out_start = 0, mbx_out_size = 0, mbx_in_start = 0, mbx_in_size = 0;
  std::uint16_t mbx_protocols = 0;  // bit 2 = CoE
  std::uint8_t coe_details = 0;     // general category byte 5 (bit 0 SDO, bit 1 SDO info, bit 5 complete access)
  bool no_lrw = false;              // general category flags bit 1
  std::string name;                 // general category's name string, "" when none
  std::vector<SiiSyncManager> sms;  // category 41, entry i = SM i
  std::vector<PdoInfo> tx_pdos, rx_pdos;  // categories 50 / 51
  bool has_coe() const { return (mbx_protocols & 0x0004) != 0 && mbx_out_size > 0; }
};

enum class SiiScan : std::uint8_t {
  need_more,  // read at least `need` words
  complete,   // the category chain ends inside the words read
  malformed,  // a category runs past kSiiMaxWords
};
// Whether `words` (read from word 0) hold the whole image; sets *need to the word count
// wanted next when need_more. Real-time safe.
SiiScan sii_scan(std::span<const std::uint16_t> words, std::size_t* need);

// Decodes a complete image (missing categories leave their fields empty). Allocates.
SiiInfo parse_sii(std::span<const std::uint16_t> words);

}  // namespace omnitwin::controller::ethercat
