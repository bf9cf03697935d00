// Tests twin/ethercat_network.cpp: the twin's EtherCAT segment, in one process, against our
// master core (controller/ethercat) over an in-process transport, stepped by the twin's own
// scheduler exactly as a lockstep run steps it: each master tick the returned frames go to
// the master before it runs, and the frame it sends enters the line at the tick + T_pre.
// The wheels are a shaft per drive that follows the amplifier setpoint. Checked: the master
// brings all four drives to OP with the expected WKC; frames in, out and lost are counted and
// captured; a link break and a slave's power loss drop the WKC and are recovered; a stopped
// master trips the process-data watchdogs; drift is set per slave; two frames sent in one
// tick share the line, the second entering when the first has gone out at 100 Mbit/s.
#include <gtest/gtest.h>
#include <pcap/pcap.h>

#include <array>
#include <filesystem>
#include <memory>
#include <set>
#include <vector>

#include "bus_emulators/ethercat/device/ec_slave.hpp"
#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "controller/ethercat/ec_config.hpp"
#include "controller/ethercat/ec_master.hpp"
#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"
#include "twin/clock.hpp"
#include "twin/ethercat_network.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin {
namespace {

namespace fs = std::filesystem;
namespace me = controller::ethercat;
using omnitwin::testing::source_path;

constexpr SimTime kCycle = 1'000'000;  // 1 ms master cycle

class EthercatNetworkTest : public ::testing::Test {
 protected:
  // The segment on mem:NAME with the scenario's defaults, and our master on the other end.
  void build(const std::string& name, std::vector<Override> extra = {}) {
    std::vector<Override> o{{"bus", "ethercat"}, {"bus.transport", "mem:" + name}, {"controller.period", "0.001"}};
    o.insert(o.end(), extra.begin(), extra.end());
    scenario_ = load_scenario(source_path("tests/data/scenarios/ethercat_short.yaml"), o);
    BusNetwork::Hooks h;
    h.wheel_angle = [this](int i) { return angle_[static_cast<std::size_t>(i)]; };
    h.wheel_speed = [this](int i) { return speed_[static_cast<std::size_t>(i)]; };
    h.set_setpoint = [this](int i, double w) { speed_[static_cast<std::size_t>(i)] = w; };
    h.axis_sample = [](int, double) {};
    h.log = [this](SimTime, std::string_view, const std::string& text) { log_.push_back(text); };
    net_ = std::make_unique<EthercatNetwork>(scenario_, sched_, std::move(h));
    net_->open_pcap((dir_ / "bus-ethercat.pcap").string());
    master_link_ = ethercat::open_transport("mem:" + name, ethercat::Role::master);
    me::EcConfig cfg = me::load_ec_config(source_path("tests/data/ethercat/drives_only.yaml"));
    master_ = std::make_unique<me::EcMaster>(me::make_master_config(cfg), [this](std::span<const std::uint8_t> pdu) {
      if (!master_link_->send(pdu)) return false;
      ++sent_;
      return true;
    });
    sched_.add_periodic("master", Phase::master, 0, kCycle, [this](SimTime t) { master_tick(t); });
    sched_.add_periodic("physics", Phase::physics, 0, kCycle, [this](SimTime t) {
      net_->advance(t);
      for (std::size_t i = 0; i < 4; ++i) angle_[i] += speed_[i] * 1e-3;
    });
  }

  // One lockstep tick: the frames returned so far reach the master, it runs and sends, and the
  // twin takes exactly what it sent.
  void master_tick(SimTime t) {
    net_->advance(t);
    net_->flush_transport();
    std::array<std::uint8_t, 1600> buf{};
    for (;;) {
      const int n = master_link_->receive(buf, std::chrono::nanoseconds(0));
      if (n <= 0) break;
      master_->on_frame(std::span<std::uint8_t>(buf.data(), static_cast<std::size_t>(n)), t);
    }
    master_->tick(t);
    ASSERT_TRUE(net_->drain_transport(sent_, t, std::chrono::milliseconds(1000)));
  }

  void run_until(double seconds) { sched_.run_until(static_cast<SimTime>(seconds * 1e9) + 1, pacer_); }

  const ethercat::Esc& esc(int i) const { return net_->slave(i).esc(); }

