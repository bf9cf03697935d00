// bus_emulators/ethercat/device — the CoE object dictionary of an emulated slave.
//
// Objects (index) hold entries (subindex) with a CoE data type, a bit size, access rights per
// state (od_access bits from ec_esi.hpp: read/write in PRE-OP, SAFE-OP, OP, RxPDO/TxPDO
// mappable), a default and optional value limits. An entry's value lives either in the
// entry's own storage or in bound storage: a field of the application (drive::Objects of an
// axis), so that SDO access and the process image read and write the drive's real variables
// without copies. Values are little-endian byte strings (the host is little-endian, checked
// at compile time). Writes can be vetted per object by a check hook (PDO mapping/assignment
// rules live in the slave, not here) and observed by an after-write hook.
//
// Built once at set-up (allocates); read()/write() do not allocate and never throw: they
// answer with the SDO abort code the CoE server sends (SdoAbort::none = success).
#pragma once

#include <bit>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "bus_emulators/ethercat/device/ec_esi.hpp"

namespace omnitwin::ethercat {

static_assert(std::endian::native == std::endian::little, "the OD stores values in host order = little-endian");

// SDO abort codes (ETG.1000.6 / CiA 301).
enum class SdoAbort : std::uint32_t {
  none = 0,
  toggle = 0x05030000,              // toggle bit not alternated
  timeout = 0x05040000,             // SDO protocol timed out
  invalid_command = 0x05040001,     // client/server command specifier not valid or unknown
  invalid_block_size = 0x05040002,
  out_of_memory = 0x05040005,
  unsupported_access = 0x06010000,  // unsupported access to an object (e.g. complete access)
  write_only = 0x06010001,          // attempt to read a write-only object
  read_only = 0x06010002,           // attempt to write a read-only object
  subindex0_not_zero = 0x06010003,  // subindex cannot be written, SI0 must be 0 for write access
  ca_variable_length = 0x06010004,
  object_too_long = 0x06010005,
  object_mapped = 0x06010006,
  no_object = 0x06020000,           // object does not exist in the object dictionary
  not_mappable = 0x06040041,        // object cannot be mapped to the PDO
  pdo_length_exceeded = 0x06040042, // number and length of mapped objects exceed the PDO length
  param_incompatible = 0x06040043,  // general parameter incompatibility
  internal_incompatible = 0x06040047,
  hardware = 0x06060000,
  length_mismatch = 0x06070010,     // data type does not match, length of service parameter does not match
  too_long = 0x06070012,            // data type does not match, length too high
  too_short = 0x06070013,           // data type does not match, length too low
  no_subindex = 0x06090011,         // subindex does not exist
  value_range = 0x06090030,         // value range of parameter exceeded
  value_too_high = 0x06090031,
  value_too_low = 0x06090032,
  max_below_min = 0x06090036,
  general = 0x08000000,
  cannot_store = 0x08000020,
  cannot_store_local = 0x08000021,
  state = 0x08000022,               // cannot be transferred because of the present device state
  no_dictionary = 0x08000023,
};
const char* to_string(SdoAbort a);  // short description, never nullptr

// CoE data type codes (ETG.1000.6 table 63).
namespace coe_type {
inline constexpr std::uint16_t boolean = 0x0001, int8 = 0x0002, int16 = 0x0003, int32 = 0x0004,
                               uint8 = 0x0005, uint16 = 0x0006, uint32 = 0x0007, real32 = 0x0008,
                               visible_string = 0x0009, octet_string = 0x000A, int64 = 0x0015,
                               uint64 = 0x001B, bit1 = 0x0030;
}

// The state an access happens in (selects the read/write bits of od_access).
enum class OdState : std::uint8_t { preop = 0, safeop = 1, op = 2 };

struct OdEntry {
  std::uint8_t subindex = 0;
  std::string name;
  std::uint16_t data_type = 0;        // coe_type code
  std::uint16_t bits = 0;             // bit size
  std::uint16_t access = od_access::read_all;
  std::vector<std::uint8_t> default_value;
  std::optional<std::int64_t> min, max;  // value limits for numeric types (inclusive)

