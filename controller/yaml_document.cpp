// controller layer — the one YAML document of a file; see yaml_document.hpp.
#include "controller/yaml_document.hpp"

#include <yaml-cpp/eventhandler.h>

#include <algorithm>
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

}  // namespace omnitwin::controller