  omnitwin::testing::TempDir dir_{"omnitwin-ecnet"};
  Scenario scenario_;
  Scheduler sched_;
  LockstepPacer pacer_;
  std::array<double, 4> angle_{}, speed_{};
  std::vector<std::string> log_;
  std::unique_ptr<EthercatNetwork> net_;
  std::unique_ptr<ethercat::EcTransport> master_link_;
  std::unique_ptr<me::EcMaster> master_;
  std::uint64_t sent_ = 0;
};

TEST_F(EthercatNetworkTest, MasterBringsTheFourDrivesToOpOverTheSegment) {
  build("ecnet-op");
  run_until(1.0);
  EXPECT_TRUE(master_->operational()) << master_->error();
  EXPECT_EQ(master_->slave_count(), 4);
  EXPECT_EQ(master_->stats().wkc_errors, 0u);
  EXPECT_EQ(master_->stats().last_wkc, 12u);
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(esc(i).al_state(), ethercat::AlState::op) << "slave " << i + 1;
    EXPECT_EQ(esc(i).station_address(), 0x1001 + i);
    EXPECT_EQ(net_->wheel_record(i).node, 0x1001 + i);
  }
  // Every frame the master sent went through the line and came back (the last one after the
  // final tick is still on its way), and the capture holds both directions.
  const BusSample b = net_->bus_sample();
  EXPECT_EQ(b.frames_rx, sent_);
  EXPECT_EQ(b.dropouts, 0u);
  EXPECT_GE(b.frames_tx + 1, b.frames_rx);
  EXPECT_EQ(b.wkc, 12);  // the process data's WKC as the master saw it (LRW: 3 per slave)
  for (int i = 0; i < 4; ++i) {
    EXPECT_STREQ(net_->drive_detail(i).comm, "OP") << "slave " << i + 1;
    // This master takes the segment to OP and enables no drive: CiA 402 stays where it starts.
    EXPECT_STREQ(net_->drive_detail(i).device, "switch on disabled") << "slave " << i + 1;
  }
  const nlohmann::json m = net_->bus_metrics(sched_.now());
  EXPECT_EQ(m.at("name"), "ethercat");
  EXPECT_EQ(m.at("transport"), "mem:ecnet-op");
  EXPECT_GT(m.at("load").get<double>(), 0.0);
  // AL state changes were logged.
  EXPECT_NE(std::find_if(log_.begin(), log_.end(), [](const std::string& s) { return s.find("AL OP") != std::string::npos; }),
            log_.end());
}

