// Test support for bus_emulators/canopen: a small CiA 301 dictionary built by hand (no EDS),
// with the communication objects the node layers use and a few application objects, so each
// layer's tests stand on their own.
#pragma once

#include <cstdint>
#include <vector>

#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::canopen::test {

inline std::vector<std::uint8_t> le(std::uint64_t v, int bytes) {
  std::vector<std::uint8_t> out;
  for (int i = 0; i < bytes; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  return out;
}

inline OdEntry entry(std::uint8_t sub, std::uint16_t type, std::uint16_t bits, std::uint16_t access, std::uint64_t dflt) {
  OdEntry e;
  e.subindex = sub;
  e.data_type = type;
  e.bits = bits;
  e.access = access;
  e.default_value = le(dflt, (bits + 7) / 8);
  return e;
}

inline void add_var(ObjectDictionary& od, std::uint16_t index, std::uint16_t type, std::uint16_t bits,
                    std::uint16_t access, std::uint64_t dflt) {
  OdObject o;
  o.index = index;
  o.object_code = 7;
  o.data_type = type;
  o.entries.push_back(entry(0, type, bits, access, dflt));
  od.add(std::move(o));
}

inline void add_record(ObjectDictionary& od, std::uint16_t index, std::vector<OdEntry> entries) {
  OdObject o;
  o.index = index;
  o.object_code = 9;
  o.entries = std::move(entries);
  od.add(std::move(o));
}

inline constexpr std::uint16_t kRw = od_access::rw, kRo = od_access::read_all;
inline constexpr std::uint16_t kU8 = data_type::uint8, kU16 = data_type::uint16, kU32 = data_type::uint32,
                               kI32 = data_type::int32;

// PDO n (0-based) communication and mapping objects with a default mapping.
inline void add_pdo(ObjectDictionary& od, bool tx, int n, std::uint32_t cob_id, std::uint8_t type,
                    std::vector<std::uint32_t> mapping) {
  const auto comm = static_cast<std::uint16_t>((tx ? 0x1800 : 0x1400) + n);
  std::vector<OdEntry> c{entry(0, kU8, 8, kRo, tx ? 6 : 5), entry(1, kU32, 32, kRw, cob_id), entry(2, kU8, 8, kRw, type)};
  if (tx) c.push_back(entry(3, kU16, 16, kRw, 0));
  c.push_back(entry(5, kU16, 16, kRw, 0));
  if (tx) c.push_back(entry(6, kU8, 8, kRw, 0));
  add_record(od, comm, c);
  std::vector<OdEntry> m{entry(0, kU8, 8, kRw, mapping.size())};
  for (std::uint8_t s = 1; s <= 8; ++s) m.push_back(entry(s, kU32, 32, kRw, s <= mapping.size() ? mapping[s - 1] : 0));
  add_record(od, static_cast<std::uint16_t>((tx ? 0x1A00 : 0x1600) + n), m);
}

// A node's communication objects (node ID 5 baked into the COB-IDs) and application objects
// 0x2000 (u16, RPDO-mappable), 0x2001 (i32, RPDO-mappable), 0x2002 (u16, TPDO-mappable),
// 0x2003 (i32, TPDO-mappable), 0x2004 (u32, not mappable).
inline void build_node_od(ObjectDictionary& od, std::uint8_t id = 5) {
  add_var(od, 0x1000, kU32, 32, kRo, 0x00020192);
  add_var(od, 0x1001, kU8, 8, kRo, 0);
  std::vector<OdEntry> h{entry(0, kU8, 8, kRw, 0)};
  for (std::uint8_t s = 1; s <= 4; ++s) h.push_back(entry(s, kU32, 32, kRo, 0));
  add_record(od, 0x1003, h);
  add_var(od, 0x1005, kU32, 32, kRw, 0x80);
  add_var(od, 0x1006, kU32, 32, kRw, 0);
  add_var(od, 0x100C, kU16, 16, kRw, 0);
  add_var(od, 0x100D, kU8, 8, kRw, 0);
  add_var(od, 0x1012, kU32, 32, kRw, 0x80000100);
  add_var(od, 0x1014, kU32, 32, kRw, 0x80u + id);
  add_var(od, 0x1015, kU16, 16, kRw, 0);
  add_record(od, 0x1016, {entry(0, kU8, 8, kRo, 1), entry(1, kU32, 32, kRw, 0)});
  add_var(od, 0x1017, kU16, 16, kRw, 0);
  add_record(od, 0x1018, {entry(0, kU8, 8, kRo, 4), entry(1, kU32, 32, kRo, 0x4F54574E), entry(2, kU32, 32, kRo, 0x402),
                          entry(3, kU32, 32, kRo, 1), entry(4, kU32, 32, kRo, 0)});
  add_var(od, 0x1019, kU8, 8, kRw, 0);
  add_record(od, 0x1029, {entry(0, kU8, 8, kRo, 1), entry(1, kU8, 8, kRw, 0)});
  add_var(od, 0x2000, kU16, 16, kRw | od_access::rxpdo, 0);
  add_var(od, 0x2001, kI32, 32, kRw | od_access::rxpdo, 0);
  add_var(od, 0x2002, kU16, 16, kRw | od_access::txpdo, 0);
  add_var(od, 0x2003, kI32, 32, kRw | od_access::txpdo, 0);
  add_var(od, 0x2004, kU32, 32, kRw, 0);
  add_pdo(od, false, 0, 0x200u + id, 1, {0x20000010, 0x20010020});
  add_pdo(od, false, 1, 0x300u + id, 255, {0x20000010});
  add_pdo(od, true, 0, 0x180u + id, 1, {0x20020010, 0x20030020});
  add_pdo(od, true, 1, 0x80000280u + id, 255, {});
}

}  // namespace omnitwin::canopen::test
