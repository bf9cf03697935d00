// twin layer — scenario loading and validation; see scenario.hpp.
//
// Order of work: read the scenario YAML, apply --set overrides to the tree, then walk the
// tree once with YamlField (yaml_schema.hpp), filling the Scenario as each key is checked.
// The platform parameters come in layers — built-in defaults, the parameter file, the
// scenario's platform section — and each layer is validated against its own file, so an
// error names the file the bad value was written in.
#include "twin/scenario.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <optional>
#include <utility>

#include "controller/master_bounds.hpp"
#include "controller/yaml_document.hpp"
#include "twin/expectations.hpp"
#include "twin/master_command.hpp"
#include "twin/scheduler.hpp"
#include "twin/yaml_schema.hpp"

namespace omnitwin::twin {

namespace fs = std::filesystem;

namespace {

// Whether a path the scenario names is a regular file. Never throws: a name the file system
// refuses (a component over NAME_MAX, a loop of links) is just "not a file", so the scenario
// gets its one-line error naming the key (found by fuzz/scenario_fuzz: std::filesystem threw
// "File name too long" and `omnitwin run` ended with exit 3).
bool is_file(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}


// ---------------------------------------------------------------------------------------
// Small helpers

// `text` with control characters written as \xHH, so an error message stays one line
// whatever bytes a bad file put into it (a YAML parser quotes the character it choked on).
std::string one_line(const std::string& text) {
  std::string out;
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) out += fmt::format("\\x{:02x}", u);
    else out += c;
  }
  return out;
}

std::string format_error(const std::string& file, int line, const std::string& key,
                         const std::string& message) {
  std::string out = one_line(file);
  if (line > 0) out += fmt::format(":{}", line);
  out += ": ";
  if (!key.empty()) out += one_line(key) + ": ";
  return out + one_line(message);
}

// The longest run a scenario may ask for [s]: 11.6 days simulated. Anything longer is a typo
// (a duration of 1e308 s would run until someone kills it), not a soak.
constexpr double kMaxRunSeconds = 1e6;

std::vector<std::string> split_key(const std::string& key) {
  const auto views = split_dots(key);
  return {views.begin(), views.end()};
}

std::string join(const std::vector<std::string>& parts, std::size_t from, std::size_t to) {
  std::string out;
  for (std::size_t i = from; i < to; ++i) out += (i == from ? "" : ".") + parts[i];
  return out;
}

long parse_index(const std::string& s) {
  long v = -1;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  return (!s.empty() && ec == std::errc() && p == s.data() + s.size() && v >= 0) ? v : -1;
}

}  // namespace

// Parses the one YAML document of a file; syntax errors name the file and line. A second
// document ('---' and anything after it) is an error, not silently ignored: yaml-cpp's
// LoadFile reads the first document only, whatever follows.
YAML::Node load_yaml_file(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw ScenarioError(file, 0, "", "cannot open the file");
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  controller::YamlDocument d;
  try {
    d = controller::load_yaml_document(text);
  } catch (const YAML::Exception& e) {
    const controller::YamlSyntaxError se = controller::describe_syntax_error(text, e);
    throw ScenarioError(file, se.line, "", se.message);
  }
  const int line = d.second.is_null() ? 0 : d.second.line + 1;
  if (d.stray) throw ScenarioError(file, line, "", "not YAML: a ',' outside any [ ] or { }");
  if (d.count > 1)
    throw ScenarioError(file, line, "",
                        fmt::format("{} YAML documents; a file holds one (remove the '---' and what follows)", d.count));
  return d.node;
}