// Two frames in one tick (as a master sends an image larger than a frame): the second enters
// the line when the first's 1,000 bytes, Ethernet overhead and inter-frame gap have gone out,
// (1000 + 38) × 80 ns = 83.04 µs later (the capture's timestamps), and both come back,
// answered by all four slaves.
TEST_F(EthercatNetworkTest, TwoFramesOfOneTickShareTheLineOneAfterTheOther) {
  build("ecnet-serial");
  sched_.add_periodic("burst", Phase::master, 200'000'000, 1'000'000'000, [this](SimTime t) {
    for (int k = 0; k < 2; ++k) {
      std::array<std::uint8_t, 1000> pdu{};
      ethercat::PduBuilder b(pdu);
      ASSERT_GE(b.add(ethercat::Cmd::brd, static_cast<std::uint8_t>(0xE0 + k), 0, 0x0000, 1000 - 14), 0);
      ASSERT_EQ(b.finish(), 1000u);
      ASSERT_TRUE(master_link_->send(pdu));
      ++sent_;
    }
    ASSERT_TRUE(net_->drain_transport(sent_, t, std::chrono::milliseconds(1000)));
  });
  run_until(0.21);
  net_.reset();  // closes the capture
  char err[PCAP_ERRBUF_SIZE];
  pcap_t* p = pcap_open_offline_with_tstamp_precision((dir_ / "bus-ethercat.pcap").c_str(), PCAP_TSTAMP_PRECISION_NANO, err);
  ASSERT_NE(p, nullptr) << err;
  std::vector<std::int64_t> at_ns;  // the burst's records in capture order: out, back, out, back
  std::vector<int> wkc;              // … and the WKC each carries (the PDU's last two bytes)
  pcap_pkthdr* h = nullptr;
  const u_char* data = nullptr;
  while (pcap_next_ex(p, &h, &data) == 1) {
    if (h->caplen < 1000) continue;
    at_ns.push_back(static_cast<std::int64_t>(h->ts.tv_sec) * 1'000'000'000 + h->ts.tv_usec);
    wkc.push_back(data[h->caplen - 2] | data[h->caplen - 1] << 8);
  }
  pcap_close(p);
  ASSERT_EQ(at_ns.size(), 4u);
  EXPECT_EQ(at_ns[2] - at_ns[0], 83'040);
  EXPECT_EQ(wkc, (std::vector<int>{0, 4, 0, 4}));  // out untouched, back read by all four slaves
}

TEST_F(EthercatNetworkTest, LinkBreakDropsTheWkcAndTheSlavesComeBack) {
  build("ecnet-link");
  run_until(1.0);
  ASSERT_TRUE(master_->operational());
  FaultSpec f;
  f.kind = FaultSpec::Kind::link_break;
  f.wheel = 2;  // after slave 2: slaves 3 and 4 unreachable
  net_->apply_fault(f, true, sched_.now());
  run_until(1.3);
  EXPECT_GT(master_->stats().wkc_errors, 0u);
  EXPECT_LT(net_->bus_sample().wkc, 12);  // the live view sees the WKC drop too
  // Slaves 3 and 4 lost their outputs: watchdog, SAFE-OP with 0x001B; 1 and 2 run on.
  EXPECT_EQ(esc(0).al_state(), ethercat::AlState::op);
  EXPECT_EQ(esc(1).al_state(), ethercat::AlState::op);
  for (int i : {2, 3}) {
    EXPECT_EQ(esc(i).al_state(), ethercat::AlState::safeop) << "slave " << i + 1;
    EXPECT_EQ(esc(i).al_status_code(), ethercat::AlStatusCode::watchdog) << "slave " << i + 1;
  }
  net_->apply_fault(f, false, sched_.now());
  run_until(3.0);
  EXPECT_EQ(master_->stats().last_wkc, 12u);
  EXPECT_GE(master_->stats().recoveries, 1u);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(esc(i).al_state(), ethercat::AlState::op) << "slave " << i + 1;
}

TEST_F(EthercatNetworkTest, PowerLossTakesTheSlaveOffAndItReturnsInItsPowerOnState) {
  build("ecnet-power");
  run_until(1.0);
  ASSERT_TRUE(master_->operational());
  FaultSpec f;
  f.kind = FaultSpec::Kind::power_loss;
  f.wheel = 1;
  net_->apply_fault(f, true, sched_.now());
  run_until(1.2);
  EXPECT_EQ(net_->drive_state(1), DriveStateCode::off);
  EXPECT_STREQ(net_->drive_detail(1).comm, "off");
  EXPECT_DOUBLE_EQ(speed_[1], 0.0);  // the amplifier lost its setpoint
  net_->apply_fault(f, false, sched_.now());
  EXPECT_EQ(esc(1).al_state(), ethercat::AlState::init);  // power-on state
  EXPECT_EQ(esc(1).station_address(), 0);
  run_until(3.0);
  EXPECT_EQ(esc(1).al_state(), ethercat::AlState::op);
  EXPECT_EQ(master_->stats().last_wkc, 12u);
}

TEST_F(EthercatNetworkTest, StoppedMasterTripsTheWatchdogs) {
  build("ecnet-wd");
  run_until(1.0);
  ASSERT_TRUE(master_->operational());
  FaultSpec f;
  f.kind = FaultSpec::Kind::frame_loss;
  f.wheel = FaultSpec::kMaster;
  f.rate = 1.0;
  net_->apply_fault(f, true, sched_.now());
  run_until(1.4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(esc(i).al_state(), ethercat::AlState::safeop) << "slave " << i + 1;
    EXPECT_TRUE(esc(i).al_error());
    EXPECT_EQ(esc(i).al_status_code(), ethercat::AlStatusCode::watchdog);
  }
  EXPECT_GT(net_->bus_metrics(sched_.now()).at("lost_frames").get<int>(), 300);
  net_->apply_fault(f, false, sched_.now());
  run_until(3.0);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(esc(i).al_state(), ethercat::AlState::op) << "slave " << i + 1;
}

// Found in review: the delay fault's jitter was drawn once per fault, so every returned frame
// came back equally late; it is drawn per frame (FaultSpec), so the return times spread.
TEST_F(EthercatNetworkTest, DelayJitterIsDrawnPerFrame) {
  build("ecnet-jitter");
  run_until(1.0);
  ASSERT_TRUE(master_->operational());
  FaultSpec f;
  f.kind = FaultSpec::Kind::delay;
  f.wheel = FaultSpec::kMaster;
  f.jitter_ms = 0.3;
  net_->apply_fault(f, true, sched_.now());
  run_until(1.1);
  net_.reset();  // closes the capture
  char err[PCAP_ERRBUF_SIZE];
  pcap_t* p = pcap_open_offline_with_tstamp_precision((dir_ / "bus-ethercat.pcap").c_str(), PCAP_TSTAMP_PRECISION_NANO, err);
  ASSERT_NE(p, nullptr) << err;
  std::set<std::int64_t> phases;  // each record's time within its 1 ms cycle
  pcap_pkthdr* h = nullptr;
  const u_char* data = nullptr;
  while (pcap_next_ex(p, &h, &data) == 1) {
    const std::int64_t t = static_cast<std::int64_t>(h->ts.tv_sec) * 1'000'000'000 + h->ts.tv_usec;
    if (t > 1'001'000'000 && t < 1'099'000'000) phases.insert(t % kCycle);
  }
  pcap_close(p);
  EXPECT_GT(phases.size(), 50u) << "one delay for all frames gives a handful of phases";
}

TEST_F(EthercatNetworkTest, DriftFaultChangesOneSlavesOscillator) {
  build("ecnet-drift");
  run_until(0.2);
  const std::int64_t before = esc(2).local_time(sched_.now()) - esc(1).local_time(sched_.now());
  FaultSpec f;
  f.kind = FaultSpec::Kind::drift;
  f.wheel = 2;
  f.drift = 500e-6;
  net_->apply_fault(f, true, sched_.now());
  const SimTime t0 = sched_.now();
  run_until(1.2);
  const std::int64_t after = esc(2).local_time(sched_.now()) - esc(1).local_time(sched_.now());
  // Slave 3 now gains about 500 ppm − (−15 ppm) on slave 2 per second of sim time.
  const double gained = static_cast<double>(after - before) / (static_cast<double>(sched_.now() - t0) * 1e-9);
  EXPECT_NEAR(gained, (500e-6 + 15e-6) * 1e9, 20e3);
  EXPECT_EQ(net_->slave_metrics().at(2).at("drift"), 500e-6);
}

}  // namespace
}  // namespace omnitwin::twin
