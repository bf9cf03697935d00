// twin layer — the validating YAML walker; see yaml_schema.hpp.
#include "twin/yaml_schema.hpp"
#include "controller/yaml_document.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace omnitwin::twin {

namespace {

// Shortest round-trip text of a bound or value, for messages.
std::string num(double v) { return fmt::format("{}", v); }

// "a, b, c" from a list of names.
template <class List>
std::string join_names(const List& names, std::string_view sep = ", ") {
  std::string out;
  for (std::string_view n : names) out += (out.empty() ? "" : std::string(sep)) + std::string(n);
  return out;
}

// True if `key` is `prefix` or lies below it in the dotted hierarchy.
bool at_or_below(const std::string& key, const std::string& prefix) {
  if (key.size() < prefix.size() || key.compare(0, prefix.size(), prefix) != 0) return false;
  return key.size() == prefix.size() || key[prefix.size()] == '.';
}

}  // namespace

// ---------------------------------------------------------------------------------------
// YamlDoc

YamlDoc::YamlDoc(std::string file, std::vector<std::string> overridden)
    : file_(std::move(file)), overridden_(std::move(overridden)) {}

bool YamlDoc::overridden(const std::string& key) const {
  return std::any_of(overridden_.begin(), overridden_.end(),
                     [&](const std::string& o) { return at_or_below(key, o); });
}

bool YamlDoc::leads_to_override(const std::string& key) const {
  return std::any_of(overridden_.begin(), overridden_.end(),
                     [&](const std::string& o) { return at_or_below(o, key); });
}

int YamlDoc::line_of(const YAML::Mark& mark, const std::string& key) const {
  if (overridden(key)) return 0;
  if (mark.is_null() || mark.line < 0) return 0;
  return mark.line + 1;
}

ScenarioError YamlDoc::error(const YAML::Mark& mark, const std::string& key,
                             const std::string& message) const {
  // Values from --set, and the maps created on the way to them, have no line in any file.
  const bool from_set = overridden(key) || (mark.is_null() && leads_to_override(key));
  if (from_set) return ScenarioError(kOverrideFile, 0, key, message);
  return ScenarioError(file_, line_of(mark, key), key, message);
}

// ---------------------------------------------------------------------------------------
// Bounds

bool Bounds::contains(double v) const {
  const bool lo_ok = lo_open ? v > lo : v >= lo;
  const bool hi_ok = hi_open ? v < hi : v <= hi;
  return lo_ok && hi_ok;
}

std::string Bounds::describe() const {
  const bool has_lo = std::isfinite(lo);
  const bool has_hi = std::isfinite(hi);
  if (has_lo && has_hi) {
    return fmt::format("in {}{}, {}{}", lo_open ? '(' : '[', num(lo), num(hi), hi_open ? ')' : ']');
  }
  if (has_lo) return fmt::format("{} {}", lo_open ? ">" : ">=", num(lo));
  if (has_hi) return fmt::format("{} {}", hi_open ? "<" : "<=", num(hi));
  return "finite";
}

// ---------------------------------------------------------------------------------------
// YamlField: position and errors

YamlField::YamlField(const YamlDoc& doc, YAML::Node node, std::string key, std::string name,
                     YAML::Mark mark)
    : doc_(&doc), node_(std::move(node)), key_(std::move(key)), name_(std::move(name)), mark_(mark) {}

YamlField YamlField::root(const YamlDoc& doc, const YAML::Node& node) {
  return YamlField(doc, node, "", "", node.IsDefined() ? node.Mark() : YAML::Mark::null_mark());
}

ScenarioError YamlField::error(const std::string& message) const {
  return doc_->error(mark_, key_, message);
}

void YamlField::fail(const std::string& message) const { throw error(message); }

std::string YamlField::child_key(std::string_view name) const {
  return key_.empty() ? std::string(name) : key_ + "." + std::string(name);
}

std::string YamlField::type_name() const {
  if (!present()) return "nothing";
  if (node_.IsMap()) return "a mapping";
  if (node_.IsSequence()) return "a list";
  return "'" + node_.Scalar() + "'";
}

// ---------------------------------------------------------------------------------------
// YamlField: mappings

void YamlField::require_map() const {
  if (present() && !node_.IsMap()) fail("expected a mapping, got " + type_name());
}

void YamlField::allow_keys(std::initializer_list<std::string_view> allowed) const {
  allow_keys(std::vector<std::string_view>(allowed));
}

void YamlField::allow_keys(const std::vector<std::string_view>& allowed) const {
  require_map();
  if (!present()) return;
  for (const auto& m : members()) {
    const std::string& n = m.name();
    const bool known = std::find(allowed.begin(), allowed.end(), n) != allowed.end();
    if (known) continue;
    // List the accepted keys so a typo is easy to spot.
    m.fail(fmt::format("unknown key (expected one of: {})", join_names(allowed)));
  }
}

YamlField YamlField::operator[](std::string_view name) const {
  require_map();
  const std::string k(name);
  if (!present()) return absent(name);
  for (auto it = node_.begin(); it != node_.end(); ++it) {
    if (it->first.IsScalar() && it->first.Scalar() == k) {
      return YamlField(*doc_, it->second, child_key(name), k, it->first.Mark());
    }
  }
  return absent(name);
}

