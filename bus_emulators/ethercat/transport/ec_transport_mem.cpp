// bus_emulators/ethercat/transport — in-process EtherCAT transport; see ec_transport_mem.hpp.
#include "bus_emulators/ethercat/transport/ec_transport_mem.hpp"

#include "bus_emulators/ethercat/ec_frame.hpp"

#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>

namespace omnitwin::ethercat {

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
  slots_.resize(capacity_ * kMaxPdu);
  sizes_.resize(capacity_);
  {
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
}

MemTransport::~MemTransport() {
  {
    std::lock_guard lock(pair_->mu);
    pair_->ends[index_of(role_)] = nullptr;
  }
  ::close(event_fd_);
}

std::string MemTransport::describe() const {
  return "mem:" + name_ + " (" + to_string(role_) + ")";
}

void MemTransport::deliver(std::span<const std::uint8_t> pdu) {
  std::lock_guard lock(mu_);
  if (count_ == capacity_) {
    ++stats_.dropped_overflow;
    return;
  }
  const std::size_t slot = (head_ + count_) % capacity_;
  std::memcpy(slots_.data() + slot * kMaxPdu, pdu.data(), pdu.size());
  sizes_[slot] = static_cast<std::uint16_t>(pdu.size());
  if (count_++ == 0) {
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t n = ::write(event_fd_, &one, sizeof one);
  }
}

bool MemTransport::send(std::span<const std::uint8_t> pdu) {
  if (pdu.size() > kMaxPdu) {
    std::lock_guard lock(mu_);
    ++stats_.send_errors;
    return false;
  }
  {
    std::lock_guard plock(pair_->mu);
    if (MemTransport* peer = pair_->ends[1 - index_of(role_)]) peer->deliver(pdu);
  }
  std::lock_guard lock(mu_);
  ++stats_.sent;
  return true;
}

int MemTransport::receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) {
  detail::ReadableWaiter waiter(timeout);
  for (;;) {
    {
      std::lock_guard lock(mu_);
      while (count_ > 0) {
        const std::size_t slot = head_;
        const std::size_t n = sizes_[slot];
        head_ = (head_ + 1) % capacity_;
        if (--count_ == 0) {
          std::uint64_t v = 0;
          [[maybe_unused]] const ssize_t r = ::read(event_fd_, &v, sizeof v);
        }
        const std::size_t got = std::min(n, buf.size());
        std::memcpy(buf.data(), slots_.data() + slot * kMaxPdu, got);
        std::size_t size = 0;
        switch (check_pdu(buf.data(), got, size)) {
          case PduCheck::ok: ++stats_.received; return static_cast<int>(size);
          case PduCheck::foreign: ++stats_.dropped_foreign; break;
          case PduCheck::malformed: ++stats_.dropped_malformed; break;
        }
      }
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

EcTransport::Stats MemTransport::stats() const {
  std::lock_guard lock(mu_);
  return stats_;
}

std::size_t MemTransport::pending() const {
  std::lock_guard lock(mu_);
  return count_;
}

}  // namespace omnitwin::ethercat
