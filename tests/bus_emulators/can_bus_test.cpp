// Tests bus_emulators/can/can_bus: arbitration order among simultaneous and late (SOF-bit)
// submits, exact SOF/EOF times from frame_bits, back-to-back frames separated by the
// intermission, ACK errors of a lone node (TEC to 128, error passive, retries with suspend
// bits, never bus-off), bus-off after injected corruption, recovery only on request after
// 128 × 11 recessive bits (idle and busy bus), suspend transmission letting others go first,
// power loss and return, listen-only nodes, bad submits, and per-node / per-bus statistics.
#include "bus_emulators/can/can_bus.hpp"

#include <gtest/gtest.h>

#include <vector>

#include "bus_emulators/can/can_timing.hpp"

namespace omnitwin::can {
namespace {

constexpr std::int64_t kUs = 1'000;  // one bit time at 1 Mbit/s [ns]

struct Rx {
  BusNode receiver;
  Frame frame;
  FrameTiming timing;
};

// Records every callback of a bus.
struct Recorder {
  std::vector<Rx> rx;
  std::vector<Rx> tx;  // receiver = sender
  std::vector<BusEvent> events;

  explicit Recorder(CanBus& bus) {
    bus.on_deliver([this](BusNode r, const Frame& f, const FrameTiming& t) { rx.push_back({r, f, t}); });
    bus.on_tx_done([this](BusNode s, const Frame& f, const FrameTiming& t) { tx.push_back({s, f, t}); });
    bus.on_event([this](const BusEvent& e) { events.push_back(e); });
  }
  std::vector<Frame> received_by(BusNode n) const {
    std::vector<Frame> out;
    for (const Rx& r : rx)
      if (r.receiver == n) out.push_back(r.frame);
    return out;
  }
  std::vector<BusEvent> of_kind(BusEventKind k) const {
    std::vector<BusEvent> out;
    for (const BusEvent& e : events)
      if (e.kind == k) out.push_back(e);
    return out;
  }
};

TEST(CanBus, ArbitrationOrderWithSimultaneousSubmits) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode a = bus.attach(), b = bus.attach(), c = bus.attach(), d = bus.attach();
  const Frame f202 = make_data(0x202, {0x04, 0, 0, 0, 0, 0});
  const Frame f102 = make_data(0x102, {0x02, 0, 0, 0, 0});
  const Frame r000 = make_remote(0x000);
  ASSERT_EQ(bus.submit(a, f202, 0), SubmitStatus::queued);
  ASSERT_EQ(bus.submit(b, f102, 0), SubmitStatus::queued);
  ASSERT_EQ(bus.submit(c, r000, 0), SubmitStatus::queued);
  bus.advance(1'000'000);
  const std::vector<Frame> got = rec.received_by(d);
  ASSERT_EQ(got.size(), 3u);
  EXPECT_EQ(got[0], r000);
  EXPECT_EQ(got[1], f102);
  EXPECT_EQ(got[2], f202);
  EXPECT_EQ(bus.node_stats(a).arbitration_lost, 2u);
  EXPECT_EQ(bus.node_stats(b).arbitration_lost, 1u);
  EXPECT_EQ(bus.node_stats(c).arbitration_lost, 0u);
  // Losers retry at the next idle: each SOF is the previous EOF plus the intermission.
  ASSERT_EQ(rec.tx.size(), 3u);
  EXPECT_EQ(rec.tx[0].timing.sof_ns, 0);
  EXPECT_EQ(rec.tx[0].timing.end_ns, frame_bits(r000) * kUs);
  EXPECT_EQ(rec.tx[1].timing.sof_ns, rec.tx[0].timing.end_ns + 3 * kUs);
  EXPECT_EQ(rec.tx[2].timing.sof_ns, rec.tx[1].timing.end_ns + 3 * kUs);
  EXPECT_EQ(rec.tx[2].timing.submit_ns, 0);
  EXPECT_EQ(rec.tx[2].timing.attempts, 1);  // arbitrations lost are not attempts
}

TEST(CanBus, StandardBeatsExtendedWithTheSameBaseIdAndDataBeatsRemote) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode ext = bus.attach(), rem = bus.attach(), dat = bus.attach(), xrem = bus.attach(),
                sink = bus.attach();
  const Frame fx = make_data(0x123u << 18, {1}, true);  // same base id 0x123, extended
  const Frame fr = make_remote(0x123, 1);
  const Frame fd = make_data(0x123, {1});
  const Frame fxr = make_remote(0x123u << 18, 1, true);
  bus.submit(xrem, fxr, 0);
  bus.submit(ext, fx, 0);
  bus.submit(rem, fr, 0);
  bus.submit(dat, fd, 0);
  bus.advance(10'000'000);
  const std::vector<Frame> got = rec.received_by(sink);
  ASSERT_EQ(got.size(), 4u);
  EXPECT_EQ(got[0], fd);   // standard data
  EXPECT_EQ(got[1], fr);   // standard remote (IDE dominant beats the extended frames' SRR/IDE)
  EXPECT_EQ(got[2], fx);   // extended data
  EXPECT_EQ(got[3], fxr);  // extended remote
}

