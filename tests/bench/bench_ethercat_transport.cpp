// Benchmarks the EtherCAT transports: the round trip of one PDU from a master transport
// through a bare echo (bus_emulators/ethercat/transport/ec_echo: a slaves-role transport that
// sends every PDU straight back, no EtherCAT processing) on its own thread, and back.
//
//   BM_RawEchoRoundTrip/<PDU bytes>  raw Ethernet on a veth pair made for the run: master on
//                    end a, the echo on end b (needs root; skipped with the reason otherwise).
//   BM_UdpEchoRoundTrip/<PDU bytes>  EtherCAT over UDP on 127.0.0.1 (master → echo on port 48899).
// PDU sizes 60 and 1000 bytes (one LRW datagram of 46 / 986 data bytes). One iteration = one
// send + one receive of the answer (checked: same size). Counters: rtt_median_us,
// rtt_p99_us and rtt_min_us over every round trip of the run (the iteration time is the mean).
//
// The raw echo is the baseline the emulated chain is reported against (DESIGN §11): the same
// exchange with the emulated slaves answering, on the same kind of veth pair, in the same run,
// divided by BM_RawEchoRoundTrip's median.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/transport/ec_echo.hpp"
#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "tests/support/veth.hpp"

namespace {

using namespace omnitwin;
using namespace std::chrono_literals;

// A PDU of exactly `size` bytes: the EtherCAT header and one LRW datagram.
std::vector<std::uint8_t> pdu_of_size(std::size_t size) {
  const auto data_len = static_cast<std::uint16_t>(size - ethercat::kEcatHeaderSize - ethercat::kDatagramHeaderSize -
                                                   ethercat::kWkcSize);
  std::vector<std::uint8_t> data(data_len);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(i * 13);
  std::vector<std::uint8_t> buf(ethercat::kMaxPdu);
  ethercat::PduBuilder b(buf);
  b.add_logical(ethercat::Cmd::lrw, 1, 0x00010000, data_len, data.data());
  buf.resize(b.finish());
  return buf;
}

// The timed loop shared by every variant: send, wait for the answer, record the round trip.
void round_trips(benchmark::State& state, ethercat::EcTransport& master) {
  const auto pdu = pdu_of_size(static_cast<std::size_t>(state.range(0)));
  std::vector<std::uint8_t> buf(ethercat::kMaxPdu);
  std::vector<double> rtt_us;
  rtt_us.reserve(1 << 20);
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    master.send(pdu);
    const int n = master.receive(buf, 1s);
    const auto t1 = std::chrono::steady_clock::now();
    if (n != static_cast<int>(pdu.size())) {
      state.SkipWithError("no answer of the PDU's size within 1 s");
      break;
    }
    if (rtt_us.size() < rtt_us.capacity()) rtt_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
  }
  if (rtt_us.empty()) return;
  std::sort(rtt_us.begin(), rtt_us.end());
  state.counters["rtt_median_us"] = rtt_us[rtt_us.size() / 2];
  state.counters["rtt_p99_us"] = rtt_us[std::min(rtt_us.size() - 1, rtt_us.size() * 99 / 100)];
  state.counters["rtt_min_us"] = rtt_us.front();
  state.SetItemsProcessed(state.iterations());
  state.SetBytesProcessed(state.iterations() * 2 * state.range(0));
}

void BM_RawEchoRoundTrip(benchmark::State& state) {
  if (const auto why = testing::VethPair::unavailable_reason()) {
    state.SkipWithError(why->c_str());
    return;
  }
  testing::VethPair veth;
  ethercat::EchoThread echo("raw:" + veth.b());
  auto master = ethercat::open_transport("raw:" + veth.a(), ethercat::Role::master);
  round_trips(state, *master);
}

void BM_UdpEchoRoundTrip(benchmark::State& state) {
  ethercat::EchoThread echo("udp:127.0.0.1:48899");
  auto master = ethercat::open_transport("udp:127.0.0.1:48899", ethercat::Role::master);
  round_trips(state, *master);
}

// LEAD: add BM_ChainRoundTrip/<PDU bytes> here — the emulated EscChain (with its slaves) behind
// a slaves-role raw transport on end b of a VethPair, on its own thread, the master on end a
// driving round_trips() with the same PDUs; report its rtt_median_us as a ratio against
// BM_RawEchoRoundTrip's (same sizes, same run).

}  // namespace

BENCHMARK(BM_RawEchoRoundTrip)->Arg(60)->Arg(1000)->UseRealTime();
BENCHMARK(BM_UdpEchoRoundTrip)->Arg(60)->Arg(1000)->UseRealTime();
BENCHMARK_MAIN();
