// twin layer — a master program of the user's (`master.command`, `--master-cmd`): its command
// line split into words and whether its program can be started. Kept apart from the
// virtual-time pacer (master_vtime) so that the scenario reader, which checks the program
// before a run begins, needs nothing else. Not real-time safe (strings, the filesystem).
#pragma once

#include <string>
#include <vector>

namespace omnitwin::twin {

// A command line split into words as a POSIX shell would (quotes, backslashes; no expansion
// beyond that). Throws std::invalid_argument for an unbalanced quote.
std::vector<std::string> split_command(const std::string& command);

// Where `program` runs from: itself when it names a folder, else the first executable of that
// name on PATH ("" when none).
std::string program_path(const std::string& program);

// Why `program` cannot be started ("not found on PATH", "no such file", "not an executable
// file"), or "" when it can.
std::string program_problem(const std::string& program);

}  // namespace omnitwin::twin
