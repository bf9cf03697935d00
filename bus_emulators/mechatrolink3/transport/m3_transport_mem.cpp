// bus_emulators/mechatrolink3/transport — in-process M-III transport; see m3_transport_mem.hpp.
#include "bus_emulators/mechatrolink3/transport/m3_transport_mem.hpp"

#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>

namespace omnitwin::m3 {

struct MemTransport::Pair {
  std::mutex mu;                                  // guards ends; taken before an end's mu_
  MemTransport* ends[2] = {nullptr, nullptr};     // indexed by Role
};

namespace {

// The pairs by name, while any end is open. One registry per process (the name is the only
// way two ends find each other).
struct Registry {
  std::mutex mu;
  std::map<std::string, std::weak_ptr<MemTransport::Pair>, std::less<>> pairs;
};
Registry& registry() {
  static Registry r;
  return r;
}

std::size_t index_of(Role r) { return r == Role::master ? 0 : 1; }

}  // namespace

MemTransport::MemTransport(std::string name, Role role, std::size_t capacity)
    : name_(std::move(name)), role_(role), capacity_(capacity) {
  if (name_.empty()) throw TransportError("mem: empty pair name");
  if (capacity_ == 0) throw TransportError("mem:" + name_ + ": queue capacity must be at least 1");
  slots_.resize(capacity_ * kMaxFrame);
  sizes_.resize(capacity_);
  attach();
}

void MemTransport::attach() {
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
  if (pair_->ends[index_of(role_)] != nullptr)
    throw TransportError("mem:" + name_ + ": a " + to_string(role_) + " end is already open under this name");
  event_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (event_fd_ < 0) throw TransportError("mem:" + name_ + ": eventfd: " + std::strerror(errno));
  pair_->ends[index_of(role_)] = this;
}

MemTransport::~MemTransport() {
  {
    std::lock_guard lock(pair_->mu);
    pair_->ends[index_of(role_)] = nullptr;
  }
  ::close(event_fd_);
}

std::string MemTransport::describe() const { return spec() + " (" + to_string(role_) + ")"; }

void MemTransport::deliver(std::span<const std::uint8_t> frame) {
  std::lock_guard lock(mu_);
  if (count_ == capacity_) {
    ++stats_.dropped_overflow;
    return;
  }
  const std::size_t slot = (head_ + count_) % capacity_;
  std::memcpy(slots_.data() + slot * kMaxFrame, frame.data(), frame.size());
  sizes_[slot] = static_cast<std::uint8_t>(frame.size());
  if (count_++ == 0) {
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t n = ::write(event_fd_, &one, sizeof one);
  }
}

bool MemTransport::send(std::span<const std::uint8_t> frame) {
  if (frame.size() < kMinFrame || frame.size() > kMaxFrame) {
    std::lock_guard lock(mu_);
    ++stats_.send_errors;
    return false;
  }
  {
    std::lock_guard plock(pair_->mu);
    if (MemTransport* peer = pair_->ends[1 - index_of(role_)]) peer->deliver(frame);
  }
  std::lock_guard lock(mu_);
  ++stats_.sent;
  return true;
}

// Takes queued frames until a good one (copied to buf) or none is left; mu_ held by the caller.
int MemTransport::take_queued(std::span<std::uint8_t> buf) {
  while (count_ > 0) {
    const std::size_t slot = head_;
    const std::size_t n = sizes_[slot];
    head_ = (head_ + 1) % capacity_;
    if (--count_ == 0) {
      std::uint64_t v = 0;
      [[maybe_unused]] const ssize_t r = ::read(event_fd_, &v, sizeof v);
    }
    const std::size_t got = std::min(n, buf.size());
    std::memcpy(buf.data(), slots_.data() + slot * kMaxFrame, got);
    std::size_t size = 0;
    if (check_frame(buf.data(), got, size) == FrameCheck::ok) {
      ++stats_.received;
      return static_cast<int>(size);
    }
    ++stats_.dropped_malformed;
  }
  return 0;
}

int MemTransport::receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) {
  detail::ReadableWaiter waiter(timeout);
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

M3Transport::Stats MemTransport::stats() const {
  std::lock_guard lock(mu_);
  return stats_;
}

std::size_t MemTransport::pending() const {
  std::lock_guard lock(mu_);
  return count_;
}

}  // namespace omnitwin::m3