namespace {

// ---------------------------------------------------------------------------------------
// --set overrides

// Splits `parts` for the expect section, whose keys are dotted metric paths themselves:
// expect.<metric>.min|max or expect.<metric> (a whole {min, max} mapping).
std::vector<std::string> group_expect_key(const std::vector<std::string>& parts) {
  if (parts.size() < 2 || parts[0] != "expect") return parts;
  const bool bound = parts.back() == "min" || parts.back() == "max";
  const std::size_t metric_end = bound && parts.size() > 2 ? parts.size() - 1 : parts.size();
  std::vector<std::string> out{parts[0], join(parts, 1, metric_end)};
  if (metric_end < parts.size()) out.push_back(parts.back());
  return out;
}

// Steps from `cur` into child `part` (creating a mapping if there is none yet), or, when
// `value` is given, sets that child. Returns false, with the reason in `why`, if the child
// is a plain value that cannot hold children or `part` is not a usable list index.
bool descend(YAML::Node& cur, const std::string& part, const YAML::Node* value, std::string& why) {
  if (cur.IsSequence()) {
    const long i = parse_index(part);
    if (i < 0 || static_cast<std::size_t>(i) > cur.size()) {
      why = fmt::format("'{}' is not an index of a list of {}", part, cur.size());
      return false;
    }
    const auto idx = static_cast<std::size_t>(i);
    if (idx == cur.size()) cur.push_back(YAML::Node(YAML::NodeType::Null));
    if (value != nullptr) {
      cur[idx] = *value;
      return true;
    }
    if (cur[idx].IsScalar()) {
      why = fmt::format("'{}' holds a single value, not a mapping or list", part);
      return false;
    }
    if (!cur[idx].IsMap() && !cur[idx].IsSequence()) cur[idx] = YAML::Node(YAML::NodeType::Map);
    cur.reset(cur[idx]);
    return true;
  }
  if (value != nullptr) {
    cur[part] = *value;
    return true;
  }
  if (cur[part].IsScalar()) {
    why = fmt::format("'{}' holds a single value, not a mapping or list", part);
    return false;
  }
  if (!cur[part].IsMap() && !cur[part].IsSequence()) cur[part] = YAML::Node(YAML::NodeType::Map);
  cur.reset(cur[part]);
  return true;
}

// An override key must be a dotted path with no empty components.
void check_override_key(const std::string& key) {
  if (key.empty()) throw ScenarioError(kOverrideFile, 0, "", "empty key (expected key=value)");
  for (const auto& part : split_key(key)) {
    if (part.empty()) throw ScenarioError(kOverrideFile, 0, key, "empty component in dotted key");
  }
}

// The settings a bus of each kind takes under `bus:` (its `type` included), in the order the
// "unknown key" message lists them.
std::vector<std::string_view> bus_setting_keys(BusKind kind) {
  switch (kind) {
    case BusKind::can:
      return {"type", "bit_rate", "transport", "t_pre_us", "t_post_us", "isr_us", "drift", "sync", "sync_interval",
              "missing_command", "start_phase", "detect_every", "master", "seed", "handshake_timeout", "supervision",
              "refuse_foreign"};
    case BusKind::canopen:
      return {"type", "bit_rate", "transport", "t_pre_us", "master", "seed", "handshake_timeout", "supervision",
              "eds", "mode", "cycle", "sync_producer", "drive_period", "counts_per_rev", "heartbeat_ms", "drift",
              "startup", "refuse_foreign"};
    case BusKind::tml:
      return {"type", "bit_rate", "transport", "t_pre_us", "master", "seed", "handshake_timeout", "supervision",
              "protocol", "cycle", "drive_period", "counts_per_rev", "drift", "startup", "refuse_foreign"};
    case BusKind::ethercat:
      return {"type", "transport", "master_iface", "esi", "extra_axes", "mode", "drive_period", "counts_per_rev", "dc",
              "drift", "t_pre_us", "startup", "master", "seed", "handshake_timeout", "supervision", "refuse_foreign"};
    case BusKind::m3:
      return {"type", "transport", "master_iface", "cycle", "retry_slots", "data_bytes", "communication", "mode",
              "topology", "stations", "cable_m", "response_us", "margin_us", "drive_period", "counts_per_rev",
              "startup", "master", "seed", "handshake_timeout", "supervision", "refuse_foreign"};
    case BusKind::direct: return {"type"};
  }
  return {"type"};
}

// The bus kind named `name`; false when it names none.
bool bus_kind_named(const std::string& name, BusKind& kind) {
  for (BusKind b : {BusKind::direct, BusKind::can, BusKind::canopen, BusKind::ethercat, BusKind::m3, BusKind::tml}) {
    if (name == to_string(b)) {
      kind = b;
      return true;
    }
  }
  return false;
}

// Whether a bus setting means the same, within the same limits, on bus `to` as on `from`: the
// run's own (seed, start-up handshake, supervision, foreign senders) on every bus but direct;
// the CAN wire's (bit rate, transport, T_pre) among can, canopen and tml. Everything else
// (drift, mode, cycle, master, start-up …) is a bus's own, with its own limits or meaning.
bool carries_over(std::string_view key, BusKind from, BusKind to) {
  static constexpr std::string_view kRun[] = {"seed", "handshake_timeout", "supervision", "refuse_foreign"};
  static constexpr std::string_view kWire[] = {"bit_rate", "transport", "t_pre_us"};
  const auto can_family = [](BusKind b) { return b == BusKind::can || b == BusKind::canopen || b == BusKind::tml; };
  if (std::find(std::begin(kRun), std::end(kRun), key) != std::end(kRun)) return to != BusKind::direct;
  return can_family(from) && can_family(to) && std::find(std::begin(kWire), std::end(kWire), key) != std::end(kWire);
}

// `--bus NEW` over a file's `bus: {type: OLD, …}`: the settings that carry over stay (a CAN bit
// rate on CANopen), the file's others are left out, since they are OLD's, not misspellings, and
// named in a note so that nothing goes quietly. A setting an earlier override gave
// (`set_keys`, dotted) stays, so that NEW refuses it and the refusal names --set.
void switch_bus_type(YAML::Node& bus, const std::string& to, const std::vector<std::string>& set_keys,
                     std::vector<std::string>& notes) {
  BusKind from_kind{}, to_kind{};
  const std::string from = bus["type"] && bus["type"].IsScalar() ? bus["type"].as<std::string>() : "";
  if (from == to || !bus_kind_named(from, from_kind) || !bus_kind_named(to, to_kind)) return;
  const auto set_here = [&](const std::string& k) {
    const std::string key = "bus." + k;
    return std::any_of(set_keys.begin(), set_keys.end(),
                       [&](const std::string& s) { return s == key || s.rfind(key + ".", 0) == 0; });
  };
  std::vector<std::string> left_out;
  for (const auto& kv : bus) {
    if (!kv.first.IsScalar()) continue;  // not a name: read_bus refuses it
    const std::string k = kv.first.as<std::string>();
    if (k != "type" && !carries_over(k, from_kind, to_kind) && !set_here(k)) left_out.push_back(k);
  }
  for (const std::string& k : left_out) bus.remove(k);
  if (!left_out.empty())
    notes.push_back(fmt::format("bus {} instead of the file's {}: the file's {} setting{} {} {} left out", to, from,
                                from, left_out.size() == 1 ? "" : "s", fmt::join(left_out, ", "),
                                left_out.size() == 1 ? "is" : "are"));
}

// Applies one override to the scenario tree (see Override in scenario.hpp); returns the
// dotted key whose value it replaced, so only that key (and what lies below it) is blamed
// on --set and everything else keeps its file and line.
std::string apply_override(YAML::Node& root, const Override& o, const std::vector<std::string>& set_keys,
                           std::vector<std::string>& notes) {
  const auto parts = group_expect_key(split_key(o.key));
  YAML::Node value;
  try {
    value = YAML::Load(o.value);
  } catch (const YAML::Exception& e) {
    throw ScenarioError(kOverrideFile, 0, o.key, fmt::format("cannot parse value '{}': {}", o.value, e.msg));
  }
  // `bus` is a name or a mapping of settings: --bus can keeps the settings, and a setting
  // given for a bus written by name turns the name into {type: name}.
  if (!parts.empty() && parts[0] == "bus" && root["bus"].IsMap() && parts.size() == 1 && value.IsScalar()) {
    YAML::Node bus = root["bus"];
    switch_bus_type(bus, value.as<std::string>(), set_keys, notes);
    root["bus"]["type"] = value;
    return "bus.type";
  }
  if (parts.size() > 1 && parts[0] == "bus" && !root["bus"].IsMap()) {
    YAML::Node bus(YAML::NodeType::Map);
    bus["type"] = root["bus"].IsScalar() ? root["bus"].as<std::string>() : std::string("direct");
    root["bus"] = bus;
  }
  YAML::Node cur;
  cur.reset(root);  // reset(), not '=': assigning a yaml-cpp node overwrites the tree
  for (std::size_t i = 0; i < parts.size(); ++i) {
    std::string why;
    const bool last = i + 1 == parts.size();
    // An index into a list the file does not write: there is no list to index (the default
    // lives in the program), so the whole list must be given.
    if (!last && parse_index(parts[i + 1]) >= 0 && cur.IsMap() && !cur[parts[i]]) {
      const std::string list = join(parts, 0, i + 1);
      throw ScenarioError(kOverrideFile, 0, o.key,
                          fmt::format("cannot apply: {} is not written in the scenario, so it has no element {} to "
                                      "set; give the whole list (--set {}=[...])",
                                      list, parts[i + 1], list));
    }
    if (!descend(cur, parts[i], last ? &value : nullptr, why)) {
      throw ScenarioError(kOverrideFile, 0, o.key, fmt::format("cannot apply: {}", why));
    }
  }
  return o.key;
}

// ---------------------------------------------------------------------------------------
// Platform parameters

// The sections of a parameter file (models/platform/omni4.yaml).
std::vector<std::string_view> param_sections() {
  return {"geometry", "rollers", "capsule", "floor", "motor", "driver", "dac", "encoder", "velocity_loop", "sim"};
}

// The field that last set geometry.r or rollers.radius in one layer (for the cross-check).
struct ParamTrace {
  std::optional<YamlField> radius_or_r;
};

void read_geometry(const YamlField& s, physics::GeometryParams& g, ParamTrace& t) {
  s.allow_keys({"L", "r", "chassis_size", "chassis_mass", "hub_mass", "wheel_width", "load_mass",
                "load_size"});
  read_number(s, "L", g.L, Bounds::positive());
  if (read_number(s, "r", g.r, Bounds::positive())) t.radius_or_r = s["r"];
  if (s["chassis_size"].exists()) {
    const auto v = s["chassis_size"].numbers(3, Bounds::positive());
    g.chassis_size = {v[0], v[1], v[2]};
  }
  read_number(s, "chassis_mass", g.chassis_mass, Bounds::positive());
  read_number(s, "hub_mass", g.hub_mass, Bounds::positive());
  read_number(s, "wheel_width", g.wheel_width, Bounds::positive());
  read_number(s, "load_mass", g.load_mass, Bounds::non_negative());
  if (s["load_size"].exists()) {
    const auto v = s["load_size"].numbers(3, Bounds::positive());
    g.load_size = {v[0], v[1], v[2]};
  }
}

void read_rollers(const YamlField& s, physics::RollerParams& r, ParamTrace& t) {
  s.allow_keys({"rows", "per_row", "row_offset", "row_phase_deg", "wheel_phase_deg", "radius",
                "coverage_deg", "mass", "damping", "friction_torque"});
  // Each roller is a body of the model, 4 × rows × per_row of them: real omniwheels have 1-3
  // rows of 5-16; the caps keep a typo from building millions of bodies (and rows × per_row an int).
  read_integer(s, "rows", r.rows, Bounds::closed(1, 8));
  read_integer(s, "per_row", r.per_row, Bounds::closed(1, 64));
  read_number(s, "row_offset", r.row_offset, Bounds::non_negative());
  read_number(s, "row_phase_deg", r.row_phase_deg);
  read_number(s, "wheel_phase_deg", r.wheel_phase_deg);
  if (read_number(s, "radius", r.radius, Bounds::positive())) t.radius_or_r = s["radius"];
  read_number(s, "coverage_deg", r.coverage_deg, Bounds{0.0, 180.0, true, true});
  read_number(s, "mass", r.mass, Bounds::positive());
  read_number(s, "damping", r.damping, Bounds::non_negative());
  read_number(s, "friction_torque", r.friction_torque, Bounds::non_negative());
}

void read_capsule(const YamlField& s, physics::CapsuleParams& c) {
  s.allow_keys({"half_length", "contact_offset", "solver_tolerance", "centre_contact"});
  read_number(s, "half_length", c.half_length, Bounds::positive());
  read_number(s, "contact_offset", c.contact_offset, Bounds::closed(-0.05, 0.05));
  read_number(s, "solver_tolerance", c.solver_tolerance, Bounds::open_closed(0, 1e-2));
  read_bool(s, "centre_contact", c.centre_contact);
}

void read_floor(const YamlField& s, physics::FloorParams& f) {
  s.allow_keys({"friction", "lateral_friction", "slip_gain"});
  read_number(s, "friction", f.friction, Bounds::non_negative());
  read_number(s, "lateral_friction", f.lateral_friction, Bounds::non_negative());
  read_number(s, "slip_gain", f.slip_gain, Bounds::non_negative());
}

void read_motor(const YamlField& s, physics::MotorParams& m) {
  s.allow_keys({"kv", "electrical_tau", "torque_limit", "speed_limit", "armature", "damping",
                "friction_torque", "backlash"});
  read_number(s, "kv", m.kv, Bounds::positive());
  read_number(s, "backlash", m.backlash, Bounds::closed(0.0, 0.5));
  read_number(s, "electrical_tau", m.electrical_tau, Bounds::non_negative());
  read_number(s, "friction_torque", m.friction_torque, Bounds::non_negative());
  read_number(s, "torque_limit", m.torque_limit, Bounds::positive());
  read_number(s, "speed_limit", m.speed_limit, Bounds::positive());
  read_number(s, "armature", m.armature, Bounds::non_negative());
  read_number(s, "damping", m.damping, Bounds::non_negative());
}

void read_electronics(const YamlField& section, const std::string& name, physics::PlatformParams& p) {
  // The small drive-chain sections: driver, dac, encoder, velocity_loop.
  if (name == "driver") {
    section.allow_keys({"zero_volts", "gain", "dead_band", "gain_error"});
    read_number(section, "zero_volts", p.driver.zero_volts);
    read_number(section, "gain", p.driver.gain, Bounds::positive());
    read_number(section, "dead_band", p.driver.dead_band, Bounds::non_negative());
    if (section["gain_error"].exists()) {
      const auto e = section["gain_error"].numbers(4, Bounds::closed(-0.5, 0.5));
      std::copy(e.begin(), e.end(), p.driver.gain_error.begin());
    }
  } else if (name == "dac") {
    section.allow_keys({"bits", "vref"});
    read_integer(section, "bits", p.dac.bits, Bounds::closed(1, 16));
    read_number(section, "vref", p.dac.vref, Bounds::positive());
  } else if (name == "encoder") {
    section.allow_keys({"lines", "index_per_rev"});
    // 4·lines counts per revolution: what the masters' platform loop counts (geometry.counts_per_rev).
    read_integer(section, "lines", p.encoder.lines, Bounds::closed(1, controller::kMaxCountsPerRev / 4));
    read_integer(section, "index_per_rev", p.encoder.index_per_rev, Bounds::non_negative());
  } else if (name == "velocity_loop") {
    section.allow_keys({"period", "kp", "ki", "kff", "arithmetic"});
    read_number(section, "period", p.velocity_loop.period, Bounds::open_closed(0, 1));
    read_number(section, "kp", p.velocity_loop.kp, Bounds::non_negative());
    read_number(section, "ki", p.velocity_loop.ki, Bounds::non_negative());
    read_number(section, "kff", p.velocity_loop.kff, Bounds::non_negative());
    if (const YamlField a = section["arithmetic"]; a.exists())
      p.velocity_loop.arithmetic = a.choice({"real", "int16"}) == "int16"
                                       ? physics::LoopArithmetic::int16
                                       : physics::LoopArithmetic::real;
  }
}

physics::ModelVariant read_variant(const YamlField& f) {
  return f.choice({"rollers", "capsule"}) == "capsule" ? physics::ModelVariant::capsule
                                                       : physics::ModelVariant::rollers;
}

void read_sim(const YamlField& s, physics::SimParams& sim) {
  s.allow_keys({"timestep", "variant"});
  read_number(s, "timestep", sim.timestep, Bounds::open_closed(0, 0.01));
  if (s["variant"].exists()) sim.variant = read_variant(s["variant"]);
}

// Applies the parameter sections present in `map` (a parameter file's root or a
// scenario's platform section) over `p`, checking each value, then the cross-field rules.
void apply_param_sections(const YamlField& map, physics::PlatformParams& p) {
  ParamTrace t;
  read_geometry(map["geometry"], p.geometry, t);
  read_rollers(map["rollers"], p.rollers, t);
  read_capsule(map["capsule"], p.capsule);
  read_floor(map["floor"], p.floor);
  read_motor(map["motor"], p.motor);
  for (const char* name : {"driver", "dac", "encoder", "velocity_loop"}) {
    read_electronics(map[name], name, p);
  }
  read_sim(map["sim"], p.sim);
  // An electrical lag shorter than the step is integrated unstably by Euler.
  if (p.motor.electrical_tau > 0 && p.motor.electrical_tau < p.sim.timestep) {
    const YamlField tau = map["motor"]["electrical_tau"].exists() ? map["motor"]["electrical_tau"]
                                                                   : map["sim"]["timestep"];
    if (tau.exists())
      tau.fail(fmt::format("motor.electrical_tau ({}) must be 0 or at least sim.timestep ({})",
                           p.motor.electrical_tau, p.sim.timestep));
  }
  // The 8051 holds its gains as whole numbers: int16 arithmetic refuses a fractional gain
  // rather than rounding it (blame the gain this layer set, else the arithmetic switch).
  if (p.velocity_loop.arithmetic == physics::LoopArithmetic::int16) {
    const YamlField loop = map["velocity_loop"];
    for (const auto& [key, gain] : {std::pair{"kp", p.velocity_loop.kp}, std::pair{"ki", p.velocity_loop.ki}}) {
      if (gain == std::round(gain)) continue;
      const YamlField blamed = loop[key].exists() ? loop[key] : loop["arithmetic"];
      if (blamed.exists())
        blamed.fail(fmt::format("velocity_loop.{} ({}) must be a whole number with arithmetic int16 "
                                "(the 8051 holds its gains as integers)", key, gain));
    }
  }
  // Rollers must fit inside the wheel envelope; blame whichever this layer set last.
  if (t.radius_or_r && !(p.rollers.radius < p.geometry.r)) {
    t.radius_or_r->fail(fmt::format("rollers.radius ({}) must be smaller than geometry.r ({})",
                                    p.rollers.radius, p.geometry.r));
  }
}

// Loads a parameter file over `p`; errors name that file.
void apply_param_file(const std::string& file, physics::PlatformParams& p) {
  const YAML::Node node = load_yaml_file(file);
  const YamlDoc doc(file);
  const YamlField root = YamlField::root(doc, node);
  root.allow_keys(param_sections());
  apply_param_sections(root, p);
  p.source = file;
}

// The scenario's platform section: parameter file, then its overrides, then the variant.
physics::PlatformParams read_platform(const YamlField& s, const std::string& scenario_file) {
  std::vector<std::string_view> allowed = param_sections();
  allowed.insert(allowed.begin(), {"params", "variant", "mjcf"});
  s.allow_keys(allowed);
  physics::PlatformParams p;
  if (const YamlField params = s["params"]; params.exists()) {
    // Relative parameter paths are relative to the scenario file.
    const fs::path given = params.string();
    const fs::path resolved =
        given.is_absolute() ? given : (fs::path(scenario_file).parent_path() / given).lexically_normal();
    if (!is_file(resolved)) {
      params.fail(fmt::format("cannot open parameter file '{}'", resolved.string()));
    }
    apply_param_file(resolved.string(), p);
  }
  apply_param_sections(s, p);
  if (s["variant"].exists()) p.sim.variant = read_variant(s["variant"]);
  if (const YamlField mjcf = s["mjcf"]; mjcf.exists()) {
    // A hand-written model instead of the generated one, relative to the scenario file.
    const fs::path given = mjcf.string();
    const fs::path resolved =
        given.is_absolute() ? given : (fs::path(scenario_file).parent_path() / given).lexically_normal();
    if (!is_file(resolved)) mjcf.fail(fmt::format("cannot open model file '{}'", resolved.string()));
    p.sim.mjcf = resolved.string();
  }
  return p;
}

// ---------------------------------------------------------------------------------------
// Bus, clock, controller

// bus.startup of the buses whose master file gets startup_timeout = max(1, startup), plus
// kRealtimeStartupGrace in realtime: at most what the masters accept.
const Bounds kStartupBounds = Bounds::closed(0, controller::kMaxStartupTimeout - controller::kRealtimeStartupGrace);

// The `can` bus's settings (bus: {type: can, …}).
// The CAN wire's settings, shared by the buses on it (can, canopen).
void read_can_wire(const YamlField& f, CanSpec& c) {
  double rate = static_cast<double>(c.bit_rate);
  if (read_number(f, "bit_rate", rate, Bounds::closed(10'000, 1'000'000))) c.bit_rate = std::llround(rate);
  if (f["transport"].exists()) c.transport = f["transport"].string();
  read_number(f, "t_pre_us", c.t_pre_us, Bounds::non_negative());
  if (f["master"].exists()) c.master = f["master"].string();
  int seed = static_cast<int>(c.seed);
  if (read_integer(f, "seed", seed, Bounds::non_negative())) c.seed = static_cast<std::uint64_t>(seed);
  read_number(f, "handshake_timeout", c.handshake_timeout, Bounds::positive());
  read_bool(f, "refuse_foreign", c.refuse_foreign);
}

void read_can(const YamlField& f, CanSpec& c) {
  read_can_wire(f, c);
  read_number(f, "t_post_us", c.t_post_us, Bounds::non_negative());
  read_number(f, "isr_us", c.isr_us, Bounds::non_negative());
  if (const YamlField d = f["drift"]; d.exists()) {
    // One drift for every slave, or one per axis.
    const Bounds b{-0.5, 0.5};
    if (d.node().IsSequence()) {
      const auto v = d.numbers(4, b);
      std::copy(v.begin(), v.end(), c.drift.begin());
    } else {
      c.drift.fill(d.number(b));
    }
  }
  read_bool(f, "sync", c.sync);
  if (const YamlField m = f["missing_command"]; m.exists())
    c.hold_missing_command = m.choice({"skip", "hold"}) == "hold";
  read_integer(f, "sync_interval", c.sync_interval, Bounds::at_least(1));
  if (const YamlField p = f["start_phase"]; p.exists()) {
    // `random`, one fraction of a period for every slave, or one per axis.
    const Bounds b{0.0, 1.0, false, true};
    if (p.node().IsSequence()) {
      const auto v = p.numbers(4, b);
      std::copy(v.begin(), v.end(), c.start_phase.begin());
    } else if (p.node().IsScalar() && p.node().Scalar() == "random") {
      c.start_phase_random = true;
    } else {
      c.start_phase.fill(p.number(b));
    }
  }
  read_integer(f, "detect_every", c.detect_every, Bounds::non_negative());
}

// The `ethercat` bus's settings (bus: {type: ethercat, …}); paths relative to the scenario.
void read_ethercat(const YamlField& f, EthercatSpec& e, const std::string& scenario_file) {
  if (const YamlField t = f["transport"]; t.exists()) {
    e.transport = t.string();
    const bool ok = e.transport == "auto" || e.transport == "veth" || e.transport.starts_with("raw:") ||
                    e.transport.starts_with("udp:") || e.transport.starts_with("mem:");
    if (!ok) t.fail("expected auto, veth, raw:IFACE, udp:HOST:PORT or mem:NAME");
  }
  if (f["master_iface"].exists()) e.master_iface = f["master_iface"].string();
  if (e.transport.starts_with("raw:") && e.master_iface.empty())
    f["transport"].fail("raw:IFACE needs master_iface: the interface the master sends on");
  if (const YamlField esi = f["esi"]; esi.exists() && !esi.string().empty()) {  // "": the shipped one
    const fs::path given = esi.string();
    const fs::path resolved =
        given.is_absolute() ? given : (fs::path(scenario_file).parent_path() / given).lexically_normal();
    if (!is_file(resolved)) esi.fail(fmt::format("cannot open device description '{}'", resolved.string()));
    e.esi = resolved.string();
  }
  if (f["mode"].exists()) e.mode = f["mode"].choice({"csv", "csp"});
  read_integer(f, "extra_axes", e.extra_axes, Bounds::closed(0, 1600));
  read_number(f, "drive_period", e.drive_period, Bounds::closed(50e-6, 0.01));
  read_integer(f, "counts_per_rev", e.counts_per_rev, Bounds::closed(4, 1 << 24));
  read_bool(f, "dc", e.dc);
  read_bool(f, "refuse_foreign", e.refuse_foreign);
  if (const YamlField d = f["drift"]; d.exists()) {
    const Bounds b{-1e-3, 1e-3};  // crystal oscillators: within ±1000 ppm
    if (d.node().IsSequence()) {
      const auto v = d.numbers(4, b);
      std::copy(v.begin(), v.end(), e.drift.begin());
    } else {
      e.drift.fill(d.number(b));
    }
  }
  read_number(f, "t_pre_us", e.t_pre_us, Bounds::non_negative());
  read_number(f, "startup", e.startup, Bounds::non_negative());
  if (f["master"].exists()) e.master = f["master"].string();
  int seed = static_cast<int>(e.seed);
  if (read_integer(f, "seed", seed, Bounds::non_negative())) e.seed = static_cast<std::uint64_t>(seed);
  read_number(f, "handshake_timeout", e.handshake_timeout, Bounds::positive());
}

// The `canopen` bus's own settings (bus: {type: canopen, …}); the wire's are read by read_can.
void read_canopen(const YamlField& f, CanopenSpec& c, const std::string& scenario_file) {
  if (const YamlField eds = f["eds"]; eds.exists() && !eds.string().empty()) {  // "": the shipped one
    const fs::path given = eds.string();
    const fs::path resolved =
        given.is_absolute() ? given : (fs::path(scenario_file).parent_path() / given).lexically_normal();
    if (!is_file(resolved)) eds.fail(fmt::format("cannot open EDS file '{}'", resolved.string()));
    c.eds = resolved.string();
  }
  if (f["mode"].exists()) c.mode = f["mode"].choice({"csv", "pv"});
  read_number(f, "cycle", c.cycle, Bounds::closed(250e-6, 0.1));
  if (f["sync_producer"].exists()) c.sync_producer = f["sync_producer"].choice({"master", "drive"});
  read_number(f, "drive_period", c.drive_period, Bounds::closed(50e-6, 0.01));
  read_integer(f, "counts_per_rev", c.counts_per_rev, Bounds::closed(4, 1 << 24));
  read_integer(f, "heartbeat_ms", c.heartbeat_ms, Bounds::closed(1, 10000));
  if (const YamlField d = f["drift"]; d.exists()) {
    const Bounds b{-1e-3, 1e-3};  // crystal oscillators: within ±1000 ppm
    if (d.node().IsSequence()) {
      const auto v = d.numbers(4, b);
      std::copy(v.begin(), v.end(), c.drift.begin());
    } else {
      c.drift.fill(d.number(b));
    }
  }
  read_number(f, "startup", c.startup, kStartupBounds);
}

// The `tml` bus's own settings (bus: {type: tml, …}); the wire's are read by read_can_wire.
void read_tml(const YamlField& f, TmlSpec& t) {
  if (f["protocol"].exists()) t.protocol = f["protocol"].choice({"tmlcan", "techcan"});
  read_number(f, "cycle", t.cycle, Bounds::closed(250e-6, 0.1));
  read_number(f, "drive_period", t.drive_period, Bounds::closed(50e-6, 0.01));
  read_integer(f, "counts_per_rev", t.counts_per_rev, Bounds::closed(4, 1 << 24));
  if (const YamlField d = f["drift"]; d.exists()) {
    const Bounds b{-1e-3, 1e-3};
    if (d.node().IsSequence()) {
      const auto v = d.numbers(4, b);
      std::copy(v.begin(), v.end(), t.drift.begin());
    } else {
      t.drift.fill(d.number(b));
    }
  }
  read_number(f, "startup", t.startup, kStartupBounds);
}

// The `m3` bus's settings (bus: {type: m3, …}).
void read_m3(const YamlField& f, M3Spec& m) {
  if (const YamlField t = f["transport"]; t.exists()) {
    m.transport = t.string();
    const bool ok = m.transport == "auto" || m.transport == "veth" || m.transport.starts_with("raw:") ||
                    m.transport.starts_with("udp:") || m.transport.starts_with("mem:");
    if (!ok) t.fail("expected auto, veth, raw:IFACE, udp:HOST:PORT or mem:NAME");
  }
  if (f["master_iface"].exists()) m.master_iface = f["master_iface"].string();
  if (m.transport.starts_with("raw:") && m.master_iface.empty())
    f["transport"].fail("raw:IFACE needs master_iface: the interface the master sends on");
  // The emulated servos take 0.125 … 32 ms at COM_TIM 1 (m3_link's CONNECT check).
  read_number(f, "cycle", m.cycle, Bounds::closed(125e-6, 0.032));
  read_integer(f, "retry_slots", m.retry_slots, Bounds::closed(0, 4));
  if (f["data_bytes"].exists()) m.data_bytes = std::stoi(f["data_bytes"].choice({"32", "48"}));
  if (f["mode"].exists()) m.mode = f["mode"].choice({"velctrl", "interpolate"});
  if (f["communication"].exists()) m.communication = f["communication"].choice({"cyclic", "event"});
  if (m.communication == "event" && m.mode == "interpolate")
    f["mode"].fail("INTERPOLATE needs phase 3, which event-driven communication never enters (mode: velctrl)");
  if (f["topology"].exists()) m.topology = f["topology"].choice({"cascade", "star"});
  read_integer(f, "stations", m.stations, Bounds::closed(4, 62));
  read_number(f, "cable_m", m.cable_m, Bounds::closed(0, 100));
  read_number(f, "response_us", m.response_us, Bounds::closed(0, 1000));
  read_number(f, "margin_us", m.margin_us, Bounds::closed(0, 10'000));
  read_number(f, "drive_period", m.drive_period, Bounds::closed(50e-6, 0.01));
  read_integer(f, "counts_per_rev", m.counts_per_rev, Bounds::closed(4, 1 << 24));
  read_number(f, "startup", m.startup, kStartupBounds);
  if (f["master"].exists()) m.master = f["master"].string();
  int seed = static_cast<int>(m.seed);
  if (read_integer(f, "seed", seed, Bounds::non_negative())) m.seed = static_cast<std::uint64_t>(seed);
  read_number(f, "handshake_timeout", m.handshake_timeout, Bounds::positive());
  read_bool(f, "refuse_foreign", m.refuse_foreign);
}

// bus.supervision: how a realtime run watches the master it started.
void read_supervision(const YamlField& f, SupervisionSpec& v) {
  if (!f.exists()) return;
  f.allow_keys({"silent_periods", "on_master_loss"});
  read_integer(f, "silent_periods", v.silent_periods, Bounds::at_least(1));
  if (f["on_master_loss"].exists())
    v.on_master_loss = f["on_master_loss"].choice({"fail", "record"}) == "record" ? SupervisionSpec::OnLoss::record
                                                                                  : SupervisionSpec::OnLoss::fail;
}

BusSpec read_bus(const YamlField& f, const std::string& scenario_file) {
  BusSpec bus;
  if (!f.present()) return bus;
  // Either `bus: can` or `bus: {type: can, …settings}`. (No YamlField reassignment: assigning
  // a yaml-cpp node overwrites the node it refers to.)
  const bool settings = f.node().IsMap();
  const std::string k = (settings ? f.required("type") : f).choice({"direct", "can", "canopen", "ethercat", "m3", "tml"});
  bus_kind_named(k, bus.kind);  // choice() took only these names
  if (!settings) return bus;
  f.allow_keys(bus_setting_keys(bus.kind));
  if (bus.kind == BusKind::can) {
    read_can(f, bus.can);
    read_supervision(f["supervision"], bus.supervision);
  } else if (bus.kind == BusKind::canopen) {
    read_can_wire(f, bus.can);
    read_canopen(f, bus.canopen, scenario_file);
    read_supervision(f["supervision"], bus.supervision);
  } else if (bus.kind == BusKind::tml) {
    read_can_wire(f, bus.can);
    read_tml(f, bus.tml);
    read_supervision(f["supervision"], bus.supervision);
  } else if (bus.kind == BusKind::ethercat) {
    read_ethercat(f, bus.ethercat, scenario_file);
    read_supervision(f["supervision"], bus.supervision);
  } else if (bus.kind == BusKind::m3) {
    read_m3(f, bus.m3);
    read_supervision(f["supervision"], bus.supervision);
  }
  return bus;
}

ControllerSpec read_controller(const YamlField& s) {
  ControllerSpec c;
  s.allow_keys({"period", "kp", "ki", "feedforward", "max_speed", "max_yaw_rate"});
  // The master programs' bounds: a period they refuse would start a run whose master exits.
  read_number(s, "period", c.period, Bounds::closed(controller::kMinLoopPeriod, controller::kMaxLoopPeriod));
  for (const auto& [name, gains] : {std::pair{"kp", c.kp}, std::pair{"ki", c.ki}}) {
    if (!s[name].exists()) continue;
    const auto v = s[name].numbers(3, Bounds::non_negative());
    std::copy(v.begin(), v.end(), gains);
  }
  read_bool(s, "feedforward", c.feedforward);
  read_number(s, "max_speed", c.max_speed, Bounds::positive());
  read_number(s, "max_yaw_rate", c.max_yaw_rate, Bounds::positive());
  return c;
}

// ---------------------------------------------------------------------------------------
// Path

PathSegment read_segment(const YamlField& item) {
  using K = PathSegment::Kind;
  const YamlField v = item.single_member(
      {"line", "arc", "rotate", "dwell", "square", "circle", "figure_eight"});
  const std::string& kind = v.name();
  PathSegment seg;
  seg.line = v.line();
  // Each kind: its keys, then its values; duration (> 0) is required everywhere.
  if (kind == "line") {
    v.allow_keys({"dx", "dy", "dphi_deg", "duration"});
    seg.kind = K::line;
    read_number(v, "dx", seg.dx);
    read_number(v, "dy", seg.dy);
    read_number(v, "dphi_deg", seg.dphi_deg);
  } else if (kind == "arc") {
    v.allow_keys({"cx", "cy", "sweep_deg", "dphi_deg", "duration"});
    seg.kind = K::arc;
    seg.cx = v.required("cx").number();
    seg.cy = v.required("cy").number();
    seg.sweep_deg = v.required("sweep_deg").number();
    read_number(v, "dphi_deg", seg.dphi_deg);
    if (seg.cx == 0 && seg.cy == 0) v.fail("arc centre (cx, cy) must differ from the start point");
  } else if (kind == "rotate") {
    v.allow_keys({"dphi_deg", "duration"});
    seg.kind = K::rotate;
    seg.dphi_deg = v.required("dphi_deg").number();
  } else if (kind == "dwell") {
    v.allow_keys({"duration"});
    seg.kind = K::dwell;
  } else if (kind == "square") {
    v.allow_keys({"side", "duration", "ccw"});
    seg.kind = K::square;
    seg.side = v.required("side").number(Bounds::positive());
    read_bool(v, "ccw", seg.ccw);
  } else {  // circle, figure_eight
    v.allow_keys({"radius", "duration", "ccw"});
    seg.kind = kind == "circle" ? K::circle : K::figure_eight;
    seg.radius = v.required("radius").number(Bounds::positive());
    read_bool(v, "ccw", seg.ccw);
  }
  seg.duration = v.required("duration").number(Bounds::open_closed(0, kMaxRunSeconds));
  return seg;
}

PathSpec read_path(const YamlField& s) {
  PathSpec path;
  s.allow_keys({"start", "segments"});
  const YamlField start = s["start"];
  start.allow_keys({"x", "y", "phi_deg"});
  read_number(start, "x", path.x0);
  read_number(start, "y", path.y0);
  read_number(start, "phi_deg", path.phi0_deg);
  for (const auto& item : s["segments"].elements()) path.segments.push_back(read_segment(item));
  return path;
}

// Time the whole path takes [s] (a square's duration is per side).
double path_duration(const PathSpec& path) {
  double t = 0;
  for (const auto& seg : path.segments) {
    t += seg.kind == PathSegment::Kind::square ? 4 * seg.duration : seg.duration;
  }
  return t;
}

// ---------------------------------------------------------------------------------------
// Faults and expectations

// The fault kinds a scenario may name.
const std::vector<std::string_view> kFaultKinds = {"wheel_slip", "frame_loss", "delay",      "drift",
                                                   "power_loss", "bus_off",    "link_break", "corruption",
                                                   "second_master"};

// `node:` of a CAN fault: 1..4 (a slave), or `master` / `all` where the kind allows them.
int read_fault_node(const YamlField& v, bool master_ok, bool all_ok) {
  const YamlField n = v.required("node");
  if (n.node().IsScalar() && (n.node().as<std::string>() == "master" || n.node().as<std::string>() == "all")) {
    const bool master = n.node().as<std::string>() == "master";
    if (master ? !master_ok : !all_ok) n.fail(fmt::format("'{}' is not a node this fault can act on", n.string()));
    return master ? FaultSpec::kMaster : FaultSpec::kAllNodes;
  }
  return n.integer(Bounds::closed(1, 4)) - 1;  // files count axes from 1
}

FaultSpec read_fault(const YamlField& item, const BusSpec& bus) {
  using K = FaultSpec::Kind;
  const YamlField v = item.single_member(kFaultKinds);
  FaultSpec f;
  f.line = v.line();
  const std::string& kind = v.name();
  // canopen runs on the same CAN wire as can: the same wire faults.
  const bool can = bus.kind == BusKind::can || bus.kind == BusKind::canopen || bus.kind == BusKind::tml, ethercat = bus.kind == BusKind::ethercat,
             m3 = bus.kind == BusKind::m3;
  if (kind != "wheel_slip" && !can && !ethercat && !m3) v.fail("a bus fault needs bus: can, canopen, tml, ethercat or m3");
  if (kind == "bus_off" && !can) v.fail("bus_off is a CAN fault (bus: can, canopen or tml)");
  if (kind == "link_break" && !ethercat && !m3) v.fail("link_break is a fault of a line (bus: ethercat or m3)");
  if (kind == "corruption" && !m3) v.fail("corruption is an M-III fault (bus: m3)");
  if (kind == "second_master" && !m3) v.fail("second_master is an M-III fault (bus: m3)");
  if (kind == "drift" && m3) v.fail("drift has no meaning on M-III: the slaves follow the master's SYNC");
  if (kind == "wheel_slip") {
    v.allow_keys({"wheel", "at", "duration", "friction_scale"});
    f.kind = K::wheel_slip;
    f.wheel = v.required("wheel").integer(Bounds::closed(1, 4)) - 1;
    f.friction_scale = v.required("friction_scale").number(Bounds::non_negative());
  } else if (kind == "frame_loss") {
    v.allow_keys({"node", "at", "duration", "rate", "burst"});
    f.kind = K::frame_loss;
    f.wheel = read_fault_node(v, true, true);
    f.rate = v.required("rate").number(Bounds::closed(0, 1));
    read_integer(v, "burst", f.burst, Bounds::at_least(1));
    // The M-III line loses frames one at a time: bursts are the CAN wire's.
    if (m3 && f.burst != 1) v["burst"].fail("burst is a CAN wire setting; on bus: m3 frames are lost one at a time");
  } else if (kind == "delay") {
    v.allow_keys({"node", "at", "duration", "extra_ms", "jitter_ms"});
    f.kind = K::delay;
    f.wheel = read_fault_node(v, true, false);
    read_number(v, "extra_ms", f.extra_ms, Bounds::non_negative());
    read_number(v, "jitter_ms", f.jitter_ms, Bounds::non_negative());
  } else if (kind == "drift") {
    v.allow_keys({"node", "at", "duration", "drift"});
    f.kind = K::drift;
    f.wheel = read_fault_node(v, false, false);
    f.drift = v.required("drift").number(Bounds{-0.5, 0.5});
  } else if (kind == "link_break") {
    v.allow_keys({"after", "at", "duration"});
    f.kind = K::link_break;
    f.wheel = v.required("after").integer(Bounds::closed(0, 3));  // slaves 1..after stay reachable
  } else if (kind == "second_master") {
    v.allow_keys({"at", "duration"});
    f.kind = K::second_master;
  } else if (kind == "corruption") {
    v.allow_keys({"node", "at", "duration", "rate"});
    f.kind = K::corruption;
    f.wheel = read_fault_node(v, true, true);
    f.rate = v.required("rate").number(Bounds::closed(0, 1));
  } else {  // power_loss, bus_off
    v.allow_keys({"node", "at", "duration"});
    f.kind = kind == "power_loss" ? K::power_loss : K::bus_off;
    f.wheel = read_fault_node(v, false, false);
  }
  // The EtherCAT segment loses and delays whole frames: a slave cannot be singled out.
  if (ethercat && (f.kind == K::frame_loss || f.kind == K::delay) && f.wheel < FaultSpec::kMaster)
    v["node"].fail(fmt::format("{} on bus: ethercat acts on the whole segment: node must be master{}", kind,
                               f.kind == K::frame_loss ? " or all" : ""));
  f.at = v.required("at").number(Bounds::non_negative());
  read_number(v, "duration", f.duration, Bounds::non_negative());
  return f;
}

// The newest fault (faults.back()) must start inside the run and must not overlap an earlier
// fault of the same kind on the same wheel/node: the first one's end would otherwise cancel
// the second early. The EtherCAT and M-III lines keep one state per bus fault kind for the
// whole line, so there any two bus faults of one kind must not overlap, whatever their node.
void check_fault_timing(const YamlField& item, const std::vector<FaultSpec>& faults, double run_duration,
                        BusKind bus) {
  const FaultSpec& f = faults.back();
  const YamlField v = item.single_member(kFaultKinds);
  if (f.at >= run_duration)
    v["at"].fail(fmt::format("{} s is not inside the run (it lasts {} s): the fault would never happen", f.at,
                             run_duration));
  // In the scheduler's integer nanoseconds, as the run schedules them: in doubles 0.2 + 0.1
  // ends after 0.3 begins, and back-to-back faults were refused or not by rounding (found in
  // review). A fault's end runs before a later-listed fault's start at the same instant.
  const auto start_of = [](const FaultSpec& x) { return seconds_to_ns(x.at); };
  const auto end_of = [](const FaultSpec& x) {
    return x.duration > 0 ? seconds_to_ns(x.at + x.duration) : std::numeric_limits<SimTime>::max();
  };
  for (std::size_t i = 0; i + 1 < faults.size(); ++i) {
    const FaultSpec& g = faults[i];
    const bool line_wide =
        (bus == BusKind::ethercat || bus == BusKind::m3) && f.kind != FaultSpec::Kind::wheel_slip;
    if (g.kind == f.kind && (g.wheel == f.wheel || line_wide) && start_of(f) < end_of(g) && start_of(g) < end_of(f))
      v["at"].fail(g.line > 0 ? fmt::format("overlaps the {} fault at line {}", to_string(g.kind), g.line)
                              : fmt::format("overlaps the {} fault given by --set", to_string(g.kind)));
  }
}

Expectation read_expectation(const YamlField& m) {
  Expectation e;
  e.metric = m.name();
  e.line = m.line();
  if (!is_known_metric(e.metric)) m.fail(fmt::format("unknown metric '{}'", e.metric));
  m.allow_keys({"min", "max"});
  if (m["min"].exists()) e.min = m["min"].number();
  if (m["max"].exists()) e.max = m["max"].number();
  if (!e.min && !e.max) m.fail("an expectation needs min, max or both");
  if (e.min && e.max && *e.min > *e.max) {
    m.fail(fmt::format("min {} is greater than max {}", *e.min, *e.max));
  }
  return e;
}

// ---------------------------------------------------------------------------------------
// Outputs

VideoSpec read_video(const YamlField& f) {
  VideoSpec v;
  if (!f.present()) return v;
  if (!f.node().IsMap()) {
    v.enabled = f.boolean();
    return v;
  }
  f.allow_keys({"enabled", "width", "height", "fps", "overview_inset"});
  read_bool(f, "enabled", v.enabled);
  read_integer(f, "width", v.width, Bounds::closed(64, 3840));
  read_integer(f, "height", v.height, Bounds::closed(48, 2160));
  if (v.width % 2) f["width"].fail("must be even (H.264 yuv420p)");
  if (v.height % 2) f["height"].fail("must be even (H.264 yuv420p)");
  read_number(f, "fps", v.fps, Bounds::closed(1, 120));
  read_bool(f, "overview_inset", v.overview_inset);
  return v;
}

DdsSpec read_dds(const YamlField& f, double control_period) {
  DdsSpec d;
  if (!f.present()) return d;
  if (!f.node().IsMap()) {
    d.enabled = f.boolean();
    return d;
  }
  f.allow_keys({"enabled", "domain", "interface", "config", "rate_hz", "wait_for_readers", "wait_s"});
  read_bool(f, "enabled", d.enabled);
  read_integer(f, "domain", d.domain, Bounds::closed(0, 232));
  if (f["interface"].exists()) d.interface = f["interface"].string();
  if (f["config"].exists()) d.config_file = f["config"].string();
  read_number(f, "rate_hz", d.rate_hz, Bounds::positive());
  read_integer(f, "wait_for_readers", d.wait_for_readers, Bounds::closed(0, 1000));
  read_number(f, "wait_s", d.wait_s, Bounds::closed(0, 3600));
  if (d.rate_hz > 1.0 / control_period + 1e-9)
    f["rate_hz"].fail(fmt::format("at most the control rate ({:g} Hz)", 1.0 / control_period));
  return d;
}

OutputsSpec read_outputs(const YamlField& f, double control_period) {
  OutputsSpec o;
  if (!f.present()) return o;
  f.allow_keys({"video", "dds", "report"});
  o.video = read_video(f["video"]);
  o.dds = read_dds(f["dds"], control_period);
  read_bool(f, "report", o.report);
  return o;
}

// master: a program the user brings instead of omni-master (bus ethercat or can).
MasterSpec read_master(const YamlField& f, const BusSpec& bus) {
  MasterSpec m;
  if (!f.exists()) return m;
  f.allow_keys({"command", "on_static", "watchdog", "stop_grace"});
  if (f["command"].exists()) m.command = f["command"].string();
  if (!m.command.empty() && bus.kind != BusKind::ethercat && bus.kind != BusKind::can)
    f["command"].fail("a master program of your own runs on bus ethercat or can");
  // A program that is not there is bad input, found before the run begins (it was a runtime
  // failure, exit 3, with advice about the virtual clock; found by a walkthrough). A program
  // word holding a placeholder ({iface}, {out}) is left to the run.
  if (f["command"].exists()) {
    std::vector<std::string> words;
    try {
      words = split_command(m.command);
    } catch (const std::invalid_argument& e) {
      f["command"].fail(e.what());
    }
    if (words.empty()) f["command"].fail("an empty command");
    if (words[0].find('{') == std::string::npos)
      if (const std::string why = program_problem(words[0]); !why.empty())
        f["command"].fail(fmt::format("{}: {}", words[0], why));
  }
  if (f["on_static"].exists())
    m.on_static = f["on_static"].choice({"fail", "realtime"}) == "realtime" ? MasterSpec::OnStatic::realtime
                                                                           : MasterSpec::OnStatic::fail;
  read_number(f, "watchdog", m.watchdog, Bounds::positive());
  read_number(f, "stop_grace", m.stop_grace, Bounds::positive());
  return m;
}

// ---------------------------------------------------------------------------------------
// The whole scenario

Scenario read_scenario(const YamlField& root, const std::string& file) {
  root.allow_keys({"name", "description", "platform", "bus", "clock", "controller", "path",
                   "settle", "duration", "faults", "expect", "outputs", "master"});
  Scenario s;
  s.file = file;
  s.name = root["name"].exists() ? root["name"].string() : fs::path(file).stem().string();
  // The name becomes a directory under out/: keep it a plain, safe file name.
  const bool safe = !s.name.empty() && s.name[0] != '.' &&
                    s.name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_.-") ==
                        std::string::npos;
  if (!safe) {
    if (root["name"].exists())
      root["name"].fail("must be letters, digits, '_', '-' or '.', not empty and not starting with '.' (it names the run "
                        "directory)");
    throw ScenarioError(file, 0, "name", "the file name does not make a safe scenario name; set name:");
  }
  if (root["description"].exists()) s.description = root["description"].string();
  s.platform = read_platform(root["platform"], file);
  s.bus = read_bus(root["bus"], file);
  if (root["clock"].exists()) {
    s.clock = root["clock"].choice({"lockstep", "realtime"}) == "realtime" ? ClockMode::realtime
                                                                           : ClockMode::lockstep;
  }
  s.controller = read_controller(root["controller"]);
  if (s.bus.kind == BusKind::can && !(s.bus.can.isr_us * 1e-6 < s.platform.velocity_loop.period))
    root["bus"]["isr_us"].fail(fmt::format("the slaves' interrupt routine must end within their period ({:g} µs)",
                                           s.platform.velocity_loop.period * 1e6));
  s.path = read_path(root["path"]);
  read_number(root, "settle", s.settle, Bounds::closed(0, kMaxRunSeconds));
  s.duration = path_duration(s.path) + s.settle;
  if (s.bus.kind == BusKind::ethercat) s.duration += s.bus.ethercat.startup;
  if (s.bus.kind == BusKind::m3) s.duration += s.bus.m3.startup;
  if (s.bus.kind == BusKind::canopen) s.duration += s.bus.canopen.startup;
  if (s.bus.kind == BusKind::tml) s.duration += s.bus.tml.startup;
  // omni-master's path starts kStartupTicks late; one tick more brings its NMT stop to the slaves.
  if (s.bus.kind == BusKind::can) s.duration += (controller::kStartupTicks + 1) * s.controller.period;
  read_number(root, "duration", s.duration, Bounds::open_closed(0, kMaxRunSeconds));
  if (!(s.duration > 0)) root.fail("the run has no length: give a path, settle or duration > 0");
  if (s.duration > kMaxRunSeconds)
    root.fail(fmt::format("the run would last {:g} s; at most {:g} s (11.6 days) can be simulated", s.duration,
                          kMaxRunSeconds));
  for (const auto& item : root["faults"].elements()) {
    s.faults.push_back(read_fault(item, s.bus));
    check_fault_timing(item, s.faults, s.duration, s.bus.kind);
  }
  for (const auto& m : root["expect"].members()) s.expectations.push_back(read_expectation(m));
  s.outputs = read_outputs(root["outputs"], s.controller.period);
  s.master = read_master(root["master"], s.bus);
  return s;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Public API

ScenarioError::ScenarioError(std::string file, int line, std::string key, const std::string& message)
    : std::runtime_error(format_error(file, line, key, message)),
      file_(std::move(file)),
      line_(line),
      key_(std::move(key)) {}

Override parse_override(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos) throw ScenarioError(kOverrideFile, 0, text, "expected key=value");
  Override o{text.substr(0, eq), text.substr(eq + 1)};
  check_override_key(o.key);
  return o;
}

Scenario load_scenario(const std::string& path, const std::vector<Override>& overrides) {
  if (!is_file(path)) throw ScenarioError(path, 0, "", "cannot open scenario file");
  YAML::Node root = load_yaml_file(path);
  if (!root.IsDefined() || root.IsNull()) throw ScenarioError(path, 0, "", "empty scenario file");
  if (!root.IsMap()) throw ScenarioError(path, root.Mark().line + 1, "", "expected a mapping at the top level");
  // Overrides edit the tree first, so they are checked exactly like file values.
  std::vector<std::string> overridden, notes;
  for (const auto& o : overrides) {
    check_override_key(o.key);
    overridden.push_back(apply_override(root, o, overridden, notes));
  }
  const YamlDoc doc(path, overridden);
  Scenario s = read_scenario(YamlField::root(doc, root), path);
  for (const auto& o : overrides) s.overrides.push_back(o.key + "=" + o.value);
  s.notes = std::move(notes);
  return s;
}

const char* to_string(BusKind b) {
  switch (b) {
    case BusKind::direct: return "direct";
    case BusKind::can: return "can";
    case BusKind::canopen: return "canopen";
    case BusKind::ethercat: return "ethercat";
    case BusKind::m3: return "m3";
    case BusKind::tml: return "tml";
  }
  return "?";
}

const char* to_string(FaultSpec::Kind k) {
  switch (k) {
    case FaultSpec::Kind::wheel_slip: return "wheel_slip";
    case FaultSpec::Kind::frame_loss: return "frame_loss";
    case FaultSpec::Kind::delay: return "delay";
    case FaultSpec::Kind::drift: return "drift";
    case FaultSpec::Kind::power_loss: return "power_loss";
    case FaultSpec::Kind::bus_off: return "bus_off";
    case FaultSpec::Kind::link_break: return "link_break";
    case FaultSpec::Kind::corruption: return "corruption";
    case FaultSpec::Kind::second_master: return "second_master";
  }
  return "?";
}

const char* to_string(ClockMode c) {
  switch (c) {
    case ClockMode::lockstep: return "lockstep";
    case ClockMode::realtime: return "realtime";
  }
  return "?";
}

// ---------------------------------------------------------------------------------------
// --loopback

namespace {

const char* const kLoopbackFlag = "--loopback";

// True for a host that is this machine's loopback (127.0.0.0/8, ::1, localhost).
bool loopback_host(const std::string& host) {
  return host == "localhost" || host == "::1" || host == "[::1]" || host.rfind("127.", 0) == 0;
}

// A CAN-family UDP spec with iface=lo (refused when it names another interface).
std::string can_spec_on_loopback(const std::string& spec, const std::string& key) {
  if (spec.rfind("udp:", 0) != 0) return spec;  // socketcan:, mem: stay on this machine's kernel
  const std::size_t q = spec.find('?');
  if (q != std::string::npos) {
    const std::string options = "&" + spec.substr(q + 1) + "&";
    const std::size_t at = options.find("&iface=");
    if (at != std::string::npos) {
      const std::string iface = options.substr(at + 7, options.find('&', at + 7) - at - 7);
      if (iface == "lo") return spec;
      throw ScenarioError(kLoopbackFlag, 0, key, fmt::format("'{}' sends on interface {}, not lo", spec, iface));
    }
  }
  return spec + (q == std::string::npos ? "?" : "&") + "iface=lo";
}

// EtherCAT / M-III: auto, veth and mem are local; udp must name a loopback host; raw is a NIC.
void check_ethernet_spec(const std::string& spec, const std::string& key) {
  if (spec == "auto" || spec == "veth" || spec.rfind("mem:", 0) == 0) return;
  if (spec.rfind("udp:", 0) == 0) {
    const std::string rest = spec.substr(4);
    const std::string host = rest.substr(0, rest.rfind(':'));
    if (loopback_host(host)) return;
    throw ScenarioError(kLoopbackFlag, 0, key, fmt::format("'{}' reaches host {}, not this machine", spec, host));
  }
  throw ScenarioError(kLoopbackFlag, 0, key, fmt::format("'{}' puts frames on a network interface", spec));
}

}  // namespace

void confine_to_loopback(Scenario& s) {
  s.bus.can.transport = can_spec_on_loopback(s.bus.can.transport, "bus.transport");
  if (s.bus.kind == BusKind::ethercat) check_ethernet_spec(s.bus.ethercat.transport, "bus.transport");
  if (s.bus.kind == BusKind::m3) check_ethernet_spec(s.bus.m3.transport, "bus.transport");
  if (!s.outputs.dds.config_file.empty())
    throw ScenarioError(kLoopbackFlag, 0, "outputs.dds.config",
                        "a Cyclone DDS configuration file names its own interfaces; drop it or --loopback");
  s.outputs.dds.interface = "lo";
}

}  // namespace omnitwin::twin