TEST(CanBus, DeliveryTimesFollowFrameBitsAndBitRate) {
  for (const std::int64_t rate : {1'000'000, 125'000}) {
    BusConfig cfg;
    cfg.bit_rate_bps = rate;
    CanBus bus(cfg);
    Recorder rec(bus);
    const BusNode a = bus.attach(), b = bus.attach();
    const Frame f = make_data(0x102, {0x02, 0, 0, 0, 0});
    ASSERT_EQ(frame_bits(f), 93);
    const std::int64_t bit = 1'000'000'000 / rate;
    EXPECT_EQ(bus.next_event_ns(), kNoEvent);
    bus.submit(a, f, 7 * bit);
    EXPECT_EQ(bus.next_event_ns(), 7 * bit);  // bus idle: SOF at once
    bus.advance(7 * bit);
    EXPECT_EQ(bus.phase(), BusPhase::frame);
    EXPECT_EQ(bus.next_event_ns(), 7 * bit + 93 * bit);  // end of EOF
    bus.advance(7 * bit + 93 * bit - 1);
    EXPECT_TRUE(rec.rx.empty());
    bus.advance(7 * bit + 93 * bit);
    ASSERT_EQ(rec.rx.size(), 1u);
    EXPECT_EQ(rec.rx[0].receiver, b);
    EXPECT_EQ(rec.rx[0].timing.sof_ns, 7 * bit);
    EXPECT_EQ(rec.rx[0].timing.end_ns, 100 * bit);
    EXPECT_EQ(rec.rx[0].timing.end_ns - rec.rx[0].timing.sof_ns,
              transmission_time_ns(f, rate, Intermission::excluded));
    EXPECT_EQ(bus.next_event_ns(), 103 * bit);  // intermission end
    bus.advance(103 * bit);
    EXPECT_EQ(bus.phase(), BusPhase::idle);
    EXPECT_EQ(bus.next_event_ns(), kNoEvent);
  }
}

TEST(CanBus, BackToBackQueuedFramesAreSeparatedByTheIntermission) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode a = bus.attach();
  bus.attach();
  const Frame f1 = make_data(0x010, {1, 2, 3});
  const Frame f2 = make_data(0x7F0, {});  // higher id, but FIFO within a node
  const Frame f3 = make_data(0x011, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF});
  for (const Frame& f : {f1, f2, f3}) ASSERT_EQ(bus.submit(a, f, 0), SubmitStatus::queued);
  EXPECT_EQ(bus.pending(a), 3);
  bus.advance(1'000'000);
  ASSERT_EQ(rec.tx.size(), 3u);
  EXPECT_EQ(rec.tx[0].frame, f1);
  EXPECT_EQ(rec.tx[1].frame, f2);
  EXPECT_EQ(rec.tx[2].frame, f3);
  std::int64_t expected_sof = 0;
  for (const Rx& t : rec.tx) {
    EXPECT_EQ(t.timing.sof_ns, expected_sof);
    EXPECT_EQ(t.timing.end_ns, expected_sof + frame_bits(t.frame) * kUs);
    expected_sof = t.timing.end_ns + 3 * kUs;
  }
  EXPECT_EQ(bus.pending(a), 0);
}

