// libFuzzer target for bus_emulators/ethercat/device/ec_esi: ESI (EtherCAT Slave Information)
// XML text → DeviceDescription, and what the slave builds from a description it accepted
// (ec_sii's EEPROM image, ec_slave's object dictionary, PDO layout and ESC).
//
// The input is the XML text. Properties checked (ASan/UBSan check memory and UB; anything else
// than EsiError escaping is a crash by design, libFuzzer reports the uncaught exception):
//  - parse_esi returns at least one device or throws EsiError whose message starts with the
//    name it was given and a line number ("<fuzz>:N: ...");
//  - an accepted description is consistent: objects sorted by index without duplicates, every
//    object lookup finds itself, sm_of_kind names an SM of that kind;
//  - build_sii and the DriveSlave constructor (one axis) either succeed or throw EsiError; a
//    built SII image fills the EEPROM size exactly.
// Seeds: the shipped models/ethercat/*.xml (the ctest passes that directory) and the small
// files in fuzz/corpus/ec_esi; dictionary fuzz/ec_esi.dict (ESI element and attribute names).
//
//   ./ec_esi_fuzz -dict=fuzz/ec_esi.dict -max_total_time=60 /tmp/esi-corpus models/ethercat fuzz/corpus/ec_esi
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "bus_emulators/ethercat/device/ec_esi.hpp"
#include "bus_emulators/ethercat/device/ec_sii.hpp"
#include "bus_emulators/ethercat/device/ec_slave.hpp"

using namespace omnitwin::ethercat;

namespace {

#define CHECK(cond)   \
  do {                \
    if (!(cond)) __builtin_trap(); \
  } while (0)

const std::string kName = "<fuzz>";

// "<fuzz>:N: ..." with N a decimal line number.
void check_message(const EsiError& e) {
  const std::string m = e.what();
  CHECK(m.compare(0, kName.size() + 1, kName + ":") == 0);
  std::size_t i = kName.size() + 1;
  const std::size_t digits = i;
  while (i < m.size() && m[i] >= '0' && m[i] <= '9') ++i;
  CHECK(i > digits && i + 1 < m.size() && m[i] == ':' && m[i + 1] == ' ');
}

void check_description(const DeviceDescription& d) {
  for (std::size_t i = 0; i < d.objects.size(); ++i) {
    if (i > 0) CHECK(d.objects[i - 1].index < d.objects[i].index);
    CHECK(d.object(d.objects[i].index) == &d.objects[i]);
  }
  for (auto k : {SmKind::mbox_out, SmKind::mbox_in, SmKind::outputs, SmKind::inputs}) {
    const int i = d.sm_of_kind(k);
    CHECK(i >= -1 && i < static_cast<int>(d.sms.size()));
    if (i >= 0) CHECK(d.sms[static_cast<std::size_t>(i)].kind == k);
    CHECK(to_string(k) != nullptr);
  }
  for (const auto& p : d.rx_pdos) CHECK(d.pdo(p.index) != nullptr);
  for (const auto& p : d.tx_pdos) CHECK(d.pdo(p.index) != nullptr);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string xml(reinterpret_cast<const char*>(data), size);
  std::vector<DeviceDescription> devices;
  try {
    devices = parse_esi(xml, kName);
  } catch (const EsiError& e) {
    check_message(e);
    return 0;
  }
  CHECK(!devices.empty());
  for (const auto& d : devices) {
    check_description(d);
    try {
      const auto sii = build_sii(d, 0x1234, 42);
      CHECK(sii.size() == d.eeprom_bytes / 2);
    } catch (const EsiError&) {
    }
    try {
      DriveSlaveConfig cfg;
      cfg.axes = 1;
      DriveSlave s(d, cfg);
      CHECK(s.axes() == 1 && s.esc().al_state() == AlState::init);
    } catch (const EsiError&) {
    }
  }
  return 0;
}
