// controller layer — the tokenizer of the Botnana Control word set (see botnana_lexer.hpp).
#include "controller/botnana/botnana_lexer.hpp"

namespace omnitwin::botnana {

std::optional<Token> Lexer::next() noexcept {
  while (pos_ < line_.size() && is_blank(line_[pos_])) ++pos_;
  if (pos_ >= line_.size()) return std::nullopt;
  const std::size_t start = pos_;
  while (pos_ < line_.size() && !is_blank(line_[pos_])) ++pos_;
  Token t{line_.substr(start, pos_ - start), start};
  if (pos_ < line_.size()) ++pos_;  // the one blank that ends the word belongs to it
  return t;
}

std::optional<Token> Lexer::until(char delimiter) noexcept {
  const std::size_t end = line_.find(delimiter, pos_);
  if (end == std::string_view::npos) return std::nullopt;
  Token t{line_.substr(pos_, end - pos_), pos_};
  pos_ = end + 1;
  return t;
}

bool Lexer::at_end() const noexcept {
  std::size_t p = pos_;
  while (p < line_.size() && is_blank(line_[p])) ++p;
  return p >= line_.size();
}

}  // namespace omnitwin::botnana
