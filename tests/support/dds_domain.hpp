// Test support — DDS domain ids that no other test process on this machine holds.
//
// ctest -j runs DDS tests in parallel processes on the same loopback interface; two that
// share a domain hear each other's samples and run events. A domain picked from the pid
// (pid mod 230) collided in CI: a reader got another process's start event first. Here a
// process owns a domain while it holds an exclusive flock on /tmp/omnitwin-dds-domain/<id>;
// the kernel drops the lock when the process ends, also when it crashes, so nothing needs
// cleaning up. Ids 1..232 (Cyclone's domain ids end at 232; 0 is the default, left to users).
#pragma once

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

namespace omnitwin::testing {

// Where the lock files are: one per domain id, named by the id.
inline constexpr char kDdsDomainLockDir[] = "/tmp/omnitwin-dds-domain";

// The k-th domain this process owns (k = 0, 1, ...): the same k gives the same id for the
// life of the process; different k give different ids. Thread-safe. Throws when every id is
// held by other processes.
inline int owned_dds_domain(int k = 0) {
  constexpr int kFirst = 1, kLast = 232;
  static std::mutex mutex;
  static std::vector<int> owned;  // ids, in the order of k; their lock fds stay open
  const std::lock_guard<std::mutex> lock(mutex);
  const std::string dir = kDdsDomainLockDir;
  if (::mkdir(dir.c_str(), 0777) == 0) ::chmod(dir.c_str(), 01777);  // like /tmp; exists: fine
  // Start the scan at a pid-based id so that concurrent processes rarely race for one file.
  int next = kFirst + static_cast<int>(::getpid() % (kLast - kFirst + 1));
  for (int tries = 0; static_cast<int>(owned.size()) <= k; ++tries) {
    if (tries > kLast - kFirst) throw std::runtime_error("no free DDS domain id in " + dir);
    const int id = next;
    next = next == kLast ? kFirst : next + 1;
    if (std::find(owned.begin(), owned.end(), id) != owned.end()) continue;
    const std::string path = dir + "/" + std::to_string(id);
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0) continue;
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      ::close(fd);
      continue;
    }
    owned.push_back(id);  // fd deliberately kept open: the lock is the ownership
    tries = -1;
  }
  return owned[static_cast<std::size_t>(k)];
}

}  // namespace omnitwin::testing
