// Tests controller/omni_master: the fig. 4-15 master core driven by hand-made frames and
// ticks. Start-up: one detection request per tick until the four slaves answer, then NMT
// start `00 01` on ID 0 (fig. 4-20), the slave setting fan-out `02 01 00 64` before it, and
// the first 0x102 command `02 00 00 00 00` on the next tick (path time 0); the PC's
// parameter 0x702 `01 0C 00 00 00 64` forwarded to 0x704/0x708/0x710/0x720 (fig. 4-19) and
// refused while running; the PC's detection request answered with 0x002. Running: the
// commands are exactly the platform loop's (checked against a PlatformLoop fed the same
// counts), a +X line turns axes 1, 2 positive and 3, 4 negative, and the ideal closed loop
// ends at the goal. Stops: a missing detection answer (after detect_misses rounds), missing
// feedback, NMT stop from the bus (to all: nothing sent; to the master: stop all), startup
// timeout, a refusing transport, and the normal end after settle; wait_for_pc; restart after
// a stop; bad frames counted, never thrown.
#include "controller/omni_master.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

namespace omnitwin::controller {
namespace {

using can::Frame;
using can::make_data;
using can::make_remote;
namespace node = omni::node;

constexpr std::int64_t kPeriodNs = 10'000'000;

// A master on a recording bus, with its own tick clock (10 ms).
struct Harness {
  explicit Harness(const MasterConfig& c)
      : master(c, [this](const Frame& f) {
          if (refuse) return false;
          sent.push_back(f);
          return true;
        }) {}
  Harness(const Harness&) = delete;

  void tick() {
    master.on_tick(now);
    now += kPeriodNs;
  }
  FrameOutcome rx(const Frame& f) { return master.on_frame(f, now); }
  std::vector<Frame> take() {
    std::vector<Frame> out;
    out.swap(sent);
    return out;
  }
  void answer(std::initializer_list<std::uint8_t> nodes) {
    for (std::uint8_t n : nodes) EXPECT_EQ(rx(make_remote(n)), FrameOutcome::handled);
  }
  void answer_all() { answer({node::axis1, node::axis2, node::axis3, node::axis4}); }
  void feedback(int axis, std::int32_t value) {
    const auto r = omni::encode(omni::SpeedFeedback{omni::slave_of_axis(axis), omni::data_type::speed, value});
    EXPECT_EQ(rx(std::get<Frame>(r)), FrameOutcome::handled);
  }
  void feedback_all(std::array<std::int32_t, 4> v) {
    for (int a = 1; a <= 4; ++a) feedback(a, v[a - 1]);
  }
  // detecting → running: a tick with a request, the four answers, the tick that starts.
  void start() {
    tick();
    answer_all();
    tick();
    ASSERT_EQ(master.state(), MasterState::running);
    take();
  }

