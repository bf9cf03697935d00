// controller layer — the Omni master's configuration file; see master_config.hpp.
//
// One pass over the YAML tree with a small validating reader: each mapping's keys are
// checked against the allowed set first, then each value is read with its type and range,
// so the first problem names its file, line and dotted key. Dumping writes the same keys
// back with round-trip number formatting.
#include "controller/master_config.hpp"
#include "controller/master_bounds.hpp"
#include "controller/yaml_document.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <limits>
#include <numbers>

namespace omnitwin::controller {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr const char* kCodeFile = "<config>";  // "file" of configurations built in code

std::string format_error(const std::string& file, int line, const std::string& key,
                         const std::string& message) {
  std::string out = file;
  if (line > 0) out += fmt::format(":{}", line);
  out += ": ";
  if (!key.empty()) out += key + ": ";
  // One line, whatever the message (yaml-cpp's own messages are single lines already).
  for (char ch : message) out += (ch == '\n' || ch == '\r') ? ' ' : ch;
  return out;
}

// A YAML value with where it sits: its dotted key, its last key component, and the 1-based
// line of its key (0 = unknown).
struct Item {
  YAML::Node node;
  std::string key;
  std::string name;
  int line = 0;
};

// The validating reader of one file: every error names the file, the line and the key.
class Reader {
 public:
  explicit Reader(std::string file) : file_(std::move(file)) {}

  [[noreturn]] void fail(const Item& at, const std::string& message) const {
    throw MasterConfigError(file_, at.line, at.key, message);
  }

  // Members of a mapping in file order (absent/null = none); unknown or repeated keys fail.
  std::vector<Item> members(const Item& map, std::initializer_list<std::string_view> allowed) const {
    std::vector<Item> out;
    if (!map.node.IsDefined() || map.node.IsNull()) return out;
    if (!map.node.IsMap()) fail(map, "expected a mapping, got " + describe(map.node));
    for (auto it = map.node.begin(); it != map.node.end(); ++it) {
      if (!it->first.IsScalar()) fail(map, "mapping keys must be plain names");
      const std::string name = it->first.Scalar();
      const Item item{it->second, map.key.empty() ? name : map.key + "." + name, name,
                      it->first.Mark().line + 1};
      check_key(item, out, allowed);
      out.push_back(item);
    }
    return out;
  }

  // Elements of a list (absent/null = none).
  std::vector<Item> elements(const Item& list) const {
    std::vector<Item> out;
    if (!list.node.IsDefined() || list.node.IsNull()) return out;
    if (!list.node.IsSequence()) fail(list, "expected a list, got " + describe(list.node));
    for (std::size_t i = 0; i < list.node.size(); ++i) {
      const YAML::Node n = list.node[i];
      out.push_back({n, fmt::format("{}.{}", list.key, i), std::to_string(i), n.Mark().line + 1});
    }
    return out;
  }

  // A finite number above lo (or at least lo when !lo_open).
  double number(const Item& it, double lo = -std::numeric_limits<double>::infinity(),
                bool lo_open = false) const {
    const std::string text = scalar(it);
    double v = 0;
    if (!YAML::convert<double>::decode(it.node, v) || !std::isfinite(v)) {
      fail(it, not_a_number(text));
    }
    if (lo_open ? !(v > lo) : !(v >= lo)) fail(it, fmt::format("must be {} {}", lo_open ? ">" : ">=", lo));
    return v;
  }

  // A finite number in [lo, hi].
  double bounded(const Item& it, double lo, double hi) const {
    const double v = number(it);
    if (v < lo || v > hi) fail(it, fmt::format("must be in [{}, {}]", lo, hi));
    return v;
  }

  // An integer in [lo, hi].
  long integer(const Item& it, long lo, long hi) const {
    const std::string text = scalar(it);
    long v = 0;
    if (!YAML::convert<long>::decode(it.node, v)) fail(it, fmt::format("expected an integer, got '{}'", text));
    if (v < lo || v > hi) fail(it, fmt::format("must be in [{}, {}]", lo, hi));
    return v;
  }

  bool boolean(const Item& it) const {
    const std::string text = scalar(it);
    bool v = false;
    if (!YAML::convert<bool>::decode(it.node, v)) fail(it, fmt::format("expected true or false, got '{}'", text));
    return v;
  }