TEST(CanBus, LateSubmitDuringTheSofBitJoinsTheArbitration) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode a = bus.attach(), b = bus.attach(), c = bus.attach(), sink = bus.attach();
  bus.submit(a, make_data(0x200, {}), 0);
  bus.advance(0);  // SOF of a's frame
  ASSERT_EQ(bus.phase(), BusPhase::frame);
  bus.submit(b, make_data(0x100, {}), 500);   // still inside the SOF bit: joins and wins
  bus.submit(c, make_data(0x001, {}), 1'000); // after the SOF bit: waits for the next idle
  bus.advance(1'000'000);
  const std::vector<Frame> got = rec.received_by(sink);
  ASSERT_EQ(got.size(), 3u);
  EXPECT_EQ(got[0].id, 0x100u);
  EXPECT_EQ(got[1].id, 0x001u);
  EXPECT_EQ(got[2].id, 0x200u);
  EXPECT_EQ(rec.tx[0].timing.sof_ns, 0);
  EXPECT_EQ(bus.node_stats(a).arbitration_lost, 2u);
  EXPECT_EQ(rec.tx[2].timing.attempts, 1);
}

TEST(CanBus, LoneNodeAckErrorsMakeItErrorPassiveAndItKeepsRetrying) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode a = bus.attach();
  const Frame f = make_data(0x102, {0x02, 0, 0, 0, 0});
  const std::int64_t region = stuffed_region_bits(f);
  bus.submit(a, f, 0);
  bus.advance(5'000'000);
  const std::vector<BusEvent> errors = rec.of_kind(BusEventKind::error_frame);
  ASSERT_GT(errors.size(), 40u);
  // Error flag starts at the ACK delimiter: SOF + stuffed region + CRC delimiter + ACK slot.
  EXPECT_EQ(errors[0].t_ns, (region + 2) * kUs);
  for (std::size_t i = 1; i < errors.size(); ++i) {
    const bool passive = i >= 16;  // TEC 128 after the 16th ACK error
    const std::int64_t gap = (14 + 3 + (passive ? 8 : 0) + region + 2) * kUs;
    ASSERT_EQ(errors[i].t_ns - errors[i - 1].t_ns, gap) << "error " << i;
    EXPECT_EQ(errors[i].cause, ErrorCause::ack);
  }
  EXPECT_EQ(errors[14].state, ErrorState::error_active);
  EXPECT_EQ(errors[15].state, ErrorState::error_passive);
  EXPECT_EQ(bus.tec(a), 128);  // the exception for unanswered passive ACK errors holds it there
  EXPECT_EQ(bus.error_state(a), ErrorState::error_passive);
  EXPECT_EQ(bus.pending(a), 1);
  EXPECT_EQ(bus.node_stats(a).ack_errors, errors.size());
  EXPECT_EQ(bus.node_stats(a).tx_frames, 0u);
  EXPECT_EQ(bus.node_stats(a).bus_off_events, 0u);
  const std::vector<BusEvent> changes = rec.of_kind(BusEventKind::state_changed);
  ASSERT_EQ(changes.size(), 1u);
  EXPECT_EQ(changes[0].state, ErrorState::error_passive);
  EXPECT_NE(bus.next_event_ns(), kNoEvent);  // it never gives up
  // A second node arrives: the next attempt is acknowledged and TEC starts to fall.
  const BusNode b = bus.attach();
  bus.advance(6'000'000);
  EXPECT_EQ(bus.node_stats(b).rx_frames, 1u);
  EXPECT_EQ(bus.tec(a), 127);
  EXPECT_EQ(bus.error_state(a), ErrorState::error_active);
}