  std::vector<Frame> sent;
  bool refuse = false;
  std::int64_t now = 0;
  OmniMaster master;
};

MasterConfig line_config(double dx = 0.5, double duration = 2.0) {
  MasterConfig c;
  c.path.segments.push_back(SegmentSpec{.kind = SegmentSpec::Kind::line, .duration = duration, .dx = dx});
  return c;
}

const Frame kDetect = make_remote(0x000);
const Frame kStartAll = make_data(0x000, {0x00, 0x01});
const Frame kStopAll = make_data(0x000, {0x00, 0x02});

std::string str(const std::vector<Frame>& fs) {
  std::string s;
  for (const Frame& f : fs) s += can::to_string(f) + "; ";
  return s;
}

omni::SpeedCommand command_of(const Frame& f) {
  const auto r = omni::decode(f);
  const auto* m = std::get_if<omni::Message>(&r);
  if (m == nullptr || !std::holds_alternative<omni::SpeedCommand>(*m)) {
    ADD_FAILURE() << "not a speed command: " << can::to_string(f);
    return {};
  }
  return std::get<omni::SpeedCommand>(*m);
}

// The one 0x102 frame among `fs`.
omni::SpeedCommand the_command(const std::vector<Frame>& fs) {
  int n = 0;
  omni::SpeedCommand c;
  for (const Frame& f : fs)
    if (f.id == 0x102) c = command_of(f), ++n;
  EXPECT_EQ(n, 1) << str(fs);
  return c;
}

// Ideal slaves: each turns exactly its command's counts in its sample and reports them.
void ideal_slaves(Harness& h, const std::vector<Frame>& fs, std::array<std::int32_t, 4>* total = nullptr) {
  for (const Frame& f : fs) {
    if (f.id == 0x000 && f.kind == can::FrameKind::remote) h.answer_all();
    if (f.id != 0x102) continue;
    const omni::SpeedCommand c = command_of(f);
    h.feedback_all({c.axis[0], c.axis[1], c.axis[2], c.axis[3]});
    if (total)
      for (int i = 0; i < 4; ++i) (*total)[i] += c.axis[i];
  }
}

TEST(OmniMaster, StartUpDetectsEveryTickThenStartsAllAndCommandsNextTick) {
  Harness h(line_config());
  EXPECT_EQ(h.master.state(), MasterState::detecting);
  EXPECT_TRUE(h.sent.empty());
  for (int i = 0; i < 3; ++i) h.tick();
  EXPECT_EQ(h.take(), (std::vector<Frame>{kDetect, kDetect, kDetect}));
  // Three of four answers (fig. 4-18's IDs 4, 8, 16): still detecting.
  h.answer({node::axis1, node::axis2, node::axis3});
  h.tick();
  EXPECT_EQ(h.take(), std::vector<Frame>{kDetect});
  EXPECT_EQ(h.master.state(), MasterState::detecting);
  h.answer({node::axis4});
  h.tick();
  EXPECT_EQ(h.take(), std::vector<Frame>{kStartAll});
  EXPECT_EQ(h.master.state(), MasterState::running);
  EXPECT_EQ(h.master.report().path_origin_ns, -1);
  // Next sample: the first command at rest, `02 00 00 00 00` on 0x102 (fig. 4-20), then
  // node detection between the samples.
  const std::int64_t t_origin = h.now;
  h.tick();
  EXPECT_EQ(h.take(), (std::vector<Frame>{make_data(0x102, {0x02, 0, 0, 0, 0}), kDetect}));
  EXPECT_EQ(h.master.report().path_origin_ns, t_origin);
  EXPECT_EQ(h.master.stats().starts, 1u);
  EXPECT_EQ(h.master.stats().detection_answers, 4u);
}

TEST(OmniMaster, ForwardsThePcParameterToTheFourSlavesFig419) {
  Harness h(line_config());
  EXPECT_EQ(h.rx(make_data(0x702, {0x01, 0x0C, 0x00, 0x00, 0x00, 0x64})), FrameOutcome::handled);
  EXPECT_EQ(h.take(), (std::vector<Frame>{make_data(0x704, {0x02, 0x01, 0x00, 0x64}),
                                          make_data(0x708, {0x02, 0x01, 0x00, 0x64}),
                                          make_data(0x710, {0x02, 0x01, 0x00, 0x64}),
                                          make_data(0x720, {0x02, 0x01, 0x00, 0x64})}));
  EXPECT_EQ(h.master.slave_setting(), std::optional<std::uint16_t>(100));
  EXPECT_EQ(h.master.stats().parameters_forwarded, 1u);
  // Another data type, or a value the 2-byte slave frame cannot carry: refused.
  EXPECT_EQ(h.rx(make_data(0x702, {0x01, 0x05, 0, 0, 0, 1})), FrameOutcome::refused);
  EXPECT_EQ(h.rx(make_data(0x702, {0x01, 0x0C, 0, 1, 0, 0})), FrameOutcome::refused);
  // Addressed to a slave directly: not the master's business.
  EXPECT_EQ(h.rx(make_data(0x704, {0x01, 0x01, 0x00, 0x64})), FrameOutcome::ignored);
  EXPECT_TRUE(h.take().empty());
  // The setting is sent again before the NMT start, then kept from the PC's value.
  h.tick();
  h.answer_all();
  h.take();
  h.tick();
  EXPECT_EQ(h.take(), (std::vector<Frame>{make_data(0x704, {0x02, 0x01, 0x00, 0x64}),
                                          make_data(0x708, {0x02, 0x01, 0x00, 0x64}),
                                          make_data(0x710, {0x02, 0x01, 0x00, 0x64}),
                                          make_data(0x720, {0x02, 0x01, 0x00, 0x64}), kStartAll}));
  // While running the slaves take no parameters: refused and counted, nothing sent.
  EXPECT_EQ(h.rx(make_data(0x702, {0x01, 0x0C, 0x00, 0x00, 0x00, 0x32})), FrameOutcome::refused);
  EXPECT_TRUE(h.take().empty());
  EXPECT_EQ(h.master.stats().parameters_refused, 3u);
  EXPECT_EQ(h.master.slave_setting(), std::optional<std::uint16_t>(100));
}

TEST(OmniMaster, ConfiguredSlaveKpPrecedesTheNmtStart) {
  MasterConfig c = line_config();
  c.slave_kp = 0x1234;
  Harness h(c);
  h.tick();
  h.answer_all();
  h.take();
  h.tick();
  const auto fs = h.take();
  ASSERT_EQ(fs.size(), 5u) << str(fs);
  const std::uint16_t ids[] = {0x704, 0x708, 0x710, 0x720};
  for (int i = 0; i < 4; ++i) EXPECT_EQ(fs[i], make_data(ids[i], {0x02, 0x01, 0x12, 0x34}));
  EXPECT_EQ(fs[4], kStartAll);
}

TEST(OmniMaster, AnswersThePcDetectionRequestInEveryState) {
  MasterConfig c = line_config();
  c.wait_for_pc = true;
  Harness h(c);
  EXPECT_EQ(h.rx(kDetect), FrameOutcome::handled);
  EXPECT_EQ(h.take(), std::vector<Frame>{make_remote(0x002)});
  EXPECT_EQ(h.master.stats().pc_detections_answered, 1u);
}

TEST(OmniMaster, WaitsForThePcStartThenDetects) {
  MasterConfig c = line_config();
  c.wait_for_pc = true;
  Harness h(c);
  EXPECT_EQ(h.master.state(), MasterState::waiting);
  for (int i = 0; i < 5; ++i) h.tick();
  EXPECT_TRUE(h.take().empty());
  // A start for one slave or a stop is not for a waiting master.
  EXPECT_EQ(h.rx(make_data(0x000, {0x04, 0x01})), FrameOutcome::ignored);
  EXPECT_EQ(h.rx(make_data(0x000, {0x02, 0x02})), FrameOutcome::ignored);
  EXPECT_EQ(h.master.state(), MasterState::waiting);
  // fig. 4-20: the PC starts the master with ID 0 `02 01`.
  EXPECT_EQ(h.rx(make_data(0x000, {0x02, 0x01})), FrameOutcome::handled);
  EXPECT_EQ(h.master.state(), MasterState::detecting);
  EXPECT_TRUE(h.take().empty());
  h.tick();
  EXPECT_EQ(h.take(), std::vector<Frame>{kDetect});
  // A second start while detecting changes nothing.
  EXPECT_EQ(h.rx(make_data(0x000, {0x02, 0x01})), FrameOutcome::ignored);
}

TEST(OmniMaster, CommandsAreThePlatformLoopsAndAPlusXLineTurnsAxes12Positive) {
  const MasterConfig c = line_config(0.5, 2.0);
  Harness h(c);
  h.start();
  // The reference: the same loop fed the same counts at the same path times.
  PlatformLoop ref(c.loop, build_path(c.path));
  ref.reset(Pose2{}, WheelCounts{});
  std::array<std::int32_t, 4> total{};
  int moving = 0;
  for (int k = 0; k < 200; ++k) {
    h.tick();
    const auto fs = h.take();
    const omni::SpeedCommand got = the_command(fs);
    const auto out = ref.step(k / 100.0, WheelCounts{total[0], total[1], total[2], total[3]});
    for (int i = 0; i < 4; ++i) ASSERT_EQ(got.axis[i], omni::axis_command_from(out.wheel_counts_per_sample[i])) << k;
    // Wire order: byte 1 = axis 4 … byte 4 = axis 1.
    const Frame& f = fs.front();
    ASSERT_EQ(f.id, 0x102u);
    EXPECT_EQ(static_cast<std::int8_t>(f.data[4]), got.axis[0]);
    EXPECT_EQ(static_cast<std::int8_t>(f.data[1]), got.axis[3]);
    if (got.axis[0] != 0) {
      ++moving;
      EXPECT_GT(got.axis[0], 0);
      EXPECT_EQ(got.axis[1], got.axis[0]);
      EXPECT_EQ(got.axis[2], -got.axis[0]);
      EXPECT_EQ(got.axis[3], -got.axis[0]);
    }
    ideal_slaves(h, fs, &total);
  }
  EXPECT_GT(moving, 150);
  EXPECT_EQ(h.master.state(), MasterState::running);
  EXPECT_EQ(h.master.stats().commands_sent, 200u);
  EXPECT_EQ(h.master.stats().detection_rounds, 199u);
  EXPECT_EQ(h.master.stats().detection_misses, 0u);
}

TEST(OmniMaster, IdealClosedLoopReachesTheGoalAndFinishesAfterSettle) {
  MasterConfig c = line_config(0.5, 2.0);
  c.settle = 4.0;
  Harness h(c);
  h.start();
  int ticks = 0;
  while (h.master.state() == MasterState::running && ticks < 1000) {
    h.tick();
    ideal_slaves(h, h.take());
    ++ticks;
  }
  // Path 2 s + settle 4 s = 600 samples of commands, then the stop on tick 601.
  EXPECT_EQ(h.master.state(), MasterState::finished);
  EXPECT_EQ(ticks, 601);
  EXPECT_EQ(h.master.stats().commands_sent, 600u);
  const auto r = h.master.report();
  EXPECT_EQ(r.reason, StopReason::none);
  EXPECT_NEAR(r.odometry[0], 0.5, 0.003);
  EXPECT_NEAR(r.odometry[1], 0.0, 1e-9);
  EXPECT_NEAR(r.reference[0], 0.5, 1e-12);
  // The last tick sent only the stop; a finished master sends nothing more.
  h.tick();
  EXPECT_TRUE(h.take().empty());
}

TEST(OmniMaster, LastTickOfAFinishSendsStopAll) {
  MasterConfig c = line_config(0.01, 0.05);
  c.settle = 0.0;
  Harness h(c);
  h.start();
  std::vector<Frame> last;
  for (int k = 0; k < 6; ++k) {
    h.tick();
    last = h.take();
    ideal_slaves(h, last);
  }
  EXPECT_EQ(h.master.state(), MasterState::finished);
  EXPECT_EQ(last, std::vector<Frame>{kStopAll});
}

TEST(OmniMaster, NegativeSettleNeverFinishes) {
  MasterConfig c = line_config(0.01, 0.05);
  c.settle = -1;
  Harness h(c);
  h.start();
  for (int k = 0; k < 100; ++k) {
    h.tick();
    ideal_slaves(h, h.take());
  }
  EXPECT_EQ(h.master.state(), MasterState::running);
}

TEST(OmniMaster, AMissingNodeStopsTheSystemAtTheNextRound) {
  Harness h(line_config());
  h.start();
  h.tick();  // origin tick: command + request
  h.take();
  h.feedback_all({0, 0, 0, 0});
  h.answer({node::axis1, node::axis3, node::axis4});  // 0x08 does not answer
  h.tick();
  EXPECT_EQ(h.take(), std::vector<Frame>{kStopAll});
  const auto r = h.master.report();
  EXPECT_EQ(r.state, MasterState::stopped);
  EXPECT_EQ(r.reason, StopReason::node_missing);
  EXPECT_EQ(r.node, node::axis2);
  // Stopped: holds, sends nothing.
  h.tick();
  EXPECT_TRUE(h.take().empty());
}

TEST(OmniMaster, DetectMissesAndDetectEveryShapeTheRounds) {
  MasterConfig c = line_config();
  c.detect_every = 3;
  c.detect_misses = 2;
  Harness h(c);
  h.start();
  int requests = 0;
  // Node 0x20 never answers: rounds at run ticks 0, 3, 6; checks at 3 (miss 1), 6 (miss 2).
  for (int k = 0; k < 7 && h.master.state() == MasterState::running; ++k) {
    h.tick();
    for (const Frame& f : h.take()) requests += f == kDetect;
    h.feedback_all({0, 0, 0, 0});
    h.answer({node::axis1, node::axis2, node::axis3});
  }
  EXPECT_EQ(requests, 2);
  EXPECT_EQ(h.master.report().reason, StopReason::node_missing);
  EXPECT_EQ(h.master.report().node, node::axis4);
  EXPECT_EQ(h.master.stats().detection_rounds, 2u);
  EXPECT_EQ(h.master.stats().detection_misses, 2u);
}

TEST(OmniMaster, DetectEveryZeroSendsNoRequestsWhileRunning) {
  MasterConfig c = line_config();
  c.detect_every = 0;
  Harness h(c);
  h.start();
  for (int k = 0; k < 20; ++k) {
    h.tick();
    const auto fs = h.take();
    ASSERT_EQ(fs.size(), 1u) << str(fs);
    ideal_slaves(h, fs);
  }
  EXPECT_EQ(h.master.state(), MasterState::running);
}

TEST(OmniMaster, MissingFeedbackStopsAfterTheTimeout) {
  MasterConfig c = line_config();
  c.feedback_timeout = 4;
  Harness h(c);
  h.start();
  int ticks = 0;
  while (h.master.state() == MasterState::running && ticks < 50) {
    h.tick();
    ++ticks;
    h.take();
    h.answer_all();
    h.feedback(1, 0), h.feedback(2, 0), h.feedback(4, 0);  // axis 3 (0x10) is silent
  }
  // Origin tick, then 4 ticks without axis 3's feedback.
  EXPECT_EQ(ticks, 5);
  EXPECT_EQ(h.master.report().reason, StopReason::feedback_missing);
  EXPECT_EQ(h.master.report().node, node::axis3);
}

TEST(OmniMaster, NmtStopFromTheBus) {
  {  // to all: the slaves heard it; the master only stops
    Harness h(line_config());
    h.start();
    EXPECT_EQ(h.rx(kStopAll), FrameOutcome::handled);
    EXPECT_TRUE(h.take().empty());
    EXPECT_EQ(h.master.report().state, MasterState::stopped);
    EXPECT_EQ(h.master.report().reason, StopReason::nmt_stop);
  }
  {  // to the master: it stops the slaves
    Harness h(line_config());
    h.start();
    EXPECT_EQ(h.rx(make_data(0x000, {0x02, 0x02})), FrameOutcome::handled);
    EXPECT_EQ(h.take(), std::vector<Frame>{kStopAll});
    EXPECT_EQ(h.master.report().reason, StopReason::nmt_stop);
  }
  {  // to one slave: not for the master
    Harness h(line_config());
    h.start();
    EXPECT_EQ(h.rx(make_data(0x000, {0x10, 0x02})), FrameOutcome::ignored);
    EXPECT_EQ(h.master.state(), MasterState::running);
  }
  {  // while detecting
    Harness h(line_config());
    h.tick();
    EXPECT_EQ(h.rx(make_data(0x000, {0x02, 0x02})), FrameOutcome::handled);
    EXPECT_EQ(h.master.state(), MasterState::stopped);
  }
}

TEST(OmniMaster, RestartAfterAStopKeepsOdometryAndRestartsThePath) {
  Harness h(line_config(0.5, 2.0));
  h.start();
  for (int k = 0; k < 100; ++k) {
    h.tick();
    ideal_slaves(h, h.take());
  }
  EXPECT_EQ(h.rx(make_data(0x000, {0x02, 0x02})), FrameOutcome::handled);
  h.take();
  const double x_stop = h.master.report().odometry[0];
  EXPECT_GT(x_stop, 0.1);
  // The PC starts the master again: detection, NMT start, path time 0 at the next tick.
  EXPECT_EQ(h.rx(make_data(0x000, {0x02, 0x01})), FrameOutcome::handled);
  EXPECT_EQ(h.master.report().reason, StopReason::none);
  h.start();
  const std::int64_t origin = h.now;
  h.tick();
  const auto fs = h.take();
  EXPECT_EQ(h.master.report().path_origin_ns, origin);
  // Odometry kept: the first step only adds the one sample reported after the last step
  // (under 0.5 m/s · 10 ms).
  EXPECT_GE(h.master.report().odometry[0], x_stop);
  EXPECT_NEAR(h.master.report().odometry[0], x_stop, 0.005);
  EXPECT_DOUBLE_EQ(h.master.report().reference[0], 0.0);
  // Behind the platform: the path restarts at x = 0, so the axes drive it back (−X).
  EXPECT_LT(the_command(fs).axis[0], 0);
  EXPECT_EQ(h.master.stats().starts, 2u);
}

TEST(OmniMaster, StartupTimeoutStopsAndNamesTheFirstMissingSlave) {
  MasterConfig c = line_config();
  c.startup_timeout = 0.05;
  Harness h(c);
  h.answer({node::axis1});
  std::vector<Frame> all;
  for (int k = 0; k < 8; ++k) {
    h.tick();
    for (const Frame& f : h.take()) all.push_back(f);
  }
  // Requests at 0, 10, 20, 30, 40 ms; at 50 ms the stop.
  EXPECT_EQ(all, (std::vector<Frame>{kDetect, kDetect, kDetect, kDetect, kDetect, kStopAll}));
  EXPECT_EQ(h.master.report().reason, StopReason::startup_timeout);
  EXPECT_EQ(h.master.report().node, node::axis2);
}

TEST(OmniMaster, ARefusingTransportIsABusError) {
  Harness h(line_config());
  h.start();
  h.refuse = true;
  h.tick();
  EXPECT_EQ(h.master.report().state, MasterState::stopped);
  EXPECT_EQ(h.master.report().reason, StopReason::bus_error);
  EXPECT_GE(h.master.stats().send_failures, 2u);  // the command, and the stop it tried
}

TEST(OmniMaster, ARefusalReportedAfterTheTickIsABusErrorToo) {
  // A shell that batches its sends learns of a refusal only after on_tick().
  Harness h(line_config());
  h.start();
  h.tick();
  ASSERT_FALSE(h.take().empty());
  const std::uint64_t sent = h.master.stats().frames_sent;
  h.master.note_send_failures(1);
  EXPECT_EQ(h.master.report().state, MasterState::stopped);
  EXPECT_EQ(h.master.report().reason, StopReason::bus_error);
  EXPECT_EQ(h.take(), (std::vector<Frame>{kStopAll}));  // the stop goes out at once
  EXPECT_EQ(h.master.stats().frames_sent, sent);        // − the refused one + the stop
  EXPECT_EQ(h.master.stats().send_failures, 1u);
  // Stopped already: counted, nothing more.
  h.master.note_send_failures(1);
  EXPECT_TRUE(h.take().empty());
  EXPECT_EQ(h.master.stats().send_failures, 2u);
  h.master.note_send_failures(0);
  EXPECT_EQ(h.master.stats().send_failures, 2u);
}

TEST(OmniMaster, ShutdownStopsTheSlavesUnlessAlreadyStopped) {
  Harness h(line_config());
  h.start();
  h.master.shutdown();
  EXPECT_EQ(h.take(), std::vector<Frame>{kStopAll});
  EXPECT_EQ(h.master.state(), MasterState::stopped);
  h.master.shutdown();
  EXPECT_TRUE(h.take().empty());
  EXPECT_EQ(h.master.stats().illegal_transitions, 0u);
}

TEST(OmniMaster, BadFramesAreCountedNeverThrown) {
  Harness h(line_config());
  Frame ext = make_data(0x102, {0x02, 0, 0, 0, 0}, true);
  Frame err;
  err.kind = can::FrameKind::error;
  const std::vector<Frame> bad = {
      ext, err,
      make_data(0x402, {1, 2}),                       // function code 100: unknown
      make_data(0x102, {0x02, 0, 0, 0}),              // 4-byte command: wrong DLC
      make_data(0x202, {0x08, 0, 0, 0, 0, 1}),        // axis 2's sender on axis 1's id
      make_data(0x000, {0x00, 0x07}),                 // NMT state 7
      make_remote(0x000, 3),                          // detection with DLC 3
  };
  for (const Frame& f : bad) EXPECT_EQ(h.rx(f), FrameOutcome::decode_error) << can::to_string(f);
  // Valid but not for the master: another master's command and answer, feedback of another type.
  EXPECT_EQ(h.rx(make_data(0x102, {0x02, 1, 2, 3, 4})), FrameOutcome::ignored);
  EXPECT_EQ(h.rx(make_remote(0x002)), FrameOutcome::ignored);
  EXPECT_EQ(h.rx(make_data(0x202, {0x04, 0x07, 0, 0, 0, 9})), FrameOutcome::ignored);
  const auto& s = h.master.stats();
  EXPECT_EQ(s.decode_errors, bad.size());
  EXPECT_EQ(s.frames_ignored, 3u);
  EXPECT_EQ(s.frames_received, s.frames_handled + s.frames_ignored + s.frames_refused + s.decode_errors);
  EXPECT_EQ(s.feedback_other_type, 1u);
  EXPECT_EQ(h.master.counts(), (WheelCounts{0, 0, 0, 0}));
  EXPECT_EQ(h.master.state(), MasterState::detecting);
  EXPECT_TRUE(h.take().empty());
}

TEST(OmniMaster, FeedbackAccumulatesWrapSafe) {
  Harness h(line_config());
  h.feedback(1, 2'000'000'000);
  h.feedback(1, 2'000'000'000);
  h.feedback(3, -5);
  EXPECT_EQ(h.master.counts()[0], static_cast<std::int32_t>(4'000'000'000u));
  EXPECT_EQ(h.master.counts()[2], -5);
  EXPECT_EQ(h.master.stats().feedback[0], 2u);
  EXPECT_EQ(h.master.stats().feedback[2], 1u);
}

TEST(OmniMaster, RejectsABadConfiguration) {
  MasterConfig c = line_config();
  c.loop.period = 0;
  EXPECT_THROW(OmniMaster(c, [](const Frame&) { return true; }), MasterConfigError);
}

// A tick the loop ran late (the master's own process stalled: half a period or more) judges
// no slave: the open round stays open and no request replaces it, feedback misses are not
// counted. Found by the CAN soak, where a host stall read as "none of the slaves answered".
TEST(OmniMaster, ALateTickJudgesNoSlaveAndKeepsTheRoundOpen) {
  Harness h(line_config());
  h.start();
  h.tick();  // origin tick: command + request
  h.take();
  // The master's process stalls: the slaves have answered nothing yet when the late tick runs.
  h.master.on_tick(h.now, /*late=*/true);
  h.now += kPeriodNs;
  EXPECT_EQ(h.master.report().state, MasterState::running);
  const auto late = h.take();
  EXPECT_EQ(late.size(), 1u) << "the command only: the open round keeps its request";
  EXPECT_EQ(h.master.stats().late_ticks, 1u);
  EXPECT_EQ(h.master.stats().detection_misses, 0u);
  // The answers and feedback then come; the next tick on time finds the round complete.
  h.feedback_all({0, 0, 0, 0});
  h.answer_all();
  h.tick();
  EXPECT_EQ(h.master.report().state, MasterState::running);
  EXPECT_EQ(h.master.stats().detection_misses, 0u);
  // Without the late flag the same silence stops the system at once (the thesis's rule).
  Harness strict(line_config());
  strict.start();
  strict.tick();
  strict.take();
  strict.tick();
  EXPECT_EQ(strict.master.report().reason, StopReason::node_missing);
}

TEST(OmniMaster, AWholeBusGoingSilentStopsAtTheNextRoundAndCountsEverySlaveMissing) {
  Harness h(line_config());
  h.start();
  for (int k = 0; k < 5; ++k) {
    h.tick();
    ideal_slaves(h, h.take());
  }
  EXPECT_EQ(h.master.missing_slaves(), 0);
  // The twin is gone: ticks keep coming (wall clock), no frame arrives any more. The first
  // tick still has the answers to the last round; the next one finds none.
  h.tick();
  EXPECT_EQ(h.master.report().state, MasterState::running);
  h.take();
  h.tick();
  EXPECT_EQ(h.take(), std::vector<Frame>{kStopAll});
  EXPECT_EQ(h.master.report().state, MasterState::stopped);
  EXPECT_EQ(h.master.report().reason, StopReason::node_missing);
  EXPECT_EQ(h.master.report().node, node::axis1);
  EXPECT_EQ(h.master.missing_slaves(), 4);
  for (int k = 0; k < 20; ++k) h.tick();
  EXPECT_TRUE(h.take().empty()) << "stopped: no more commands";
}

TEST(OmniMaster, ASilentBusWithoutDetectionStopsOnTheFeedbackTimeout) {
  MasterConfig c = line_config();
  c.detect_every = 0;
  c.feedback_timeout = 3;
  Harness h(c);
  h.start();
  h.tick();
  ideal_slaves(h, h.take());
  int ticks = 0;
  while (h.master.state() == MasterState::running && ticks < 50) h.tick(), ++ticks;
  EXPECT_EQ(ticks, 4);  // one tick on the last feedback, then 3 without
  EXPECT_EQ(h.master.report().reason, StopReason::feedback_missing);
  EXPECT_EQ(h.master.missing_slaves(), 4);
}

TEST(OmniMaster, OneMissingNodeIsNotASilentBus) {
  Harness h(line_config());
  h.start();
  h.tick();
  h.take();
  h.feedback_all({0, 0, 0, 0});
  h.answer({node::axis1, node::axis3, node::axis4});
  h.tick();
  EXPECT_EQ(h.master.report().reason, StopReason::node_missing);
  EXPECT_EQ(h.master.missing_slaves(), 1);
}

}  // namespace
}  // namespace omnitwin::controller
