// bus_emulators — the in-process transport of the frame buses (`mem:NAME`: EtherCAT,
// MECHATROLINK-III), for tests and for running a master and the emulated slaves inside one
// process. One template, so both buses share one implementation; each bus gives its traits:
// its transport interface (Base, with its Stats), Role, TransportError, the largest and
// smallest frame, and the framing check its receivers apply.
//
// The two transports opened with the same NAME, one per role, form a pair: a frame the master
// sends is queued for the slaves end and the reply for the master, like the two ends of a
// cable. A second transport of a role already open under NAME is refused (TransportError); a
// frame sent while the other end is not open is lost like a frame on an unplugged cable
// (send() still succeeds). Each end has a bounded queue of `capacity` frames in memory
// allocated when it is opened (send() and receive() allocate nothing); a frame arriving at a
// full queue is dropped and counted in the receiver's dropped_overflow, as a NIC drops frames
// its ring has no room for. receive() hands out what the bus's check accepts and counts the
// rest (dropped_foreign, dropped_malformed). Each end has an eventfd, readable while its
// queue is not empty. Each bus has its own registry of names (one per instantiation).
//
// Thread-safe: the two ends may run on different threads (a master thread, a slaves thread).
// Header-only.
#pragma once

#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "bus_emulators/readable_waiter.hpp"

namespace omnitwin::bus_emulators {

// What a bus's framing check says of received bytes.
enum class FrameVerdict : std::uint8_t { ok, foreign, malformed };

template <class Traits>
class MemPairTransport final : public Traits::Base {
 public:
  using Role = typename Traits::Role;
  using Error = typename Traits::Error;
  using Stats = typename Traits::Base::Stats;

  // Throws Error when NAME is empty, the role is already open under NAME, or capacity is 0.
  MemPairTransport(std::string name, Role role, std::size_t capacity = Traits::kDefaultCapacity)
      : name_(std::move(name)), role_(role), capacity_(capacity) {
    if (name_.empty()) throw Error("mem: empty pair name");
    if (capacity_ == 0) throw Error("mem:" + name_ + ": queue capacity must be at least 1");
    slots_.resize(capacity_ * Traits::kMaxFrame);
    sizes_.resize(capacity_);
    attach();
  }
  ~MemPairTransport() {
    {
      std::lock_guard lock(pair_->mu);
      pair_->ends[Traits::end_of(role_)] = nullptr;
    }
    ::close(event_fd_);
  }
  MemPairTransport(const MemPairTransport&) = delete;
  MemPairTransport& operator=(const MemPairTransport&) = delete;

  // A frame to the other end: false (send_errors) when its size is outside the bus's frames.
  bool send(std::span<const std::uint8_t> frame) {
    if (frame.size() < Traits::kMinFrame || frame.size() > Traits::kMaxFrame) {
      std::lock_guard lock(mu_);
      ++stats_.send_errors;
      return false;
    }
    {
      std::lock_guard plock(pair_->mu);
      if (MemPairTransport* peer = pair_->ends[1 - Traits::end_of(role_)]) peer->deliver(frame);
    }
    std::lock_guard lock(mu_);
    ++stats_.sent;
    return true;
  }
  // The next frame the bus's check accepts, waiting up to timeout: its size, 0 on timeout,
  // -1 when waiting failed (receive_errors).
  int receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) {
    ReadableWaiter waiter(timeout);
    for (;;) {
      {
        std::lock_guard lock(mu_);
        if (const int n = take_queued(buf); n > 0) return n;
      }
      const int w = waiter.wait(event_fd_);
      if (w == 0) return 0;
      if (w < 0) {
        std::lock_guard lock(mu_);
        ++stats_.receive_errors;
        return -1;
      }
    }
  }
  int fd() const { return event_fd_; }
  std::string spec() const { return "mem:" + name_; }
  std::string describe() const { return spec() + " (" + Traits::role_name(role_) + ")"; }
  Stats stats() const {
    std::lock_guard lock(mu_);
    return stats_;
  }
  std::size_t pending() const {  // frames waiting in this end's queue
    std::lock_guard lock(mu_);
    return count_;
  }
  std::size_t capacity() const { return capacity_; }

