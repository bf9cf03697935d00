// Benchmarks the EtherCAT transports: the round trip of one PDU from a master transport
// through a bare echo (bus_emulators/ethercat/transport/ec_echo: a slaves-role transport that
// sends every PDU straight back, no EtherCAT processing) on its own thread, and back.
//
//   BM_RawEchoRoundTrip/<PDU bytes>  raw Ethernet on a veth pair made for the run: master on
//                    end a, the echo on end b (needs root; skipped with the reason otherwise).
//   BM_UdpEchoRoundTrip/<PDU bytes>  EtherCAT over UDP on 127.0.0.1 (master → echo on port 48899).
// PDU sizes 60 and 1000 bytes (one LRW datagram of 46 / 986 data bytes), and 202 bytes for the
// raw echo (the size of the cyclic frame below). One iteration = one send + one receive of the
// answer (checked: same size). Counters: rtt_median_us, rtt_p99_us and rtt_min_us over every
// round trip of the run (the iteration time is the mean).
//
//   BM_ChainRoundTrip/<PDU bytes>  the emulated segment answering instead of the echo: four
//                    DriveSlaves built from models/ethercat/omnitwin_drive.xml (load_esi) on an
//                    EscChain, brought to OP with distributed clocks by our master core
//                    (controller/ethercat EcMaster, in-process at set-up, 1 ms cycle), then
//                    served by a thread on end b of a veth pair that does per frame what the
//                    twin's EthercatNetwork does in realtime: receive on a slaves-role
//                    "raw:IFACE" transport → EscChain::advance (SYNC0 pulses due: the drives'
//                    firmware cycles, the CiA 402 axes stepped) → EscChain::process → send back.
//                    The master (benchmark thread) sends and waits for the answer.
//                    202: the master's own cyclic frame in OP, captured from EcMaster: one LRW
//                    over the four drives' process image (4 × 18 output + 4 × 24 input bytes)
//                    and the FRMW 0x0910 of the DC reference time; WKC 12 expected.
//                    60: one LRW of 46 bytes over the first two slaves' inputs (WKC 2). It
//                    writes no outputs, so the slaves' SyncManager watchdogs (100 ms) take
//                    them to SAFE-OP with AL status 0x001B, as real drives would:
//                    slaves_not_op reads 4 and al_status_code 27 there, by design.
//                    The baseline is measured in the same loop (DESIGN §11): every iteration
//                    also sends the very same PDU through a bare echo (ec_echo) on a second
//                    veth pair, so both see the same machine load. The iteration time (manual)
//                    is the chain's round trip. Counters: rtt_median_us / rtt_p99_us /
//                    rtt_min_us (chain), echo_median_us / echo_p99_us (raw echo, same PDU),
//                    ratio_median and ratio_p99 (chain / echo; issue target: ratio_median ≤ 2),
//                    wkc_errors (answers whose first datagram's WKC was not the expected one;
//                    must read 0), slaves_not_op and al_status_code (after the run; 0 for the
//                    cyclic frame).
//   BM_ChainProcess/<PDU bytes>  the chain's share alone, no sockets: advance + process of the
//                    same PDUs on simulated time (20 µs per frame), in the benchmark thread.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "bus_emulators/ethercat/device/ec_esi.hpp"
#include "bus_emulators/ethercat/device/ec_slave.hpp"
#include "bus_emulators/ethercat/ec_chain.hpp"
#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/transport/ec_echo.hpp"
#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "controller/ethercat/ec_master.hpp"
#include "tests/bench/ec_chain_thread.hpp"
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

// ---- the emulated segment ---------------------------------------------------------------

namespace me = controller::ethercat;
using ethercat::SimTime;

std::vector<double> sorted(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v;
}
double pct(const std::vector<double>& s, int p) { return s[std::min(s.size() - 1, s.size() * p / 100)]; }

