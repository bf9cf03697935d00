// controller/ethercat — the EtherCAT master's configuration file (see ec_config.hpp).
//
// yaml-cpp parses the file; this reader walks the tree once, checking each mapping's keys
// against the allowed set and each value's type and range, so the first problem names its
// file, 1-based line (from yaml-cpp's Mark) and dotted key.
#include "controller/ethercat/ec_config.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace omnitwin::controller::ethercat {

using namespace config;

EcConfig parse_ec_config(std::string_view yaml, const std::string& file, const std::string& base_dir) {
  const YAML::Node doc = load_document(yaml, file);
  const Val root(doc, line_of(doc, 1));
  EcConfig c;
  c.file = file;
  const Members top(file, root, "",
                    {"esi", "cycle", "dc", "expected_slaves", "startup", "wheels", "wheel_mode", "wheel_counts_per_rev",
                     "platform", "user_pdo", "segment_loss_cycles", "segment_loss_ms", "startup_timeout",
                     "wheel_loss_timeout"});
  const Val* esi = top.get("esi");
  if (!esi) fail(file, root, "esi", "required (the ESI files describing the slaves)");
  if (esi->node.IsScalar()) {
    c.esi_files.push_back(resolve(base_dir, esi->node.Scalar()));
  } else if (esi->node.IsSequence() && esi->node.size() > 0) {
    for (const Val& e : elements(*esi)) {
      if (!e.node.IsScalar()) fail(file, e, "esi", "expected a file name");
      c.esi_files.push_back(resolve(base_dir, e.node.Scalar()));
    }
  } else {
    fail(file, *esi, "esi", "expected a file name or a list of them");
  }
  if (const Val* n = top.get("cycle")) {
    c.cycle = number(file, *n, "cycle");
    if (c.cycle <= 0 || c.cycle > 1) fail(file, *n, "cycle", "must be in (0, 1] s");
  }
  if (const Val* n = top.get("dc")) {
    if (n->node.IsScalar()) {
      c.dc = boolean(file, *n, "dc");
    } else {
      const Members dc(file, *n, "dc", {"enabled", "sync0_shift_us"});
      if (const Val* v = dc.get("enabled")) c.dc = boolean(file, *v, "dc.enabled");
      if (const Val* v = dc.get("sync0_shift_us")) c.sync0_shift_us = number(file, *v, "dc.sync0_shift_us");
    }
  }
  if (const Val* n = top.get("expected_slaves")) {
    c.expected_slaves = static_cast<int>(integer(file, *n, "expected_slaves"));
    if (c.expected_slaves < 1) fail(file, *n, "expected_slaves", "must be >= 1");
  }
  if (const Val* n = top.get("segment_loss_cycles")) {
    const std::int64_t v = integer(file, *n, "segment_loss_cycles");
    if (v < 0 || v > 100000) fail(file, *n, "segment_loss_cycles", "must be in 0..100000 (0 = off)");
    c.segment_loss_cycles = static_cast<int>(v);
  }
  if (const Val* n = top.get("segment_loss_ms")) {
    const std::int64_t v = integer(file, *n, "segment_loss_ms");
    if (v < 0 || v > 100000) fail(file, *n, "segment_loss_ms", "must be in 0..100000");
    c.segment_loss_ms = static_cast<int>(v);
  }
  if (const Val* n = top.get("startup_timeout")) c.startup_timeout = bounded(file, *n, "startup_timeout", 0.001, 3600);
  if (const Val* n = top.get("wheel_loss_timeout"))
    c.wheel_loss_timeout = bounded(file, *n, "wheel_loss_timeout", 0, 3600);
  if (const Val* n = top.get("startup")) {
    if (!n->node.IsSequence()) fail(file, *n, "startup", "expected a list");
    for (const Val& e : elements(*n)) {
      const Members m(file, e, "startup", {"slave", "index", "sub", "size", "value"});
      StartupSdo s;
      s.origin = fmt::format("{}:{}: startup", file, e.line);
      const Val* slave = m.get("slave");
      if (!slave || (slave->node.IsScalar() && slave->node.Scalar() == "all")) {
        s.position = -1;
      } else {
        const auto v = integer(file, *slave, "startup.slave");
        if (v < 1) fail(file, *slave, "startup.slave", "1-based slave number or 'all'");
        s.position = static_cast<int>(v - 1);
      }
      const Val* index = m.get("index");
      const Val* value = m.get("value");
      if (!index) fail(file, e, "startup.index", "required");
      if (!value) fail(file, e, "startup.value", "required");
      const auto idx = integer(file, *index, "startup.index");
      if (idx < 0 || idx > 0xFFFF) fail(file, *index, "startup.index", "must be 0..0xFFFF");
      s.index = static_cast<std::uint16_t>(idx);
      std::int64_t sub = 0, size = 4;
      if (const Val* v = m.get("sub")) {
        sub = integer(file, *v, "startup.sub");
        if (sub < 0 || sub > 255) fail(file, *v, "startup.sub", "must be 0..255");
      }
      if (const Val* v = m.get("size")) {
        size = integer(file, *v, "startup.size");
        if (size != 1 && size != 2 && size != 4 && size != 8) fail(file, *v, "startup.size", "must be 1, 2, 4 or 8 bytes");
      }
      s.sub = static_cast<std::uint8_t>(sub);
      s.data = value_bytes(integer(file, *value, "startup.value"), static_cast<unsigned>(size));
      c.startup.push_back(std::move(s));
    }
  }
  if (const Val* n = top.get("wheels")) {
    if (!n->node.IsSequence() || n->node.size() != 4) fail(file, *n, "wheels", "expected a list of four {slave, channel}");
    const std::vector<Val> ws = elements(*n);
    for (std::size_t i = 0; i < 4; ++i) {
      const Val& w = ws[i];
      const Members m(file, w, "wheels", {"slave", "channel"});
      const Val* slave = m.get("slave");
      if (!slave) fail(file, w, "wheels.slave", "required");
      c.wheels[i].slave = static_cast<int>(integer(file, *slave, "wheels.slave"));
      if (const Val* ch = m.get("channel")) c.wheels[i].channel = static_cast<int>(integer(file, *ch, "wheels.channel"));
      if (c.wheels[i].slave < 1 || c.wheels[i].channel < 1) fail(file, w, "wheels", "slave and channel are 1-based");
    }
    c.has_wheels = true;
  }
  if (const Val* n = top.get("wheel_mode")) {
    const std::string mode = n->node.IsScalar() ? n->node.Scalar() : std::string();
    if (mode != "csv" && mode != "csp") fail(file, *n, "wheel_mode", "csv or csp");
    c.wheel_mode = mode == "csv" ? WheelMode::csv : WheelMode::csp;
  }
  if (const Val* n = top.get("wheel_counts_per_rev")) {
    c.wheel_counts_per_rev = number(file, *n, "wheel_counts_per_rev");
    if (c.wheel_counts_per_rev <= 0) fail(file, *n, "wheel_counts_per_rev", "must be > 0");
  }
  if (const Val* n = top.get("user_pdo")) {
    const Members m(file, *n, "user_pdo", {"wpdo1", "wpdo2", "rpdo1", "rpdo2"});
    const char* names[4] = {"wpdo1", "wpdo2", "rpdo1", "rpdo2"};
    for (int i = 0; i < 4; ++i) {
      const Val* v = m.get(names[i]);
      if (!v) continue;
      const std::string key = std::string("user_pdo.") + names[i];
      if (!v->node.IsScalar()) fail(file, *v, key, "expected INDEX or INDEX:SUB");
      const std::string& text = v->node.Scalar();
      const auto colon = text.find(':');
      const auto index = integer_text(file, v->line, key, text.substr(0, colon));
      std::int64_t sub = 0;
      if (colon != std::string::npos) sub = integer_text(file, v->line, key, text.substr(colon + 1));
      if (index <= 0 || index > 0xFFFF || sub < 0 || sub > 255) fail(file, *v, key, "index 1..0xFFFF, sub 0..255");
      c.user_pdos[i] = {static_cast<std::uint16_t>(index), static_cast<std::uint8_t>(sub)};
    }
  }
  if (const Val* n = top.get("platform")) read_platform(file, *n, base_dir, c.platform_yaml, c.platform_file);
  if (c.has_wheels && c.platform_yaml.empty() && c.platform_file.empty())
    fail(file, *top.get("wheels"), "platform", "required with wheels (the platform loop and its path)");
  return c;
}

