// Tests controller/botnana/botnana_lexer: words split at every kind of blank with their byte
// offsets; until() returns the raw text up to a delimiter (the `."` and `(` parsing words),
// leaves the position alone when the delimiter is missing; skip_line and at_end.
#include "controller/botnana/botnana_lexer.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace omnitwin::botnana {
namespace {

std::vector<std::pair<std::string, std::size_t>> words(std::string_view line) {
  Lexer lex(line);
  std::vector<std::pair<std::string, std::size_t>> out;
  while (const auto t = lex.next()) out.emplace_back(std::string(t->text), t->position);
  return out;
}

TEST(BotnanaLexer, SplitsAtBlanksWithOffsets) {
  const auto w = words("  pp 1\t1  op-mode!\r\n");
  ASSERT_EQ(w.size(), 4u);
  EXPECT_EQ(w[0], (std::pair<std::string, std::size_t>{"pp", 2}));
  EXPECT_EQ(w[1], (std::pair<std::string, std::size_t>{"1", 5}));
  EXPECT_EQ(w[2], (std::pair<std::string, std::size_t>{"1", 7}));
  EXPECT_EQ(w[3], (std::pair<std::string, std::size_t>{"op-mode!", 10}));
}

TEST(BotnanaLexer, EmptyAndBlankLinesHaveNoWords) {
  EXPECT_TRUE(words("").empty());
  EXPECT_TRUE(words(" \t \r\n").empty());
  Lexer lex("   ");
  EXPECT_TRUE(lex.at_end());
}

TEST(BotnanaLexer, UntilTakesRawTextAfterTheWord) {
  Lexer lex(".\" hello  world\" cr");
  const auto dq = lex.next();
  ASSERT_TRUE(dq);
  EXPECT_EQ(dq->text, ".\"");
  const auto s = lex.until('"');
  ASSERT_TRUE(s);
  EXPECT_EQ(s->text, "hello  world");  // inner blanks kept
  EXPECT_EQ(s->position, 3u);
  const auto cr = lex.next();
  ASSERT_TRUE(cr);
  EXPECT_EQ(cr->text, "cr");
  EXPECT_EQ(cr->position, 17u);
  EXPECT_FALSE(lex.next());
}

TEST(BotnanaLexer, UntilWithoutDelimiterLeavesPosition) {
  Lexer lex("( no end");
  ASSERT_TRUE(lex.next());
  const std::size_t before = lex.position();
  EXPECT_FALSE(lex.until(')'));
  EXPECT_EQ(lex.position(), before);
  const auto t = lex.next();
  ASSERT_TRUE(t);
  EXPECT_EQ(t->text, "no");
}

TEST(BotnanaLexer, SkipLineEndsInput) {
  Lexer lex("1 \\ 2 3");
  ASSERT_TRUE(lex.next());
  const auto bs = lex.next();
  ASSERT_TRUE(bs);
  EXPECT_EQ(bs->text, "\\");
  lex.skip_line();
  EXPECT_TRUE(lex.at_end());
  EXPECT_FALSE(lex.next());
}

}  // namespace
}  // namespace omnitwin::botnana
