// twin layer — the run directory as a whole: one run per directory, and what it holds.
//
// A run directory holds one run only. `omnitwin run` (and each scenario of `check`) prepares
// it before the first record: a missing or empty directory is used as it is; one that holds
// an earlier run (it has the marker file `.omnitwin-run`, or a `run.json`) is cleared first,
// so nothing of the earlier run (its metrics, capture or video) can sit beside the new
// records; any other non-empty directory is refused, because it is not ours to clear.
// After the run, the inventory says which records are missing or left partial (under their
// temporary `.NAME.part` name), so a failed run can say exactly what it did not write.
#pragma once

#include <string>
#include <vector>

namespace omnitwin::twin {

// The marker a prepared run directory holds (the run's pid and start time, for people).
inline constexpr const char* kRunMarker = ".omnitwin-run";

// Makes `dir` ready for a new run: created if missing, cleared when it holds an earlier run.
// Returns "" or why it cannot be used (a non-empty directory that holds no run, a file in
// the way, no permission): bad input, the caller's exit code 2. Not real-time safe.
std::string prepare_run_directory(const std::string& dir);

struct RecordInventory {
  std::vector<std::string> missing;  // expected under their final name, absent
  std::vector<std::string> partial;  // present only as ".NAME.part"
};

// Checks `dir` for each of `expected` (file names relative to dir).
RecordInventory take_inventory(const std::string& dir, const std::vector<std::string>& expected);

}  // namespace omnitwin::twin
