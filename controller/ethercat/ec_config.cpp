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

namespace {

// A YAML value with the 1-based line its errors name. Not assignable: assigning a
// YAML::Node that refers into a tree overwrites the node it refers to.
struct Val {
  YAML::Node node;
  int line = 0;
  Val(YAML::Node n, int l) : node(std::move(n)), line(l) {}
  Val(const Val&) = default;
  Val& operator=(const Val&) = delete;
};

// The line of `n`; values without a position of their own (an empty value) take `fallback`.
int line_of(const YAML::Node& n, int fallback) {
  if (n.IsNull() || n.Mark().is_null()) return fallback;
  return n.Mark().line + 1;
}

[[noreturn]] void fail(const std::string& file, int line, const std::string& key, const std::string& msg) {
  throw EcConfigError(fmt::format("{}:{}: {}{}", file, line, key.empty() ? "" : key + ": ", msg));
}
[[noreturn]] void fail(const std::string& file, const Val& v, const std::string& key, const std::string& msg) {
  fail(file, v.line, key, msg);
}

// An integer written in C style (decimal, 0x hex, 0 octal), as std::stoll with base 0 reads it.
std::int64_t integer_text(const std::string& file, int line, const std::string& key, const std::string& s) {
  try {
    std::size_t used = 0;
    const long long v = std::stoll(s, &used, 0);
    if (used != s.size()) throw std::invalid_argument(s);
    return v;
  } catch (const std::exception&) {
    fail(file, line, key, fmt::format("'{}' is not an integer", s));
  }
}

std::int64_t integer(const std::string& file, const Val& v, const std::string& key) {
  if (!v.node.IsScalar()) fail(file, v, key, "expected an integer");
  return integer_text(file, v.line, key, v.node.Scalar());
}

double number(const std::string& file, const Val& v, const std::string& key) {
  if (!v.node.IsScalar()) fail(file, v, key, "expected a number");
  double d = 0;
  if (!YAML::convert<double>::decode(v.node, d) || !std::isfinite(d))
    fail(file, v, key, fmt::format("'{}' is not a number", v.node.Scalar()));
  return d;
}

bool boolean(const std::string& file, const Val& v, const std::string& key) {
  bool b = false;
  if (!v.node.IsScalar() || !YAML::convert<bool>::decode(v.node, b)) fail(file, v, key, "expected true or false");
  return b;
}

// The members of a mapping, in file order; anything but a mapping, an unknown key or a
// repeated key is an error.
class Members {
 public:
  Members(const std::string& file, const Val& map, const std::string& where, const std::set<std::string>& keys) {
    if (!map.node.IsMap()) fail(file, map, where, "expected a mapping");
    for (auto it = map.node.begin(); it != map.node.end(); ++it) {
      const int key_line = it->first.Mark().is_null() ? map.line : it->first.Mark().line + 1;
      if (!it->first.IsScalar()) fail(file, key_line, where, "mapping keys must be plain names");
      const std::string name = it->first.Scalar();
      const std::string dotted = where.empty() ? name : where + "." + name;
      if (!keys.count(name)) {
        std::string names;
        for (const auto& n : keys) names += (names.empty() ? "" : ", ") + n;
        fail(file, key_line, dotted, fmt::format("unknown key (expected one of: {})", names));
      }
      if (get(name)) fail(file, key_line, dotted, "repeated key");
      items_.emplace_back(name, Val(it->second, line_of(it->second, key_line)));
    }
  }
  const Val* get(const std::string& name) const {
    for (const auto& kv : items_)
      if (kv.first == name) return &kv.second;
    return nullptr;
  }

 private:
  std::vector<std::pair<std::string, Val>> items_;
};

// The elements of a sequence.
std::vector<Val> elements(const Val& seq) {
  std::vector<Val> out;
  for (std::size_t i = 0; i < seq.node.size(); ++i) {
    const YAML::Node e = seq.node[i];
    out.emplace_back(e, line_of(e, seq.line));
  }
  return out;
}

std::string resolve(const std::string& base, const std::string& p) {
  if (base.empty() || std::filesystem::path(p).is_absolute()) return p;
  return (std::filesystem::path(base) / p).lexically_normal().string();
}

}  // namespace

EcConfig parse_ec_config(std::string_view yaml, const std::string& file, const std::string& base_dir) {
  YAML::Node doc;
  std::vector<YAML::Node> docs;
  try {
    // All documents, so one after a '---' is refused rather than silently dropped.
    docs = YAML::LoadAll(std::string(yaml));
  } catch (const YAML::Exception& e) {
    if (e.mark.is_null()) throw EcConfigError(fmt::format("{}: {}", file, e.msg));
    throw EcConfigError(fmt::format("{}:{}: {}", file, e.mark.line + 1, e.msg));
  }
  if (docs.size() > 1) {
    throw EcConfigError(fmt::format("{}:{}: {} YAML documents; a configuration file holds one", file,
                                    docs[1].Mark().is_null() ? 0 : docs[1].Mark().line + 1, docs.size()));
  }
  if (!docs.empty()) doc = docs[0];
  if (!doc.IsDefined() || doc.IsNull()) throw EcConfigError(fmt::format("{}: empty configuration", file));
  const Val root(doc, line_of(doc, 1));
  EcConfig c;
  c.file = file;
  const Members top(file, root, "",
                    {"esi", "cycle", "dc", "expected_slaves", "startup", "wheels", "wheel_mode", "wheel_counts_per_rev",
                     "platform", "user_pdo", "segment_loss_cycles"});
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
  if (const Val* n = top.get("startup")) {
    if (!n->node.IsSequence()) fail(file, *n, "startup", "expected a list");
    for (const Val& e : elements(*n)) {
      const Members m(file, e, "startup", {"slave", "index", "sub", "size", "value"});
      StartupSdo s;
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
  if (const Val* n = top.get("platform")) {
    if (n->node.IsScalar()) {
      c.platform_file = resolve(base_dir, n->node.Scalar());
    } else if (n->node.IsMap() && n->node.Style() != YAML::EmitterStyle::Flow) {
      c.platform_yaml = YAML::Dump(n->node);
      if (c.platform_yaml.empty() || c.platform_yaml.back() != '\n') c.platform_yaml += '\n';
    } else {
      fail(file, *n, "platform", "expected a block mapping (master configuration keys) or a file name");
    }
  }
  if (c.has_wheels && c.platform_yaml.empty() && c.platform_file.empty())
    fail(file, *top.get("wheels"), "platform", "required with wheels (the platform loop and its path)");
  return c;
}

EcConfig load_ec_config(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw EcConfigError(fmt::format("{}: cannot read the file", path));
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_ec_config(ss.str(), path, std::filesystem::path(path).parent_path().string());
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
  m.expected_slaves = c.expected_slaves;
  m.segment_loss_cycles = c.segment_loss_cycles;
  return m;
}

}  // namespace omnitwin::controller::ethercat
