// controller layer — the tokenizer of the Botnana Control word set (docs/botnana.md).
//
// Forth reads its input one blank-delimited word at a time, and a few words (`."`, `(`,
// `\`) take the raw text after them up to a delimiter instead. So the lexer is not a
// tokenizer that runs ahead: the interpreter pulls one word with next(), and when that word
// is one of the parsing words it pulls the raw text with until(). Every token carries its
// 0-based byte offset in the line, which error statuses report. No allocation: tokens are
// views into the caller's line, which must outlive them.
#pragma once

#include <cstddef>
#include <optional>
#include <string_view>

namespace omnitwin::botnana {

struct Token {
  std::string_view text;     // the word or the raw text (a view into the line)
  std::size_t position = 0;  // byte offset of its first character in the line
};

class Lexer {
 public:
  explicit Lexer(std::string_view line) noexcept : line_(line) {}
  // The next blank-delimited word (blanks: space, tab, CR, LF, VT, FF); nullopt at the end.
  std::optional<Token> next() noexcept;
  // The raw text from the current position (after the one blank that ended the previous
  // word) up to, not including, `delimiter`; the position moves past the delimiter.
  // nullopt (position unchanged) when the delimiter does not occur in the rest of the line.
  std::optional<Token> until(char delimiter) noexcept;
  // Skips the rest of the line (`\` comments).
  void skip_line() noexcept { pos_ = line_.size(); }
  std::size_t position() const noexcept { return pos_; }
  bool at_end() const noexcept;

 private:
  std::string_view line_;
  std::size_t pos_ = 0;
};

// True for the blanks that separate words.
constexpr bool is_blank(char c) noexcept {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f';
}

}  // namespace omnitwin::botnana
