// Tests controller/mechatrolink3/m3_lockstep: our C1 master in exchange-level lockstep with a
// twin-like counterpart in another thread — frames over a real M-III transport (in-process
// pair), time and counts over a real sim-clock socket. The twin side is the segment
// (bus_emulators/mechatrolink3/transport/m3_segment) answering each Sent, with the test
// turning its answer into the Horizon and running the slaves' timers and drives between ticks.
// The transport is the in-process pair, UDP on loopback and raw Ethernet on a veth pair (the
// run must not change).
// Checks: the driver sequence measures TR_DLY exactly as in process, four servos start and
// turn, every cycle exchanges with every slave and nothing is missed or late, the frame counts
// of both ends agree, a SYNC is reported with the command after it (one exchange fewer per
// cycle), and two runs give the same log.
#include "controller/mechatrolink3/m3_lockstep.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_segment.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"
#include "controller/mechatrolink3/m3_servo_axis.hpp"
#include "tests/support/temp_dir.hpp"
#include "tests/support/veth.hpp"

namespace omnitwin::m3 {
namespace {

using namespace std::chrono_literals;
constexpr SimTime kPeriod = 1'000'000;
constexpr int kSlaves = 4;

// The twin's side: the segment (line and four servo slaves behind the slaves end of the
// transport) and, between ticks, the slaves' timers and drives.
struct TwinSide {
  std::unique_ptr<M3Transport> transport;
  M3Segment segment;
  std::vector<drive::AxisModel> axes = std::vector<drive::AxisModel>(kSlaves);