// Drives `bus` until `a` went bus-off by injected corruption; returns the time it happened.
std::int64_t drive_to_bus_off(CanBus& bus, BusNode a, const Frame& f) {
  bus.corrupt_next_frames(32);
  bus.submit(a, f, 0);
  while (bus.error_state(a) != ErrorState::bus_off && bus.next_event_ns() != kNoEvent)
    bus.advance(bus.next_event_ns());
  return bus.next_event_ns();
}

TEST(CanBus, CorruptedFramesDriveTheTransmitterBusOff) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode a = bus.attach(), b = bus.attach();
  const Frame f = make_data(0x102, {0x02, 0, 0, 0, 0});
  drive_to_bus_off(bus, a, f);
  bus.advance(100'000'000);
  EXPECT_EQ(bus.error_state(a), ErrorState::bus_off);
  EXPECT_EQ(bus.tec(a), 256);  // 32 × 8 > 255
  EXPECT_EQ(bus.rec(b), 32);
  EXPECT_EQ(bus.error_state(b), ErrorState::error_active);
  EXPECT_EQ(bus.stats().error_frames, 32u);
  EXPECT_EQ(bus.stats().frames, 0u);
  EXPECT_EQ(bus.corruptions_pending(), 0);
  EXPECT_TRUE(rec.rx.empty());
  EXPECT_EQ(bus.pending(a), 1);  // kept for after recovery
  EXPECT_EQ(bus.next_event_ns(), kNoEvent);  // a bus-off node stays silent without a request
  const std::vector<BusEvent> changes = rec.of_kind(BusEventKind::state_changed);
  ASSERT_EQ(changes.size(), 2u);
  EXPECT_EQ(changes[0].state, ErrorState::error_passive);
  EXPECT_EQ(changes[1].state, ErrorState::bus_off);
  const std::vector<BusEvent> errors = rec.of_kind(BusEventKind::error_frame);
  EXPECT_EQ(errors[15].t_ns, changes[0].t_ns);
  EXPECT_EQ(errors[31].t_ns, changes[1].t_ns);
  for (const BusEvent& e : errors) EXPECT_EQ(e.cause, ErrorCause::bit);
  // Bit error at the last CRC bit: the flag starts right after the stuffed region.
  EXPECT_EQ(errors[0].t_ns, stuffed_region_bits(f) * kUs);
  EXPECT_EQ(bus.node_stats(a).bus_off_events, 1u);
  EXPECT_EQ(bus.node_stats(b).rx_errors, 32u);
  // Submits to a bus-off node are queued, not sent.
  EXPECT_EQ(bus.submit(a, f, 100'000'000), SubmitStatus::queued);
  bus.advance(200'000'000);
  EXPECT_TRUE(rec.rx.empty());
}

TEST(CanBus, CorruptionAimedAtOneNodeSparesTheOthers) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode a = bus.attach(), b = bus.attach(), c = bus.attach();
  EXPECT_FALSE(bus.corrupt_frames_of(7, 1));
  ASSERT_TRUE(bus.corrupt_frames_of(a, 32));
  // b's frame has the lower identifier and goes first, untouched; a fails 32 times.
  bus.submit(a, make_data(0x202, {0x04, 0, 0, 0, 0, 0}), 0);
  bus.submit(b, make_data(0x102, {0x02, 0, 0, 0, 0}), 0);
  bus.advance(100'000'000);
  EXPECT_EQ(bus.error_state(a), ErrorState::bus_off);
  EXPECT_EQ(bus.error_state(b), ErrorState::error_active);
  EXPECT_EQ(bus.node_stats(b).tx_frames, 1u);
  EXPECT_EQ(bus.stats().error_frames, 32u);
  EXPECT_EQ(rec.received_by(c).size(), 1u);
  // b sends again without error: the corruption was a's alone and is used up.
  bus.submit(b, make_data(0x102, {0x02, 1, 1, 1, 1}), 100'000'000);
  bus.advance(200'000'000);
  EXPECT_EQ(bus.node_stats(b).tx_frames, 2u);
  EXPECT_EQ(bus.stats().error_frames, 32u);
}

