// media (shared with twin) — one line for a user about a JSON file we could not read: nlohmann::json's exception
// text without its "[json.exception.parse_error.101] " tag, which names the library's error
// class, not the file's problem. Used where a record (run.json, its faults, check.json) is read back; here, below the twin
// layer, so that both can call it.
#pragma once

#include <exception>
#include <string>

namespace omnitwin::media {

// e.what() less a leading "[json.exception.…] " tag; other exceptions' text unchanged.
inline std::string json_problem(const std::exception& e) {
  std::string text = e.what();
  if (text.rfind("[json.exception.", 0) == 0)
    if (const auto end = text.find("] "); end != std::string::npos) text.erase(0, end + 2);
  return text;
}

}  // namespace omnitwin::media
