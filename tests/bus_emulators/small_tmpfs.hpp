// Test support — a full disk on demand: a tmpfs of a few KiB mounted on a fresh directory, so
// that writes fail with ENOSPC as on a real disk that fills up. Needs root (CAP_SYS_ADMIN);
// where mounting is not allowed, mounted() is false and skip_reason() says why (tests skip).
// Unmounted and removed when the object goes, also when the test fails.
#pragma once

#include <stdlib.h>
#include <sys/mount.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>

namespace omnitwin::testing {

class SmallTmpfs {
 public:
  // size: tmpfs's size option, e.g. "64k".
  explicit SmallTmpfs(const std::string& size = "64k") {
    std::string templ = std::filesystem::temp_directory_path().string() + "/omnitwin-fulldisk-XXXXXX";
    if (::mkdtemp(templ.data()) == nullptr) {
      reason_ = std::string("mkdtemp: ") + std::strerror(errno);
      return;
    }
    dir_ = templ;
    if (::geteuid() != 0) {
      reason_ = "not root: cannot mount a small tmpfs to simulate a full disk";
      return;
    }
    const std::string opts = "size=" + size + ",mode=0700";
    if (::mount("tmpfs", dir_.c_str(), "tmpfs", 0, opts.c_str()) != 0) {
      reason_ = std::string("mount -t tmpfs -o ") + opts + " failed: " + std::strerror(errno);
      return;
    }
    mounted_ = true;
  }
  ~SmallTmpfs() {
    if (mounted_) ::umount2(dir_.c_str(), MNT_DETACH);
    if (!dir_.empty()) ::rmdir(dir_.c_str());
  }
  SmallTmpfs(const SmallTmpfs&) = delete;
  SmallTmpfs& operator=(const SmallTmpfs&) = delete;

  bool mounted() const { return mounted_; }
  // Remounts it read-only (an unwritable output place: EROFS, which root cannot bypass as it
  // bypasses permission bits). false when that fails.
  bool make_read_only() {
    return mounted_ && ::mount(nullptr, dir_.c_str(), nullptr, MS_REMOUNT | MS_RDONLY, nullptr) == 0;
  }
  const std::string& skip_reason() const { return reason_; }
  std::filesystem::path operator/(const std::string& name) const { return std::filesystem::path(dir_) / name; }

 private:
  std::string dir_;
  std::string reason_;
  bool mounted_ = false;
};

}  // namespace omnitwin::testing
