// bus_emulators/can — in-process CAN transport (`mem:NAME`), for unit tests and for running
// several emulated nodes inside one process.
//
// Every MemTransport opened with the same NAME joins one hub; a frame sent by one is queued
// to every other member (not to the sender). Each member has a bounded queue (overflow is
// counted in rx_dropped) and an eventfd that is readable while its queue is not empty. The
// hub lives while any member does. Thread-safe: send and receive may run on different threads.
#pragma once

#include "bus_emulators/can/transport.hpp"

#include <atomic>
#include <cstddef>
#include <deque>
#include <memory>
#include <mutex>

namespace omnitwin::can {

class MemTransport final : public Transport {
 public:
  static constexpr std::size_t kDefaultQueueCapacity = 4096;
  explicit MemTransport(std::string name, std::size_t queue_capacity = kDefaultQueueCapacity);
  ~MemTransport() override;

  bool send(const Frame& f, std::int64_t timestamp_ns = 0) override;
  std::optional<TimedFrame> receive() override;
  int poll_fd() const override { return event_fd_; }
  TransportStats stats() const override;
  std::string spec() const override { return "mem:" + name_; }

  std::size_t pending() const;  // frames waiting in this member's queue

  struct Hub;  // implementation detail, shared by the members of one bus

 private:
  friend struct Hub;
  void deliver(const TimedFrame& tf);  // called by the hub with the hub's lock held

  std::string name_;
  std::size_t capacity_;
  int event_fd_ = -1;
  std::shared_ptr<Hub> hub_;
  mutable std::mutex mu_;  // guards queue_ and stats_
  std::deque<TimedFrame> queue_;
  TransportStats stats_;
};

}  // namespace omnitwin::can
