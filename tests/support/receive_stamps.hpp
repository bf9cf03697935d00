// Test support — waiting for the kernel's receive stamps. The kernel turns receive stamping
// on from a work item shortly after the first socket asks for it (SO_TIMESTAMPNS), so a test
// that checks a frame's age first sends probes until one that waited shows its wait.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <span>
#include <thread>

namespace omnitwin::testing {

// Sends `probe` from `from` to `to` and takes it after 5 ms until to.last_age_ns() says at
// least 4 ms; false when that has not happened within 2 s. Tx and Rx are M-III transports.
template <class Tx, class Rx>
bool wait_for_receive_stamps(Tx& from, Rx& to, std::span<const std::uint8_t> probe) {
  std::array<std::uint8_t, 256> buf{};
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  while (std::chrono::steady_clock::now() < give_up) {
    if (!from.send(probe)) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (to.receive(buf, std::chrono::seconds(1)) <= 0) return false;
    if (to.last_age_ns() >= 4'000'000) return true;
  }
  return false;
}

}  // namespace omnitwin::testing
