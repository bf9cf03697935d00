// Test support: bad scenario files made from the shipped ones (models/scenarios/*.yaml,
// tests/regression/*.yaml), for the robustness tests of the scenario reader and the CLI
// (tests/twin/scenario_mutants_test.cpp, tests/twin/cli_scenario_mutants_slow_test.cpp).
//
// Each mutant is one edit of one file — a truncation, a value of the wrong type, NaN, ±inf or a
// huge number, a missing line, a duplicated line, an unknown key, a tab in the indentation, a
// flow collection left open — or a whole file of binary garbage or nothing. The files' relative
// `params:`/`mjcf:` references are made absolute first, so a mutant fails for its edit and not
// because it was moved. The set is drawn with a fixed seed: the same build makes the same
// mutants. A header, so no test binary is built from it.
#pragma once

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <stdexcept>
#include <string>
#include <vector>

#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::testing {

struct ScenarioMutant {
  std::string name;  // source file stem, kind and index: what a failure message shows
  std::string kind;  // truncate, wrong_type, delete_line, duplicate_line, unknown_key, tab, open_flow, garbage, empty,
                     // stray_comma, long_file_name
  std::string text;  // the file's bytes
};

// Writes `bytes` to `p` (created or truncated); throws std::runtime_error when it cannot.
inline void write_bytes(const std::filesystem::path& p, const std::string& bytes) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f << bytes;
  f.close();
  if (!f) throw std::runtime_error("cannot write " + p.string());
}

// The shipped scenario files, sorted.
inline std::vector<std::filesystem::path> shipped_scenarios() {
  std::vector<std::filesystem::path> files;
  for (const char* dir : {"models/scenarios", "tests/regression"})
    for (const auto& e : std::filesystem::directory_iterator(source_path(dir)))
      if (e.path().extension() == ".yaml") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

// The file's lines (without their newlines).
inline std::vector<std::string> split_lines(const std::string& text) {
  std::vector<std::string> lines;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t nl = text.find('\n', start);
    if (nl == std::string::npos) {
      if (start < text.size()) lines.push_back(text.substr(start));
      break;
    }
    lines.push_back(text.substr(start, nl - start));
    start = nl + 1;
  }
  return lines;
}

inline std::string join_lines(const std::vector<std::string>& lines) {
  std::string out;
  for (const std::string& l : lines) out += l + "\n";
  return out;
}

// `file`'s text with relative params:/mjcf: references made absolute.
inline std::string with_absolute_references(const std::filesystem::path& file) {
  static const std::regex ref(R"(^(\s*(params|mjcf):\s*)([^\s#{}\[\]]+)(.*)$)");
  std::vector<std::string> lines = split_lines(read_bytes(file));
  for (std::string& l : lines) {
    std::smatch m;
    if (!std::regex_match(l, m, ref)) continue;
    const std::filesystem::path target(m[3].str());
    if (target.is_absolute()) continue;
    l = m[1].str() + (file.parent_path() / target).lexically_normal().string() + m[4].str();
  }
  return join_lines(lines);
}

// Lines of the form `KEY: VALUE` (optionally inside a list item), with where the value starts.
struct KeyLine {
  std::size_t index;        // line number, 0-based
  std::size_t value_start;  // offset of the value in the line
  std::size_t key_indent;   // column of the key
};
inline std::vector<KeyLine> key_lines(const std::vector<std::string>& lines) {
  static const std::regex kv(R"(^(\s*(?:- )?)([A-Za-z_][A-Za-z0-9_.]*):[ ]+(\S.*)$)");
  std::vector<KeyLine> out;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    std::smatch m;
    if (!std::regex_match(lines[i], m, kv)) continue;  // comments and list items without a key
    out.push_back({i, static_cast<std::size_t>(m.position(3)), static_cast<std::size_t>(m.length(1))});
  }
  return out;
}

