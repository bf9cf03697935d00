// controller layer — helpers shared by omni-master and omni-pc; see program_support.hpp.
#include "controller/program_support.hpp"

#include <sched.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/signalfd.h>
#include <unistd.h>

#include <fmt/format.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <cstring>

namespace omnitwin::controller {

std::string normalize_iface(const std::string& iface) {
  return iface.find(':') == std::string::npos ? "socketcan:" + iface : iface;
}

int open_signal_fd() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  ::sigprocmask(SIG_BLOCK, &set, nullptr);
  return ::signalfd(-1, &set, SFD_CLOEXEC | SFD_NONBLOCK);
}

bool watch_parent() {
  const char* v = std::getenv("OMNITWIN_TWIN_PID");
  if (!v || !*v) return true;
  char* end = nullptr;
  const long twin = std::strtol(v, &end, 10);
  if (*end != '\0' || twin <= 1) return true;
  if (::getppid() != static_cast<pid_t>(twin)) return ::kill(static_cast<pid_t>(twin), 0) == 0 || errno == EPERM;
  ::prctl(PR_SET_PDEATHSIG, SIGTERM);
  return ::getppid() == static_cast<pid_t>(twin);  // it may have ended just before the prctl
}

bool signalled(int sigfd) {
  signalfd_siginfo info{};
  return sigfd >= 0 && ::read(sigfd, &info, sizeof info) == static_cast<ssize_t>(sizeof info);
}

std::int64_t monotonic_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::int64_t realtime_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

timespec to_timespec(std::int64_t ns) {
  return timespec{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
}

void try_realtime(int priority) {
  sched_param sp{};
  sp.sched_priority = priority;
  if (::sched_setscheduler(0, SCHED_FIFO, &sp) != 0)
    spdlog::debug("SCHED_FIFO {} not permitted ({}); running with normal priority", priority, std::strerror(errno));
  if (::mlockall(MCL_CURRENT | MCL_FUTURE) != 0) spdlog::debug("mlockall not permitted ({})", std::strerror(errno));
}

bool write_stats_file(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  std::ofstream f(tmp);
  f << text << "\n";
  f.close();
  if (f && std::rename(tmp.c_str(), path.c_str()) == 0) return true;
  const int err = errno;
  std::remove(tmp.c_str());  // no stray PATH.tmp when the rename fails (found in review)
  spdlog::error("--stats {}: cannot write ({})", path, std::strerror(err));
  return false;
}

std::string time_value_problem(const std::string& text, double max) {
  const char* begin = text.c_str();
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(begin, &end);
  if (text.empty() || end != begin + text.size()) return fmt::format("'{}' is not a number", text);
  if (!std::isfinite(v) || v < 0 || v > max) return fmt::format("{} is not in [0, {}]", text, max);
  return "";
}

}  // namespace omnitwin::controller
