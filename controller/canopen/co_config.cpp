// controller/canopen — the CANopen master program's configuration file (see co_config.hpp).
#include "controller/canopen/co_config.hpp"
#include "controller/master_bounds.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <filesystem>

namespace omnitwin::controller::canopen {

using namespace controller::config;

namespace {

void read_nodes(const std::string& file, const Val& n, CoProgramConfig& c) {
  if (!n.node.IsSequence() || n.node.size() != 4) fail(file, n, "nodes", "expected four node IDs (wheel 1..4)");
  const std::vector<Val> ns = elements(n);
  for (std::size_t i = 0; i < 4; ++i) {
    c.nodes[i] = static_cast<std::uint8_t>(bounded_int(file, ns[i], "nodes", 1, 127));
    for (std::size_t j = 0; j < i; ++j)
      if (c.nodes[j] == c.nodes[i]) fail(file, ns[i], "nodes", fmt::format("node {} named twice", c.nodes[i]));
  }
}

}  // namespace

CoProgramConfig parse_co_config(std::string_view yaml, const std::string& file, const std::string& base_dir) {
  const YAML::Node doc = load_document(yaml, file);
  const Val root(doc, line_of(doc, 1));
  CoProgramConfig c;
  c.file = file;
  const Members top(file, root, "",
                    {"eds", "cycle", "sync_producer", "tick", "nodes", "master_node_id", "master_heartbeat_ms", "node_heartbeat_ms",
                     "heartbeat_timeout_ms", "sync_counter", "wheel_mode", "wheel_counts_per_rev", "sdo_timeout_ms",
                     "startup_timeout", "platform"});
  const Val* eds = top.get("eds");
  if (!eds || !eds->node.IsScalar()) fail(file, eds ? *eds : root, "eds", "the drives' EDS file is required");
  c.eds = resolve(base_dir, eds->node.Scalar());
  if (const Val* n = top.get("cycle")) c.cycle = bounded(file, *n, "cycle", 1e-4, 1.0);
  if (const Val* n = top.get("nodes")) read_nodes(file, *n, c);
  if (const Val* n = top.get("sync_producer")) {
    if (n->node.IsScalar() && n->node.Scalar() == "master") {
      c.sync_producer = 0;
    } else {
      c.sync_producer = static_cast<std::uint8_t>(bounded_int(file, *n, "sync_producer", 1, 127));
      if (std::find(c.nodes.begin(), c.nodes.end(), c.sync_producer) == c.nodes.end())
        fail(file, *n, "sync_producer", "master, or the node ID of one of the wheels' drives");
    }
  }
  if (const Val* n = top.get("tick")) {
    c.tick = bounded(file, *n, "tick", kMinLoopPeriod, kMaxLoopPeriod);
    // The master producing SYNC ticks once per cycle: a tick of its own would be ignored.
    if (c.sync_producer == 0) fail(file, *n, "tick", "only with a wheel's drive as sync_producer (the master ticks every cycle)");
  }
  if (const Val* n = top.get("master_node_id")) c.master_node_id = static_cast<std::uint8_t>(bounded_int(file, *n, "master_node_id", 0, 127));
  // The drives watch the master's heartbeat under its node ID: a wheel's would be the drive's own.
  if (c.master_node_id != 0 && std::find(c.nodes.begin(), c.nodes.end(), c.master_node_id) != c.nodes.end()) {
    const Val* at = top.get("master_node_id") ? top.get("master_node_id") : top.get("nodes");
    fail(file, *at, "master_node_id", fmt::format("{} is also a wheel's node ID (the master needs one of its own)", c.master_node_id));
  }
  for (auto [key, field] : {std::pair{"master_heartbeat_ms", &c.master_heartbeat_ms}, std::pair{"node_heartbeat_ms", &c.node_heartbeat_ms},
                            std::pair{"heartbeat_timeout_ms", &c.heartbeat_timeout_ms}})
    if (const Val* n = top.get(key)) *field = static_cast<std::uint16_t>(bounded_int(file, *n, key, 0, 65535));
  if (const Val* n = top.get("sync_counter")) {
    const auto v = bounded_int(file, *n, "sync_counter", 0, 240);
    if (v == 1) fail(file, *n, "sync_counter", "1 is reserved (0: no counter, 2..240)");
    c.sync_counter = static_cast<std::uint8_t>(v);
  }
  if (const Val* n = top.get("wheel_mode")) {
    const std::string m = n->node.IsScalar() ? n->node.Scalar() : "";
    if (m != "csv" && m != "pv") fail(file, *n, "wheel_mode", "csv or pv");
    c.mode = m == "csv" ? WheelMode::csv : WheelMode::pv;
  }
  if (const Val* n = top.get("wheel_counts_per_rev")) c.wheel_counts_per_rev = bounded(file, *n, "wheel_counts_per_rev", 4, 1 << 30);
  if (const Val* n = top.get("sdo_timeout_ms")) c.sdo_timeout_ms = bounded(file, *n, "sdo_timeout_ms", 1, 60'000);
  if (const Val* n = top.get("startup_timeout")) c.startup_timeout = bounded(file, *n, "startup_timeout", 0.001, kMaxStartupTimeout);
  if (const Val* n = top.get("platform")) read_platform(file, *n, base_dir, c.platform_yaml, c.platform_file);
  if (c.node_heartbeat_ms != 0 && c.heartbeat_timeout_ms <= c.node_heartbeat_ms)
    fail(file, top.get("heartbeat_timeout_ms") ? *top.get("heartbeat_timeout_ms") : root, "heartbeat_timeout_ms",
         "must exceed node_heartbeat_ms");
  return c;
}

double master_tick(const CoProgramConfig& c) { return c.sync_producer != 0 && c.tick > 0 ? c.tick : c.cycle; }

CoProgramConfig load_co_config(const std::string& path) {
  return parse_co_config(read_file(path), path, std::filesystem::path(path).parent_path().string());
}

std::string dump_co_config(const CoProgramConfig& c) {
  std::string out = fmt::format("eds: {}\ncycle: {}\nnodes: [{}, {}, {}, {}]\n", c.eds, c.cycle, c.nodes[0], c.nodes[1],
                                c.nodes[2], c.nodes[3]);
  if (c.sync_producer != 0) out += fmt::format("sync_producer: {}\ntick: {}\n", c.sync_producer, master_tick(c));
  out += fmt::format("master_node_id: {}\nmaster_heartbeat_ms: {}\nnode_heartbeat_ms: {}\nheartbeat_timeout_ms: {}\n",
                     c.master_node_id, c.master_heartbeat_ms, c.node_heartbeat_ms, c.heartbeat_timeout_ms);
  out += fmt::format("sync_counter: {}\nwheel_mode: {}\nwheel_counts_per_rev: {}\nsdo_timeout_ms: {}\nstartup_timeout: {}\n",
                     c.sync_counter, c.mode == WheelMode::csv ? "csv" : "pv", c.wheel_counts_per_rev, c.sdo_timeout_ms,
                     c.startup_timeout);
  if (!c.platform_file.empty()) out += fmt::format("platform: {}\n", c.platform_file);
  return out;
}

}  // namespace omnitwin::controller::canopen
