// Tests controller/yaml_document: the one document of a YAML text, every document counted
// (a second one named by where it starts), syntax errors thrown with their mark, and the inputs
// on which yaml-cpp 0.7's LoadAll never returns (a stray ',' at the top: found by
// fuzz/scenario_fuzz) reported as a stray token at once.
#include "controller/yaml_document.hpp"

#include <gtest/gtest.h>

#include <chrono>

namespace omnitwin::controller {
namespace {

TEST(YamlDocument, OneDocumentIsLoaded) {
  const YamlDocument d = load_yaml_document("a: 1\nb: [2, 3]\n");
  EXPECT_EQ(d.count, 1u);
  EXPECT_FALSE(d.stray);
  ASSERT_TRUE(d.node.IsMap());
  EXPECT_EQ(d.node["b"][1].as<int>(), 3);
}

TEST(YamlDocument, EmptyTextHoldsNoDocument) {
  for (const char* text : {"", "# only a comment\n", "\n\n"}) {
    const YamlDocument d = load_yaml_document(text);
    EXPECT_EQ(d.count, 0u) << text;
    EXPECT_FALSE(d.node.IsDefined() && !d.node.IsNull()) << text;
  }
}

TEST(YamlDocument, EveryDocumentIsCountedAndTheSecondLocated) {
  const YamlDocument d = load_yaml_document("a: 1\n---\nb: 2\n---\nc: 3\n");
  EXPECT_EQ(d.count, 3u);
  EXPECT_FALSE(d.stray);
  EXPECT_EQ(d.second.line + 1, 3) << "the line after the '---'";
}

TEST(YamlDocument, AStrayCommaIsReportedAtOnce) {
  for (const char* text : {",", ",\n", "  ,", ",a"}) {
    const auto t0 = std::chrono::steady_clock::now();
    const YamlDocument d = load_yaml_document(text);
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(1)) << text;
    EXPECT_TRUE(d.stray) << text;
    EXPECT_GE(d.count, 2u) << text;
  }
}

TEST(YamlDocument, SyntaxErrorsThrowWithTheirMark) {
  try {
    load_yaml_document("a: 1\n,\n");
    FAIL() << "no exception";
  } catch (const YAML::Exception& e) {
    EXPECT_EQ(e.mark.line + 1, 2);
  }
  EXPECT_THROW(load_yaml_document("a: [1, 2\n"), YAML::Exception);
}

// The syntax error yaml-cpp raises for `text`, described (fails the test if none is raised).
YamlSyntaxError syntax_error_of(const std::string& text) {
  try {
    load_yaml_document(text);
  } catch (const YAML::Exception& e) {
    return describe_syntax_error(text, e);
  }
  ADD_FAILURE() << "no syntax error in: " << text;
  return {};
}

// yaml-cpp says "illegal map value" or "end of map not found" for a tab in the indentation,
// at a line that need not be the tab's; the description names the tab and its line.
TEST(YamlDocument, ATabInTheIndentationIsNamedAtItsLine) {
  const YamlSyntaxError a = syntax_error_of("name: t\npath:\n\tsegments: []\n");
  EXPECT_EQ(a.line, 3);
  EXPECT_TRUE(a.message.starts_with("indented with a tab; YAML indents with spaces only (the parser says: "))
      << a.message;
  const YamlSyntaxError b = syntax_error_of("c:\n  kp: 1\n\tki: 0\n");
  EXPECT_EQ(b.line, 3) << b.message;
  EXPECT_NE(b.message.find("tab"), std::string::npos) << b.message;
  // Without a tab the parser's words and line stay as they are.
  const YamlSyntaxError c = syntax_error_of("a: [1, 2\n");
  EXPECT_EQ(c.message.find("tab"), std::string::npos) << c.message;
  // A tab after the error's line is not blamed.
  const YamlSyntaxError d = syntax_error_of("a: 1\n,\nb:\n\t- 1\n");
  EXPECT_EQ(d.line, 2) << d.message;
  EXPECT_EQ(d.message.find("tab"), std::string::npos) << d.message;
}

// A value that reads as a number but does not fit a double is named as such, not as text that
// is no number at all (`--set settle=1e400` said "expected a number").
TEST(YamlDocument, ANumberThatDoesNotFitIsSaidSo) {
  EXPECT_EQ(not_a_number("1e400"), "'1e400' is too large to be a number");
  EXPECT_EQ(not_a_number("-1e400"), "'-1e400' is too large to be a number");
  EXPECT_EQ(not_a_number("1e-400"), "'1e-400' is too small to be a number");
  EXPECT_EQ(not_a_number(".inf"), "'.inf' is not a finite number");
  EXPECT_EQ(not_a_number("-.Inf"), "'-.Inf' is not a finite number");
  EXPECT_EQ(not_a_number(".NaN"), "'.NaN' is not a finite number");
  EXPECT_EQ(not_a_number("abc"), "expected a number, got 'abc'");
  EXPECT_EQ(not_a_number("1e400x"), "expected a number, got '1e400x'");
  EXPECT_EQ(not_a_number(""), "expected a number, got ''");
}

}  // namespace
}  // namespace omnitwin::controller
