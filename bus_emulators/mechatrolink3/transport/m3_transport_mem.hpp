// bus_emulators/mechatrolink3/transport — in-process M-III transport (`mem:NAME`), for tests and
// for running our C1 master and the emulated slaves inside one process over the transport
// interface (the line model, m3_line, is the in-process path with wire timing; this one has
// none: a frame is there as soon as it is sent).
//
// The two transports opened with the same NAME, one per role, form a pair: a frame the master
// sends is queued for the slaves end and a response for the master, like the two ends of a
// cable. A second transport of a role already open under NAME is refused (TransportError); a
// frame sent while the other end is not open is lost like a frame on an unplugged cable (send()
// still succeeds). Each end has a bounded queue of `capacity` frames in memory allocated when
// it is opened (send() and receive() allocate nothing); a frame arriving at a full queue is
// dropped and counted in the receiver's dropped_overflow, as a NIC drops frames its ring has
// no room for. Each end has an eventfd, readable while its queue is not empty.
//
// Thread-safe: the two ends may run on different threads (a master thread, a slaves thread).
#pragma once

#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"

#include <cstddef>
#include <memory>
#include <mutex>
#include <vector>

namespace omnitwin::m3 {

class MemTransport final : public M3Transport {
 public:
  static constexpr std::size_t kDefaultCapacity = 256;  // a cycle of 62 slaves with retries
  // Throws TransportError when NAME is empty, the role is already open under NAME, or
  // capacity is 0.
  MemTransport(std::string name, Role role, std::size_t capacity = kDefaultCapacity);
  ~MemTransport() override;

  bool send(std::span<const std::uint8_t> frame) override;
  int receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) override;
  int fd() const override { return event_fd_; }
  std::string spec() const override { return "mem:" + name_; }
  std::string describe() const override;
  Stats stats() const override;

  std::size_t pending() const;  // frames waiting in this end's queue
  std::size_t capacity() const { return capacity_; }

  struct Pair;  // implementation detail: the two ends of one NAME

 private:
  void deliver(std::span<const std::uint8_t> frame);  // called by the other end, pair lock held
  void attach();                                      // joins (or starts) the pair of name_
  int take_queued(std::span<std::uint8_t> buf);       // the next good frame queued, or 0

  std::string name_;
  Role role_;
  std::size_t capacity_;
  int event_fd_ = -1;
  std::shared_ptr<Pair> pair_;
  mutable std::mutex mu_;              // guards the queue and stats_
  std::vector<std::uint8_t> slots_;    // capacity_ slots of kMaxFrame bytes
  std::vector<std::uint8_t> sizes_;    // bytes used per slot
  std::size_t head_ = 0;               // oldest queued slot
  std::size_t count_ = 0;              // queued frames
  Stats stats_;
};

}  // namespace omnitwin::m3
