// Test support — eventually(): waits for a condition that becomes true asynchronously (e.g.
// records a write-behind file's thread writes within its 20 ms period), polling every
// millisecond up to a timeout. Returns the condition's last value.
#pragma once

#include <chrono>
#include <thread>

namespace omnitwin::testing {

template <class Pred>
bool eventually(Pred pred, std::chrono::milliseconds timeout = std::chrono::milliseconds(2000)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() >= deadline) return pred();
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

}  // namespace omnitwin::testing