  // A list of exactly three numbers, each >= 0 (the x, y, phi gains).
  std::array<double, 3> gains(const Item& it) const {
    const auto e = elements(it);
    if (!it.node.IsSequence() || e.size() != 3) fail(it, "expected a list of three numbers [x, y, phi]");
    return {number(e[0], 0.0), number(e[1], 0.0), number(e[2], 0.0)};
  }

 private:
  static std::string describe(const YAML::Node& n) {
    if (n.IsMap()) return "a mapping";
    if (n.IsSequence()) return "a list";
    return n.IsScalar() ? "'" + n.Scalar() + "'" : "nothing";
  }

  // The scalar text of a value; a key with no value or a non-scalar fails.
  std::string scalar(const Item& it) const {
    if (!it.node.IsDefined() || it.node.IsNull()) fail(it, "missing value");
    if (!it.node.IsScalar()) fail(it, "expected a value, got " + describe(it.node));
    return it.node.Scalar();
  }

  void check_key(const Item& item, const std::vector<Item>& seen,
                 std::initializer_list<std::string_view> allowed) const {
    const auto same = [&](const Item& s) { return s.name == item.name; };
    if (std::any_of(seen.begin(), seen.end(), same)) fail(item, "duplicate key");
    if (std::find(allowed.begin(), allowed.end(), item.name) != allowed.end()) return;
    std::string names;
    for (std::string_view a : allowed) names += (names.empty() ? "" : ", ") + std::string(a);
    fail(item, fmt::format("unknown key (expected one of: {})", names));
  }

