// bus_emulators/canopen — CiA 306 EDS (Electronic Data Sheet, INI text) → a plain device
// description, and the object dictionary an emulated node builds from one.
//
// The same role as ethercat/device/ec_esi for EtherCAT: the emulated CANopen node builds its
// dictionary from the EDS (add_to_od), and the CANopen master reads identity and PDO
// defaults from the same file. The description is a value type with no behaviour. Set-up
// code only: everything here allocates, and errors throw EdsError with
// "path:line: [section] key: what is wrong" (line of the offending key, or of the section
// header for a missing key; line 0 when the file cannot be read).
//
// Supported subset of CiA 306:
//  - sections and keys are case-insensitive; ';' starts a comment line (whole lines only: a
//    ';' after a value belongs to the value); CR LF or LF line ends; unknown sections and keys
//    are ignored, a duplicated section or key is an error;
//  - [FileInfo], [DeviceInfo] (required), [DummyUsage], [Comments];
//  - [MandatoryObjects] (required), [OptionalObjects], [ManufacturerObjects]: SupportedObjects=N
//    and 1..N=index; every listed object needs its section, every object section must be
//    listed, no index may be listed twice;
//  - object sections [XXXX] (hex index) with ParameterName, ObjectType (0x7 VAR when absent,
//    0x8 ARRAY, 0x9 RECORD; 0x2 DOMAIN, 0x5 DEFTYPE, 0x6 DEFSTRUCT are kept in the description,
//    see add_to_od), DataType, AccessType (ro wo rw rwr rww const), DefaultValue, LowLimit,
//    HighLimit, PDOMapping, SubNumber; sub-object sections [XXXXsubY] (hex subindex) for
//    ARRAY/RECORD, whose count must equal SubNumber and which must include sub 0.
//    CompactSubObj (other than 0) is rejected: write the sub-object sections out;
//  - numbers: decimal, 0x hex, leading-0 octal, optionally negative; DefaultValue, LowLimit
//    and HighLimit may be "$NODEID", "$NODEID+n" or "n+$NODEID" (evaluated by add_to_od for
//    the node ID given); signed types also accept a hex/octal bit pattern (0xFFFF = −1 for
//    INTEGER16); REAL32/REAL64 take a decimal fraction or a 0x bit pattern; VISIBLE_STRING
//    defaults are the text after '=', OCTET_STRING defaults hex digits, UNICODE_STRING the
//    text widened to UTF-16LE. A default or limit must fit its type (and the limits), also
//    after adding any node ID 1..127.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::canopen {

class EdsError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// AccessType of an entry (CiA 306): rwr/rww are rw whose PDO direction is transmit/receive.
enum class EdsAccess : std::uint8_t { ro, wo, rw, rwr, rww, const_ };
const char* to_string(EdsAccess a);  // "ro", "wo", "rw", "rwr", "rww", "const"

// A DefaultValue, LowLimit or HighLimit. Numeric types use `number` (integers as the value
// written, sign-extended for signed types; REAL32/REAL64 as their IEEE bit pattern),
// optionally plus the node ID; string types use `bytes`.
struct EdsValue {
  std::string text;                  // as written in the file
  std::int64_t number = 0;
  bool plus_node_id = false;         // "$NODEID+number"
  std::vector<std::uint8_t> bytes;   // VISIBLE/OCTET/UNICODE_STRING value

  // The numeric value for node `node_id` (number + node_id when plus_node_id). Real-time safe.
  std::int64_t value(std::uint8_t node_id) const { return number + (plus_node_id ? node_id : 0); }
};

struct EdsEntry {
  std::uint8_t subindex = 0;
  std::string name;                  // ParameterName
  std::uint16_t data_type = 0;       // CiA 301 data type code (data_type::...)
  std::uint16_t bits = 0;            // size [bits]; strings: their default's length × 8
  EdsAccess access = EdsAccess::ro;
  bool pdo_mapping = false;
  std::optional<EdsValue> default_value, low_limit, high_limit;
  int line = 0;                      // line of the section that defined it
};

