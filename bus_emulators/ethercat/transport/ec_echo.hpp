// bus_emulators/ethercat/transport — the bare echo: a slaves-role transport that sends every
// PDU it receives straight back, unchanged, with no EtherCAT processing at all.
//
// It is the baseline of the transport benchmark (tests/bench/bench_ethercat_transport): the
// emulated chain's turnaround on a veth pair is reported as a ratio against this echo on the
// same pair, so that the cost of the kernel, the veth hop and the wake-ups is measured in the
// same run and divided out. On raw Ethernet the reply still carries the marked source MAC
// (that is the transport's doing); the PDU bytes are the ones received.
#pragma once

#include "bus_emulators/ethercat/transport/ec_transport.hpp"

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string_view>
#include <thread>

namespace omnitwin::ethercat {

// Answers every PDU `slaves` receives with the same bytes until `stop` is true (checked at
// least every `poll`) or the transport reports a receive error. Returns the PDUs echoed;
// `echoed`, when given, is kept up to date as it runs. Blocks the calling thread.
std::uint64_t run_echo(EcTransport& slaves, const std::atomic<bool>& stop,
                       std::chrono::nanoseconds poll = std::chrono::milliseconds(20),
                       std::atomic<std::uint64_t>* echoed = nullptr);

// run_echo() on its own thread, stopped and joined on destruction.
class EchoThread {
 public:
  // Opens `spec` in the slaves role here (throws TransportError), then starts echoing.
  explicit EchoThread(std::string_view spec);
  explicit EchoThread(std::unique_ptr<EcTransport> slaves);
  ~EchoThread();
  EchoThread(const EchoThread&) = delete;
  EchoThread& operator=(const EchoThread&) = delete;

  void stop();                       // stops and joins (idempotent)
  std::uint64_t echoed() const { return echoed_.load(std::memory_order_relaxed); }
  // The transport's statistics (read them after stop(): the echo thread owns it while running).
  EcTransport& transport() { return *transport_; }

 private:
  std::unique_ptr<EcTransport> transport_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> echoed_{0};
  std::thread thread_;
};

}  // namespace omnitwin::ethercat