  std::string file_;
};

// The member `name` of already-read members, or nullptr.
const Item* find(const std::vector<Item>& ms, std::string_view name) {
  for (const Item& m : ms)
    if (m.name == name) return &m;
  return nullptr;
}

// The member `name`, which must be written; `map` positions the error when it is not.
const Item& require(const Reader& r, const Item& map, const std::vector<Item>& ms, std::string_view name) {
  const Item* m = find(ms, name);
  if (m == nullptr) r.fail({map.node, map.key.empty() ? std::string(name) : map.key + "." + std::string(name),
                            std::string(name), map.line}, "missing required key");
  return *m;
}

// ---------------------------------------------------------------------------------------
// Path

// The values of one segment kind; `v` is the mapping under the kind's key.
void read_segment_values(const Reader& r, const Item& v, SegmentSpec& s) {
  using K = SegmentSpec::Kind;
  const double kAny = -std::numeric_limits<double>::infinity();
  const auto read_opt = [&](const std::vector<Item>& ms, std::string_view n, double& out) {
    if (const Item* m = find(ms, n)) out = r.number(*m, kAny);
  };
  std::vector<Item> ms;
  switch (s.kind) {
    case K::line:
      ms = r.members(v, {"dx", "dy", "dphi_deg", "duration"});
      read_opt(ms, "dx", s.dx), read_opt(ms, "dy", s.dy), read_opt(ms, "dphi_deg", s.dphi_deg);
      break;
    case K::arc:
      ms = r.members(v, {"cx", "cy", "sweep_deg", "dphi_deg", "duration"});
      s.cx = r.number(require(r, v, ms, "cx")), s.cy = r.number(require(r, v, ms, "cy"));
      s.sweep_deg = r.number(require(r, v, ms, "sweep_deg"));
      read_opt(ms, "dphi_deg", s.dphi_deg);
      if (s.cx == 0 && s.cy == 0) r.fail(v, "arc centre (cx, cy) must differ from the start point");
      break;
    case K::rotate:
      ms = r.members(v, {"dphi_deg", "duration"});
      s.dphi_deg = r.number(require(r, v, ms, "dphi_deg"));
      break;
    case K::dwell: ms = r.members(v, {"duration"}); break;
    case K::square:
      ms = r.members(v, {"side", "duration", "ccw"});
      s.side = r.number(require(r, v, ms, "side"), 0.0, true);
      if (const Item* m = find(ms, "ccw")) s.ccw = r.boolean(*m);
      break;
    case K::circle:
    case K::figure_eight:
      ms = r.members(v, {"radius", "duration", "ccw"});
      s.radius = r.number(require(r, v, ms, "radius"), 0.0, true);
      if (const Item* m = find(ms, "ccw")) s.ccw = r.boolean(*m);
      break;
  }
  s.duration = r.number(require(r, v, ms, "duration"), 0.0, true);
}

// One `- kind: {...}` list element.
SegmentSpec read_segment(const Reader& r, const Item& item) {
  using K = SegmentSpec::Kind;
  static constexpr std::pair<std::string_view, K> kKinds[] = {
      {"line", K::line},     {"arc", K::arc},       {"rotate", K::rotate},           {"dwell", K::dwell},
      {"square", K::square}, {"circle", K::circle}, {"figure_eight", K::figure_eight}};
  const auto ms = r.members(item, {"line", "arc", "rotate", "dwell", "square", "circle", "figure_eight"});
  if (!item.node.IsMap() || ms.size() != 1) {
    r.fail(item, "expected a one-key mapping naming one of: line, arc, rotate, dwell, square, circle, figure_eight");
  }
  SegmentSpec s;
  for (const auto& [name, kind] : kKinds)
    if (ms[0].name == name) s.kind = kind;
  read_segment_values(r, ms[0], s);
  return s;
}

PathSpec read_path(const Reader& r, const Item& p) {
  PathSpec spec;
  const auto ms = r.members(p, {"start", "segments"});
  if (const Item* start = find(ms, "start")) {
    for (const Item& m : r.members(*start, {"x", "y", "phi_deg"})) {
      const double v = r.number(m);
      (m.name == "x" ? spec.x : m.name == "y" ? spec.y : spec.phi_deg) = v;
    }
  }
  if (const Item* segs = find(ms, "segments")) {
    for (const Item& e : r.elements(*segs)) spec.segments.push_back(read_segment(r, e));
  }
  return spec;
}

// ---------------------------------------------------------------------------------------
// Top level

void read_geometry(const Reader& r, const Item& g, PlatformLoopConfig& loop) {
  for (const Item& m : r.members(g, {"L", "r", "counts_per_rev"})) {
    if (m.name == "L") loop.L = r.number(m, 0.0, true);
    if (m.name == "r") loop.r = r.number(m, 0.0, true);
    if (m.name == "counts_per_rev") loop.counts_per_rev = static_cast<int>(r.integer(m, 1, kMaxCountsPerRev));
  }
}

// The platform-loop keys; false if `m` is not one of them.
bool read_loop_key(const Reader& r, const Item& m, PlatformLoopConfig& loop) {
  const std::string& n = m.name;
  // Bounded as CANopen's cycle: 0 ns would divide by zero in the wall loop, and a huge one
  // overflows its nanosecond arithmetic (found in review).
  if (n == "period") loop.period = r.bounded(m, kMinLoopPeriod, kMaxLoopPeriod);
  else if (n == "kp") loop.kp = r.gains(m);
  else if (n == "ki") loop.ki = r.gains(m);
  else if (n == "feedforward") loop.feedforward = r.boolean(m);
  else if (n == "max_speed") loop.max_speed = r.number(m, 0.0, true);
  else if (n == "max_yaw_rate") loop.max_yaw_rate = r.number(m, 0.0, true);
  else if (n == "geometry") read_geometry(r, m, loop);
  else return false;
  return true;
}

// startup_timeout: > 0 and at most kMaxStartupTimeout, as every master's (1e10 s overflowed
// the master's nanoseconds into a negative time-out: found in review).
double startup_timeout(const Reader& r, const Item& m) {
  const double v = r.number(m, 0.0, true);
  if (v > kMaxStartupTimeout) r.fail(m, fmt::format("must be at most {}", kMaxStartupTimeout));
  return v;
}

// The master's own keys (everything but the platform loop's).
void read_master_key(const Reader& r, const Item& m, MasterConfig& c) {
  const std::string& n = m.name;
  constexpr long kIntMax = std::numeric_limits<int>::max();
  if (n == "settle") c.settle = m.node.IsNull() ? -1.0 : r.number(m);  // null: never
  else if (n == "wait_for_pc") c.wait_for_pc = r.boolean(m);
  else if (n == "detect_every") c.detect_every = static_cast<int>(r.integer(m, 0, kIntMax));
  else if (n == "detect_misses") c.detect_misses = static_cast<int>(r.integer(m, 1, kIntMax));
  else if (n == "feedback_timeout") c.feedback_timeout = static_cast<int>(r.integer(m, 0, kIntMax));
  else if (n == "startup_timeout") c.startup_timeout = startup_timeout(r, m);
  else if (n == "slave_kp") c.slave_kp = static_cast<std::uint16_t>(r.integer(m, 0, 0xFFFF));
  else if (n == "path") c.path = read_path(r, m);
}

MasterConfig read_config(const Reader& r, const Item& root) {
  const auto ms = r.members(root, {"period", "kp", "ki", "feedforward", "max_speed", "max_yaw_rate", "geometry",
                                   "path", "settle", "wait_for_pc", "detect_every", "detect_misses",
                                   "feedback_timeout", "startup_timeout", "slave_kp"});
  MasterConfig c;
  for (const Item& m : ms) {
    if (!read_loop_key(r, m, c.loop)) read_master_key(r, m, c);
  }
  const Item& path = require(r, root, ms, "path");
  if (!path.node.IsDefined() || path.node.IsNull()) r.fail(path, "missing value");
  return c;
}

// ---------------------------------------------------------------------------------------
// Dump

std::string num(double v) { return fmt::format("{}", v); }

void emit_segment(YAML::Emitter& e, const SegmentSpec& s) {
  using K = SegmentSpec::Kind;
  static constexpr const char* kNames[] = {"line", "arc", "rotate", "dwell", "square", "circle", "figure_eight"};
  e << YAML::BeginMap << YAML::Key << kNames[static_cast<int>(s.kind)] << YAML::Value << YAML::Flow
    << YAML::BeginMap;
  const auto kv = [&](const char* k, double v) { e << YAML::Key << k << YAML::Value << num(v); };
  switch (s.kind) {
    case K::line: kv("dx", s.dx), kv("dy", s.dy), kv("dphi_deg", s.dphi_deg); break;
    case K::arc: kv("cx", s.cx), kv("cy", s.cy), kv("sweep_deg", s.sweep_deg), kv("dphi_deg", s.dphi_deg); break;
    case K::rotate: kv("dphi_deg", s.dphi_deg); break;
    case K::dwell: break;
    case K::square: kv("side", s.side); break;
    case K::circle:
    case K::figure_eight: kv("radius", s.radius); break;
  }
  kv("duration", s.duration);
  const bool turns = s.kind == K::square || s.kind == K::circle || s.kind == K::figure_eight;
  if (turns) e << YAML::Key << "ccw" << YAML::Value << s.ccw;
  e << YAML::EndMap << YAML::EndMap;
}

void emit_gains(YAML::Emitter& e, const char* key, const std::array<double, 3>& g) {
  e << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (double v : g) e << num(v);
  e << YAML::EndSeq;
}

void emit_path(YAML::Emitter& e, const PathSpec& p) {
  e << YAML::Key << "path" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "start" << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "x" << YAML::Value
    << num(p.x) << YAML::Key << "y" << YAML::Value << num(p.y) << YAML::Key << "phi_deg" << YAML::Value
    << num(p.phi_deg) << YAML::EndMap;
  e << YAML::Key << "segments" << YAML::Value << YAML::BeginSeq;
  for (const SegmentSpec& s : p.segments) emit_segment(e, s);
  e << YAML::EndSeq << YAML::EndMap;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Public API

MasterConfigError::MasterConfigError(std::string file, int line, std::string key, const std::string& message)
    : std::runtime_error(format_error(file, line, key, message)),
      file_(std::move(file)),
      line_(line),
      key_(std::move(key)) {}

MasterConfig parse_master_config(std::string_view yaml, const std::string& file) {
  YAML::Node root;
  try {
    // Every document counted, so one after a '---' is refused rather than silently dropped.
    const YamlDocument d = load_yaml_document(yaml);
    const int line = d.second.is_null() ? 0 : d.second.line + 1;
    if (d.stray) throw MasterConfigError(file, line, "", "not YAML: a ',' outside any [ ] or { }");
    if (d.count > 1)
      throw MasterConfigError(file, line, "", std::to_string(d.count) + " YAML documents; a configuration file holds one");
    root = d.node;
  } catch (const YAML::Exception& e) {
    const YamlSyntaxError se = describe_syntax_error(yaml, e);
    throw MasterConfigError(file, se.line, "", se.message);
  }
  if (!root.IsDefined() || root.IsNull()) throw MasterConfigError(file, 0, "", "empty configuration file");
  if (!root.IsMap()) throw MasterConfigError(file, root.Mark().line + 1, "", "expected a mapping at the top level");
  const Reader reader(file);
  return read_config(reader, Item{root, "", "", root.Mark().line + 1});
}

MasterConfig load_master_config(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw MasterConfigError(path, 0, "", "a directory, not a configuration file");
  if (!std::filesystem::is_regular_file(path)) throw MasterConfigError(path, 0, "", "cannot open configuration file");
  std::string text;
  try {
    std::ifstream in(path, std::ios::binary);
    text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  } catch (const std::exception& e) {
    throw MasterConfigError(path, 0, "", e.what());
  }
  return parse_master_config(text, path);
}

std::string dump_master_config(const MasterConfig& c) {
  YAML::Emitter e;
  e << YAML::BeginMap;
  const auto kv = [&](const char* k, const std::string& v) { e << YAML::Key << k << YAML::Value << v; };
  kv("period", num(c.loop.period));
  emit_gains(e, "kp", c.loop.kp);
  emit_gains(e, "ki", c.loop.ki);
  e << YAML::Key << "feedforward" << YAML::Value << c.loop.feedforward;
  kv("max_speed", num(c.loop.max_speed));
  kv("max_yaw_rate", num(c.loop.max_yaw_rate));
  e << YAML::Key << "geometry" << YAML::Value << YAML::Flow << YAML::BeginMap;
  kv("L", num(c.loop.L)), kv("r", num(c.loop.r)), kv("counts_per_rev", std::to_string(c.loop.counts_per_rev));
  e << YAML::EndMap;
  kv("settle", num(c.settle));
  e << YAML::Key << "wait_for_pc" << YAML::Value << c.wait_for_pc;
  kv("detect_every", std::to_string(c.detect_every));
  kv("detect_misses", std::to_string(c.detect_misses));
  kv("feedback_timeout", std::to_string(c.feedback_timeout));
  kv("startup_timeout", num(c.startup_timeout));
  if (c.slave_kp) kv("slave_kp", std::to_string(*c.slave_kp));
  emit_path(e, c.path);
  e << YAML::EndMap;
  return std::string(e.c_str()) + "\n";
}

void validate_master_config(const MasterConfig& c) {
  // Round-tripping through the loader checks every key exactly as a file is checked.
  parse_master_config(dump_master_config(c), kCodeFile);
}

Path build_path(const PathSpec& spec) {
  using K = SegmentSpec::Kind;
  Path path(Pose2{spec.x, spec.y, spec.phi_deg * kDeg});
  for (const SegmentSpec& s : spec.segments) {
    switch (s.kind) {
      case K::line: path.add_line(s.dx, s.dy, s.dphi_deg * kDeg, s.duration); break;
      case K::arc: path.add_arc(s.cx, s.cy, s.sweep_deg * kDeg, s.dphi_deg * kDeg, s.duration); break;
      case K::rotate: path.add_rotate(s.dphi_deg * kDeg, s.duration); break;
      case K::dwell: path.add_dwell(s.duration); break;
      case K::square: path.add_square(s.side, s.duration, s.ccw); break;
      case K::circle: path.add_circle(s.radius, s.duration, s.ccw); break;
      case K::figure_eight: path.add_figure_eight(s.radius, s.duration, s.ccw); break;
    }
  }
  return path;
}

std::optional<MasterConfig> load_platform_section(const std::string& file, const std::string& yaml,
                                                  const std::string& config) {
  if (!file.empty()) return load_master_config(file);
  if (!yaml.empty()) return parse_master_config(yaml, config + " (platform)");
  return std::nullopt;
}

}  // namespace omnitwin::controller