struct EdsObject {
  std::uint16_t index = 0;
  std::string name;                  // ParameterName
  std::uint8_t object_type = 7;      // 7 VAR, 8 ARRAY, 9 RECORD (2 DOMAIN, 5 DEFTYPE, 6 DEFSTRUCT)
  std::uint16_t data_type = 0;       // VAR: the entry's; ARRAY/RECORD: DataType if given, else 0
  std::vector<EdsEntry> entries;     // VAR: one entry, subindex 0; ARRAY/RECORD: ascending, sub 0 first
  int line = 0;                      // line of the [XXXX] header

  const EdsEntry* entry(std::uint8_t sub) const;  // nullptr when absent
};

struct EdsFileInfo {
  std::string file_name, description, created_by, modified_by, eds_version;
  std::string creation_date, creation_time, modification_date, modification_time;
  std::uint8_t file_version = 0, file_revision = 0;
};

struct EdsDeviceInfo {
  std::string vendor_name, product_name, order_code;
  std::uint32_t vendor_number = 0, product_number = 0, revision_number = 0;
  // BaudRate_10, _20, _50, _125, _250, _500, _800, _1000 [kbit/s]: bit i set = kBaudRates[i] supported.
  std::uint8_t baud_rates = 0;
  static constexpr int kBaudRates[8] = {10, 20, 50, 125, 250, 500, 800, 1000};
  bool simple_boot_up_master = false, simple_boot_up_slave = false;
  std::uint8_t granularity = 0;      // PDO mapping granularity [bits], 0 = not mappable
  bool dynamic_channels_supported = false, group_messaging = false, lss_supported = false;
  std::uint16_t nr_of_rx_pdo = 0, nr_of_tx_pdo = 0;
  bool supports_baud(int kbit_s) const;
};

struct EdsDevice {
  EdsFileInfo file_info;
  EdsDeviceInfo device_info;
  std::uint8_t dummy_usage = 0;      // bit i set: Dummy000i may be mapped (i = 1..7)
  std::vector<std::string> comments; // [Comments] Line1..LineN
  std::vector<std::uint16_t> mandatory, optional, manufacturer;  // the lists, in file order
  std::vector<EdsObject> objects;    // every listed object, ascending index
  std::string source;                // path (or name) it came from

  const EdsObject* object(std::uint16_t index) const;  // nullptr when absent
};

// Parses an EDS file. Throws EdsError (see above). Set-up code only.
EdsDevice load_eds(const std::string& path);
// The same from the file's text; `name` stands for the path in messages.
EdsDevice parse_eds(const std::string& text, const std::string& name = "<string>");

// CiA 306 number: decimal, 0x hex, leading-0 octal, optional '-'; nullopt when not a number
// or out of the 64-bit range. Real-time safe.
std::optional<std::int64_t> parse_eds_number(const std::string& text);
// Size [bits] of a fixed-size CiA 301 data type (BOOLEAN = 1); 0 for strings, DOMAIN and
// unknown codes. Real-time safe.
std::uint16_t eds_type_bits(std::uint16_t data_type);

// od_access bits of an entry (the OD's read/write bits per state; CANopen uses the PRE-OP and
// OP ones, SAFE-OP bits are set alike):
//   ro, const      → read in every state          wo            → write in every state
//   rw, rwr, rww   → read and write in every state
//   PDOMapping=1:    rww, wo → rxpdo     rwr, ro, const → txpdo     rw → rxpdo and txpdo
// Real-time safe.
std::uint16_t eds_od_access(EdsAccess a, bool pdo_mapping);

// Adds every VAR/ARRAY/RECORD object of `dev` to `od` with own storage holding its default
// (evaluated for `node_id`: "$NODEID+0x180" → 0x185 for node 5; no default → zero), data
// type, bit size, access (eds_od_access) and LowLimit/HighLimit as OdEntry::min/max (integer
// types; REAL limits are not enforced). String entries are fixed at their default's length
// (the OD has no variable-size entries; shorter writes are zero-padded). An object already in
// `od` is replaced. DEFTYPE/DEFSTRUCT objects (type definitions) are
// skipped. Throws EdsError for a node ID outside 1..127 and for DOMAIN entries (no fixed
// size: the OD cannot hold them). Set-up code only.
void add_to_od(const EdsDevice& dev, std::uint8_t node_id, ObjectDictionary& od);

}  // namespace omnitwin::canopen
