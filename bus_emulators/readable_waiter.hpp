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
#include <cstdint>
#include <cstring>
#include <chrono>
#include <ctime>

namespace omnitwin::bus_emulators {

// The kernel's receive time of a datagram (SO_TIMESTAMPNS, CLOCK_REALTIME): how long before
// recvmsg() returned it the frame had arrived. A process that was busy (or descheduled) when
// frames came learns when they came, as the station on a real wire would have seen them.
// enable() once on the socket; attach() to each msghdr before recvmsg(); age_ns() after.
// The kernel turns its receive stamping on from a work item shortly after the first socket
// asks (net_enable_timestamp): frames in the first moments after enable() are stamped when
// recvmsg() takes them (age about 0) — a twin opens its transport long before a run starts.
// Real-time safe.
struct ReceiveStamp {
  static bool enable(int fd) noexcept {
    const int one = 1;
    return ::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one) == 0;
  }
  void attach(msghdr& msg) noexcept {
    msg.msg_control = control;
    msg.msg_controllen = sizeof control;
  }
  // How long ago the kernel received the message msg holds [ns] (≥ 0), or -1 without a stamp.
  static std::int64_t age_ns(msghdr& msg) noexcept {
    for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c; c = CMSG_NXTHDR(&msg, c)) {
      if (c->cmsg_level != SOL_SOCKET || c->cmsg_type != SCM_TIMESTAMPNS) continue;
      timespec at{}, now{};
      std::memcpy(&at, CMSG_DATA(c), sizeof at);
      if (::clock_gettime(CLOCK_REALTIME, &now) != 0) return -1;
      const std::int64_t age = (now.tv_sec - at.tv_sec) * 1'000'000'000LL + (now.tv_nsec - at.tv_nsec);
      return age > 0 ? age : 0;
    }
    return -1;
  }
  alignas(cmsghdr) unsigned char control[CMSG_SPACE(sizeof(timespec))]{};
};

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