// Four single-axis drives as the twin builds them (twin/ethercat_network.cpp: one axis each,
// their own serials, oscillator drifts and power-on instants, 1 ms drive period), on one line.
struct Segment {
  std::vector<ethercat::DeviceDescription> devices =
      ethercat::load_esi(std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/omnitwin_drive.xml");
  std::array<std::unique_ptr<ethercat::DriveSlave>, 4> slaves;
  ethercat::EscChain chain;
  SimTime t = 0;                       // set-up's simulated time when the master reached OP
  std::vector<std::uint8_t> cyclic;    // the master's cyclic PDU in OP (LRW + FRMW 0x0910)
  std::uint16_t cyclic_wkc = 0;        // the LRW's expected WKC
  std::uint32_t image_base = 0, out_bytes = 0;
  std::string error;                   // non-empty: set-up failed

  Segment() {
    constexpr std::array<double, 4> kDrift{20e-6, -15e-6, 35e-6, -30e-6};  // the twin's defaults
    for (int i = 0; i < 4; ++i) {
      const auto k = static_cast<std::size_t>(i);
      ethercat::DriveSlaveConfig c;
      c.axes = 1;
      c.serial = static_cast<std::uint32_t>(i + 1);
      c.esc.oscillator_drift = kDrift[k];
      c.esc.power_on_time_ns = 1'000'000'000LL * (i + 1);
      c.drive.period_s = 0.001;
      slaves[k] = std::make_unique<ethercat::DriveSlave>(devices.front(), c);
      // The twin steps each drive against its wheel here; no physics in this benchmark: the
      // drive's own cycle with the wheel at rest.
      slaves[k]->set_cycle_hook([this, k](SimTime at) { slaves[k]->axis(0).step(at, drive::Feedback{}); });
      chain.add(&slaves[k]->esc());
    }
    bring_to_op();
  }

  // Our master core, in-process (no sockets): scan, SII, CoE PDO mapping, DC, PRE-OP → OP,
  // one exchange per 1 ms tick; then its cyclic frame is taken as the benchmark's PDU.
  void bring_to_op() {
    me::EcMasterConfig cfg;
    cfg.devices = devices;
    cfg.cycle_ns = 1'000'000;
    cfg.dc = true;
    cfg.expected_slaves = 4;
    cfg.al_check_every_ns = std::int64_t{1} << 60;  // no AL status read riding along
    std::vector<std::uint8_t> frame;
    bool sent = false;
    me::EcMaster master(cfg, [&](std::span<const std::uint8_t> pdu) {
      frame.assign(pdu.begin(), pdu.end());
      sent = true;
      return true;
    });
    auto exchange = [&] {
      for (auto& s : slaves) s->cycle(t);  // mailbox replies (process data runs on SYNC0 once DC is on)
      chain.advance(t);
      sent = false;
      master.tick(t);
      if (sent && chain.process(frame, t)) master.on_frame(frame, t + 50'000);
      t += cfg.cycle_ns;
    };
    for (int k = 0; k < 20000 && !master.operational() && master.phase() != me::MasterPhase::failed; ++k) exchange();
    if (!master.operational()) {
      error = "the master did not bring the four slaves to OP: " + master.error();
      return;
    }
    for (int k = 0; k < 100 && cyclic.empty(); ++k) {
      exchange();
      ethercat::PduView v;
      if (!sent || ethercat::parse_pdu(frame, v) != ethercat::PduError::ok || v.count != 2) continue;
      if (v.datagrams[0].cmd() != ethercat::Cmd::lrw || v.datagrams[1].cmd() != ethercat::Cmd::frmw ||
          v.datagrams[1].ado() != 0x0910)
        continue;
      // WKCs back to zero as the master sent them (process() counted into `frame`; the bytes
      // the slaves read into are overwritten on every pass anyway).
      v.datagrams[0].set_wkc(0);
      v.datagrams[1].set_wkc(0);
      cyclic.assign(frame.begin(), frame.begin() + static_cast<std::ptrdiff_t>(v.length));
      image_base = v.datagrams[0].logical();
    }
    cyclic_wkc = master.stats().expected_wkc;
    out_bytes = master.output_bytes();
    if (cyclic.empty()) error = "no LRW + FRMW 0x0910 cyclic frame from the master in OP";
  }

  int slaves_not_op() const {
    int n = 0;
    for (const auto& s : slaves) n += s->esc().al_state() != ethercat::AlState::op;
    return n;
  }
  std::uint16_t al_status_code() const {  // the first slave that is not in OP's 0x0134, else 0
    for (const auto& s : slaves)
      if (s->esc().al_state() != ethercat::AlState::op) return s->esc().read16(0x0134);
    return 0;
  }
};

// The 60-byte PDU for the chain: one LRW of 46 bytes over the inputs of slaves 1 and 2 (the
// image's outputs come first), so that it touches process data without writing the drives'
// controlwords.
std::vector<std::uint8_t> small_chain_pdu(const Segment& seg) {
  constexpr std::uint16_t kData = 60 - ethercat::kEcatHeaderSize - ethercat::kDatagramHeaderSize - ethercat::kWkcSize;
  std::vector<std::uint8_t> buf(ethercat::kMaxPdu);
  ethercat::PduBuilder b(buf);
  b.add_logical(ethercat::Cmd::lrw, 1, seg.image_base + seg.out_bytes, kData);
  buf.resize(b.finish());
  return buf;
}

// The benchmark's PDU of `size` bytes for the segment and the WKC its first datagram must come
// back with; empty when the size is neither 60 nor the cyclic frame's.
std::pair<std::vector<std::uint8_t>, std::uint16_t> chain_pdu(const Segment& seg, std::int64_t size) {
  if (size == 60) return {small_chain_pdu(seg), 2};  // two slaves' input FMMUs read
  if (size == static_cast<std::int64_t>(seg.cyclic.size())) return {seg.cyclic, seg.cyclic_wkc};
  return {};
}

// One timed round trip of `pdu` through `master`; nullopt when no answer of its size came back.
std::optional<double> round_trip_us(ethercat::EcTransport& master, std::span<const std::uint8_t> pdu,
                                    std::span<std::uint8_t> buf) {
  const auto t0 = std::chrono::steady_clock::now();
  master.send(pdu);
  const int n = master.receive(buf, 1s);
  const auto t1 = std::chrono::steady_clock::now();
  if (n != static_cast<int>(pdu.size())) return std::nullopt;
  return std::chrono::duration<double, std::micro>(t1 - t0).count();
}

void BM_ChainRoundTrip(benchmark::State& state) {
  if (const auto why = testing::VethPair::unavailable_reason()) {
    state.SkipWithError(why->c_str());
    return;
  }
  Segment seg;
  if (!seg.error.empty()) {
    state.SkipWithError(seg.error.c_str());
    return;
  }
  const auto [pdu, expected_wkc] = chain_pdu(seg, state.range(0));
  if (pdu.empty()) {
    state.SkipWithError(("PDU sizes: 60 or the master's cyclic frame, " + std::to_string(seg.cyclic.size()) +
                         " bytes")
                            .c_str());
    return;
  }
  // The first datagram's WKC sits after the EtherCAT header, its header and its data.
  const std::size_t wkc_at = ethercat::kEcatHeaderSize + ethercat::kDatagramHeaderSize +
                             ethercat::get_u16(pdu.data() + ethercat::kEcatHeaderSize + 6) % 0x0800;

  testing::VethPair chain_veth, echo_veth;
  ethercat::EchoThread echo("raw:" + echo_veth.b());
  auto echo_master = ethercat::open_transport("raw:" + echo_veth.a(), ethercat::Role::master);
  std::optional<ecbench::ChainThread> chain;
  chain.emplace(seg.chain, seg.t, "raw:" + chain_veth.b());
  auto chain_master = ethercat::open_transport("raw:" + chain_veth.a(), ethercat::Role::master);

  std::vector<std::uint8_t> buf(ethercat::kMaxPdu);
  std::vector<double> chain_us, echo_us;
  chain_us.reserve(1 << 20);
  echo_us.reserve(1 << 20);
  std::uint64_t wkc_errors = 0;
  for (auto _ : state) {
    const auto c = round_trip_us(*chain_master, pdu, buf);
    if (!c) {
      state.SkipWithError("the chain sent no answer of the PDU's size within 1 s");
      break;
    }
    wkc_errors += ethercat::get_u16(buf.data() + wkc_at) != expected_wkc;
    state.SetIterationTime(*c * 1e-6);
    const auto e = round_trip_us(*echo_master, pdu, buf);
    if (!e) {
      state.SkipWithError("the echo sent no answer of the PDU's size within 1 s");
      break;
    }
    if (chain_us.size() < chain_us.capacity()) {
      chain_us.push_back(*c);
      echo_us.push_back(*e);
    }
  }
  chain.reset();  // joined: the segment is ours again
  if (chain_us.empty()) return;
  const auto cs = sorted(chain_us), es = sorted(echo_us);
  state.counters["rtt_median_us"] = pct(cs, 50);
  state.counters["rtt_p99_us"] = pct(cs, 99);
  state.counters["rtt_min_us"] = cs.front();
  state.counters["echo_median_us"] = pct(es, 50);
  state.counters["echo_p99_us"] = pct(es, 99);
  state.counters["ratio_median"] = pct(cs, 50) / pct(es, 50);
  state.counters["ratio_p99"] = pct(cs, 99) / pct(es, 99);
  state.counters["wkc_errors"] = static_cast<double>(wkc_errors);
  state.counters["slaves_not_op"] = seg.slaves_not_op();
  state.counters["al_status_code"] = seg.al_status_code();
  state.SetItemsProcessed(state.iterations());
}

// The chain's share alone: what ChainThread does per frame, minus the sockets (advance to the
// frame's instant, process), on simulated time advancing 20 µs per frame.
void BM_ChainProcess(benchmark::State& state) {
  Segment seg;
  if (!seg.error.empty()) {
    state.SkipWithError(seg.error.c_str());
    return;
  }
  const auto [pdu, expected_wkc] = chain_pdu(seg, state.range(0));
  if (pdu.empty()) {
    state.SkipWithError("PDU sizes: 60 or the master's cyclic frame");
    return;
  }
  std::vector<std::uint8_t> buf(pdu.size());
  SimTime t = seg.t;
  for (auto _ : state) {
    std::copy(pdu.begin(), pdu.end(), buf.begin());
    t += 20'000;
    seg.chain.advance(t);
    benchmark::DoNotOptimize(seg.chain.process(buf, t));
  }
  state.counters["slaves_not_op"] = seg.slaves_not_op();
  state.counters["al_status_code"] = seg.al_status_code();
  state.SetItemsProcessed(state.iterations());
}

}  // namespace

BENCHMARK(BM_RawEchoRoundTrip)->Arg(60)->Arg(202)->Arg(1000)->UseRealTime();
BENCHMARK(BM_UdpEchoRoundTrip)->Arg(60)->Arg(1000)->UseRealTime();
BENCHMARK(BM_ChainRoundTrip)->Arg(60)->Arg(202)->UseManualTime();
BENCHMARK(BM_ChainProcess)->Arg(60)->Arg(202);
BENCHMARK_MAIN();
