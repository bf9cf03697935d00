// libFuzzer target for twin/scenario: scenario YAML (and the platform parameter file it names)
// → Scenario, as `omnitwin run` loads it.
//
// The input is the scenario file's text. It is written to a scenario folder inside a private
// temporary tree that mirrors models/ (scenarios/ beside a link to the shipped platform/), so
// the shipped scenarios' `params: ../platform/omni4.yaml` resolves as it does for a user.
// Properties checked (ASan/UBSan check memory and UB):
//  - load_scenario returns a Scenario or throws ScenarioError; any other exception escaping
//    is a crash by design (libFuzzer reports it);
//  - a ScenarioError's message is one line that begins with the path of the file at fault (the
//    scenario, or the parameter file it names), and a line in the scenario is 0 or within it
//    (+1 for an error at the end of the input);
//  - an accepted scenario is sane: a positive control period and duration, finite path times;
//  - the same with `--bus K` (an override of `bus`, K picked by the input's first byte), which
//    keeps or leaves out the file's bus settings (switch_bus_type): the same properties, every
//    note one line, and a switch to the file's own kind gives no note.
// Seeds: models/scenarios and tests/regression (the ctest passes both directories).
//
//   ./scenario_fuzz -max_total_time=60 -dict=fuzz/scenario.dict /tmp/scn models/scenarios tests/regression
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "twin/scenario.hpp"

namespace fs = std::filesystem;
using namespace omnitwin::twin;

namespace {

#define CHECK(cond)                \
  do {                             \
    if (!(cond)) __builtin_trap(); \
  } while (0)

// The private tree: DIR/scenarios/fuzz.yaml, DIR/platform → the shipped models/platform.
struct Tree {
  Tree() {
    char tmpl[] = "/tmp/omnitwin-scenario-fuzz-XXXXXX";
    CHECK(::mkdtemp(tmpl) != nullptr);
    dir = tmpl;
    fs::create_directory(dir / "scenarios");
    fs::create_directory_symlink(fs::path(OMNITWIN_SOURCE_DIR) / "models" / "platform", dir / "platform");
    file = (dir / "scenarios" / "fuzz.yaml").string();
  }
  ~Tree() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  fs::path dir;
  std::string file;
};

Tree& tree() {
  static Tree t;
  return t;
}

void check_error(const ScenarioError& e, const std::string& file, std::size_t lines) {
  const std::string m = e.what();
  CHECK(m.find('\n') == std::string::npos);
  CHECK(!e.file().empty() && m.compare(0, e.file().size(), e.file()) == 0);
  CHECK(e.line() >= 0);
  // Errors in the named platform file carry that file's lines, not ours.
  if (e.file() == file) CHECK(static_cast<std::size_t>(e.line()) <= lines + 1);
}

void check_scenario(const Scenario& s) {
  CHECK(s.controller.period > 0 && std::isfinite(s.controller.period));
  CHECK(s.duration > 0 && std::isfinite(s.duration));
  for (const std::string& n : s.notes) CHECK(!n.empty() && n.find('\n') == std::string::npos);
}

// Loads the file as `omnitwin run FILE --bus kind` does; `base`: the plain load's result, or
// null if it was refused.
void check_bus_switch(const std::string& file, std::size_t lines, const char* kind, const Scenario* base) {
  try {
    const Scenario s = load_scenario(file, {{"bus", kind}});
    check_scenario(s);
    CHECK(std::string(to_string(s.bus.kind)) == kind);
    if (base && base->bus.kind == s.bus.kind) CHECK(s.notes.empty());
  } catch (const ScenarioError& e) {
    check_error(e, file, lines);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 64 * 1024) return -1;  // scenario files are small; keep runs fast
  Tree& t = tree();
  {
    std::ofstream out(t.file, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  const std::size_t lines = static_cast<std::size_t>(std::count(data, data + size, '\n'));
  static const char* const kBuses[] = {"direct", "can", "canopen", "ethercat", "m3", "tml"};
  const char* kind = kBuses[size > 0 ? data[0] % 6 : 0];
  try {
    const Scenario s = load_scenario(t.file);
    check_scenario(s);
    check_bus_switch(t.file, lines, kind, &s);
  } catch (const ScenarioError& e) {
    check_error(e, t.file, lines);
    check_bus_switch(t.file, lines, kind, nullptr);
  }
  return 0;
}
