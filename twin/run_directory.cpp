// twin layer — one run per run directory; see run_directory.hpp.
#include "twin/run_directory.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <filesystem>
#include <system_error>

#include "twin/records.hpp"

namespace omnitwin::twin {
namespace {

namespace fs = std::filesystem;

bool holds_a_run(const fs::path& dir) {
  std::error_code ec;
  return fs::exists(dir / kRunMarker, ec) || fs::exists(dir / "run.json", ec);
}

// Removes everything inside `dir` (not dir itself). Returns "" or the first failure.
std::string clear(const fs::path& dir) {
  std::error_code ec;
  for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
    fs::remove_all(e.path(), ec);
    if (ec) return fmt::format("cannot clear the earlier run's {}: {}", e.path().string(), ec.message());
  }
  return ec ? fmt::format("cannot list {}: {}", dir.string(), ec.message()) : "";
}

}  // namespace

std::string prepare_run_directory(const std::string& dir_name) {
  const fs::path dir(dir_name);
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    return fmt::format("run directory {} is a file, not a directory", dir_name);
  if (fs::exists(dir, ec) && !fs::is_empty(dir, ec)) {
    // Someone else's files are never ours to delete.
    if (!holds_a_run(dir))
      return fmt::format("run directory {} is not empty and holds no earlier run; choose another --out", dir_name);
    if (std::string why = clear(dir); !why.empty()) return why;
  }
  fs::create_directories(dir, ec);
  if (ec) return fmt::format("cannot create run directory {}: {}", dir_name, ec.message());
  try {
    write_text_atomic((dir / kRunMarker).string(), fmt::format("omnitwin run, pid {}\n", ::getpid()));
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

RecordInventory take_inventory(const std::string& dir, const std::vector<std::string>& expected) {
  RecordInventory inv;
  std::error_code ec;
  for (const std::string& name : expected) {
    if (fs::exists(fs::path(dir) / name, ec)) continue;
    if (fs::exists(fs::path(dir) / ("." + name + ".part"), ec))
      inv.partial.push_back(name);
    else
      inv.missing.push_back(name);
  }
  return inv;
}

}  // namespace omnitwin::twin