  std::size_t bytes() const { return (bits + 7u) / 8u; }
  bool is_string() const { return data_type == coe_type::visible_string || data_type == coe_type::octet_string; }
  bool is_signed() const;
  std::uint8_t* data() { return bound_ ? bound_ : own_.data(); }
  const std::uint8_t* data() const { return bound_ ? bound_ : own_.data(); }
  bool bound() const { return bound_ != nullptr; }
  // The value as an integer (sign-extended for signed types), up to 64 bits. RT-safe.
  std::int64_t as_int() const { return int_of({data(), bytes()}); }
  // `raw` (little endian, as a write brings it) read as this entry's type, the same way. RT-safe.
  std::int64_t int_of(std::span<const std::uint8_t> raw) const;
  void set_int(std::int64_t v);       // stores the low bits() bits. RT-safe.

 private:
  friend class ObjectDictionary;
  std::uint8_t* bound_ = nullptr;
  std::vector<std::uint8_t> own_;
};

struct OdObject;
// Vets a write of `data` to entry `sub` of `obj` before it happens; SdoAbort::none allows it.
using OdCheck = std::function<SdoAbort(const OdObject& obj, std::uint8_t sub, std::span<const std::uint8_t> data)>;
// Called after a successful write to entry `sub`.
using OdAfterWrite = std::function<void(OdObject& obj, std::uint8_t sub)>;

struct OdObject {
  std::uint16_t index = 0;
  std::string name;
  std::uint8_t object_code = 7;       // 7 VAR, 8 ARRAY, 9 RECORD
  std::uint16_t data_type = 0;        // VAR: the entry's type; ARRAY: element type; RECORD: 0x0000 (none given)
  std::vector<OdEntry> entries;       // ascending subindex; VAR: exactly subindex 0
  OdCheck check;
  OdAfterWrite after_write;

  OdEntry* entry(std::uint8_t sub);
  const OdEntry* entry(std::uint8_t sub) const;
  std::uint8_t max_subindex() const;  // highest subindex present
};

class ObjectDictionary {
 public:
  // Adds every object of the ESI dictionary with own storage, filled with its default.
  void add_from_esi(const DeviceDescription& desc);
  // Adds (or replaces) one object; entries get own storage filled with their default.
  OdObject& add(OdObject obj);
  // Binds entry index:sub to `size` bytes at `storage` (size must equal the entry's bytes()).
  // Writable entries take their default value into the storage (the ESI is authoritative for
  // parameters); read-only ones keep what the application has. false when absent/size differs.
  bool bind(std::uint16_t index, std::uint8_t sub, void* storage, std::size_t size);
  template <class T>
  bool bind(std::uint16_t index, std::uint8_t sub, T& field) {
    return bind(index, sub, &field, sizeof(T));
  }

  // Power-on values: every entry with a default takes it again (own storage, and bound storage
  // of writable entries). Set-up/power-cycle path.
  void restore_defaults();

  OdObject* find(std::uint16_t index);
  const OdObject* find(std::uint16_t index) const;
  OdEntry* entry(std::uint16_t index, std::uint8_t sub);
  const OdEntry* entry(std::uint16_t index, std::uint8_t sub) const;
  const std::vector<OdObject>& objects() const { return objects_; }

  // SDO upload of one entry into out; len = bytes written. RT-safe.
  SdoAbort read(std::uint16_t index, std::uint8_t sub, OdState state, std::span<std::uint8_t> out,
                std::size_t& len) const noexcept;
  // Size an upload would have (for the normal/segmented initiate), with the same checks as read().
  SdoAbort read_size(std::uint16_t index, std::uint8_t sub, OdState state, std::size_t& len) const noexcept;
  // SDO download of one entry: access, length, limits, the object's check hook, then store
  // and after-write hook. Strings accept shorter data (rest zeroed). RT-safe apart from hooks.
  SdoAbort write(std::uint16_t index, std::uint8_t sub, OdState state, std::span<const std::uint8_t> data) noexcept;
  // Complete access: all entries from sub (0 or 1) in order, subindex 0 as 8 bits padded to 16,
  // every other entry in whole bytes. Only ARRAY and RECORD objects: a VAR (object code 7), or a
  // sub above 1, is refused with unsupported_access (0x06010000), never answered truncated.
  SdoAbort complete_access_check(std::uint16_t index, std::uint8_t sub) const noexcept;
  SdoAbort read_complete(std::uint16_t index, std::uint8_t sub, OdState state, std::span<std::uint8_t> out,
                         std::size_t& len) const noexcept;
  SdoAbort write_complete(std::uint16_t index, std::uint8_t sub, OdState state,
                          std::span<const std::uint8_t> data) noexcept;
  std::size_t complete_size(std::uint16_t index, std::uint8_t sub) const noexcept;

 private:
  std::vector<OdObject> objects_;  // ascending index
};

}  // namespace omnitwin::ethercat