 private:
  struct Pair {
    std::mutex mu;                                   // guards ends; taken before an end's mu_
    MemPairTransport* ends[2] = {nullptr, nullptr};  // indexed by Traits::end_of(role)
  };
  // The pairs by name, while any end is open (the name is the only way two ends meet).
  struct Registry {
    std::mutex mu;
    std::map<std::string, std::weak_ptr<Pair>, std::less<>> pairs;
  };
  static Registry& registry() {
    static Registry r;
    return r;
  }

  // Joins (or starts) the pair of name_.
  void attach() {
    Registry& reg = registry();
    std::lock_guard lock(reg.mu);
    for (auto it = reg.pairs.begin(); it != reg.pairs.end();) {  // forget pairs no end holds
      if (it->second.expired()) it = reg.pairs.erase(it);
      else ++it;
    }
    auto& weak = reg.pairs[name_];
    pair_ = weak.lock();
    if (!pair_) {
      pair_ = std::make_shared<Pair>();
      weak = pair_;
    }
    std::lock_guard plock(pair_->mu);
    if (pair_->ends[Traits::end_of(role_)] != nullptr)
      throw Error("mem:" + name_ + ": a " + Traits::role_name(role_) + " end is already open under this name");
    event_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (event_fd_ < 0) throw Error("mem:" + name_ + ": eventfd: " + std::strerror(errno));
    pair_->ends[Traits::end_of(role_)] = this;
  }

  // Called by the other end with the pair lock held.
  void deliver(std::span<const std::uint8_t> frame) {
    std::lock_guard lock(mu_);
    if (count_ == capacity_) {
      ++stats_.dropped_overflow;
      return;
    }
    const std::size_t slot = (head_ + count_) % capacity_;
    std::memcpy(slots_.data() + slot * Traits::kMaxFrame, frame.data(), frame.size());
    sizes_[slot] = frame.size();
    if (count_++ == 0) {
      const std::uint64_t one = 1;
      [[maybe_unused]] const ssize_t n = ::write(event_fd_, &one, sizeof one);
    }
  }

  // Takes queued frames until one passes the bus's check (copied to buf) or none is left;
  // mu_ held by the caller. Its size, or 0.
  int take_queued(std::span<std::uint8_t> buf) {
    while (count_ > 0) {
      const std::size_t slot = head_;
      const std::size_t n = sizes_[slot];
      head_ = (head_ + 1) % capacity_;
      if (--count_ == 0) {
        std::uint64_t v = 0;
        [[maybe_unused]] const ssize_t r = ::read(event_fd_, &v, sizeof v);
      }
      const std::size_t got = std::min(n, buf.size());
      std::memcpy(buf.data(), slots_.data() + slot * Traits::kMaxFrame, got);
      std::size_t size = 0;
      switch (Traits::check(buf.data(), got, size)) {
        case FrameVerdict::ok: ++stats_.received; return static_cast<int>(size);
        case FrameVerdict::foreign: ++stats_.dropped_foreign; break;
        case FrameVerdict::malformed: ++stats_.dropped_malformed; break;
      }
    }
    return 0;
  }

  std::string name_;
  Role role_;
  std::size_t capacity_;
  int event_fd_ = -1;
  std::shared_ptr<Pair> pair_;
  mutable std::mutex mu_;             // guards the queue and stats_
  std::vector<std::uint8_t> slots_;   // capacity_ slots of kMaxFrame bytes
  std::vector<std::size_t> sizes_;    // bytes used per slot
  std::size_t head_ = 0;              // oldest queued slot
  std::size_t count_ = 0;             // queued frames
  Stats stats_;
};

}  // namespace omnitwin::bus_emulators
