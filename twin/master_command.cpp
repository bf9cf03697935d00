// twin layer — the user's master command line; see master_command.hpp.
#include "twin/master_command.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace omnitwin::twin {

namespace fs = std::filesystem;

std::vector<std::string> split_command(const std::string& command) {
  std::vector<std::string> words;
  std::string cur;
  bool in_word = false;
  char quote = 0;
  for (std::size_t i = 0; i < command.size(); ++i) {
    const char c = command[i];
    if (quote == '\'') {
      if (c == '\'') quote = 0; else cur += c;
      continue;
    }
    if (quote == '"') {
      if (c == '"') quote = 0;
      else if (c == '\\' && i + 1 < command.size() && std::strchr("\"\\$`", command[i + 1])) cur += command[++i];
      else cur += c;
      continue;
    }
    if (c == '\'' || c == '"') {
      quote = c;
      in_word = true;
    } else if (c == '\\' && i + 1 < command.size()) {
      cur += command[++i];
      in_word = true;
    } else if (c == ' ' || c == '\t' || c == '\n') {
      if (in_word) words.push_back(cur);
      cur.clear();
      in_word = false;
    } else {
      cur += c;
      in_word = true;
    }
  }
  if (quote) throw std::invalid_argument("an unbalanced quote in the master command");
  if (in_word) words.push_back(cur);
  return words;
}

std::string program_path(const std::string& program) {
  if (program.find('/') != std::string::npos) return program;
  const char* env = std::getenv("PATH");
  const std::string dirs = env ? env : "/usr/bin:/bin";
  for (std::size_t b = 0; b <= dirs.size();) {
    const std::size_t e = std::min(dirs.find(':', b), dirs.size());
    const fs::path p = fs::path(dirs.substr(b, e - b)) / program;
    if (access(p.c_str(), X_OK) == 0 && fs::is_regular_file(p)) return p.string();
    b = e + 1;
  }
  return "";
}

std::string program_problem(const std::string& program) {
  const std::string path = program_path(program);
  if (path.empty()) return "not found on PATH";
  std::error_code ec;
  if (!fs::exists(path, ec)) return "no such file";
  if (!fs::is_regular_file(path, ec) || access(path.c_str(), X_OK) != 0) return "not an executable file";
  return "";
}

}  // namespace omnitwin::twin
