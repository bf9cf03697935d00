// bus_emulators/ethercat/device — object dictionary (see ec_od.hpp).
#include "bus_emulators/ethercat/device/ec_od.hpp"

#include <algorithm>
#include <cstring>

#include "bus_emulators/ethercat/device/ec_sii.hpp"

namespace omnitwin::ethercat {

const char* to_string(SdoAbort a) {
  switch (a) {
    case SdoAbort::none: return "no error";
    case SdoAbort::toggle: return "toggle bit not alternated";
    case SdoAbort::timeout: return "SDO protocol timed out";
    case SdoAbort::invalid_command: return "command specifier not valid or unknown";
    case SdoAbort::invalid_block_size: return "invalid block size";
    case SdoAbort::out_of_memory: return "out of memory";
    case SdoAbort::unsupported_access: return "unsupported access to an object";
    case SdoAbort::write_only: return "attempt to read a write-only object";
    case SdoAbort::read_only: return "attempt to write a read-only object";
    case SdoAbort::subindex0_not_zero: return "subindex 0 must be 0 for write access";
    case SdoAbort::ca_variable_length: return "complete access not supported for variable length objects";
    case SdoAbort::object_too_long: return "object length exceeds mailbox size";
    case SdoAbort::object_mapped: return "object mapped to RxPDO, SDO download blocked";
    case SdoAbort::no_object: return "object does not exist in the object dictionary";
    case SdoAbort::not_mappable: return "object cannot be mapped to the PDO";
    case SdoAbort::pdo_length_exceeded: return "mapped objects exceed the PDO length";
    case SdoAbort::param_incompatible: return "general parameter incompatibility";
    case SdoAbort::internal_incompatible: return "general internal incompatibility";
    case SdoAbort::hardware: return "access failed due to a hardware error";
    case SdoAbort::length_mismatch: return "data type or length does not match";
    case SdoAbort::too_long: return "data type does not match, length too high";
    case SdoAbort::too_short: return "data type does not match, length too low";
    case SdoAbort::no_subindex: return "subindex does not exist";
    case SdoAbort::value_range: return "value range of parameter exceeded";
    case SdoAbort::value_too_high: return "value of parameter written too high";
    case SdoAbort::value_too_low: return "value of parameter written too low";
    case SdoAbort::max_below_min: return "maximum value is less than minimum value";
    case SdoAbort::general: return "general error";
    case SdoAbort::cannot_store: return "data cannot be transferred or stored to the application";
    case SdoAbort::cannot_store_local: return "data cannot be stored because of local control";
    case SdoAbort::state: return "data cannot be stored because of the present device state";
    case SdoAbort::no_dictionary: return "object dictionary not present";
  }
  return "unknown abort code";
}

bool OdEntry::is_signed() const {
  return data_type == coe_type::int8 || data_type == coe_type::int16 || data_type == coe_type::int32 ||
         data_type == coe_type::int64 || data_type == 0x0010 /* INT24 */;
}

std::int64_t OdEntry::int_of(std::span<const std::uint8_t> raw) const {
  const std::size_t n = std::min<std::size_t>({bytes(), raw.size(), 8});
  std::uint64_t v = 0;
  std::memcpy(&v, raw.data(), n);
  if (bits < 64) {
    v &= (std::uint64_t{1} << bits) - 1;
    if (is_signed() && (v >> (bits - 1)) & 1u) v |= ~((std::uint64_t{1} << bits) - 1);
  }
  return static_cast<std::int64_t>(v);
}

void OdEntry::set_int(std::int64_t v) {
  const std::size_t n = std::min<std::size_t>(bytes(), 8);
  const auto u = static_cast<std::uint64_t>(v);
  std::memcpy(data(), &u, n);
}

OdEntry* OdObject::entry(std::uint8_t sub) {
  for (auto& e : entries)
    if (e.subindex == sub) return &e;
  return nullptr;
}
const OdEntry* OdObject::entry(std::uint8_t sub) const {
  for (const auto& e : entries)
    if (e.subindex == sub) return &e;
  return nullptr;
}
std::uint8_t OdObject::max_subindex() const { return entries.empty() ? 0 : entries.back().subindex; }

OdObject& ObjectDictionary::add(OdObject obj) {
  std::sort(obj.entries.begin(), obj.entries.end(), [](const OdEntry& a, const OdEntry& b) { return a.subindex < b.subindex; });
  for (auto& e : obj.entries) {
    e.bound_ = nullptr;
    e.own_.assign(std::max<std::size_t>(e.bytes(), 1), 0);
    // No default (empty: data() may be null): the value starts at zero.
    if (!e.default_value.empty())
      std::memcpy(e.own_.data(), e.default_value.data(), std::min(e.default_value.size(), e.bytes()));
  }
  auto it = std::lower_bound(objects_.begin(), objects_.end(), obj.index,
                             [](const OdObject& o, std::uint16_t i) { return o.index < i; });
  if (it != objects_.end() && it->index == obj.index) {
    *it = std::move(obj);
    return *it;
  }
  return *objects_.insert(it, std::move(obj));
}

void ObjectDictionary::add_from_esi(const DeviceDescription& desc) {
  for (const auto& eo : desc.objects) {
    OdObject o;
    o.index = eo.index;
    o.name = eo.name;
    o.object_code = eo.object_code;
    for (const auto& ee : eo.entries) {
      OdEntry e;
      e.subindex = ee.subindex;
      e.name = ee.name;
      e.data_type = coe_type_code(ee.data_type);
      e.bits = ee.bit_size;
      e.access = ee.access;
      e.default_value = ee.default_data;
      o.entries.push_back(std::move(e));
    }
    if (o.object_code == 7) {
      o.data_type = o.entries.empty() ? 0 : o.entries.front().data_type;
    } else if (o.object_code == 8) {
      o.data_type = o.entries.size() > 1 ? o.entries[1].data_type : 0;
    } else {
      o.data_type = 0x002A;  // a record type without a standard code
    }
    add(std::move(o));
  }
}

bool ObjectDictionary::bind(std::uint16_t index, std::uint8_t sub, void* storage, std::size_t size) {
  OdEntry* e = entry(index, sub);
  if (!e || e->bytes() != size || storage == nullptr) return false;
  e->bound_ = static_cast<std::uint8_t*>(storage);
  const std::size_t n = std::min(size, e->default_value.size());
  if ((e->access & od_access::write_all) && n != 0) std::memcpy(e->bound_, e->default_value.data(), n);
  return true;
}

void ObjectDictionary::restore_defaults() {
  for (auto& o : objects_)
    for (auto& e : o.entries) {
      if (e.default_value.empty()) {
        if (!e.bound_) std::fill(e.own_.begin(), e.own_.end(), 0);
        continue;
      }
      if (e.bound_ && !(e.access & od_access::write_all)) continue;
      const std::size_t n = std::min(e.default_value.size(), e.bytes());
      if (n != 0) std::memcpy(e.data(), e.default_value.data(), n);
    }
}

OdObject* ObjectDictionary::find(std::uint16_t index) {
  auto it = std::lower_bound(objects_.begin(), objects_.end(), index,
                             [](const OdObject& o, std::uint16_t i) { return o.index < i; });
  return it != objects_.end() && it->index == index ? &*it : nullptr;
}
const OdObject* ObjectDictionary::find(std::uint16_t index) const {
  return const_cast<ObjectDictionary*>(this)->find(index);
}
OdEntry* ObjectDictionary::entry(std::uint16_t index, std::uint8_t sub) {
  OdObject* o = find(index);
  return o ? o->entry(sub) : nullptr;
}
const OdEntry* ObjectDictionary::entry(std::uint16_t index, std::uint8_t sub) const {
  const OdObject* o = find(index);
  return o ? o->entry(sub) : nullptr;
}

namespace {
std::uint16_t read_bit(OdState s) { return static_cast<std::uint16_t>(od_access::read_preop << static_cast<int>(s)); }
std::uint16_t write_bit(OdState s) { return static_cast<std::uint16_t>(od_access::write_preop << static_cast<int>(s)); }

SdoAbort read_check(const OdEntry& e, OdState s) {
  if (e.access & read_bit(s)) return SdoAbort::none;
  if (e.access & od_access::read_all) return SdoAbort::state;
  return SdoAbort::write_only;
}
SdoAbort write_check(const OdEntry& e, OdState s) {
  if (e.access & write_bit(s)) return SdoAbort::none;
  if (e.access & od_access::write_all) return SdoAbort::state;
  return SdoAbort::read_only;
}
}  // namespace

SdoAbort ObjectDictionary::read_size(std::uint16_t index, std::uint8_t sub, OdState state, std::size_t& len) const noexcept {
  const OdObject* o = find(index);
  if (!o) return SdoAbort::no_object;
  const OdEntry* e = o->entry(sub);
  if (!e) return SdoAbort::no_subindex;
  if (auto a = read_check(*e, state); a != SdoAbort::none) return a;
  len = e->bytes();
  return SdoAbort::none;
}

SdoAbort ObjectDictionary::read(std::uint16_t index, std::uint8_t sub, OdState state, std::span<std::uint8_t> out,
                                std::size_t& len) const noexcept {
  std::size_t n = 0;
  if (auto a = read_size(index, sub, state, n); a != SdoAbort::none) return a;
  if (n > out.size()) return SdoAbort::object_too_long;
  std::memcpy(out.data(), entry(index, sub)->data(), n);
  len = n;
  return SdoAbort::none;
}

SdoAbort ObjectDictionary::write(std::uint16_t index, std::uint8_t sub, OdState state,
                                 std::span<const std::uint8_t> data) noexcept {
  OdObject* o = find(index);
  if (!o) return SdoAbort::no_object;
  OdEntry* e = o->entry(sub);
  if (!e) return SdoAbort::no_subindex;
  if (auto a = write_check(*e, state); a != SdoAbort::none) return a;
  const std::size_t n = e->bytes();
  if (data.size() > n) return SdoAbort::too_long;
  if (data.size() < n && !e->is_string()) return SdoAbort::too_short;
  if (!e->is_string() && (e->min || e->max)) {
    std::uint64_t raw = 0;
    std::memcpy(&raw, data.data(), std::min<std::size_t>(n, 8));
    std::int64_t v = static_cast<std::int64_t>(raw);
    if (e->bits < 64 && e->is_signed() && (raw >> (e->bits - 1)) & 1u) v = static_cast<std::int64_t>(raw | ~((std::uint64_t{1} << e->bits) - 1));
    if ((e->min && v < *e->min) || (e->max && v > *e->max)) return SdoAbort::value_range;
  }
  if (o->check) {
    if (auto a = o->check(*o, sub, data); a != SdoAbort::none) return a;
  }
  std::memcpy(e->data(), data.data(), data.size());
  if (data.size() < n) std::memset(e->data() + data.size(), 0, n - data.size());
  if (o->after_write) o->after_write(*o, sub);
  return SdoAbort::none;
}

std::size_t ObjectDictionary::complete_size(std::uint16_t index, std::uint8_t sub) const noexcept {
  const OdObject* o = find(index);
  if (!o) return 0;
  std::size_t n = 0;
  for (const auto& e : o->entries) {
    if (e.subindex < sub) continue;
    n += e.subindex == 0 ? 2 : e.bytes();
  }
  return n;
}

SdoAbort ObjectDictionary::complete_access_check(std::uint16_t index, std::uint8_t sub) const noexcept {
  const OdObject* o = find(index);
  if (!o) return SdoAbort::no_object;
  // Complete access spans the entries of an ARRAY or RECORD; a VAR has none to span.
  if (sub > 1 || o->object_code == 7) return SdoAbort::unsupported_access;
  return SdoAbort::none;
}

SdoAbort ObjectDictionary::read_complete(std::uint16_t index, std::uint8_t sub, OdState state,
                                         std::span<std::uint8_t> out, std::size_t& len) const noexcept {
  if (auto a = complete_access_check(index, sub); a != SdoAbort::none) return a;
  const OdObject* o = find(index);
  const std::size_t total = complete_size(index, sub);
  if (total > out.size()) return SdoAbort::object_too_long;
  std::size_t at = 0;
  // Entries past the current subindex 0 count are not part of the value.
  const OdEntry* e0 = o->entry(0);
  const std::int64_t count = (o->object_code != 7 && e0) ? e0->as_int() : 255;
  for (const auto& e : o->entries) {
    if (e.subindex < sub) continue;
    if (auto a = read_check(e, state); a != SdoAbort::none) return a;
    if (e.subindex == 0) {
      out[at] = e.data()[0];
      out[at + 1] = 0;
      at += 2;
      continue;
    }
    if (e.subindex > count) continue;
    std::memcpy(out.data() + at, e.data(), e.bytes());
    at += e.bytes();
  }
  len = at;
  return SdoAbort::none;
}

SdoAbort ObjectDictionary::write_complete(std::uint16_t index, std::uint8_t sub, OdState state,
                                          std::span<const std::uint8_t> data) noexcept {
  if (auto a = complete_access_check(index, sub); a != SdoAbort::none) return a;
  OdObject* o = find(index);
  std::size_t at = 0;
  std::optional<std::uint8_t> count;
  if (sub == 0) {
    if (data.size() < 2) return SdoAbort::too_short;
    count = data[0];
    at = 2;
    if (o->entry(0) && o->entry(0)->data()[0] != 0 && (o->entry(0)->access & write_bit(state))) {
      const std::uint8_t zero = 0;
      if (auto a = write(index, 0, state, {&zero, 1}); a != SdoAbort::none) return a;
    }
  }
  for (auto& e : o->entries) {
    if (e.subindex == 0) continue;
    if (count && e.subindex > *count) break;
    if (at >= data.size()) break;
    if (at + e.bytes() > data.size()) return SdoAbort::too_short;
    if (auto a = write(index, e.subindex, state, data.subspan(at, e.bytes())); a != SdoAbort::none) return a;
    at += e.bytes();
  }
  if (at < data.size()) return SdoAbort::too_long;
  if (count) {
    if (auto a = write(index, 0, state, {&*count, 1}); a != SdoAbort::none) return a;
  }
  return SdoAbort::none;
}

}  // namespace omnitwin::ethercat