TEST(CanBus, RecoveryOnlyOnRequestAfter128Times11RecessiveBits) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode a = bus.attach(), b = bus.attach();
  const Frame f = make_data(0x102, {0x02, 0, 0, 0, 0});
  EXPECT_FALSE(bus.request_recovery(a, 0));  // not bus-off: nothing to recover
  drive_to_bus_off(bus, a, f);
  bus.advance(50'000'000);
  EXPECT_EQ(bus.error_state(a), ErrorState::bus_off);
  const std::int64_t t_req = 50'000'000;
  ASSERT_TRUE(bus.request_recovery(a, t_req));
  const std::int64_t t_done = t_req + 128 * 11 * kUs;
  EXPECT_EQ(bus.next_event_ns(), t_done);
  bus.advance(t_done - 1);
  EXPECT_EQ(bus.error_state(a), ErrorState::bus_off);
  bus.advance(t_done);
  EXPECT_EQ(bus.error_state(a), ErrorState::error_active);
  EXPECT_EQ(bus.tec(a), 0);
  EXPECT_EQ(bus.rec(a), 0);
  ASSERT_EQ(rec.of_kind(BusEventKind::recovery_complete).size(), 1u);
  EXPECT_EQ(rec.of_kind(BusEventKind::recovery_complete)[0].t_ns, t_done);
  // The frame kept in its queue goes out at once.
  bus.advance(t_done + 1'000'000);
  ASSERT_EQ(rec.rx.size(), 1u);
  EXPECT_EQ(rec.rx[0].receiver, b);
  EXPECT_EQ(rec.rx[0].timing.sof_ns, t_done);
  EXPECT_EQ(rec.rx[0].timing.end_ns, t_done + frame_bits(f) * kUs);
  EXPECT_EQ(bus.node_stats(a).recoveries, 1u);
}

TEST(CanBus, RecoveryOnABusyBusCountsOneSequencePerFrame) {
  BusConfig cfg;
  cfg.queue_capacity = 256;
  CanBus bus(cfg);
  Recorder rec(bus);
  const BusNode a = bus.attach(), b = bus.attach();
  bus.attach();
  drive_to_bus_off(bus, a, make_data(0x001, {}));
  bus.advance(10'000'000);
  const std::int64_t t_req = 10'000'000;
  ASSERT_TRUE(bus.request_recovery(a, t_req));  // bus idle: counting starts now
  for (int i = 0; i < 200; ++i) ASSERT_EQ(bus.submit(b, make_data(0x300, {0x55}), t_req), SubmitStatus::queued);
  bus.advance(t_req + 100'000'000);
  const std::vector<BusEvent> done = rec.of_kind(BusEventKind::recovery_complete);
  ASSERT_EQ(done.size(), 1u);
  // Back-to-back frames leave no idle time: each frame's ACK delimiter + EOF + intermission
  // is one occurrence of 11 recessive bits, so recovery completes after the 128th.
  std::vector<Rx> from_b;
  for (const Rx& t : rec.tx)
    if (t.receiver == b) from_b.push_back(t);
  ASSERT_GE(from_b.size(), 128u);
  EXPECT_EQ(done[0].t_ns, from_b[127].timing.end_ns + 3 * kUs);
  // After recovery a receives again (frames starting later).
  std::size_t a_rx = 0;
  for (const Rx& r : rec.rx)
    if (r.receiver == a) {
      ++a_rx;
      EXPECT_GE(r.timing.sof_ns, done[0].t_ns);
    }
  EXPECT_EQ(a_rx, 200u - 128u);
}

