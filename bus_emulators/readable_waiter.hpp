// bus_emulators — the waiting part of every bus transport's receive(): poll a descriptor
// until it is readable or one deadline passes, and recvmsg() without blocking while waiting
// so. Shared by the EtherCAT and MECHATROLINK-III transports (their receive() loops differ,
// the waiting does not). Header-only.
//
// The deadline is taken when the first wait begins, so a receive that finds a frame at once
// never reads the clock; EINTR resumes the wait for the time left, never cutting it short or
// extending it. Real-time safe: no allocation, no throw, a bounded number of system calls
// per wake-up.
#pragma once

#include <poll.h>
#include <sys/socket.h>

#include <cerrno>
#include <chrono>
#include <ctime>

namespace omnitwin::bus_emulators {

class ReadableWaiter {
 public:
  explicit ReadableWaiter(std::chrono::nanoseconds timeout) : timeout_(timeout) {}

  // Waits (ppoll) until fd is readable or the deadline passes: 1 readable, 0 timed out,
  // -1 error (errno set).
  int wait(int fd) noexcept {
    if (timeout_.count() <= 0) return 0;
    if (!started_) {
      started_ = true;
      deadline_ = std::chrono::steady_clock::now() + timeout_;
    }
    for (;;) {
      const auto left = std::chrono::duration_cast<std::chrono::nanoseconds>(deadline_ - std::chrono::steady_clock::now());
      if (left.count() <= 0) return 0;
      timespec ts{static_cast<time_t>(left.count() / 1'000'000'000), static_cast<long>(left.count() % 1'000'000'000)};
      pollfd p{fd, POLLIN, 0};
      const int r = ::ppoll(&p, 1, &ts, nullptr);
      if (r > 0) return 1;
      if (r == 0) return 0;
      if (errno != EINTR) return -1;
    }
  }

  // recvmsg(MSG_DONTWAIT | MSG_TRUNC) on fd, waiting as wait() does while nothing is there and
  // retrying EINTR: the message's real length (even when longer than msg's buffers),
  // kTimedOut when the deadline passed first, or -1 (errno set).
  static constexpr long kTimedOut = -2;
  long receive(int fd, msghdr& msg) noexcept {
    for (;;) {
      const ssize_t n = ::recvmsg(fd, &msg, MSG_DONTWAIT | MSG_TRUNC);
      if (n >= 0) return static_cast<long>(n);
      if (errno == EINTR) continue;
      if (errno != EAGAIN && errno != EWOULDBLOCK) return -1;
      const int w = wait(fd);
      if (w == 0) return kTimedOut;
      if (w < 0) return -1;
    }
  }

 private:
  std::chrono::nanoseconds timeout_;
  std::chrono::steady_clock::time_point deadline_{};
  bool started_ = false;
};

}  // namespace omnitwin::bus_emulators
