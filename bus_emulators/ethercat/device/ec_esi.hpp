// bus_emulators/ethercat/device — ESI (EtherCAT Slave Information, ETG.2000-style XML) → a
// plain device description.
//
// The description is what both sides need from an ESI file: the emulated slave builds its
// SII EEPROM image, object dictionary and PDO mapping from it (ec_sii, ec_od, ec_slave), and
// the master (controller/ethercat) reads identity, SyncManagers and PDOs from it. It is a
// value type with no behaviour; this library links only pugixml so that the master does not
// pull in the slaves' drives. Set-up code only: load_esi() allocates and throws EsiError
// ("file:line: what is wrong") on anything it cannot use.
//
// Supported subset of ETG.2000: EtherCATInfo/Vendor/Id+Name, Descriptions/Groups,
// Descriptions/Devices/Device with Type (ProductCode, RevisionNo), Name, GroupType, Fmmu, Sm
// (StartAddress, DefaultSize, ControlByte, Enable; text MBoxOut/MBoxIn/Outputs/Inputs), RxPdo/TxPdo
// (Sm, Fixed, Mandatory; Index, Name, Entry: Index, SubIndex, BitLen, Name, DataType),
// Mailbox/CoE (SdoInfo, CompleteAccess, PdoAssign, PdoConfig, PdoUpload), Dc/OpMode (Name, Desc,
// AssignActivate, CycleTimeSync0, ShiftTimeSync0, CycleTimeSync1), Eeprom/ByteSize,
// Profile (ProfileNo, ChannelCount) and Profile/Dictionary (DataTypes with SubItems and
// ArrayInfo, Objects with Info/DefaultData|SubItem and Flags/Access|PdoMapping). Numbers are
// decimal or "#x" hex; DefaultData is hex bytes in little-endian order.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace omnitwin::ethercat {

class EsiError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// What a SyncManager of the device is for (the text of the ESI Sm element; the SII category
// 41 type byte uses the same numbering).
enum class SmKind : std::uint8_t { unused = 0, mbox_out = 1, mbox_in = 2, outputs = 3, inputs = 4 };
const char* to_string(SmKind k);

struct EsiSyncManager {
  std::uint16_t start = 0;     // physical start address
  std::uint16_t size = 0;      // default length [bytes] (0 for process data: from the mapping)
  std::uint8_t control = 0;    // SM control byte (0x26 mailbox out, 0x22 mailbox in, 0x64 outputs, 0x20 inputs)
  bool enable = false;
  SmKind kind = SmKind::unused;
};

struct EsiPdoEntry {
  std::uint16_t index = 0;     // 0 = padding (gap)
  std::uint8_t subindex = 0;
  std::uint8_t bit_length = 0;
  std::string name;
  std::string data_type;       // "UINT", "DINT", "BOOL", ... (ESI spelling)
};

struct EsiPdo {
  std::uint16_t index = 0;     // 0x16xx (RxPDO) or 0x1Axx (TxPDO)
  std::string name;
  int sm = -1;                 // SyncManager it is assigned to by default, -1 = not assigned
  bool fixed = false;          // mapping not changeable
  bool mandatory = false;
  std::vector<EsiPdoEntry> entries;
  std::uint32_t bit_size() const;
};

// Access bits of one OD entry (the SDO information ObjAccess word uses the same bits).
namespace od_access {
inline constexpr std::uint16_t read_preop = 0x0001, read_safeop = 0x0002, read_op = 0x0004,
                               write_preop = 0x0008, write_safeop = 0x0010, write_op = 0x0020,
                               rxpdo = 0x0040, txpdo = 0x0080, backup = 0x0100, setting = 0x0200;
inline constexpr std::uint16_t read_all = read_preop | read_safeop | read_op;
inline constexpr std::uint16_t write_all = write_preop | write_safeop | write_op;
inline constexpr std::uint16_t rw = read_all | write_all;
}  // namespace od_access

struct EsiObjectEntry {
  std::uint8_t subindex = 0;
  std::string name;
  std::string data_type;       // base type name (ESI spelling)
  std::uint16_t bit_size = 0;
  std::uint16_t access = od_access::read_all;  // od_access bits incl. PDO mapping
  std::vector<std::uint8_t> default_data;      // little-endian bytes, empty = none given
};

struct EsiObject {
  std::uint16_t index = 0;
  std::string name;
  std::string data_type;       // the object's type name (a base type for VAR, a DTxxxx for records/arrays)
  std::uint8_t object_code = 7;  // 7 VAR, 8 ARRAY, 9 RECORD
  std::vector<EsiObjectEntry> entries;  // VAR: one entry, subindex 0; ARRAY/RECORD: sub 0 first
};

struct EsiCoe {
  bool present = false;         // Mailbox/CoE element given
  bool sdo_info = false, complete_access = false, pdo_assign = false, pdo_config = false,
       pdo_upload = false, segmented_sdo = true;
};

struct EsiDcOpMode {
  std::string name, desc;
  std::uint16_t assign_activate = 0;    // value for 0x0980 (e.g. 0x0300 = SYNC0 on)
  std::uint32_t cycle_time_sync0 = 0;   // [ns], 0 = the master's cycle
  std::int32_t shift_time_sync0 = 0;    // [ns]
  std::uint32_t cycle_time_sync1 = 0;   // [ns]
};

struct DeviceDescription {
  std::uint32_t vendor_id = 0;
  std::string vendor_name;
  std::uint32_t product_code = 0, revision = 0;
  std::string type_name;        // Device/Type text (order code)
  std::string name;             // Device/Name
  std::string group;            // Device/GroupType
  std::vector<SmKind> fmmus;    // Fmmu usage (outputs/inputs/mbox_in for "MBoxState")
  std::vector<EsiSyncManager> sms;
  std::vector<EsiPdo> rx_pdos, tx_pdos;
  std::vector<EsiObject> objects;  // the object dictionary, sorted by index
  EsiCoe coe;
  std::vector<EsiDcOpMode> dc;
  std::uint32_t eeprom_bytes = 2048;
  std::vector<std::uint8_t> eeprom_config;  // Eeprom/ConfigData: SII words 0..6 (up to 14 bytes)
  int profile = 0;              // ProfileNo (402 for drives)
  int axes = 1;                 // Profile/ChannelCount (1 when absent)
  std::string source;           // file it came from

  const EsiObject* object(std::uint16_t index) const;  // nullptr when absent
  const EsiPdo* pdo(std::uint16_t index) const;         // RxPdo or TxPdo, nullptr when absent
  int sm_of_kind(SmKind k) const;                        // first SM of that kind, -1 when none
};

// Parses every Device of an ESI file. Throws EsiError "path:line: message" (line 0 when the
// file cannot be read) on a missing file, malformed XML, or missing/invalid required fields
// (Vendor/Id, Device/Type ProductCode, Sm texts, PDO entries, hex values). Set-up code only.
std::vector<DeviceDescription> load_esi(const std::string& path);
// The same from XML text; `name` stands for the path in messages.
std::vector<DeviceDescription> parse_esi(const std::string& xml, const std::string& name = "<string>");

// "#x1A00" / "0x1A00" / "6656" → value; nullopt when not a number. Real-time safe.
std::optional<std::int64_t> parse_esi_number(const std::string& text);
// Bit size of an ESI base type name ("UINT" → 16, "BIT3" → 3, "STRING(8)" → 64); 0 when unknown.
std::uint16_t esi_type_bits(const std::string& type);

}  // namespace omnitwin::ethercat
