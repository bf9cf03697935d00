// Tests the JUnit XML writer (twin/junit.cpp): suite counts and times, <failure> vs
// <error>, escaping of every text and attribute, and that the document is well-formed
// (checked by a minimal tag-balance parser below) and written to disk as produced.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "twin/junit.hpp"

namespace omnitwin::twin {
namespace {

// Minimal well-formedness: balanced tags, quoted attributes, no raw '<' in text, and
// every '&' starting one of the five predefined entities. Returns "" or the problem.
std::string xml_problem(const std::string& xml) {
  std::vector<std::string> open;
  std::size_t i = xml.find("?>");
  if (xml.rfind("<?xml", 0) != 0 || i == std::string::npos) return "no XML declaration";
  for (i += 2; i < xml.size(); ++i) {
    if (xml[i] == '&') {
      bool ok = false;
      for (const char* ent : {"&amp;", "&lt;", "&gt;", "&quot;", "&apos;"}) ok |= xml.compare(i, std::strlen(ent), ent) == 0;
      if (!ok) return "bad entity at " + std::to_string(i);
    }
    if (xml[i] != '<') continue;
    const std::size_t end = xml.find('>', i);
    if (end == std::string::npos) return "unterminated tag";
    std::string tag = xml.substr(i + 1, end - i - 1);
    if (std::count(tag.begin(), tag.end(), '"') % 2 != 0) return "unbalanced quotes in <" + tag + ">";
    if (tag.find('<') != std::string::npos) return "raw '<' inside a tag";
    const bool closing = tag[0] == '/';
    const bool self = tag.back() == '/';
    const std::string name = tag.substr(closing ? 1 : 0, tag.find_first_of(" /", 1) - (closing ? 1 : 0));
    if (closing) {
      if (open.empty() || open.back() != name) return "mismatched </" + name + ">";
      open.pop_back();
    } else if (!self) {
      open.push_back(name);
    }
    i = end;
  }
  return open.empty() ? "" : "unclosed <" + open.back() + ">";
}

std::vector<JunitCase> sample_cases() {
  JunitCase pass{"line", "scenarios", 1.25, true, false, {}, ""};
  JunitCase fail{"square <fast> & \"tight\"", "scenarios", 2.5, false, false,
                 {"platform.final_error_cm = 0.73 > max 0.5", "axes.0.iae_velocity_pulse = 9 < min 10"},
                 "run & done"};
  JunitCase error{"broken", "scenarios", 0.0, false, true, {"bad.yaml:3: duration: expected a number, got 'abc'"},
                  ""};
  return {pass, fail, error};
}

TEST(Junit, XmlEscapeCoversSpecialAndControlCharacters) {
  EXPECT_EQ(xml_escape("a<b>&\"c'd"), "a&lt;b&gt;&amp;&quot;c&apos;d");
  EXPECT_EQ(xml_escape(std::string("x\x01y\tz\n")), "x?y\tz\n");
  EXPECT_EQ(xml_escape("plain"), "plain");
}

TEST(Junit, StructureAndCounts) {
  const std::string xml = junit_xml("omnitwin check", sample_cases());
  EXPECT_EQ(xml_problem(xml), "");
  EXPECT_NE(xml.find("<testsuites name=\"omnitwin check\" tests=\"3\" failures=\"1\" errors=\"1\" time=\"3.750\">"),
            std::string::npos) << xml;
  EXPECT_NE(xml.find("<testsuite name=\"omnitwin check\" tests=\"3\" failures=\"1\" errors=\"1\" skipped=\"0\" time=\"3.750\">"),
            std::string::npos) << xml;
  EXPECT_NE(xml.find("<testcase name=\"line\" classname=\"scenarios\" time=\"1.250\"/>"), std::string::npos) << xml;
}

TEST(Junit, FailureAndErrorElementsAreEscaped) {
  const std::string xml = junit_xml("s", sample_cases());
  EXPECT_NE(xml.find("name=\"square &lt;fast&gt; &amp; &quot;tight&quot;\""), std::string::npos) << xml;
  EXPECT_NE(xml.find("<failure message=\"platform.final_error_cm = 0.73 &gt; max 0.5\" type=\"expectation\">"
                     "platform.final_error_cm = 0.73 &gt; max 0.5\naxes.0.iae_velocity_pulse = 9 &lt; min 10</failure>"),
            std::string::npos) << xml;
  EXPECT_NE(xml.find("<system-out>run &amp; done</system-out>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<error message=\"bad.yaml:3: duration: expected a number, got &apos;abc&apos;\" type=\"error\">"),
            std::string::npos) << xml;
  EXPECT_EQ(std::count(xml.begin(), xml.end(), '\x01'), 0);
}

TEST(Junit, EmptySuiteIsWellFormed) {
  const std::string xml = junit_xml("empty", {});
  EXPECT_EQ(xml_problem(xml), "");
  EXPECT_NE(xml.find("tests=\"0\" failures=\"0\" errors=\"0\""), std::string::npos);
}

TEST(Junit, WriteJunitWritesTheDocument) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("omnitwin_junit_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path file = dir / "junit.xml";
  write_junit(file.string(), "s", sample_cases());
  std::ifstream in(file);
  std::stringstream ss;
  ss << in.rdbuf();
  EXPECT_EQ(ss.str(), junit_xml("s", sample_cases()));
  EXPECT_THROW(write_junit((dir / "missing" / "j.xml").string(), "s", {}), std::runtime_error);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace omnitwin::twin