// `count` mutants drawn with `seed` from the shipped scenarios.
inline std::vector<ScenarioMutant> scenario_mutants(std::size_t count, std::uint32_t seed = 20261126) {
  const std::vector<std::string> wrong_values = {"{bad: 1}", "[1, 2, 3]", ".nan", ".inf", "-.inf", "1e400",
                                                 "-1e400", "1e308", "\"text\"", "~", "0x7fffffffffffffff",
                                                 "-99999999999999999999", "[", "{", "'unclosed", "!!binary AAAA",
                                                 "*undefined_alias", "&a [*a]"};
  const std::vector<std::string> kinds = {"truncate",    "wrong_type", "wrong_type", "wrong_type", "delete_line",
                                          "duplicate_line", "unknown_key", "tab",     "open_flow",  "garbage"};
  std::vector<std::filesystem::path> files = shipped_scenarios();
  std::vector<std::string> texts;
  for (const auto& f : files) texts.push_back(with_absolute_references(f));
  std::mt19937 rng(seed);
  auto pick = [&rng](std::size_t n) { return std::uniform_int_distribution<std::size_t>(0, n - 1)(rng); };
  std::vector<ScenarioMutant> out;
  out.push_back({"empty", "empty", ""});
  out.push_back({"only_comment", "empty", "# nothing here\n"});
  // A stray ',' at the top: yaml-cpp 0.7's LoadAll never returned on these (fuzz/scenario_fuzz).
  out.push_back({"stray_comma", "stray_comma", ","});
  out.push_back({"stray_comma_first", "stray_comma", ",\n" + texts[0]});
  // A file name the file system refuses (a component over NAME_MAX): std::filesystem threw
  // and the run ended with exit 3 (fuzz/scenario_fuzz, 2026-11-26).
  out.push_back({"long_file_name", "long_file_name",
                 "platform:\n  params: " + std::string(300, 'x') + "/omni4.yaml\nbus: direct\n"});
  while (out.size() < count) {
    const std::size_t fi = pick(files.size());
    const std::string& text = texts[fi];
    std::vector<std::string> lines = split_lines(text);
    const std::vector<KeyLine> keys = key_lines(lines);
    const std::string kind = kinds[pick(kinds.size())];
    ScenarioMutant m{files[fi].stem().string() + "." + kind + "." + std::to_string(out.size()), kind, {}};
    if (kind == "truncate") {
      m.text = text.substr(0, pick(text.size()));
    } else if (kind == "garbage") {
      std::string g(pick(400), '\0');
      for (char& c : g) c = static_cast<char>(pick(256));
      m.text = g;
    } else if (kind == "tab") {
      // A tab where YAML wants spaces: the first indented line.
      for (std::string& l : lines)
        if (!l.empty() && l[0] == ' ') {
          l = "\t" + l.substr(l.find_first_not_of(' '));
          break;
        }
      m.text = join_lines(lines);
    } else if (keys.empty()) {
      continue;
    } else {
      const KeyLine k = keys[pick(keys.size())];
      std::string& l = lines[k.index];
      if (kind == "wrong_type") {
        l = l.substr(0, k.value_start) + wrong_values[pick(wrong_values.size())];
      } else if (kind == "delete_line") {
        lines.erase(lines.begin() + static_cast<std::ptrdiff_t>(k.index));
      } else if (kind == "duplicate_line") {
        lines.insert(lines.begin() + static_cast<std::ptrdiff_t>(k.index), l);
      } else if (kind == "unknown_key") {
        lines.insert(lines.begin() + static_cast<std::ptrdiff_t>(k.index) + 1,
                     std::string(k.key_indent, ' ') + "zz_unknown_key: 1");
      } else {  // open_flow: the line's closing bracket or brace removed
        const std::size_t close = l.find_last_of("}]");
        if (close == std::string::npos) continue;
        l.erase(close, 1);
      }
      m.text = join_lines(lines);
    }
    out.push_back(std::move(m));
  }
  return out;
}

// Bad `--set` values for a valid scenario: each must be refused like a bad file.
inline std::vector<std::string> bad_overrides() {
  return {"controller.period=abc",      "controller.period=0",          "controller.period=.nan",
          "controller.period=-1",       "controller.period=1e400",      "controller.kp=[1,2]",
          "controller.kp={a: 1}",       "bus=nosuch",                   "bus.bit_rate=12",
          "bus.bit_rate=-1000000",      "bus.drift=7",                  "clock=sometimes",
          "platform.motor.kv=-1",       "platform.motor.kv=.inf",       "platform.motor.backlash=2",
          "platform.driver.gain_error=[0.1]", "platform.geometry.L=0",  "platform.sim.timestep=0",
          "platform.sim.variant=wheels", "nosuch.key=1",                "platform.nosuch=1",
          "path.segments.0.line.duration=-1", "path.segments.0.line.duration=.nan",
          "path.segments.9.line.dx=1",  "settle=-2",                    "duration=abc",
          "=1",                         "controller.period",            "controller..period=1",
          "platform.velocity_loop.arithmetic=float"};
}

}  // namespace omnitwin::testing
