// bus_emulators/can — in-process CAN transport; see transport_mem.hpp.
#include "bus_emulators/can/transport_mem.hpp"

#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>
#include <vector>

namespace omnitwin::can {

struct MemTransport::Hub {
  std::mutex mu;  // guards members; taken before any member's mu_
  std::vector<MemTransport*> members;
};

namespace {

std::mutex g_registry_mu;
std::map<std::string, std::weak_ptr<MemTransport::Hub>, std::less<>> g_registry;

std::shared_ptr<MemTransport::Hub> join_hub(const std::string& name) {
  std::lock_guard lock(g_registry_mu);
  auto& weak = g_registry[name];
  auto hub = weak.lock();
  if (!hub) {
    hub = std::make_shared<MemTransport::Hub>();
    weak = hub;
  }
  // Forget hubs whose members are all gone.
  for (auto it = g_registry.begin(); it != g_registry.end();) {
    if (it->second.expired()) it = g_registry.erase(it);
    else ++it;
  }
  return hub;
}

}  // namespace

MemTransport::MemTransport(std::string name, std::size_t queue_capacity)
    : name_(std::move(name)), capacity_(std::max<std::size_t>(1, queue_capacity)) {
  if (name_.empty()) throw TransportError("mem transport: empty bus name");
  event_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (event_fd_ < 0) throw TransportError(std::string("mem transport: eventfd: ") + std::strerror(errno));
  hub_ = join_hub(name_);
  std::lock_guard lock(hub_->mu);
  hub_->members.push_back(this);
}

MemTransport::~MemTransport() {
  {
    std::lock_guard lock(hub_->mu);
    auto& m = hub_->members;
    m.erase(std::remove(m.begin(), m.end(), this), m.end());
  }
  if (event_fd_ >= 0) ::close(event_fd_);
}

void MemTransport::deliver(const TimedFrame& tf) {
  std::lock_guard lock(mu_);
  if (queue_.size() >= capacity_) {
    ++stats_.rx_dropped;
    return;
  }
  const bool was_empty = queue_.empty();
  queue_.push_back(tf);
  if (was_empty) {
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t n = ::write(event_fd_, &one, sizeof one);
  }
}

bool MemTransport::send(const Frame& f, std::int64_t timestamp_ns) {
  if (!f.valid()) {
    std::lock_guard lock(mu_);
    ++stats_.invalid_tx;
    return false;
  }
  {
    std::lock_guard lock(hub_->mu);
    const TimedFrame tf{f, timestamp_ns, reinterpret_cast<std::uintptr_t>(this)};
    for (MemTransport* m : hub_->members)
      if (m != this) m->deliver(tf);
  }
  std::lock_guard lock(mu_);
  ++stats_.frames_tx;
  return true;
}

std::optional<TimedFrame> MemTransport::receive() {
  std::lock_guard lock(mu_);
  if (queue_.empty()) return std::nullopt;
  TimedFrame tf = queue_.front();
  queue_.pop_front();
  ++stats_.frames_rx;
  if (queue_.empty()) {
    std::uint64_t v = 0;
    [[maybe_unused]] const ssize_t n = ::read(event_fd_, &v, sizeof v);
  }
  return tf;
}

TransportStats MemTransport::stats() const {
  std::lock_guard lock(mu_);
  return stats_;
}

std::size_t MemTransport::pending() const {
  std::lock_guard lock(mu_);
  return queue_.size();
}

}  // namespace omnitwin::can
