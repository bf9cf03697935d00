// controller layer — the reading half shared by the master programs' configuration files
// (controller/ethercat/ec_config, controller/mechatrolink3/m3_config): yaml-cpp parses, these
// helpers walk the tree once, checking each mapping's keys against the allowed set and each
// value's type, so the first problem is thrown as ConfigFileError "FILE:LINE: KEY: message"
// (LINE 1-based, from yaml-cpp's marks). Set-up code only.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace omnitwin::controller::config {

class ConfigFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

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
int line_of(const YAML::Node& n, int fallback);
[[noreturn]] void fail(const std::string& file, int line, const std::string& key, const std::string& msg);
[[noreturn]] void fail(const std::string& file, const Val& v, const std::string& key, const std::string& msg);
// An integer written in C style (decimal, 0x hex, 0 octal), as std::stoll with base 0 reads it.
std::int64_t integer_text(const std::string& file, int line, const std::string& key, const std::string& s);
std::int64_t integer(const std::string& file, const Val& v, const std::string& key);
double number(const std::string& file, const Val& v, const std::string& key);
// A number or integer within [lo, hi] ("must be in [lo, hi]" / "must be in lo..hi" otherwise).
double bounded(const std::string& file, const Val& v, const std::string& key, double lo, double hi);
std::int64_t bounded_int(const std::string& file, const Val& v, const std::string& key, std::int64_t lo, std::int64_t hi);
bool boolean(const std::string& file, const Val& v, const std::string& key);

// The members of a mapping, in file order; anything but a mapping, an unknown key or a
// repeated key is an error.
class Members {
 public:
  Members(const std::string& file, const Val& map, const std::string& where, const std::set<std::string>& keys);
  const Val* get(const std::string& name) const;

 private:
  std::vector<std::pair<std::string, Val>> items_;
};

// The elements of a sequence.
std::vector<Val> elements(const Val& seq);
// p against the folder `base` unless absolute.
std::string resolve(const std::string& base, const std::string& p);
// The file's one document (a second after '---' is refused rather than dropped; empty fails).
YAML::Node load_document(std::string_view yaml, const std::string& file);
// `platform:` — a block mapping in controller/master_config's vocabulary (kept as YAML text)
// or a file name (resolved against base_dir); exactly one of yaml/file is set.
void read_platform(const std::string& file, const Val& v, const std::string& base_dir, std::string& yaml,
                   std::string& platform_file);
// The text of a file; throws ConfigFileError when it cannot be read.
std::string read_file(const std::string& path);

}  // namespace omnitwin::controller::config
