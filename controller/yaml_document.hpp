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
#include <string>
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

// A syntax error of `text` as one message and its 1-based line (0: none known). yaml-cpp's own
// words ("illegal map value", "end of map not found") do not say that a tab in a line's
// indentation is the cause, which it often is: when a line up to the error's indents with a
// tab, the message says so and the line is that one. Not real-time safe.
struct YamlSyntaxError {
  int line = 0;
  std::string message;
};
YamlSyntaxError describe_syntax_error(std::string_view text, const YAML::Exception& e);

// Why the scalar `text` is not a usable number, for a reader's error message: "'1e400' is too
// large to be a number", "'.inf' is not a finite number", else "expected a number, got
// 'text'". Not real-time safe.
std::string not_a_number(const std::string& text);

}  // namespace omnitwin::controller
