// Benchmark support (not a benchmark): what the twin's EtherCAT segment does with each frame
// in realtime, on its own thread — receive on a slaves-role transport, run the line to the
// frame's instant (SYNC0 pulses: the slaves' firmware cycles), pass the frame through the
// slaves, send it back. Simulated time = `base` + wall time since the thread started. Used by
// bench_ethercat_transport (four drives, round trips) and bench_ec_scaling (the 100-axis
// segment cycled at 100 µs).
#pragma once

#include <pthread.h>
#include <sched.h>

#include <array>
#include <atomic>
#include <chrono>
#include <memory>
#include <span>
#include <string>
#include <thread>

#include "bus_emulators/ethercat/ec_chain.hpp"
#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/transport/ec_transport.hpp"

namespace ecbench {

class ChainThread {
 public:
  // fifo_priority > 0: the thread asks for SCHED_FIFO at that priority (root); fifo() says
  // whether it got it.
  ChainThread(omnitwin::ethercat::EscChain& chain, omnitwin::ethercat::SimTime base, const std::string& spec,
              int fifo_priority = 0)
      : chain_(chain),
        base_(base),
        transport_(omnitwin::ethercat::open_transport(spec, omnitwin::ethercat::Role::slaves)) {
    thread_ = std::thread([this, fifo_priority] {
      if (fifo_priority > 0) {
        sched_param sp{};
        sp.sched_priority = fifo_priority;
        fifo_.store(pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0);
      }
      serve();
    });
  }
  ~ChainThread() {
    stop_.store(true, std::memory_order_relaxed);
    thread_.join();
  }
  ChainThread(const ChainThread&) = delete;
  ChainThread& operator=(const ChainThread&) = delete;
  bool fifo() const { return fifo_.load(); }

 private:
  void serve() {
    using namespace std::chrono_literals;
    std::array<std::uint8_t, omnitwin::ethercat::kMaxPdu> buf{};
    const auto t0 = std::chrono::steady_clock::now();
    while (!stop_.load(std::memory_order_relaxed)) {
      const int n = transport_->receive(buf, 20ms);
      if (n < 0) break;
      if (n == 0) continue;
      const omnitwin::ethercat::SimTime t =
          base_ + std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count();
      chain_.advance(t);
      const std::span<std::uint8_t> pdu(buf.data(), static_cast<std::size_t>(n));
      if (chain_.process(pdu, t)) transport_->send(pdu);
    }
  }

  omnitwin::ethercat::EscChain& chain_;
  omnitwin::ethercat::SimTime base_;
  std::unique_ptr<omnitwin::ethercat::EcTransport> transport_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> fifo_{false};
  std::thread thread_;
};

}  // namespace ecbench
