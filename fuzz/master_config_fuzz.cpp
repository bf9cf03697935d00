// libFuzzer target for omni-master's configuration readers (controller/): the file a user hands
// `omni-master --config`, for each bus. Byte 0 picks the reader, the rest is the YAML text:
//   0 the Omni CAN master (master_config)   1 CANopen (co_config)   2 EtherCAT (ec_config)
//   3 MECHATROLINK-III (m3_config)          4 TML (tml_config)
// and, when the text parsed and names no platform file, its inline platform section as the
// program loads it (load_platform_section).
//
// The contract omni-master relies on: a reader throws only its documented error (the programs
// catch exactly that and exit 2 with its one line); anything else escaping is a finding: main()
// would end it as an internal error (exit 3) instead. A configuration that parsed must also print
// (--print-config) and read back to the same print where a printer exists.
// Abort on any mismatch. Platform files are not opened: the fuzzer could name /dev/zero.
//
//   build/fuzz/master_config_fuzz -dict=fuzz/master_config.dict fuzz/corpus/master_config
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "controller/canopen/co_config.hpp"
#include "controller/ethercat/ec_config.hpp"
#include "controller/master_config.hpp"
#include "controller/mechatrolink3/m3_config.hpp"
#include "controller/tml/tml_config.hpp"

using namespace omnitwin;

namespace {

const std::string kFile = "fuzz.yaml";
const std::string kBase = OMNITWIN_SOURCE_DIR "/tests/data";

// The inline platform section, as the bus programs load it after their own section.
void platform(const std::string& file, const std::string& yaml) {
  if (!file.empty()) return;
  try {
    const auto cfg = controller::load_platform_section(file, yaml, kFile);
    if (cfg && controller::dump_master_config(*cfg).empty()) std::abort();
  } catch (const controller::MasterConfigError&) {
  }
}

// Prints `c`, reads the print back, and requires the same print.
template <class Config, class Parse, class Dump>
void round_trip(const Config& c, Parse parse, Dump dump) {
  const std::string once = dump(c);
  std::string twice;
  try {
    twice = dump(parse(once));
  } catch (const std::exception&) {
    std::abort();  // the program's own print must read back
  }
  if (once != twice) std::abort();
}

// A bus program's reader: its section, then the platform section it names, as the program
// loads them; `use` exercises what the program does next with the configuration.
template <class Parse, class Use>
void program(Parse parse, Use use) {
  try {
    const auto c = parse();
    platform(c.platform_file, c.platform_yaml);
    use(c);
  } catch (const controller::config::ConfigFileError&) {
  }
}

void run(std::uint8_t which, std::string_view yaml) {
  namespace co = controller::canopen;
  namespace ec = controller::ethercat;
  namespace tml = controller::tml;
  switch (which % 5) {
    case 0:
      try {
        const auto c = controller::parse_master_config(yaml, kFile);
        round_trip(c, [](const std::string& s) { return controller::parse_master_config(s, kFile); },
                   [](const controller::MasterConfig& m) { return controller::dump_master_config(m); });
      } catch (const controller::MasterConfigError&) {
      }
      break;
    case 1:
      program([&] { return co::parse_co_config(yaml, kFile, kBase); }, [](const auto& c) { (void)co::dump_co_config(c); });
      break;
    case 2:
      program([&] { return ec::parse_ec_config(yaml, kFile, kBase); }, [](const auto&) {});
      break;
    case 3:
      program([&] { return m3::parse_m3_config(yaml, kFile, kBase); },
              [](const auto& c) { (void)m3::dump_m3_config(c), (void)m3::station_addresses(c); });
      break;
    case 4:
      program([&] { return tml::parse_tml_config(yaml, kFile, kBase); }, [](const auto& c) { (void)tml::dump_tml_config(c); });
      break;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  run(data[0], std::string_view(reinterpret_cast<const char*>(data + 1), size - 1));
  return 0;
}
