// libFuzzer target for bus_emulators/canopen/co_eds: CiA 306 EDS text → EdsDevice, and the
// object dictionary add_to_od builds from a description it accepted.
//
// The input is the EDS text. Properties checked (ASan/UBSan check memory and UB; anything else
// than EdsError escaping is a crash by design, libFuzzer reports the uncaught exception):
//  - parse_eds returns a description or throws EdsError whose message starts with the name it
//    was given and a line number ("<fuzz>:N: ...");
//  - an accepted description is consistent: objects ascending without duplicates, each found
//    by object(), one per listed index; a VAR holds exactly subindex 0, an ARRAY/RECORD starts
//    at subindex 0 (UNSIGNED8) with ascending subindices; fixed-size entries have their type's
//    size; defaults and limits of numeric entries fit their size for node IDs 1 and 127;
//  - add_to_od for nodes 1 and 127 either succeeds or throws EdsError (DOMAIN entries); a built
//    dictionary holds every VAR/ARRAY/RECORD with its entries, sizes and access bits, and every
//    entry reads back its default in PRE-OPERATIONAL (or answers write-only).
// Seeds: the shipped models/canopen/*.eds and tests/data/canopen/*.eds (the ctest passes both
// directories).
//
//   ./co_eds_fuzz -max_total_time=60 /tmp/eds-corpus models/canopen tests/data/canopen
#include <array>
#include <cstdint>
#include <cstring>
#include <string>

#include "bus_emulators/canopen/co_eds.hpp"

using namespace omnitwin::canopen;

namespace {

#define CHECK(cond)                \
  do {                             \
    if (!(cond)) __builtin_trap(); \
  } while (0)

const std::string kName = "<fuzz>";

// "<fuzz>:N: ..." with N a decimal line number.
void check_message(const EdsError& e) {
  const std::string m = e.what();
  CHECK(m.compare(0, kName.size() + 1, kName + ":") == 0);
  std::size_t i = kName.size() + 1;
  const std::size_t digits = i;
  while (i < m.size() && m[i] >= '0' && m[i] <= '9') ++i;
  CHECK(i > digits && i + 1 < m.size() && m[i] == ':' && m[i + 1] == ' ');
}

// A numeric value stays within `bits` (sign- or zero-extended) for node IDs 1 and 127.
void check_value(const EdsEntry& e, const EdsValue& v) {
  if (e.bits >= 64 || e.data_type == data_type::real32) return;
  for (std::uint8_t node : {1, 127}) {
    const std::int64_t x = v.value(node);
    const std::int64_t lo = -(std::int64_t{1} << e.bits), hi = (std::int64_t{1} << e.bits) - 1;
    CHECK(x >= lo && x <= hi);
  }
}

void check_entry(const EdsEntry& e) {
  const std::uint16_t fixed = eds_type_bits(e.data_type);
  if (fixed != 0) {
    CHECK(e.bits == fixed);
    for (const auto* v : {&e.default_value, &e.low_limit, &e.high_limit})
      if (*v) check_value(e, **v);
  } else if (e.default_value) {
    CHECK(e.bits == std::min<std::size_t>(e.default_value->bytes.size() * 8, 0xFFF8));
  }
  CHECK(to_string(e.access) != nullptr);
}

void check_description(const EdsDevice& d) {
  CHECK(d.objects.size() == d.mandatory.size() + d.optional.size() + d.manufacturer.size());
  for (std::size_t i = 0; i < d.objects.size(); ++i) {
    const EdsObject& o = d.objects[i];
    if (i > 0) CHECK(d.objects[i - 1].index < o.index);
    CHECK(d.object(o.index) == &o);
    CHECK(!o.entries.empty() && o.entries.front().subindex == 0);
    const bool has_subs = o.object_type == 6 || o.object_type == 8 || o.object_type == 9;
    if (!has_subs) CHECK(o.entries.size() == 1);
    if (has_subs) CHECK(o.entries.front().data_type == data_type::uint8);
    for (std::size_t k = 0; k < o.entries.size(); ++k) {
      if (k > 0) CHECK(o.entries[k - 1].subindex < o.entries[k].subindex);
      CHECK(o.entry(o.entries[k].subindex) == &o.entries[k]);
      check_entry(o.entries[k]);
    }
  }
}

// The dictionary built for `node` mirrors the description.
void check_od(const EdsDevice& d, std::uint8_t node) {
  ObjectDictionary od;
  try {
    add_to_od(d, node, od);
  } catch (const EdsError& e) {
    check_message(e);
    return;
  }
  std::array<std::uint8_t, 8192> buf{};
  for (const auto& o : d.objects) {
    const OdObject* oo = od.find(o.index);
    if (o.object_type == 5 || o.object_type == 6) {
      CHECK(oo == nullptr);
      continue;
    }
    CHECK(oo != nullptr && oo->entries.size() == o.entries.size());
    for (const auto& e : o.entries) {
      const OdEntry* oe = oo->entry(e.subindex);
      CHECK(oe != nullptr && oe->bits == e.bits && oe->access == eds_od_access(e.access, e.pdo_mapping));
      std::size_t len = 0;
      const SdoAbort a = od.read(o.index, e.subindex, OdState::preop, buf, len);
      CHECK(a == SdoAbort::none || (a == SdoAbort::write_only && e.access == EdsAccess::wo) ||
            (a == SdoAbort::object_too_long && oe->bytes() > buf.size()));
      if (a == SdoAbort::none && !oe->default_value.empty())
        CHECK(len == oe->bytes() && std::memcmp(buf.data(), oe->default_value.data(), std::min(len, oe->default_value.size())) == 0);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  EdsDevice d;
  try {
    d = parse_eds(text, kName);
  } catch (const EdsError& e) {
    check_message(e);
    return 0;
  }
  CHECK(d.source == kName);
  check_description(d);
  check_od(d, 1);
  check_od(d, 127);
  return 0;
}
