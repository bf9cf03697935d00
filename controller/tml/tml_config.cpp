// controller/tml — the TML master program's configuration file (see tml_config.hpp).
#include "controller/tml/tml_config.hpp"
#include "controller/master_bounds.hpp"

#include <fmt/format.h>

#include <filesystem>

namespace omnitwin::controller::tml {

using namespace controller::config;

TmlProgramConfig parse_tml_config(std::string_view yaml, const std::string& file, const std::string& base_dir) {
  const YAML::Node doc = load_document(yaml, file);
  const Val root(doc, line_of(doc, 1));
  TmlProgramConfig c;
  c.file = file;
  const Members top(file, root, "",
                    {"protocol", "cycle", "axes", "host_axis", "sample_period", "wheel_counts_per_rev", "acceleration",
                     "lost_ticks", "startup_timeout", "platform"});
  if (const Val* n = top.get("protocol")) {
    const std::string p = n->node.IsScalar() ? n->node.Scalar() : "";
    if (p != "tmlcan" && p != "techcan") fail(file, *n, "protocol", "tmlcan or techcan");
    c.techcan = p == "techcan";
    if (c.techcan) c.host_axis = 31;
  }
  const int max_axis = c.techcan ? 31 : 255;
  if (const Val* n = top.get("cycle")) c.cycle = bounded(file, *n, "cycle", 2.5e-4, 1.0);
  if (const Val* n = top.get("axes")) {
    if (!n->node.IsSequence() || n->node.size() != 4) fail(file, *n, "axes", "expected four axis IDs (wheel 1..4)");
    const std::vector<Val> as = elements(*n);
    for (std::size_t i = 0; i < 4; ++i) {
      c.axes[i] = static_cast<std::uint8_t>(bounded_int(file, as[i], "axes", 1, max_axis));
      for (std::size_t j = 0; j < i; ++j)
        if (c.axes[j] == c.axes[i]) fail(file, as[i], "axes", fmt::format("axis {} named twice", c.axes[i]));
    }
  }
  if (const Val* n = top.get("host_axis")) c.host_axis = static_cast<std::uint8_t>(bounded_int(file, *n, "host_axis", 1, max_axis));
  if (const Val* n = top.get("sample_period")) c.sample_period = bounded(file, *n, "sample_period", 1e-5, 0.1);
  if (const Val* n = top.get("wheel_counts_per_rev")) c.wheel_counts_per_rev = bounded(file, *n, "wheel_counts_per_rev", 4, 1 << 30);
  if (const Val* n = top.get("acceleration")) c.acceleration = bounded(file, *n, "acceleration", 1, 1e12);
  if (const Val* n = top.get("lost_ticks")) c.lost_ticks = static_cast<int>(bounded_int(file, *n, "lost_ticks", 1, 100000));
  if (const Val* n = top.get("startup_timeout")) c.startup_timeout = bounded(file, *n, "startup_timeout", 0.001, kMaxStartupTimeout);
  if (const Val* n = top.get("platform")) read_platform(file, *n, base_dir, c.platform_yaml, c.platform_file);
  return c;
}

TmlProgramConfig load_tml_config(const std::string& path) {
  return parse_tml_config(read_file(path), path, std::filesystem::path(path).parent_path().string());
}

std::string dump_tml_config(const TmlProgramConfig& c) {
  std::string out = fmt::format("protocol: {}\ncycle: {}\naxes: [{}, {}, {}, {}]\nhost_axis: {}\n", c.techcan ? "techcan" : "tmlcan",
                                c.cycle, c.axes[0], c.axes[1], c.axes[2], c.axes[3], c.host_axis);
  out += fmt::format("sample_period: {}\nwheel_counts_per_rev: {}\nacceleration: {}\nlost_ticks: {}\nstartup_timeout: {}\n",
                     c.sample_period, c.wheel_counts_per_rev, c.acceleration, c.lost_ticks, c.startup_timeout);
  if (!c.platform_file.empty()) out += fmt::format("platform: {}\n", c.platform_file);
  return out;
}

}  // namespace omnitwin::controller::tml
