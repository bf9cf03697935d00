// bus_emulators/ethercat/transport — the bare echo; see ec_echo.hpp.
#include "bus_emulators/ethercat/transport/ec_echo.hpp"

#include "bus_emulators/ethercat/ec_frame.hpp"

#include <array>

namespace omnitwin::ethercat {

std::uint64_t run_echo(EcTransport& slaves, const std::atomic<bool>& stop, std::chrono::nanoseconds poll,
                       std::atomic<std::uint64_t>* echoed) {
  std::array<std::uint8_t, kMaxPdu> buf{};
  std::uint64_t n = 0;
  while (!stop.load(std::memory_order_relaxed)) {
    const int size = slaves.receive(buf, poll);
    if (size < 0) break;
    if (size == 0) continue;
    if (slaves.send(std::span<const std::uint8_t>(buf.data(), static_cast<std::size_t>(size)))) {
      ++n;
      if (echoed) echoed->store(n, std::memory_order_relaxed);
    }
  }
  return n;
}

EchoThread::EchoThread(std::string_view spec) : EchoThread(open_transport(spec, Role::slaves)) {}

EchoThread::EchoThread(std::unique_ptr<EcTransport> slaves) : transport_(std::move(slaves)) {
  if (!transport_) throw TransportError("EchoThread: no transport");
  thread_ = std::thread([this] { run_echo(*transport_, stop_, std::chrono::milliseconds(20), &echoed_); });
}

EchoThread::~EchoThread() { stop(); }

void EchoThread::stop() {
  stop_.store(true, std::memory_order_relaxed);
  if (thread_.joinable()) thread_.join();
}

}  // namespace omnitwin::ethercat
