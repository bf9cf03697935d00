// controller layer — configuration-file reading helpers; see config_reader.hpp.
#include "controller/config_reader.hpp"
#include "controller/yaml_document.hpp"

#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace omnitwin::controller::config {

// The line of `n`; values without a position of their own (an empty value) take `fallback`.
int line_of(const YAML::Node& n, int fallback) {
  if (n.IsNull() || n.Mark().is_null()) return fallback;
  return n.Mark().line + 1;
}

[[noreturn]] void fail(const std::string& file, int line, const std::string& key, const std::string& msg) {
  throw ConfigFileError(fmt::format("{}:{}: {}{}", file, line, key.empty() ? "" : key + ": ", msg));
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

double bounded(const std::string& file, const Val& v, const std::string& key, double lo, double hi) {
  const double d = number(file, v, key);
  if (d < lo || d > hi) fail(file, v, key, fmt::format("must be in [{}, {}]", lo, hi));
  return d;
}

std::int64_t bounded_int(const std::string& file, const Val& v, const std::string& key, std::int64_t lo, std::int64_t hi) {
  const std::int64_t i = integer(file, v, key);
  if (i < lo || i > hi) fail(file, v, key, fmt::format("must be in {}..{}", lo, hi));
  return i;
}

std::int64_t integer(const std::string& file, const Val& v, const std::string& key) {
  if (!v.node.IsScalar()) fail(file, v, key, "expected an integer");
  return integer_text(file, v.line, key, v.node.Scalar());
}

double number(const std::string& file, const Val& v, const std::string& key) {
  if (!v.node.IsScalar()) fail(file, v, key, "expected a number");
  double d = 0;
  if (!YAML::convert<double>::decode(v.node, d) || !std::isfinite(d))
    fail(file, v, key, not_a_number(v.node.Scalar()));
  return d;
}

bool boolean(const std::string& file, const Val& v, const std::string& key) {
  bool b = false;
  if (!v.node.IsScalar() || !YAML::convert<bool>::decode(v.node, b)) fail(file, v, key, "expected true or false");
  return b;
}

Members::Members(const std::string& file, const Val& map, const std::string& where, const std::set<std::string>& keys) {
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

const Val* Members::get(const std::string& name) const {
  for (const auto& kv : items_)
    if (kv.first == name) return &kv.second;
  return nullptr;
}

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

YAML::Node load_document(std::string_view yaml, const std::string& file) {
  YamlDocument d;
  try {
    // Every document counted, so one after a '---' is refused rather than silently dropped.
    d = load_yaml_document(yaml);
  } catch (const YAML::Exception& e) {
    const YamlSyntaxError se = describe_syntax_error(yaml, e);
    if (se.line == 0) throw ConfigFileError(fmt::format("{}: {}", file, se.message));
    throw ConfigFileError(fmt::format("{}:{}: {}", file, se.line, se.message));
  }
  const int line = d.second.is_null() ? 0 : d.second.line + 1;
  if (d.stray) throw ConfigFileError(fmt::format("{}:{}: not YAML: a ',' outside any [ ] or {{ }}", file, line));
  if (d.count > 1)
    throw ConfigFileError(fmt::format("{}:{}: {} YAML documents; a configuration file holds one", file, line, d.count));
  const YAML::Node doc = d.node;
  if (!doc.IsDefined() || doc.IsNull()) throw ConfigFileError(fmt::format("{}: empty configuration", file));
  return doc;
}

void read_platform(const std::string& file, const Val& v, const std::string& base_dir, std::string& yaml,
                   std::string& platform_file) {
  if (v.node.IsScalar()) {
    platform_file = resolve(base_dir, v.node.Scalar());
  } else if (v.node.IsMap() && v.node.Style() != YAML::EmitterStyle::Flow) {
    yaml = YAML::Dump(v.node);
    if (yaml.empty() || yaml.back() != '\n') yaml += '\n';
  } else {
    fail(file, v, "platform", "expected a block mapping (master configuration keys) or a file name");
  }
}

std::string read_file(const std::string& path) {
  // An ifstream opens a directory and then reads nothing, which would pass for an empty file.
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw ConfigFileError(fmt::format("{}: a directory, not a configuration file", path));
  std::ifstream in(path);
  if (!in) throw ConfigFileError(fmt::format("{}: cannot read the file", path));
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace omnitwin::controller::config
