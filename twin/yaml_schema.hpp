// twin layer — a small validating walker over yaml-cpp nodes, shared by every config loader.
//
// Config files are checked up front, key by key, and the first problem becomes a
// ScenarioError naming the file, the 1-based line and the dotted key. A YamlField is a
// node plus where it sits (its document and dotted key), so each typed read (number(),
// integer(), choice(), ...) can report its own position without the caller threading
// file/line/key through. Values that a --set override replaced carry no line of their own:
// the document knows the overridden keys and reports them as file "--set", line 0.
// Not real-time safe (allocates, throws); used only while loading.
#pragma once

#include <yaml-cpp/yaml.h>

#include <initializer_list>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "twin/scenario.hpp"

namespace omnitwin::twin {

// The file name reported for values that came from --set overrides.
inline constexpr const char* kOverrideFile = "--set";

// One YAML document being validated: its file name and the dotted keys --set replaced.
class YamlDoc {
 public:
  explicit YamlDoc(std::string file, std::vector<std::string> overridden = {});

  const std::string& file() const { return file_; }

  // The error for `key` at `mark`: file "--set"/line 0 if the key (or a parent of it)
  // was overridden, or if the node has no mark and lies on the way to an overridden key.
  ScenarioError error(const YAML::Mark& mark, const std::string& key,
                      const std::string& message) const;

  // The line reported for a node (1-based; 0 for overridden or unknown).
  int line_of(const YAML::Mark& mark, const std::string& key) const;

 private:
  bool overridden(const std::string& key) const;
  bool leads_to_override(const std::string& key) const;

  std::string file_;
  std::vector<std::string> overridden_;
};

// Allowed range of a number: [lo, hi] with either end optionally open.
struct Bounds {
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false;
  bool hi_open = false;

  static Bounds any() { return {}; }
  static Bounds positive() { return {0.0, std::numeric_limits<double>::infinity(), true, false}; }
  static Bounds non_negative() { return {0.0, std::numeric_limits<double>::infinity()}; }
  static Bounds closed(double lo, double hi) { return {lo, hi}; }
  static Bounds open_closed(double lo, double hi) { return {lo, hi, true, false}; }
  static Bounds at_least(double lo) { return {lo, std::numeric_limits<double>::infinity()}; }

  bool contains(double v) const;
  std::string describe() const;  // e.g. "> 0", "in (0, 0.01]", ">= 1"
};

// A node with its position: document, dotted key and the mark to report.
// Cheap to copy (yaml-cpp nodes are handles); the YamlDoc must outlive it.
class YamlField {
 public:
  // `name` is the last component of `key`: the mapping key (which may itself hold dots,
  // e.g. a metric path) or the sequence index.
  YamlField(const YamlDoc& doc, YAML::Node node, std::string key, std::string name,
            YAML::Mark mark);

  // The root of a document (key "").
  static YamlField root(const YamlDoc& doc, const YAML::Node& node);

  const std::string& key() const { return key_; }
  const YamlDoc& doc() const { return *doc_; }
  const YAML::Node& node() const { return node_; }
  // exists(): the key is written (perhaps with no value); present(): it has a value.
  bool exists() const { return node_.IsDefined(); }
  bool present() const { return node_.IsDefined() && !node_.IsNull(); }
  int line() const { return doc_->line_of(mark_, key_); }

  // The error for this field (to throw, or to keep for later).
  ScenarioError error(const std::string& message) const;
  [[noreturn]] void fail(const std::string& message) const;

  // --- mappings ---
  void require_map() const;  // also accepts an absent/null node as an empty mapping
  // Rejects any key not in `allowed` (error at the offending key's line).
  void allow_keys(std::initializer_list<std::string_view> allowed) const;
  void allow_keys(const std::vector<std::string_view>& allowed) const;
  // The member `name` (absent -> present() == false, positioned at this mapping).
  YamlField operator[](std::string_view name) const;
  // The member `name`, which must be present.
  YamlField required(std::string_view name) const;
  // All members in file order; each positioned at its key.
  std::vector<YamlField> members() const;
  // The only key of a one-key mapping (e.g. "line" in `- line: {...}`), which must be one
  // of `kinds`; returns the value field positioned at the key.
  YamlField single_member(std::initializer_list<std::string_view> kinds) const;
  YamlField single_member(const std::vector<std::string_view>& kinds) const;
  // Last component of the dotted key (the mapping key or sequence index).
  const std::string& name() const { return name_; }

  // --- sequences ---
  std::vector<YamlField> elements() const;  // also accepts absent/null as empty

  // --- scalars (each checks the type, and the range where bounds are given) ---
  double number(const Bounds& bounds = Bounds::any()) const;  // finite
  int integer(const Bounds& bounds = Bounds::any()) const;
  bool boolean() const;
  std::string string() const;
  std::string choice(std::initializer_list<std::string_view> options) const;
  // A list of exactly n numbers, each within bounds.
  std::vector<double> numbers(std::size_t n, const Bounds& bounds = Bounds::any()) const;

 private:
  std::string child_key(std::string_view name) const;
  YamlField absent(std::string_view name) const;
  std::string scalar_text() const;
  std::string type_name() const;

  const YamlDoc* doc_;
  YAML::Node node_;
  std::string key_;
  std::string name_;
  YAML::Mark mark_;
};

// Reads an optional member into `out` (left unchanged when the key is absent; a key with no
// value is an error). Returns whether it was set.
bool read_number(const YamlField& map, std::string_view name, double& out,
                 const Bounds& bounds = Bounds::any());
bool read_integer(const YamlField& map, std::string_view name, int& out,
                  const Bounds& bounds = Bounds::any());
bool read_bool(const YamlField& map, std::string_view name, bool& out);

}  // namespace omnitwin::twin
