// Tests physics/mujoco_message.hpp: MuJoCo's several-line load errors become one line, so a
// torn platform.xml gives the one-line message every other bad input gives.
#include "physics/mujoco_message.hpp"

#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <fstream>
#include <string>

#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::physics {
namespace {

TEST(MujocoMessage, LinesAreJoinedAndTrimmed) {
  EXPECT_EQ(one_line("XML Error: mismatched element\nElement 'body', line 12\n"),
            "XML Error: mismatched element; Element 'body', line 12");
  EXPECT_EQ(one_line("a  \r\n\n   b\n"), "a; b");
  EXPECT_EQ(one_line("XML parse error 14:\nError=X"), "XML parse error 14: Error=X");
  EXPECT_EQ(one_line("\n\none"), "one");
  EXPECT_EQ(one_line(""), "");
  EXPECT_EQ(one_line(nullptr), "");
}

using MujocoMessageLoad = testing::MujocoTest;

// The real thing: a torn MJCF file's error from mj_loadXML holds line breaks; ours none.
TEST_F(MujocoMessageLoad, ATornModelsErrorIsOneLine) {
  const testing::TempDir dir("omnitwin-mjmsg");
  const auto file = dir.path() / "torn.xml";
  std::ofstream(file) << "<mujoco><worldbody><body name=\"a\"><geom size=\"1\"/></worldbody></mujoco>\n";
  char err[1000] = "";
  mjModel* m = mj_loadXML(file.c_str(), nullptr, err, sizeof err);
  ASSERT_EQ(m, nullptr);
  const std::string raw(err), joined = one_line(err);
  EXPECT_NE(raw.find('\n'), std::string::npos) << raw;
  EXPECT_EQ(joined.find('\n'), std::string::npos) << joined;
  EXPECT_NE(joined.find("Line number=1"), std::string::npos) << joined;
  EXPECT_EQ(joined.find(":;"), std::string::npos) << joined;
}

}  // namespace
}  // namespace omnitwin::physics
