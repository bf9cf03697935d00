// controller/mechatrolink3 — the C1 master program's configuration file (see m3_config.hpp).
#include "controller/mechatrolink3/m3_config.hpp"
#include "controller/master_bounds.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

namespace omnitwin::m3 {

using namespace controller::config;

namespace {

void read_wheels(const std::string& file, const Val& n, M3ProgramConfig& c) {
  if (!n.node.IsSequence() || n.node.size() != 4) fail(file, n, "wheels", "expected four station addresses (wheel 1..4)");
  const std::vector<Val> ws = elements(n);
  for (std::size_t i = 0; i < 4; ++i) {
    c.wheels[i] = static_cast<std::uint8_t>(bounded_int(file, ws[i], "wheels", kFirstSlave, kFirstSlave + 61));
    for (std::size_t j = 0; j < i; ++j)
      if (c.wheels[j] == c.wheels[i]) fail(file, ws[i], "wheels", fmt::format("station {:02X}h named twice", c.wheels[i]));
  }
}

void read_params(const std::string& file, const Val& n, M3ProgramConfig& c) {
  if (!n.node.IsSequence()) fail(file, n, "params", "expected a list of {number, value}");
  for (const Val& e : elements(n)) {
    const Members m(file, e, "params", {"number", "value"});
    const Val* no = m.get("number");
    const Val* value = m.get("value");
    if (!no || !value) fail(file, e, "params", "number and value are required");
    c.params.emplace_back(static_cast<std::uint16_t>(bounded_int(file, *no, "params.number", 0, 0xFFFF)),
                          static_cast<std::int32_t>(bounded_int(file, *value, "params.value", INT32_MIN, INT32_MAX)));
  }
}

}  // namespace

M3ProgramConfig parse_m3_config(std::string_view yaml, const std::string& file, const std::string& base_dir) {
  const YAML::Node doc = load_document(yaml, file);
  const Val root(doc, line_of(doc, 1));
  M3ProgramConfig c;
  c.file = file;
  const Members top(file, root, "",
                    {"cycle", "retry_slots", "wheels", "extra_axes", "data_bytes", "communication", "response_us", "margin_us", "software_us",
                     "detect_timeout_ms", "startup_timeout", "lost_cycles", "wheel_command", "wheel_counts_per_rev",
                     "params", "platform"});
  // Our master connects with COM_TIM 1, and a servo takes 0.125 … 32 ms (m3_link's CONNECT
  // check): a cycle outside is bad input here, not a CONNECT refused at run time.
  if (const Val* n = top.get("cycle")) c.cycle = bounded(file, *n, "cycle", 125e-6, 0.032);
  if (const Val* n = top.get("retry_slots")) c.retry_slots = static_cast<int>(bounded_int(file, *n, "retry_slots", 0, 4));
  if (const Val* n = top.get("wheels")) read_wheels(file, *n, c);
  if (const Val* n = top.get("extra_axes")) {
    c.extra_axes = static_cast<int>(bounded_int(file, *n, "extra_axes", 0, 58));
    const int highest = *std::max_element(c.wheels.begin(), c.wheels.end());
    if (highest + c.extra_axes > kFirstSlave + 61)
      fail(file, *n, "extra_axes", fmt::format("addresses after {:02X}h run past 40h (62 stations at most)", highest));
  }
  if (const Val* n = top.get("communication")) {
    const std::string m = n->node.IsScalar() ? n->node.Scalar() : "";
    if (m != "cyclic" && m != "event") fail(file, *n, "communication", "cyclic or event");
    c.event_driven = m == "event";
    if (c.event_driven) c.data_bytes = kMaxData;  // event-driven frames carry 64 bytes
  }
  if (const Val* n = top.get("data_bytes")) {
    c.data_bytes = static_cast<std::size_t>(integer(file, *n, "data_bytes"));
    if (c.event_driven ? c.data_bytes != kMaxData : c.data_bytes != 32 && c.data_bytes != 48)
      fail(file, *n, "data_bytes", c.event_driven ? "event-driven data is 64 bytes" : "the servo profile's lengths are 32 and 48");
  }
  if (const Val* n = top.get("response_us")) c.response_us = bounded(file, *n, "response_us", 0, 10'000);
  if (const Val* n = top.get("margin_us")) c.margin_us = bounded(file, *n, "margin_us", 0, 10'000);
  if (const Val* n = top.get("software_us")) c.software_us = bounded(file, *n, "software_us", 0, 10'000);
  if (const Val* n = top.get("detect_timeout_ms")) c.detect_timeout_ms = bounded(file, *n, "detect_timeout_ms", 0.001, 1000);
  if (const Val* n = top.get("startup_timeout")) c.startup_timeout = bounded(file, *n, "startup_timeout", 0.001, controller::kMaxStartupTimeout);
  if (const Val* n = top.get("lost_cycles")) c.lost_cycles = static_cast<int>(bounded_int(file, *n, "lost_cycles", 1, 100000));
  if (const Val* n = top.get("wheel_command")) {
    const std::string m = n->node.IsScalar() ? n->node.Scalar() : "";
    if (m != "velctrl" && m != "interpolate") fail(file, *n, "wheel_command", "velctrl or interpolate");
    c.command = m == "velctrl" ? WheelCommand::velctrl : WheelCommand::interpolate;
  }
  if (const Val* n = top.get("wheel_counts_per_rev")) c.wheel_counts_per_rev = bounded(file, *n, "wheel_counts_per_rev", 4, 1 << 30);
  if (const Val* n = top.get("params")) read_params(file, *n, c);
  if (const Val* n = top.get("platform")) read_platform(file, *n, base_dir, c.platform_yaml, c.platform_file);
  if (c.event_driven && c.command == WheelCommand::interpolate)
    fail(file, *top.get("wheel_command"), "wheel_command", "INTERPOLATE needs phase 3, which event-driven communication never enters");
  return c;
}

M3ProgramConfig load_m3_config(const std::string& path) {
  return parse_m3_config(read_file(path), path, std::filesystem::path(path).parent_path().string());
}

std::vector<std::uint8_t> station_addresses(const M3ProgramConfig& c) {
  std::vector<std::uint8_t> out(c.wheels.begin(), c.wheels.end());
  const int highest = *std::max_element(c.wheels.begin(), c.wheels.end());
  for (int i = 1; i <= c.extra_axes; ++i) out.push_back(static_cast<std::uint8_t>(highest + i));
  return out;
}

MasterConfig make_master_config(const M3ProgramConfig& c) {
  MasterConfig m;
  for (std::uint8_t a : station_addresses(c))
    m.slaves.push_back(MasterSlave{.address = a, .data_bytes = c.data_bytes, .response_ns = std::llround(c.response_us * 1e3)});
  m.cycle_ns = std::llround(c.cycle * 1e9);
  m.retry_slots = c.retry_slots;
  m.margin_ns = std::llround(c.margin_us * 1e3);
  m.software_ns = std::llround(c.software_us * 1e3);
  m.detect_timeout_ns = std::llround(c.detect_timeout_ms * 1e6);
  m.event_driven = c.event_driven;
  return m;
}

std::string dump_m3_config(const M3ProgramConfig& c) {
  std::string out = fmt::format("cycle: {}\nretry_slots: {}\nwheels: [0x{:02X}, 0x{:02X}, 0x{:02X}, 0x{:02X}]\n", c.cycle,
                                c.retry_slots, c.wheels[0], c.wheels[1], c.wheels[2], c.wheels[3]);
  if (c.extra_axes > 0) out += fmt::format("extra_axes: {}\n", c.extra_axes);
  if (c.event_driven) out += "communication: event\n";
  out += fmt::format("data_bytes: {}\nresponse_us: {}\nmargin_us: {}\nsoftware_us: {}\n", c.data_bytes, c.response_us,
                     c.margin_us, c.software_us);
  out += fmt::format("detect_timeout_ms: {}\nstartup_timeout: {}\nlost_cycles: {}\n", c.detect_timeout_ms,
                     c.startup_timeout, c.lost_cycles);
  out += fmt::format("wheel_command: {}\nwheel_counts_per_rev: {}\n",
                     c.command == WheelCommand::velctrl ? "velctrl" : "interpolate", c.wheel_counts_per_rev);
  if (!c.params.empty()) {
    out += "params:\n";
    for (const auto& [no, v] : c.params) out += fmt::format("  - {{number: 0x{:04X}, value: {}}}\n", no, v);
  }
  if (!c.platform_file.empty()) out += fmt::format("platform: {}\n", c.platform_file);
  return out;
}

}  // namespace omnitwin::m3
