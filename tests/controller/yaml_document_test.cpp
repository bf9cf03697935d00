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

}  // namespace
}  // namespace omnitwin::controller