  static SegmentConfig config() {
    SegmentConfig c;
    c.topology = Topology::cascade_of(kSlaves, 10.0);
    c.servo.drive.counts_per_rev = 10000;
    return c;
  }
  // spec: the slaves' end ("mem:NAME", "udp:127.0.0.1:0", "raw:IFACE").
  explicit TwinSide(const std::string& spec)
      : transport(open_transport(spec, Role::slaves)), segment(config(), *transport) {}
  // What the master opens: the same pair, or the port the slaves' UDP socket was given.
  std::string master_spec() const { return transport->spec(); }
  std::uint64_t to_master() const { return segment.to_master(); }
  std::uint64_t sents = 0;  // Sent records answered
  simclock::Horizon answer(const simclock::Sent& s) {
    ++sents;
    const SegmentAnswer a = segment.take_sent(s.frames[0], s.t_ns, 5s);
    simclock::Horizon h;
    h.tick = s.tick;
    h.arrival_ns = a.arrival_ns;
    h.frames[0] = a.to_master;
    return h;
  }
  void after_tick(SimTime end) {
    segment.advance(end);
    for (std::size_t k = 0; k < axes.size(); ++k)
      axes[k].step(segment.step_drive(static_cast<int>(k), end, axes[k].feedback()), 1e-3);
  }
};

struct RunResult {
  std::vector<std::string> log;
  std::vector<SimTime> tr_dly;
  std::vector<SlaveCounters> counters;
  std::vector<AxisStep> steps;
  std::uint64_t master_sent = 0, master_received = 0, twin_from_master = 0, twin_to_master = 0, sents = 0;
  double wheel0_rad_s = 0;
  std::string error;
};

// One lockstep run of `ticks` 1 ms ticks; `spec` is the slaves' end of the transport and
// `master` the master's ("": what the slaves' end names: the same pair, the bound UDP port).
RunResult run_lockstep(const std::string& spec, int ticks, const std::string& master = "") {
  omnitwin::testing::TempDir dir("omnitwin-m3-lockstep");
  const std::string address = "unix:" + (dir / "clock").string();
  RunResult r;
  TwinSide twin(spec);
  const std::string master_spec = master.empty() ? twin.master_spec() : master;
  simclock::Server server(address);
  std::thread master_thread([&] {
    try {
      simclock::Client clock(address, 2s);
      std::unique_ptr<M3Transport> transport = open_transport(master_spec, Role::master);
      MasterLockstep lockstep(*transport, clock);
      MasterConfig cfg;
      for (int k = 0; k < kSlaves; ++k) cfg.slaves.push_back(MasterSlave{.address = static_cast<std::uint8_t>(kFirstSlave + k)});
      std::vector<ServoAxis> apps;
      for (int k = 0; k < kSlaves; ++k) {
        apps.emplace_back("axis " + std::to_string(k + 1), ServoAxisConfig{}, [&r](SimTime, const std::string& s) { r.log.push_back(s); });
        apps.back().set_velocity(10000);
      }
      std::unique_ptr<C1Master> master;
      master = std::make_unique<C1Master>(
          cfg, [&](std::span<const std::uint8_t> f, SimTime t) { lockstep.emit(f, t); },
          [&](std::uint64_t, SimTime t) {
            for (int k = 0; k < kSlaves; ++k)
              apps[static_cast<std::size_t>(k)].on_interrupt(master->response(k), master->fresh(k), master->command(k), t);
          },
          [&r](SimTime, const std::string& s) { r.log.push_back(s); });
      simclock::Grant g;
      bool started = false;
      while (clock.next(g, 5s) == simclock::WaitStatus::ok) {
        if (!started) master->start(g.t_ns), started = true;
        if (lockstep.run_tick(*master, g, kPeriod) != simclock::WaitStatus::ok) break;
        simclock::Done d;
        d.tick = g.tick;
        d.frames[0] = lockstep.frames_sent();
        if (!clock.done(d)) break;
      }
      for (int k = 0; k < kSlaves; ++k) {
        r.tr_dly.push_back(master->tr_dly_ns(k));
        r.counters.push_back(master->counters(k));
        r.steps.push_back(apps[static_cast<std::size_t>(k)].step());
      }
      r.master_sent = lockstep.frames_sent();
      r.master_received = lockstep.frames_received();
    } catch (const std::exception& e) {
      r.error = e.what();
    }
  });
  if (server.accept(5s) != simclock::WaitStatus::ok) r.error = "no master";
  const simclock::Server::OnSent on_sent = [](void* ctx, const simclock::Sent& s) {
    return static_cast<TwinSide*>(ctx)->answer(s);
  };
  for (int k = 0; k < ticks && r.error.empty(); ++k) {
    simclock::Grant g;
    g.tick = static_cast<std::uint64_t>(k);
    g.t_ns = k * kPeriod;
    g.frames[0] = twin.to_master();
    simclock::Done d;
    if (server.grant(g, d, 5s, on_sent, &twin) != simclock::WaitStatus::ok) r.error = "grant failed at tick " + std::to_string(k);
    twin.after_tick((k + 1) * kPeriod);
  }
  server.end(ticks * kPeriod);
  master_thread.join();
  r.twin_from_master = twin.segment.from_master();
  r.twin_to_master = twin.segment.to_master();
  r.sents = twin.sents;
  r.wheel0_rad_s = twin.axes[0].velocity_rad_s();
  return r;
}

TEST(M3Lockstep, TheMasterRunsAgainstTheTwinOverATransportAndTheSimClock) {
  const RunResult r = run_lockstep("mem:m3-lockstep-a", 600);
  ASSERT_EQ(r.error, "");
  const Topology topo = Topology::cascade_of(kSlaves, 10.0);
  for (int k = 0; k < kSlaves; ++k) {
    EXPECT_EQ(r.tr_dly[static_cast<std::size_t>(k)], tr_dly_ns(topo, k)) << "TR_DLY measured in simulated time";
    EXPECT_EQ(r.steps[static_cast<std::size_t>(k)], AxisStep::running) << k;
    EXPECT_EQ(r.counters[static_cast<std::size_t>(k)].missed, 0u) << k;
    EXPECT_EQ(r.counters[static_cast<std::size_t>(k)].late, 0u) << k;
    EXPECT_GT(r.counters[static_cast<std::size_t>(k)].exchanges, 590u) << k;
  }
  EXPECT_EQ(r.master_sent, r.twin_from_master);
  EXPECT_EQ(r.master_received, r.twin_to_master);
  EXPECT_LE(r.sents + 590, r.twin_from_master) << "each cycle's SYNC goes with its first command: one exchange fewer";
  EXPECT_NEAR(r.wheel0_rad_s, 2 * M_PI, 0.2) << "1 rev/s";
}

TEST(M3Lockstep, TwoRunsGiveTheSameLog) {
  const RunResult a = run_lockstep("mem:m3-lockstep-b", 300), b = run_lockstep("mem:m3-lockstep-c", 300);
  ASSERT_EQ(a.error, "");
  ASSERT_EQ(b.error, "");
  EXPECT_EQ(a.log, b.log);
  EXPECT_EQ(a.master_sent, b.master_sent);
}

// The same over a real transport between the two ends: UDP on loopback, a free port.
TEST(M3Lockstep, OverUdpTheRunIsTheSameAsInProcess) {
  const RunResult udp = run_lockstep("udp:127.0.0.1:0", 300), mem = run_lockstep("mem:m3-lockstep-d", 300);
  ASSERT_EQ(udp.error, "");
  ASSERT_EQ(mem.error, "");
  EXPECT_EQ(udp.log, mem.log);
  EXPECT_EQ(udp.master_sent, mem.master_sent);
  EXPECT_EQ(udp.master_received, udp.twin_to_master);
  for (int k = 0; k < kSlaves; ++k) EXPECT_EQ(udp.steps[static_cast<std::size_t>(k)], AxisStep::running) << k;
}

// And over raw Ethernet (EtherType 0x88B5) on a veth pair of the test's own, as root.
TEST(M3Lockstep, OverAVethPairTheRunIsTheSameAsInProcess) {
  if (const auto why = omnitwin::testing::VethPair::unavailable_reason()) GTEST_SKIP() << *why;
  omnitwin::testing::VethPair veth;  // deleted when the test ends, whatever its outcome
  const RunResult raw = run_lockstep("raw:" + veth.b(), 300, "raw:" + veth.a());
  const RunResult mem = run_lockstep("mem:m3-lockstep-e", 300);
  ASSERT_EQ(raw.error, "");
  EXPECT_EQ(raw.log, mem.log);
  EXPECT_EQ(raw.master_received, raw.twin_to_master);
}

}  // namespace
}  // namespace omnitwin::m3
