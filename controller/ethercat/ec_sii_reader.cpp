// controller/ethercat — SII image decoding (see ec_sii_reader.hpp).
#include "controller/ethercat/ec_sii_reader.hpp"

namespace omnitwin::controller::ethercat {

namespace {
constexpr std::size_t kFirstCategory = 0x40;
std::uint32_t u32w(std::span<const std::uint16_t> w, std::size_t i) {
  return i + 1 < w.size() ? (static_cast<std::uint32_t>(w[i]) | (static_cast<std::uint32_t>(w[i + 1]) << 16)) : 0;
}
std::uint8_t byte_at(std::span<const std::uint16_t> w, std::size_t byte) {
  const std::size_t i = byte / 2;
  if (i >= w.size()) return 0;
  return static_cast<std::uint8_t>(byte % 2 ? w[i] >> 8 : w[i]);
}
std::uint16_t u16b(std::span<const std::uint16_t> w, std::size_t byte) {
  return static_cast<std::uint16_t>(byte_at(w, byte) | (byte_at(w, byte + 1) << 8));
}
}  // namespace

std::uint32_t PdoInfo::bits() const {
  std::uint32_t n = 0;
  for (const auto& e : entries) n += e.bits;
  return n;
}

SiiScan sii_scan(std::span<const std::uint16_t> words, std::size_t* need) {
  std::size_t at = kFirstCategory;
  for (;;) {
    if (at + 2 > kSiiMaxWords) return SiiScan::malformed;
    if (words.size() < at + 1) {
      *need = at + 2;
      return SiiScan::need_more;
    }
    if (words[at] == 0xFFFF) return SiiScan::complete;
    if (words.size() < at + 2) {
      *need = at + 2;
      return SiiScan::need_more;
    }
    const std::size_t next = at + 2 + words[at + 1];
    if (next > kSiiMaxWords) return SiiScan::malformed;
    if (words.size() < next + 1) {
      *need = next + 1;
      return SiiScan::need_more;
    }
    at = next;
  }
}

SiiInfo parse_sii(std::span<const std::uint16_t> w) {
  SiiInfo s;
  s.vendor = u32w(w, 0x08);
  s.product = u32w(w, 0x0A);
  s.revision = u32w(w, 0x0C);
  s.serial = u32w(w, 0x0E);
  if (w.size() > 0x1C) {
    s.mbx_out_start = w[0x18];
    s.mbx_out_size = w[0x19];
    s.mbx_in_start = w[0x1A];
    s.mbx_in_size = w[0x1B];
    s.mbx_protocols = w[0x1C];
  }
  std::vector<std::string> strings;
  std::uint8_t name_index = 0;
  std::size_t at = kFirstCategory;
  while (at + 2 <= w.size() && w[at] != 0xFFFF) {
    const std::uint16_t type = w[at] & 0x7FFF;
    const std::size_t count = w[at + 1];
    if (at + 2 + count > w.size()) break;
    const auto cat = w.subspan(at + 2, count);
    const std::size_t bytes = count * 2;
    switch (type) {
      case 10: {  // strings
        std::size_t b = 1;
        const std::size_t n = byte_at(cat, 0);
        for (std::size_t i = 0; i < n && b < bytes; ++i) {
          const std::size_t len = byte_at(cat, b);
          std::string str;
          for (std::size_t k = 0; k < len; ++k) str.push_back(static_cast<char>(byte_at(cat, b + 1 + k)));
          strings.push_back(std::move(str));
          b += 1 + len;
        }
        break;
      }
      case 30:  // general
        name_index = byte_at(cat, 3);
        s.coe_details = byte_at(cat, 5);
        s.no_lrw = (byte_at(cat, 11) & 0x02) != 0;
        break;
      case 41:  // sync managers
        for (std::size_t b = 0; b + 8 <= bytes; b += 8) {
          SiiSyncManager sm;
          sm.start = u16b(cat, b);
          sm.length = u16b(cat, b + 2);
          sm.control = byte_at(cat, b + 4);
          sm.status = byte_at(cat, b + 5);
          sm.enable = byte_at(cat, b + 6);
          sm.type = byte_at(cat, b + 7);
          s.sms.push_back(sm);
        }
        break;
      case 50:
      case 51: {  // TXPDO / RXPDO
        std::size_t b = 0;
        while (b + 8 <= bytes) {
          PdoInfo pdo;
          pdo.index = u16b(cat, b);
          const std::size_t n = byte_at(cat, b + 2);
          const std::uint8_t sm = byte_at(cat, b + 3);
          pdo.sm = sm == 0xFF ? -1 : sm;
          b += 8;
          for (std::size_t i = 0; i < n && b + 8 <= bytes; ++i, b += 8) {
            pdo.entries.push_back({u16b(cat, b), byte_at(cat, b + 2), byte_at(cat, b + 5)});
          }
          (type == 50 ? s.tx_pdos : s.rx_pdos).push_back(std::move(pdo));
        }
        break;
      }
      default:
        break;
    }
    at += 2 + count;
  }
  if (name_index > 0 && name_index <= strings.size()) s.name = strings[name_index - 1];
  return s;
}

}  // namespace omnitwin::controller::ethercat
