// controller layer — reading the one YAML document of a configuration or scenario file, shared
// by every reader of YAML files (master configurations, scenarios, platform parameters).
//
// yaml-cpp 0.7's LoadAll never returns on some inputs: after a stray ',' at the top of a file
// its parser yields the same empty document again and again, and LoadAll collects them until
// memory runs out (found by fuzz/scenario_fuzz: a file holding just "," hung `omnitwin run`).
// This reader counts documents with yaml-cpp's event parser, stops at a document that makes no
// progress, and loads the first one only when there is exactly one. Not real-time safe.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstddef>
#include <string_view>

namespace omnitwin::controller {

struct YamlDocument {
  YAML::Node node;           // the document (Null when the text holds none); unset when count > 1
  std::size_t count = 0;     // documents in the text (a stray token counts as a second)
  YAML::Mark second;         // where the second document's content starts (count > 1)
  bool stray = false;        // the "second" is a token no document can hold (a stray ',')
};

// Parses `text`; throws YAML::Exception (with its mark) on a syntax error.
YamlDocument load_yaml_document(std::string_view text);

}  // namespace omnitwin::controller
