// bus_emulators/ethercat/device — SII EEPROM image builder (see ec_sii.hpp).
#include "bus_emulators/ethercat/device/ec_sii.hpp"

#include <fmt/format.h>

#include <map>
#include <string>

namespace omnitwin::ethercat {

std::uint8_t sii_crc8(std::span<const std::uint8_t> bytes) noexcept {
  std::uint8_t crc = 0xFF;
  for (std::uint8_t b : bytes) {
    crc ^= b;
    for (int i = 0; i < 8; ++i) crc = (crc & 0x80) ? static_cast<std::uint8_t>((crc << 1) ^ 0x07) : static_cast<std::uint8_t>(crc << 1);
  }
  return crc;
}

std::uint16_t coe_type_code(const std::string& t) noexcept {
  if (t == "BOOL" || t == "BIT") return 0x0001;
  if (t == "SINT") return 0x0002;
  if (t == "INT") return 0x0003;
  if (t == "DINT") return 0x0004;
  if (t == "USINT" || t == "BYTE") return 0x0005;
  if (t == "UINT" || t == "WORD") return 0x0006;
  if (t == "UDINT" || t == "DWORD") return 0x0007;
  if (t == "REAL") return 0x0008;
  if (t.rfind("STRING", 0) == 0) return 0x0009;
  if (t.rfind("OCTET_STRING", 0) == 0 || t.rfind("ARRAY [", 0) == 0) return 0x000A;
  if (t == "INT24") return 0x0010;
  if (t == "LREAL") return 0x0011;
  if (t == "LINT") return 0x0015;
  if (t == "UINT24") return 0x0016;
  if (t == "ULINT") return 0x001B;
  if (t.size() == 4 && t.compare(0, 3, "BIT") == 0 && t[3] >= '1' && t[3] <= '8') return static_cast<std::uint16_t>(0x0030 + (t[3] - '1'));
  return 0;
}

namespace {

// Collects the strings of category 10 (index 1-based, 0 = none), without duplicates.
class Strings {
 public:
  std::uint8_t add(const std::string& s) {
    if (s.empty()) return 0;
    if (auto it = index_.find(s); it != index_.end()) return it->second;
    if (list_.size() >= 255) return 0;
    list_.push_back(s.size() > 255 ? s.substr(0, 255) : s);
    const auto i = static_cast<std::uint8_t>(list_.size());
    index_[s] = i;
    return i;
  }
  std::vector<std::uint8_t> bytes() const {
    std::vector<std::uint8_t> b{static_cast<std::uint8_t>(list_.size())};
    for (const auto& s : list_) {
      b.push_back(static_cast<std::uint8_t>(s.size()));
      b.insert(b.end(), s.begin(), s.end());
    }
    return b;
  }