EcConfig load_ec_config(const std::string& path) {
  return parse_ec_config(read_file(path), path, std::filesystem::path(path).parent_path().string());
}

EcMasterConfig make_master_config(const EcConfig& c) {
  EcMasterConfig m;
  for (const auto& f : c.esi_files) {
    try {
      auto devs = omnitwin::ethercat::load_esi(f);
      for (auto& d : devs) m.devices.push_back(std::move(d));
    } catch (const omnitwin::ethercat::EsiError& e) {
      throw EcConfigError(fmt::format("{}: esi: {}", c.file, e.what()));
    }
  }
  m.cycle_ns = std::llround(c.cycle * 1e9);
  m.dc = c.dc;
  m.sync0_shift_ns = std::llround(c.sync0_shift_us * 1e3);
  m.startup = c.startup;
  m.read_back = {{0x607D, 1}, {0x607D, 2}};  // seed 004: drive-nsl@ / drive-psl@ answer what was read at boot
  m.expected_slaves = c.expected_slaves;
  m.segment_loss_cycles = c.segment_loss_cycles;
  m.segment_loss_ns = static_cast<SimTime>(c.segment_loss_ms) * 1'000'000;
  m.startup_timeout_ns = std::llround(c.startup_timeout * 1e9);
  return m;
}

}  // namespace omnitwin::controller::ethercat
