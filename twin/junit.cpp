// twin layer — JUnit XML writer; see junit.hpp.
#include "twin/junit.hpp"

#include <fmt/format.h>

#include "twin/records.hpp"

namespace omnitwin::twin {

namespace {

// All failure lines as one text block.
std::string joined(const std::vector<std::string>& lines) {
  std::string out;
  for (const auto& l : lines) out += (out.empty() ? "" : "\n") + l;
  return out;
}

// One <testcase> element, indented for a testsuite.
std::string testcase_xml(const JunitCase& c) {
  std::string out = fmt::format("    <testcase name=\"{}\" classname=\"{}\" time=\"{:.3f}\"",
                                xml_escape(c.name), xml_escape(c.classname), c.time_s);
  const bool failed = c.error || !c.passed;
  if (!failed && c.system_out.empty()) return out + "/>\n";
  out += ">\n";
  if (failed) {
    // <error> for cases that could not run, <failure> for unmet expectations.
    const char* tag = c.error ? "error" : "failure";
    const std::string first = c.failures.empty() ? std::string(c.error ? "error" : "failed") : c.failures.front();
    out += fmt::format("      <{0} message=\"{1}\" type=\"{2}\">{3}</{0}>\n", tag, xml_escape(first),
                       c.error ? "error" : "expectation", xml_escape(joined(c.failures)));
  }
  if (!c.system_out.empty()) {
    out += fmt::format("      <system-out>{}</system-out>\n", xml_escape(c.system_out));
  }
  return out + "    </testcase>\n";
}

}  // namespace

std::string xml_escape(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char ch : text) {
    const auto c = static_cast<unsigned char>(ch);
    switch (ch) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      // Tab, newline and CR are allowed; other control characters are not in XML 1.0.
      default: out += (c < 0x20 && ch != '\t' && ch != '\n' && ch != '\r') ? '?' : ch;
    }
  }
  return out;
}

std::string junit_xml(const std::string& suite, const std::vector<JunitCase>& cases) {
  int failures = 0, errors = 0;
  double time = 0;
  std::string body;
  for (const auto& c : cases) {
    errors += c.error ? 1 : 0;
    failures += (!c.error && !c.passed) ? 1 : 0;
    time += c.time_s;
    body += testcase_xml(c);
  }
  const std::string counts = fmt::format("tests=\"{}\" failures=\"{}\" errors=\"{}\"", cases.size(), failures, errors);
  std::string out = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  out += fmt::format("<testsuites name=\"{}\" {} time=\"{:.3f}\">\n", xml_escape(suite), counts, time);
  out += fmt::format("  <testsuite name=\"{}\" {} skipped=\"0\" time=\"{:.3f}\">\n", xml_escape(suite), counts, time);
  out += body;
  out += "  </testsuite>\n</testsuites>\n";
  return out;
}

void write_junit(const std::string& path, const std::string& suite, const std::vector<JunitCase>& cases) {
  write_text_atomic(path, junit_xml(suite, cases));
}

}  // namespace omnitwin::twin
