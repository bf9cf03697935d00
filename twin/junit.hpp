// twin layer — JUnit XML for `omnitwin check --junit FILE`, the format CI systems read.
//
// One <testsuites> holding one <testsuite>; each scenario is a <testcase>, with a
// <failure> when its expectations failed and an <error> when it could not run (bad input,
// runtime failure). Everything written is XML-escaped, including characters XML 1.0 cannot
// carry at all. Written atomically (temp file + rename). Not real-time safe.
#pragma once

#include <string>
#include <vector>

namespace omnitwin::twin {

struct JunitCase {
  std::string name;
  std::string classname;
  double time_s = 0;        // wall time the case took [s]
  bool passed = false;
  bool error = false;       // could not run: reported as <error>, counted in errors
  std::vector<std::string> failures;  // one line each (expectation failures or the error)
  std::string system_out;   // optional captured output
};

// The XML document for `cases` in one suite named `suite`.
std::string junit_xml(const std::string& suite, const std::vector<JunitCase>& cases);

// Writes junit_xml() to `path`. Throws std::runtime_error if the file cannot be written.
void write_junit(const std::string& path, const std::string& suite, const std::vector<JunitCase>& cases);

// `text` escaped for XML attribute values and character data.
std::string xml_escape(const std::string& text);

}  // namespace omnitwin::twin