TEST(CanBus, ErrorPassiveTransmitterWaitsEightSuspendBits) {
  for (const bool other_traffic : {false, true}) {
    CanBus bus;
    Recorder rec(bus);
    const BusNode a = bus.attach(), b = bus.attach();
    bus.corrupt_next_frames(17);  // TEC 136: still passive after one success (135)
    bus.submit(a, make_data(0x010, {1}), 0);
    bus.submit(a, make_data(0x010, {2}), 0);
    while (!(bus.corruptions_pending() == 0 && bus.phase() == BusPhase::frame))
      bus.advance(bus.next_event_ns());
    const std::int64_t sof = bus.next_event_ns() - frame_bits(make_data(0x010, {1})) * kUs;
    if (other_traffic) bus.submit(b, make_data(0x700, {}), sof + 5 * kUs);  // higher id than a's
    bus.advance(sof + 10'000'000);
    EXPECT_EQ(bus.tec(a), 134);
    EXPECT_EQ(bus.error_state(a), ErrorState::error_passive);
    ASSERT_EQ(rec.tx.size(), other_traffic ? 3u : 2u);
    const FrameTiming& a1 = rec.tx[0].timing;
    EXPECT_EQ(a1.sof_ns, sof);
    EXPECT_EQ(a1.attempts, 18);
    if (!other_traffic) {
      EXPECT_EQ(rec.tx[1].timing.sof_ns, a1.end_ns + (3 + 8) * kUs);
    } else {
      // b may start right after the intermission while a is suspended, despite its higher id.
      EXPECT_EQ(rec.tx[1].receiver, b);
      EXPECT_EQ(rec.tx[1].timing.sof_ns, a1.end_ns + 3 * kUs);
      EXPECT_EQ(rec.tx[2].receiver, a);
      EXPECT_EQ(rec.tx[2].timing.sof_ns, rec.tx[1].timing.end_ns + 3 * kUs);
    }
  }
}

TEST(CanBus, PowerLossAndReturn) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode a = bus.attach(), b = bus.attach(), c = bus.attach();
  ASSERT_TRUE(bus.detach(c, 0));
  EXPECT_FALSE(bus.detach(c, 0));
  EXPECT_EQ(bus.submit(c, make_data(0x1, {}), 0), SubmitStatus::node_off);
  bus.corrupt_next_frames(2);
  bus.submit(a, make_data(0x100, {1}), 0);
  bus.advance(1'000'000);
  EXPECT_EQ(rec.received_by(b).size(), 1u);
  EXPECT_TRUE(rec.received_by(c).empty());  // powered off
  EXPECT_EQ(bus.tec(a), 15);
  // The transmitter loses power mid-frame: receivers see a stuff error 6 bits later.
  const Frame f = make_data(0x100, {1, 2, 3, 4});
  bus.submit(a, f, 2'000'000);
  bus.submit(a, f, 2'000'000);
  bus.advance(2'000'000);
  ASSERT_TRUE(bus.detach(a, 2'000'000 + 20 * kUs));
  bus.advance(3'000'000);
  const std::vector<BusEvent> errors = rec.of_kind(BusEventKind::error_frame);
  ASSERT_EQ(errors.size(), 3u);
  EXPECT_EQ(errors[2].cause, ErrorCause::transmitter_lost);
  EXPECT_EQ(errors[2].t_ns, 2'000'000 + 26 * kUs);
  EXPECT_EQ(bus.rec(b), 2 - 1 + 1);  // two corruptions, one good frame, one cut-off frame
  EXPECT_EQ(rec.received_by(b).size(), 1u);
  EXPECT_EQ(bus.pending(a), 0);  // its queue died with it
  // Power returns: a power-on reset, and both come back into service.
  ASSERT_TRUE(bus.reattach(a, 4'000'000));
  ASSERT_TRUE(bus.reattach(c, 4'000'000));
  EXPECT_EQ(bus.tec(a), 0);
  EXPECT_EQ(bus.error_state(a), ErrorState::error_active);
  bus.submit(a, f, 4'000'000);
  bus.advance(5'000'000);
  ASSERT_EQ(rec.received_by(c).size(), 1u);
  EXPECT_EQ(rec.rx.back().timing.sof_ns, 4'000'000 + 11 * kUs);  // integration: 11 bits
  EXPECT_EQ(rec.received_by(b).size(), 2u);
}