YamlField YamlField::absent(std::string_view name) const {
  // An undefined node: exists() and present() are false; errors point at this mapping.
  return YamlField(*doc_, YAML::Node(YAML::NodeType::Undefined), child_key(name),
                   std::string(name), mark_);
}

YamlField YamlField::required(std::string_view name) const {
  YamlField f = (*this)[name];
  if (!f.present()) f.fail(f.exists() ? "missing value" : "missing required key");
  return f;
}

std::vector<YamlField> YamlField::members() const {
  require_map();
  std::vector<YamlField> out;
  if (!present()) return out;
  for (auto it = node_.begin(); it != node_.end(); ++it) {
    if (!it->first.IsScalar()) {
      throw doc_->error(it->first.Mark(), key_, "mapping keys must be plain names");
    }
    // yaml-cpp keeps a repeated key and lookups answer with the first, so the later value
    // (often the one meant) would be ignored without a word: refuse it, naming both lines.
    for (const auto& earlier : out) {
      if (earlier.name() != it->first.Scalar()) continue;
      const int first = earlier.line();
      throw doc_->error(it->first.Mark(), child_key(it->first.Scalar()),
                        first > 0 ? fmt::format("duplicate key (first given at line {})", first) : "duplicate key");
    }
    out.emplace_back(*doc_, it->second, child_key(it->first.Scalar()), it->first.Scalar(),
                     it->first.Mark());
  }
  return out;
}

YamlField YamlField::single_member(std::initializer_list<std::string_view> kinds) const {
  return single_member(std::vector<std::string_view>(kinds));
}

YamlField YamlField::single_member(const std::vector<std::string_view>& kinds) const {
  if (!present() || !node_.IsMap() || node_.size() != 1) {
    fail(fmt::format("expected a one-key mapping naming one of: {}", join_names(kinds)));
  }
  const YamlField member = members().front();
  const std::string& n = member.name();
  if (std::find(kinds.begin(), kinds.end(), n) == kinds.end()) {
    member.fail(fmt::format("unknown kind '{}' (expected one of: {})", n, join_names(kinds)));
  }
  return member;
}

// ---------------------------------------------------------------------------------------
// YamlField: sequences and scalars

std::vector<YamlField> YamlField::elements() const {
  std::vector<YamlField> out;
  if (!present()) return out;
  if (!node_.IsSequence()) fail("expected a list, got " + type_name());
  for (std::size_t i = 0; i < node_.size(); ++i) {
    const YAML::Node item = node_[i];
    out.emplace_back(*doc_, item, child_key(std::to_string(i)), std::to_string(i), item.Mark());
  }
  return out;
}

std::string YamlField::scalar_text() const {
  if (!present()) fail("missing value");
  if (!node_.IsScalar()) fail("expected a single value, got " + type_name());
  return node_.Scalar();
}

double YamlField::number(const Bounds& bounds) const {
  const std::string text = scalar_text();
  double v = 0;
  if (!YAML::convert<double>::decode(node_, v) || !std::isfinite(v)) {
    fail(controller::not_a_number(text));
  }
  if (!bounds.contains(v)) fail(fmt::format("{} is out of range (must be {})", text, bounds.describe()));
  return v;
}

int YamlField::integer(const Bounds& bounds) const {
  const std::string text = scalar_text();
  int v = 0;
  if (!YAML::convert<int>::decode(node_, v)) fail(fmt::format("expected an integer, got '{}'", text));
  if (!bounds.contains(v)) fail(fmt::format("{} is out of range (must be {})", text, bounds.describe()));
  return v;
}

bool YamlField::boolean() const {
  const std::string text = scalar_text();
  bool v = false;
  if (!YAML::convert<bool>::decode(node_, v)) fail(fmt::format("expected true or false, got '{}'", text));
  return v;
}

std::string YamlField::string() const { return scalar_text(); }

std::string YamlField::choice(std::initializer_list<std::string_view> options) const {
  const std::string text = scalar_text();
  if (std::find(options.begin(), options.end(), text) != options.end()) return text;
  fail(fmt::format("'{}' is not one of: {}", text, join_names(options, " | ")));
}

std::vector<double> YamlField::numbers(std::size_t n, const Bounds& bounds) const {
  if (!present() || !node_.IsSequence() || node_.size() != n) {
    fail(fmt::format("expected a list of {} numbers, got {}", n,
                     present() && node_.IsSequence()
                         ? fmt::format("a list of {}", node_.size()) : type_name()));
  }
  std::vector<double> out;
  for (const auto& e : elements()) out.push_back(e.number(bounds));
  return out;
}

// ---------------------------------------------------------------------------------------
// Optional-member helpers

bool read_number(const YamlField& map, std::string_view name, double& out, const Bounds& bounds) {
  const YamlField f = map[name];
  if (!f.exists()) return false;
  out = f.number(bounds);
  return true;
}

bool read_integer(const YamlField& map, std::string_view name, int& out, const Bounds& bounds) {
  const YamlField f = map[name];
  if (!f.exists()) return false;
  out = f.integer(bounds);
  return true;
}

bool read_bool(const YamlField& map, std::string_view name, bool& out) {
  const YamlField f = map[name];
  if (!f.exists()) return false;
  out = f.boolean();
  return true;
}

}  // namespace omnitwin::twin
