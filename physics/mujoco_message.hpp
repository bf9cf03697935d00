// physics layer — MuJoCo's error text as one line.
//
// mj_loadXML writes its error over several lines ("XML Error: …\nElement 'x', line 12\n"). Every
// message of ours is one line naming the file and the place (DESIGN.md §9), so the loaders
// join MuJoCo's lines with "; " before they put the text into theirs.
#pragma once

#include <string>

namespace omnitwin::physics {

// `err` with each run of line breaks (and the spaces around it) turned into "; " (a space
// after a ':'), and no leading or trailing space. Not real-time safe (allocates).
inline std::string one_line(const char* err) {
  std::string out;
  bool pending_break = false;
  for (const char* c = err; c != nullptr && *c != '\0'; ++c) {
    if (*c == '\n' || *c == '\r') {
      while (!out.empty() && out.back() == ' ') out.pop_back();
      pending_break = !out.empty();
      continue;
    }
    if (pending_break) {
      if (*c == ' ' || *c == '\t') continue;
      out += out.back() == ':' ? " " : "; ";  // "error 14:\nError=…" reads as one clause
      pending_break = false;
    }
    out += *c;
  }
  while (!out.empty() && (out.back() == ' ' || out.back() == '\t')) out.pop_back();
  return out;
}

}  // namespace omnitwin::physics