 private:
  std::vector<std::string> list_;
  std::map<std::string, std::uint8_t> index_;
};

void put16(std::vector<std::uint8_t>& b, std::uint16_t v) {
  b.push_back(static_cast<std::uint8_t>(v));
  b.push_back(static_cast<std::uint8_t>(v >> 8));
}
void put32(std::vector<std::uint8_t>& b, std::uint32_t v) {
  put16(b, static_cast<std::uint16_t>(v));
  put16(b, static_cast<std::uint16_t>(v >> 16));
}

// Appends one category (type, word size, data padded to whole words).
void category(std::vector<std::uint16_t>& w, std::uint16_t type, std::vector<std::uint8_t> data) {
  if (data.size() % 2) data.push_back(0);
  w.push_back(type);
  w.push_back(static_cast<std::uint16_t>(data.size() / 2));
  for (std::size_t i = 0; i < data.size(); i += 2) w.push_back(static_cast<std::uint16_t>(data[i] | (data[i + 1] << 8)));
}

std::uint16_t process_sm_size(const DeviceDescription& d, int sm, const EsiSyncManager& s) {
  if (s.size || (s.kind != SmKind::outputs && s.kind != SmKind::inputs)) return s.size;
  std::uint32_t bits = 0;
  const auto& pdos = s.kind == SmKind::outputs ? d.rx_pdos : d.tx_pdos;
  for (const auto& p : pdos)
    if (p.sm == sm) bits += p.bit_size();
  return static_cast<std::uint16_t>((bits + 7) / 8);
}

std::vector<std::uint8_t> pdo_category(const std::vector<EsiPdo>& pdos, Strings& str) {
  std::vector<std::uint8_t> b;
  for (const auto& p : pdos) {
    put16(b, p.index);
    b.push_back(static_cast<std::uint8_t>(p.entries.size()));
    b.push_back(p.sm >= 0 ? static_cast<std::uint8_t>(p.sm) : 0xFF);
    b.push_back(0);  // DC sync
    b.push_back(str.add(p.name));
    put16(b, static_cast<std::uint16_t>((p.mandatory ? 0x0001 : 0) | (p.sm >= 0 ? 0x0002 : 0) | (p.fixed ? 0x0010 : 0)));
    for (const auto& e : p.entries) {
      put16(b, e.index);
      b.push_back(e.subindex);
      b.push_back(str.add(e.name));
      b.push_back(static_cast<std::uint8_t>(coe_type_code(e.data_type)));
      b.push_back(e.bit_length);
      put16(b, 0);
    }
  }
  return b;
}

}  // namespace

std::vector<std::uint16_t> build_sii(const DeviceDescription& d, std::uint16_t alias, std::uint32_t serial) {
  std::vector<std::uint16_t> w(sii::first_category, 0);
  // ESC configuration area: ConfigData from the ESI (PDI control, PDI config, ...), alias in word 4.
  std::uint8_t cfg[14] = {};
  for (std::size_t i = 0; i < d.eeprom_config.size() && i < 14; ++i) cfg[i] = d.eeprom_config[i];
  cfg[8] = static_cast<std::uint8_t>(alias);
  cfg[9] = static_cast<std::uint8_t>(alias >> 8);
  for (int i = 0; i < 7; ++i) w[static_cast<std::size_t>(i)] = static_cast<std::uint16_t>(cfg[2 * i] | (cfg[2 * i + 1] << 8));
  w[7] = sii_crc8(cfg);
  auto put_u32w = [&](std::uint16_t at, std::uint32_t v) {
    w[at] = static_cast<std::uint16_t>(v);
    w[at + 1u] = static_cast<std::uint16_t>(v >> 16);
  };
  put_u32w(sii::vendor_id, d.vendor_id);
  put_u32w(sii::product_code, d.product_code);
  put_u32w(sii::revision, d.revision);
  put_u32w(sii::serial, serial);
  const int mo = d.sm_of_kind(SmKind::mbox_out), mi = d.sm_of_kind(SmKind::mbox_in);
  if (mo >= 0 && mi >= 0) {
    w[sii::mbx_rx_offset] = d.sms[static_cast<std::size_t>(mo)].start;
    w[sii::mbx_rx_size] = d.sms[static_cast<std::size_t>(mo)].size;
    w[sii::mbx_tx_offset] = d.sms[static_cast<std::size_t>(mi)].start;
    w[sii::mbx_tx_size] = d.sms[static_cast<std::size_t>(mi)].size;
    w[sii::mbx_protocols] = d.coe.present ? sii::proto_coe : 0;
  }
  w[sii::size] = static_cast<std::uint16_t>(d.eeprom_bytes * 8 / 1024 - 1);
  w[sii::version] = 1;

  Strings str;
  const std::uint8_t name_idx = str.add(d.name);
  const std::uint8_t order_idx = str.add(d.type_name);
  const std::uint8_t group_idx = str.add(d.group);
  // General (30): 32 bytes.
  std::vector<std::uint8_t> gen(32, 0);
  gen[0] = group_idx;
  gen[1] = 0;  // image
  gen[2] = order_idx;
  gen[3] = name_idx;
  if (d.coe.present) {
    gen[5] = static_cast<std::uint8_t>(0x01 | (d.coe.sdo_info ? 0x02 : 0) | (d.coe.pdo_assign ? 0x04 : 0) |
                                       (d.coe.pdo_config ? 0x08 : 0) | (d.coe.pdo_upload ? 0x10 : 0) |
                                       (d.coe.complete_access ? 0x20 : 0));
  }
  gen[9] = d.profile == 402 ? static_cast<std::uint8_t>(d.axes) : 0;  // DS402 channels
  gen[11] = 0x01;  // flags: enable SAFEOP; LRW supported (bit 1 clear)
  gen[14] = group_idx;
  gen[16] = 0x11;  // physical ports 0 and 1: MII
  // FMMU (40)
  std::vector<std::uint8_t> fm;
  for (auto k : d.fmmus) fm.push_back(k == SmKind::outputs ? 1 : k == SmKind::inputs ? 2 : 3);
  // SyncManager (41)
  std::vector<std::uint8_t> sm;
  for (std::size_t i = 0; i < d.sms.size(); ++i) {
    const auto& s = d.sms[i];
    put16(sm, s.start);
    put16(sm, process_sm_size(d, static_cast<int>(i), s));
    sm.push_back(s.control);
    sm.push_back(0);
    sm.push_back(s.enable ? 1 : 0);
    sm.push_back(static_cast<std::uint8_t>(s.kind));
  }
  auto tx = pdo_category(d.tx_pdos, str);
  auto rx = pdo_category(d.rx_pdos, str);
  std::vector<std::uint8_t> dc;
  for (const auto& m : d.dc) {
    put32(dc, m.cycle_time_sync0);
    put32(dc, static_cast<std::uint32_t>(m.shift_time_sync0));
    put32(dc, 0);  // shift time SYNC1
    put16(dc, 0);  // SYNC1 cycle factor
    put16(dc, m.assign_activate);
    put16(dc, m.cycle_time_sync0 ? 0 : 1);  // SYNC0 cycle factor
    dc.push_back(str.add(m.name));
    dc.push_back(str.add(m.desc));
    put32(dc, 0);
  }
  category(w, sii::cat_strings, str.bytes());
  category(w, sii::cat_general, gen);
  if (!fm.empty()) category(w, sii::cat_fmmu, fm);
  if (!sm.empty()) category(w, sii::cat_syncm, sm);
  if (!tx.empty()) category(w, sii::cat_txpdo, tx);
  if (!rx.empty()) category(w, sii::cat_rxpdo, rx);
  if (!dc.empty()) category(w, sii::cat_dc, dc);
  w.push_back(sii::cat_end);
  const std::size_t words = d.eeprom_bytes / 2;
  if (w.size() > words)
    throw EsiError(fmt::format("{}: SII image of '{}' needs {} words, EEPROM holds {}", d.source, d.name, w.size(), words));
  w.resize(words, 0xFFFF);
  return w;
}

}  // namespace omnitwin::ethercat
