// controller layer — the one YAML document of a file; see yaml_document.hpp.
#include "controller/yaml_document.hpp"

#include <yaml-cpp/eventhandler.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <string>

namespace omnitwin::controller {

namespace {

// Records where each document's content starts (its first node: the line after a '---');
// every other event is ignored.
struct DocumentStarts final : YAML::EventHandler {
  void OnDocumentStart(const YAML::Mark&) override {
    ++count;
    fresh = true;
  }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& m, YAML::anchor_t) override { node(m); }
  void OnAlias(const YAML::Mark& m, YAML::anchor_t) override { node(m); }
  void OnScalar(const YAML::Mark& m, const std::string&, YAML::anchor_t, const std::string&) override { node(m); }
  void OnSequenceStart(const YAML::Mark& m, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {
    node(m);
  }
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark& m, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {
    node(m);
  }
  void OnMapEnd() override {}
  void node(const YAML::Mark& m) {
    if (fresh) last = m;
    fresh = false;
  }
  YAML::Mark last;
  std::size_t count = 0;
  bool fresh = false;
};

}  // namespace

YamlDocument load_yaml_document(std::string_view text) {
  std::istringstream in{std::string(text)};
  YAML::Parser parser(in);
  DocumentStarts starts;
  YamlDocument d;
  int previous_pos = -1;
  while (parser.HandleNextDocument(starts)) {
    // A document that starts where the previous one did consumed nothing: yaml-cpp would
    // yield it forever.
    if (starts.count > 1 && starts.last.pos == previous_pos) {
      d.stray = true;
      if (d.count < 2) d.second = starts.last;
      d.count = std::max<std::size_t>(d.count, 2);
      return d;
    }
    previous_pos = starts.last.pos;
    d.count = starts.count;
    if (d.count == 2) d.second = starts.last;
  }
  if (d.count <= 1) d.node = YAML::Load(std::string(text));
  return d;
}

YamlSyntaxError describe_syntax_error(std::string_view text, const YAML::Exception& e) {
  YamlSyntaxError out{e.mark.is_null() ? 0 : e.mark.line + 1, e.msg};
  if (e.mark.is_null()) return out;
  // The last line up to the error's whose indentation holds a tab.
  int line = 1, tab_line = 0;
  bool indenting = true;
  for (const char c : text) {
    if (line > out.line) break;
    if (c == '\n') {
      ++line, indenting = true;
      continue;
    }
    if (indenting && c == '\t') tab_line = line;
    if (c != ' ' && c != '\t') indenting = false;
  }
  if (tab_line == 0) return out;
  return {tab_line, "indented with a tab; YAML indents with spaces only (the parser says: " + e.msg + ")"};
}

std::string not_a_number(const std::string& text) {
  // YAML's own spellings of infinity and not-a-number, in any case yaml-cpp accepts.
  std::string t = text;
  if (!t.empty() && (t[0] == '+' || t[0] == '-')) t.erase(0, 1);
  std::transform(t.begin(), t.end(), t.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (t == ".inf" || t == ".nan") return "'" + text + "' is not a finite number";
  // A literal that parses whole but overflows (or underflows) a double.
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  const bool whole = !text.empty() && end == text.c_str() + text.size();
  if (whole && (std::isinf(v) || errno == ERANGE)) {
    return "'" + text + (std::fabs(v) > 1.0 ? "' is too large to be a number" : "' is too small to be a number");
  }
  return "expected a number, got '" + text + "'";
}

}  // namespace omnitwin::controller
