// Tests controller/config_reader: the YAML walker the master programs' configuration files
// share. Members refuse unknown and repeated keys naming the line and the dotted key; numbers,
// integers (C-style hex) and booleans are checked; a second document and an empty file are
// refused; platform is a block mapping kept as YAML text or a file resolved against a folder.
#include "controller/config_reader.hpp"

#include <gtest/gtest.h>

#include <string>

namespace omnitwin::controller::config {
namespace {

template <class F>
std::string error_of(F f) {
  try {
    f();
  } catch (const ConfigFileError& e) {
    return e.what();
  }
  return "";
}

TEST(ConfigReader, MembersRefuseUnknownAndRepeatedKeys) {
  const YAML::Node doc = load_document("a: 1\nb: 2\n", "f.yaml");
  const Val root(doc, 1);
  const Members m("f.yaml", root, "", {"a", "b"});
  ASSERT_NE(m.get("b"), nullptr);
  EXPECT_EQ(m.get("b")->line, 2);
  EXPECT_EQ(m.get("c"), nullptr);
  EXPECT_EQ(error_of([&] { Members("f.yaml", root, "top", {"a"}); }),
            "f.yaml:2: top.b: unknown key (expected one of: a)");
  const YAML::Node twice = load_document("a: 1\na: 2\n", "f.yaml");
  EXPECT_EQ(error_of([&] { Members("f.yaml", Val(twice, 1), "", {"a"}); }), "f.yaml:2: a: repeated key");
}

TEST(ConfigReader, ValuesAreChecked) {
  const YAML::Node doc = load_document("n: 0x1F\nx: 2.5\nb: yes\nw: word\n", "f.yaml");
  const Members m("f.yaml", Val(doc, 1), "", {"n", "x", "b", "w"});
  EXPECT_EQ(integer("f.yaml", *m.get("n"), "n"), 31);
  EXPECT_EQ(number("f.yaml", *m.get("x"), "x"), 2.5);
  EXPECT_TRUE(boolean("f.yaml", *m.get("b"), "b"));
  EXPECT_EQ(error_of([&] { integer("f.yaml", *m.get("w"), "w"); }), "f.yaml:4: w: 'word' is not an integer");
  EXPECT_EQ(error_of([&] { number("f.yaml", *m.get("w"), "w"); }), "f.yaml:4: w: expected a number, got 'word'");
  EXPECT_EQ(error_of([&] { boolean("f.yaml", *m.get("w"), "w"); }), "f.yaml:4: w: expected true or false");
}

TEST(ConfigReader, OneDocumentNotEmpty) {
  EXPECT_EQ(error_of([] { load_document("", "f.yaml"); }), "f.yaml: empty configuration");
  EXPECT_EQ(error_of([] { load_document("a: 1\n---\nb: 2\n", "f.yaml"); }),
            "f.yaml:3: 2 YAML documents; a configuration file holds one");
}

TEST(ConfigReader, PlatformIsABlockMappingOrAFile) {
  std::string yaml, file;
  const YAML::Node a = load_document("platform: p.yaml\n", "f.yaml");
  read_platform("f.yaml", Val(a["platform"], 1), "/cfg", yaml, file);
  EXPECT_EQ(file, "/cfg/p.yaml");
  EXPECT_TRUE(yaml.empty());
  file.clear();
  const YAML::Node b = load_document("platform:\n  settle: 1.5\n", "f.yaml");
  read_platform("f.yaml", Val(b["platform"], 2), "/cfg", yaml, file);
  EXPECT_EQ(yaml, "settle: 1.5\n");
  EXPECT_TRUE(file.empty());
  EXPECT_EQ(resolve("/cfg", "/abs/p.yaml"), "/abs/p.yaml");
  EXPECT_EQ(error_of([] { read_file("/nonexistent/omnitwin.yaml"); }), "/nonexistent/omnitwin.yaml: cannot read the file");
  // A directory is named as one, not read as an empty configuration.
  EXPECT_EQ(error_of([] { read_file("/tmp"); }), "/tmp: a directory, not a configuration file");
}

}  // namespace
}  // namespace omnitwin::controller::config
