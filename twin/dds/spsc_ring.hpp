// twin/dds — a fixed-capacity single-producer/single-consumer ring of trivially copyable
// values: the hand-over from the run loop (producer, real-time) to the DDS publishing thread
// (consumer). Storage is allocated once at construction; push and pop never allocate, never
// lock and never block. Indices are monotonic 64-bit counters (no wrap-around in practice).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <type_traits>

namespace omnitwin::twin {

template <class T>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>, "the ring copies values bytewise");

 public:
  explicit SpscRing(std::size_t capacity)
      : capacity_(capacity > 0 ? capacity : 1), slots_(std::make_unique<T[]>(capacity_)) {}

  // Producer only. False when full (the value is not stored).
  bool push(const T& v) {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_.load(std::memory_order_acquire) >= capacity_) return false;
    slots_[head % capacity_] = v;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  // Consumer only. False when empty.
  bool pop(T& out) {
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_.load(std::memory_order_acquire)) return false;
    out = slots_[tail % capacity_];
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  bool empty() const {
    return tail_.load(std::memory_order_acquire) == head_.load(std::memory_order_acquire);
  }
  std::size_t capacity() const { return capacity_; }

 private:
  const std::size_t capacity_;
  std::unique_ptr<T[]> slots_;
  alignas(64) std::atomic<std::uint64_t> head_{0};  // next slot the producer writes
  alignas(64) std::atomic<std::uint64_t> tail_{0};  // next slot the consumer reads
};

}  // namespace omnitwin::twin
