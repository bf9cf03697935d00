// twin layer — the process table from /proc; see process_tree.hpp.
#include "twin/process_tree.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>

namespace omnitwin::twin {

namespace fs = std::filesystem;

std::optional<ProcessEntry> process_entry(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string stat;
  if (!std::getline(f, stat)) return std::nullopt;
  // The command name may hold spaces and parentheses: the fields start after the last ')'.
  const auto close = stat.rfind(')');
  if (close == std::string::npos || close + 2 >= stat.size()) return std::nullopt;
  std::istringstream rest(stat.substr(close + 2));
  ProcessEntry p;
  p.pid = pid;
  rest >> p.state >> p.ppid;
  std::string skip;
  for (int field = 5; field < 22 && rest; ++field) {  // pgrp … itrealvalue
    rest >> skip;
    if ((field == 14 || field == 15) && rest) p.cpu += std::stoull(skip);  // utime, stime
  }
  rest >> p.start;
  return p;
}

std::vector<ProcessEntry> process_table() {
  std::vector<ProcessEntry> all;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator("/proc", ec)) {
    const std::string name = e.path().filename().string();
    if (name.empty() || name.find_first_not_of("0123456789") != std::string::npos) continue;
    if (const auto p = process_entry(static_cast<pid_t>(std::stol(name)))) all.push_back(*p);
  }
  return all;
}

std::vector<ProcessEntry> descendants_of(pid_t root, const std::vector<ProcessEntry>& all) {
  std::vector<ProcessEntry> found{ProcessEntry{root, 0, 0, 0}};
  for (std::size_t k = 0; k < found.size(); ++k)
    for (const ProcessEntry& p : all)
      if (p.ppid == found[k].pid && p.state != 'Z') found.push_back(p);
  found.erase(found.begin());
  return found;
}

bool same_process(const ProcessEntry& a, const ProcessEntry& b) { return a.pid == b.pid && a.start == b.start; }

bool alive_in(const ProcessEntry& p, const std::vector<ProcessEntry>& all) {
  return std::any_of(all.begin(), all.end(), [&](const ProcessEntry& q) { return same_process(p, q) && q.state != 'Z'; });
}

}  // namespace omnitwin::twin