TEST(CanBus, ListenOnlyNodesReceiveButNeverAcknowledge) {
  CanBus bus;
  Recorder rec(bus);
  const BusNode a = bus.attach();
  NodeConfig silent;
  silent.acknowledges = false;
  const BusNode spy = bus.attach(silent);
  bus.submit(a, make_data(0x123, {}), 0);
  bus.advance(500'000);
  EXPECT_GT(bus.node_stats(a).ack_errors, 0u);
  EXPECT_TRUE(rec.rx.empty());
  EXPECT_EQ(bus.rec(spy), 0);
  const BusNode c = bus.attach();
  bus.advance(1'000'000);
  EXPECT_EQ(rec.received_by(spy).size(), 1u);
  EXPECT_EQ(rec.received_by(c).size(), 1u);
  EXPECT_EQ(bus.node_stats(a).tx_frames, 1u);
}

TEST(CanBus, BadSubmitsAreRefusedAndCounted) {
  BusConfig cfg;
  cfg.queue_capacity = 2;
  CanBus bus(cfg);
  const BusNode a = bus.attach();
  Frame bad = make_data(0x7FF, {});
  bad.id = 0x800;  // does not fit 11 bits
  EXPECT_EQ(bus.submit(a, bad, 0), SubmitStatus::invalid_frame);
  Frame err;
  err.kind = FrameKind::error;
  EXPECT_EQ(bus.submit(a, err, 0), SubmitStatus::invalid_frame);
  EXPECT_EQ(bus.submit(a, make_data(1, {}), 0), SubmitStatus::queued);
  EXPECT_EQ(bus.submit(a, make_data(2, {}), 0), SubmitStatus::queued);
  EXPECT_EQ(bus.submit(a, make_data(3, {}), 0), SubmitStatus::queue_full);
  EXPECT_EQ(bus.submit(7, make_data(3, {}), 0), SubmitStatus::unknown_node);
  EXPECT_EQ(bus.node_stats(a).invalid_submits, 2u);
  EXPECT_EQ(bus.node_stats(a).queue_overflows, 1u);
  EXPECT_THROW(CanBus(BusConfig{5'000, 8, 4, 0}), std::invalid_argument);
  BusConfig one;
  one.max_nodes = 1;
  CanBus tiny(one);
  tiny.attach();
  EXPECT_THROW(tiny.attach(), std::length_error);
}

TEST(CanBus, StatisticsAndBusLoad) {
  CanBus bus;
  const BusNode a = bus.attach(), b = bus.attach(), c = bus.attach();
  const Frame f = make_data(0x102, {0x02, 0, 0, 0, 0});  // 93 bits + 3 intermission
  for (int i = 0; i < 4; ++i) bus.submit(a, f, i * 1'000'000);
  bus.submit(b, make_data(0x202, {}), 0);  // loses the first arbitration to 0x102
  bus.advance(4'000'000);
  EXPECT_EQ(bus.node_stats(a).tx_frames, 4u);
  EXPECT_EQ(bus.node_stats(b).tx_frames, 1u);
  EXPECT_EQ(bus.node_stats(b).arbitration_lost, 1u);
  EXPECT_EQ(bus.node_stats(b).rx_frames, 4u);
  EXPECT_EQ(bus.node_stats(c).rx_frames, 5u);
  EXPECT_EQ(bus.node_stats(a).rx_frames, 1u);
  EXPECT_EQ(bus.stats().frames, 5u);
  EXPECT_EQ(bus.stats().error_frames, 0u);
  const std::int64_t busy = (4 * frame_bits_with_intermission(f) + frame_bits_with_intermission(make_data(0x202, {}))) * kUs;
  EXPECT_EQ(bus.stats().busy_ns, busy);
  EXPECT_DOUBLE_EQ(bus.bus_load(4'000'000), static_cast<double>(busy) / 4e6);
  EXPECT_DOUBLE_EQ(bus.bus_load(0), 0.0);
}

}  // namespace
}  // namespace omnitwin::can
