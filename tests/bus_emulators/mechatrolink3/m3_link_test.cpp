// Tests bus_emulators/mechatrolink3/m3_link: a slave station's communication core driven by
// frames a C1 master would send, with a small recording profile above it. Covers the link
// services (detection, the TR_DLY echo with its fixed turnaround, cycle notification,
// communication start), the phases of seed 000 fig. 7 (CONNECT with its checks, SYNC_SET
// only in synchronous mode, DISCONNECT, power off and on), CMD_ALM for a wrong phase, an
// unknown command and a bad subcommand, and COMM_ALM as the profile counts it: FCS errors,
// missing commands and a stopped master (a warning, then an alarm that drops phase 3 to 2
// and stops the profile), a stalled WDT (an alarm at once), and ALM_CLR clearing it; a retry
// of the command just executed is answered from its stored response, never run twice, while
// a new command that comes with the same sequence number is run.
#include "bus_emulators/mechatrolink3/m3_link.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

namespace omnitwin::m3 {
namespace {

constexpr SimTime kCycle = 1'000'000;  // 1 ms transmission cycle

// The profile above the link in these tests: records what reaches it.
struct RecordingProfile final : Profile {
  std::vector<Command> executed;
  int stops = 0;
  bool alarm = false;
  std::uint8_t profile_type() const override { return 0x10; }
  bool accepts_length(std::size_t n) const override { return n == 32 || n == 48; }
  CmdAlarm execute(Command c, std::span<const std::uint8_t>, std::span<std::uint8_t> rsp, SimTime) override {
    executed.push_back(c);
    rsp[4] = 0xAB;  // a mark the response must carry
    return CmdAlarm::normal;
  }
  void stop(SimTime) override { ++stops; }
  bool device_alarm() const override { return alarm; }
};

struct Sent {
  std::vector<std::uint8_t> bytes;
  SimTime t;
  FrameView view() const {
    FrameView v;
    EXPECT_EQ(decode(bytes, v), FrameStatus::ok);
    return v;
  }
};

class M3Link : public ::testing::Test {
 protected:
  RecordingProfile profile;
  std::vector<Sent> sent;
  SlaveLink link{LinkConfig{.address = 0x03, .response_ns = 2'000, .vendor_id = 0x1234, .device_code = 7}, profile,
                 [this](std::span<const std::uint8_t> f, SimTime t) { sent.push_back({{f.begin(), f.end()}, t}); }};
  std::uint8_t wdt = 0;
  SimTime now = 0;

  void frame(FrameType type, std::vector<std::uint8_t> data, std::uint8_t dst = 0x03, bool retry = false,
             std::uint8_t src = kC1Master) {
    std::vector<std::uint8_t> b(kMaxFrame);
    b.resize(encode(FrameSpec{.dst = dst, .src = src, .type = type, .sequence = 0, .retry = retry, .data = data}, b));
    ASSERT_FALSE(b.empty());
    link.on_frame(b, now);
  }
  // A cyclic command; the WDT count advances unless told not to.
  void command(Command c, std::size_t len = 32, std::uint16_t ctrl = 0, bool advance_wdt = true, bool retry = false,
               std::vector<std::pair<std::size_t, std::uint8_t>> bytes = {}) {
    if (advance_wdt) wdt = static_cast<std::uint8_t>(wdt + 0x10);
    std::vector<std::uint8_t> d(len, 0);
    write_header(d, CommandHeader{static_cast<std::uint8_t>(c), wdt, ctrl});
    for (auto [at, v] : bytes) d[at] = v;
    frame(FrameType::cyclic_command, d, 0x03, retry);
  }
  void connect(bool sync = true, std::size_t len = 32, std::uint8_t ver = 0x30, std::uint8_t com_tim = 1,
               std::uint8_t profile_type = 0x10, bool sub = false) {
    const auto mod = static_cast<std::uint8_t>((sync ? kComModSync : 0) | (sub ? kComModSubcommand : 0));
    command(Command::connect, len, 0, true, false, {{4, ver}, {5, mod}, {6, com_tim}, {7, profile_type}});
  }
  void start(SimTime cycle = kCycle) {
    link.power_on(now);
    std::vector<std::uint8_t> n(16, 0);
    put_i32(n, 0, static_cast<std::int32_t>(cycle));
    frame(FrameType::cycle_notify, n, kBroadcast);
    frame(FrameType::comm_start, std::vector<std::uint8_t>(8, 0), kBroadcast);
  }
  void to_phase3() {
    start();
    connect();
    command(Command::sync_set);
    ASSERT_EQ(link.phase(), Phase::p3);
  }
  // One healthy cycle: sync, a command, time to the next cycle.
  void cycle(bool with_sync = true, bool with_command = true) {
    if (with_sync) frame(FrameType::sync, std::vector<std::uint8_t>(8, 0), kBroadcast);
    now += 100'000;
    if (with_command) command(Command::nop);
    now += kCycle - 100'000;
    link.advance(now);
  }
  CmdStat last_stat() const {
    const FrameView v = sent.back().view();
    return unpack_stat(get_u16(v.data, 2));
  }
};

TEST_F(M3Link, PoweredOffItIsSilentPoweredOnItAnswersDetectionAndTheDelayEcho) {
  frame(FrameType::detect, {});
  EXPECT_TRUE(sent.empty());
  EXPECT_EQ(link.phase(), Phase::p5);
  link.power_on(0);
  EXPECT_EQ(link.phase(), Phase::p1);
  now = 5'000;
  frame(FrameType::detect, {});
  ASSERT_EQ(sent.size(), 1u);
  const FrameView d = sent[0].view();
  EXPECT_EQ(d.type, FrameType::detect_reply);
  EXPECT_EQ(d.dst, kC1Master);
  EXPECT_EQ(d.src, 0x03);
  EXPECT_EQ(get_i32(d.data, 0), 0x1234);
  EXPECT_EQ(get_u16(d.data, 4), 7);
  EXPECT_EQ(d.data[6], 0x10);
  EXPECT_EQ(d.data[7], 1) << "phase 1";
  EXPECT_EQ(sent[0].t, 5'000 + 2'000);
  frame(FrameType::delay_request, {});
  ASSERT_EQ(sent.size(), 2u);
  EXPECT_EQ(sent[1].view().type, FrameType::delay_reply);
  EXPECT_EQ(sent[1].t, 5'000 + kDelayEchoNs);
}

TEST_F(M3Link, ASlaveThatMissedTheNotificationLearnsTheCycleFromSyncFrames) {
  link.power_on(0);
  connect();
  EXPECT_EQ(link.phase(), Phase::p2) << "commands are answered without COMM_START";
  EXPECT_FALSE(link.communication_started());
  command(Command::sync_set);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::condition_error) << "no cycle known yet";
  frame(FrameType::sync, std::vector<std::uint8_t>(8, 0), kBroadcast);
  now += kCycle;
  frame(FrameType::sync, std::vector<std::uint8_t>(8, 0), kBroadcast);
  EXPECT_EQ(link.transmission_cycle_ns(), kCycle);
  command(Command::sync_set);
  EXPECT_EQ(link.phase(), Phase::p3);
}

TEST_F(M3Link, ConnectMovesToPhase2AndEchoesItsParameters) {
  start();
  connect(true, 48, 0x30, 4, 0x10, true);
  EXPECT_EQ(link.phase(), Phase::p2);
  const FrameView r = sent.back().view();
  EXPECT_EQ(r.type, FrameType::cyclic_response);
  EXPECT_EQ(r.data.size(), 48u);
  EXPECT_EQ(r.data[0], 0x0E) << "RCMD";
  EXPECT_EQ(r.data[4], 0x30);
  EXPECT_EQ(r.data[6], 4);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::normal);
  EXPECT_TRUE(link.connection().subcommand);
  EXPECT_EQ(link.connection().com_tim, 4);
  EXPECT_EQ(link.connection().data_bytes, 48u);
}

// The response to CONNECT was lost; the master's retry (retry bit, same sequence number) gets
// the stored answer instead of a phase error, while a fresh CONNECT in phase 2 is one.
TEST_F(M3Link, ARetryOfTheLastCommandIsAnsweredFromItsStoredResponse) {
  start();
  connect();
  ASSERT_EQ(link.phase(), Phase::p2);
  const std::vector<std::uint8_t> first = sent.back().bytes;
  const auto mod = static_cast<std::uint8_t>(kComModSync);
  command(Command::connect, 32, 0, false, true, {{4, 0x30}, {5, mod}, {6, 1}, {7, 0x10}});
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(link.stats().repeated, 1u);
  FrameView a = sent.back().view(), b;
  ASSERT_EQ(decode(first, b), FrameStatus::ok);
  EXPECT_TRUE(std::equal(a.data.begin(), a.data.end(), b.data.begin(), b.data.end())) << "the same answer";
  connect();
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::phase_error) << "not a retry: executed, and refused in phase 2";
  EXPECT_EQ(link.stats().repeated, 1u);
}

// A new command that comes flagged as a retry with the last command's sequence number,
// length and code (a master whose sequence counter came round to the same number) is
// executed: only a retry of the very same command is answered from the stored response.
TEST_F(M3Link, ANewCommandWithTheLastSequenceNumberAndCodeIsExecutedNotAnsweredFromTheStore) {
  start();
  connect();
  command(Command::velctrl, 32, 0, true, false, {{16, 1}});
  command(Command::velctrl, 32, 0, false, true, {{16, 2}});  // retry flag, sequence 0, other data
  EXPECT_EQ(profile.executed.size(), 2u) << "a different command, not a retry of the last one";
  EXPECT_EQ(link.stats().repeated, 0u);
  command(Command::velctrl, 32, 0, false, true, {{16, 2}});  // now the very same command again
  EXPECT_EQ(profile.executed.size(), 2u);
  EXPECT_EQ(link.stats().repeated, 1u);
}

TEST_F(M3Link, ABadConnectIsInvalidDataAndStaysInPhase1) {
  start();
  connect(true, 32, 0x20);  // version
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::invalid_data);
  connect(true, 32, 0x30, 0);  // COM_TIM 0
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::invalid_data);
  connect(true, 32, 0x30, 1, 0x30);  // an I/O profile to a servo
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::invalid_data);
  connect(true, 32, 0x30, 1, 0x10, true);  // subcommands need the 48-byte mode
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::invalid_data);
  connect(true, 16);  // a length the servo does not take
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::invalid_data);
  EXPECT_EQ(link.phase(), Phase::p1);
}

// CONNECT is refused (invalid data, phase 1 kept) when the communication cycle (transmission
// cycle × COM_TIM) is outside 0.125 ms … 32 ms, the range a typical servo accepts
// (facts/mechatrolink3.md), or COM_MOD sets a reserved bit or a DTMODE other than single
// transfer (00b, the only one built).
TEST_F(M3Link, AConnectOutsideTheCycleRangeOrWithReservedComModBitsIsInvalidData) {
  auto connect_with = [&](std::uint8_t mod, std::uint8_t com_tim) {
    command(Command::connect, 32, 0, true, false, {{4, 0x30}, {5, mod}, {6, com_tim}, {7, 0x10}});
    return last_stat().cmd_alm;
  };
  start(kCycle);
  EXPECT_EQ(connect_with(kComModSync, 255), CmdAlarm::invalid_data) << "255 ms";
  EXPECT_EQ(connect_with(kComModSync, 33), CmdAlarm::invalid_data) << "33 ms";
  EXPECT_EQ(connect_with(0x0E, 1), CmdAlarm::invalid_data) << "DTMODE 11b (reserved)";
  EXPECT_EQ(connect_with(0x06, 1), CmdAlarm::invalid_data) << "DTMODE 01b (consecutive transfer, not built)";
  EXPECT_EQ(connect_with(0x73, 1), CmdAlarm::invalid_data) << "reserved bits 0, 4-6";
  EXPECT_EQ(connect_with(0x03, 1), CmdAlarm::invalid_data) << "reserved bit 0";
  EXPECT_EQ(connect_with(0x12, 1), CmdAlarm::invalid_data) << "reserved bit 4";
  EXPECT_EQ(link.phase(), Phase::p1);
  EXPECT_EQ(connect_with(kComModSync, 32), CmdAlarm::normal) << "32 ms, the longest";
  link.power_off(now);
  start(62'500);
  EXPECT_EQ(connect_with(kComModSync, 1), CmdAlarm::invalid_data) << "62.5 µs";
  EXPECT_EQ(link.phase(), Phase::p1);
  EXPECT_EQ(connect_with(kComModSync, 2), CmdAlarm::normal) << "125 µs, the shortest";
}

TEST_F(M3Link, CommandsOutsideTheirPhaseArePhaseErrorsAndNeverReachTheProfile) {
  start();
  command(Command::velctrl);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::phase_error);
  connect();
  command(Command::interpolate);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::phase_error) << "INTERPOLATE needs phase 3";
  connect();
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::phase_error) << "CONNECT twice";
  EXPECT_TRUE(profile.executed.empty());
  EXPECT_EQ(link.stats().phase_errors, 3u);
  command(Command::velctrl);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::normal) << "a normal command clears CMD_ALM";
  ASSERT_EQ(profile.executed.size(), 1u);
  EXPECT_EQ(sent.back().view().data[4], 0xAB) << "the profile's response data";
}

TEST_F(M3Link, AnUnknownCommandIsUnsupportedAndEchoed) {
  start();
  connect();
  command(static_cast<Command>(0x7F));
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::unsupported);
  EXPECT_EQ(sent.back().view().data[0], 0x7F);
  EXPECT_EQ(link.stats().unsupported, 1u);
}

TEST_F(M3Link, SyncSetNeedsSynchronousModeAndACycle) {
  link.power_on(0);
  frame(FrameType::comm_start, std::vector<std::uint8_t>(8, 0), kBroadcast);
  EXPECT_TRUE(link.communication_started());
  connect();
  command(Command::sync_set);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::condition_error) << "no cycle notified yet";
  link.power_off(0);
  start();
  connect(false);
  command(Command::sync_set);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::condition_error) << "event-driven mode never enters phase 3";
  EXPECT_EQ(link.phase(), Phase::p2);
}

TEST_F(M3Link, HealthyCyclesKeepPhase3WithoutAlarms) {
  to_phase3();
  for (int k = 0; k < 50; ++k) cycle();
  EXPECT_EQ(link.phase(), Phase::p3);
  EXPECT_EQ(link.comm_alarm(), CommAlarm::normal);
  EXPECT_EQ(link.stats().missed_commands + link.stats().missed_syncs, 0u);
}

// A cycle without a command is noticed when the next SYNC opens the next cycle.
TEST_F(M3Link, AMissingCommandIsAWarningTwiceInARowAnAlarm) {
  to_phase3();
  for (int k = 0; k < 5; ++k) cycle();
  cycle(true, false);
  EXPECT_EQ(link.comm_alarm(), CommAlarm::normal) << "not known before the next cycle begins";
  cycle();
  EXPECT_EQ(link.comm_alarm(), CommAlarm::no_command_warning);
  EXPECT_EQ(link.phase(), Phase::p3);
  cycle(true, false);
  cycle();
  EXPECT_EQ(link.phase(), Phase::p3) << "not in a row";
  cycle(true, false);
  cycle(true, false);
  cycle();
  EXPECT_EQ(link.comm_alarm(), CommAlarm::no_command);
  EXPECT_EQ(link.phase(), Phase::p2);
  EXPECT_EQ(profile.stops, 1);
  EXPECT_EQ(link.stats().missed_commands, 4u);
}

// SYNC frames 0.2 ms early or late, alternately (intervals of 0.6 and 1.4 cycles), with the
// command late in its cycle, are no miss: the slave's checks follow the master's SYNC, not a
// grid of its own. A SYNC is missing 1.5 cycles after the last one.
TEST_F(M3Link, SyncJitterIsNoMissWhileTheIntervalStaysBelowOneAndAHalfCycles) {
  to_phase3();
  const SimTime start = now;
  for (int k = 1; k <= 40; ++k) {
    const SimTime nominal = start + k * kCycle, jitter = (k % 2 == 0 ? 1 : -1) * 200'000;
    now = nominal + jitter;
    link.advance(now);
    frame(FrameType::sync, std::vector<std::uint8_t>(8, 0), kBroadcast);
    now += 550'000;
    command(Command::nop);
    link.advance(now);
  }
  EXPECT_EQ(link.stats().missed_syncs + link.stats().missed_commands, 0u);
  EXPECT_EQ(link.comm_alarm(), CommAlarm::normal);
  link.advance(now - 550'000 + 3 * kCycle / 2);
  EXPECT_EQ(link.stats().missed_syncs, 1u) << "1.5 cycles after the last SYNC";
}

TEST_F(M3Link, AStoppedMasterIsNoSyncAndStopsTheProfile) {
  to_phase3();
  for (int k = 0; k < 5; ++k) cycle();
  now += 10 * kCycle;  // nothing more from the master
  link.advance(now);
  EXPECT_EQ(link.comm_alarm(), CommAlarm::no_sync);
  EXPECT_EQ(link.phase(), Phase::p2);
  EXPECT_EQ(profile.stops, 1);
  EXPECT_EQ(link.stats().comm_alarms, 1u);
}

TEST_F(M3Link, AStalledWatchdogIsAnAlarmAtOnceButRetriesDoNotTripIt) {
  to_phase3();
  cycle();
  command(Command::nop, 32, 0, false, true);  // a retry repeats the count: fine
  EXPECT_EQ(link.comm_alarm(), CommAlarm::normal);
  command(Command::nop, 32, 0, false, false);  // a new cycle with the old count
  EXPECT_EQ(link.comm_alarm(), CommAlarm::wdt);
  EXPECT_EQ(link.phase(), Phase::p2);
  EXPECT_EQ(link.stats().wdt_errors, 1u);
}

TEST_F(M3Link, TwoCorruptedFramesInARowAreAnFcsAlarm) {
  to_phase3();
  std::vector<std::uint8_t> b(kMaxFrame);
  std::vector<std::uint8_t> d(32, 0);
  b.resize(encode(FrameSpec{.dst = 0x03, .type = FrameType::cyclic_command, .data = d}, b));
  b[10] ^= 0x01;
  link.on_frame(b, now);
  EXPECT_EQ(link.comm_alarm(), CommAlarm::fcs_warning);
  command(Command::nop);  // a good one between: not in a row
  link.on_frame(b, now);
  EXPECT_EQ(link.phase(), Phase::p3);
  link.on_frame(b, now);
  EXPECT_EQ(link.comm_alarm(), CommAlarm::fcs);
  EXPECT_EQ(link.phase(), Phase::p2);
  EXPECT_EQ(link.stats().fcs_errors, 3u);
  b[0] = 0x09;  // someone else's corrupted frame is not ours to count
  link.on_frame(b, now);
  EXPECT_EQ(link.stats().fcs_errors, 3u);
}

TEST_F(M3Link, AlarmClearInCmdCtrlClearsCommAlmAndSaysSo) {
  to_phase3();
  now += 10 * kCycle;
  link.advance(now);
  ASSERT_EQ(link.comm_alarm(), CommAlarm::no_sync);
  command(Command::nop, 32, pack(CmdCtrl{.alm_clr = true, .cmd_id = 1}));
  const CmdStat s = last_stat();
  EXPECT_EQ(s.comm_alm, CommAlarm::normal);
  EXPECT_TRUE(s.alm_clr_cmp);
  EXPECT_EQ(s.rcmd_id, 1);
}

// Before CONNECT there is no communication to supervise: corrupted frames are counted, not
// raised into COMM_ALM.
TEST_F(M3Link, CorruptedFramesInPhase1AreCountedButRaiseNoCommunicationAlarm) {
  start();
  std::vector<std::uint8_t> b(kMaxFrame);
  std::vector<std::uint8_t> d(32, 0);
  b.resize(encode(FrameSpec{.dst = 0x03, .type = FrameType::cyclic_command, .data = d}, b));
  b[10] ^= 0x01;
  link.on_frame(b, now);
  link.on_frame(b, now);
  EXPECT_EQ(link.comm_alarm(), CommAlarm::normal);
  EXPECT_EQ(link.stats().fcs_errors, 2u);
  EXPECT_EQ(link.stats().comm_alarms, 0u);
  connect();
  link.on_frame(b, now);
  EXPECT_EQ(link.comm_alarm(), CommAlarm::fcs_warning) << "from phase 2 on they count";
}

// ALM_CLR refused for its phase (phase 1: CMD_ALM phase error) clears nothing; in phase 2 it does.
TEST_F(M3Link, AnAlarmClearRefusedInPhase1LeavesCommAlmAsItIs) {
  to_phase3();
  now += 10 * kCycle;
  link.advance(now);
  ASSERT_EQ(link.comm_alarm(), CommAlarm::no_sync);
  command(Command::disconnect);
  ASSERT_EQ(link.phase(), Phase::p1);
  command(Command::alm_clr);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::phase_error);
  EXPECT_EQ(last_stat().comm_alm, CommAlarm::no_sync);
  command(Command::nop, 32, pack(CmdCtrl{.alm_clr = true, .cmd_id = 0}));
  EXPECT_EQ(last_stat().comm_alm, CommAlarm::no_sync) << "CMD_CTRL.ALM_CLR is ALM_CLR's clear too";
  EXPECT_FALSE(last_stat().alm_clr_cmp);
  connect();
  command(Command::alm_clr);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::normal);
  EXPECT_EQ(link.comm_alarm(), CommAlarm::normal);
}

TEST_F(M3Link, TheResponseCarriesDeviceStateAndTheWatchdogEcho) {
  start();
  connect();
  profile.alarm = true;
  command(Command::nop);
  const FrameView r = sent.back().view();
  EXPECT_TRUE(unpack_stat(get_u16(r.data, 2)).d_alm);
  EXPECT_EQ(r.data[1] & 0xF0, wdt & 0xF0) << "RWDT echoes the master's count";
  EXPECT_EQ(sent.back().t, now + 2'000);
}

TEST_F(M3Link, DisconnectReturnsToPhase1AndStopsTheProfile) {
  to_phase3();
  command(Command::disconnect);
  EXPECT_EQ(link.phase(), Phase::p1);
  EXPECT_EQ(profile.stops, 1);
  command(Command::velctrl);
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::phase_error) << "phase 1 again";
  connect();
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::normal) << "communication goes on: CONNECT again at once";
  EXPECT_EQ(link.phase(), Phase::p2);
}

TEST_F(M3Link, PowerOffSilencesAndPowerOnForgets) {
  to_phase3();
  link.power_off(now);
  command(Command::nop);
  EXPECT_EQ(link.phase(), Phase::p5);
  const auto answered = sent.size();
  link.power_on(now);
  EXPECT_EQ(link.phase(), Phase::p1);
  EXPECT_EQ(link.stats().commands, 0u);
  EXPECT_EQ(link.transmission_cycle_ns(), 0) << "the cycle must be notified again";
  EXPECT_EQ(sent.size(), answered);
}

TEST_F(M3Link, OthersFramesAndASecondMasterAreCountedNotServed) {
  start();
  frame(FrameType::detect, {}, 0x04);
  EXPECT_EQ(link.stats().not_for_me, 1u);
  frame(FrameType::detect, {}, 0x03, false, kC2Master);
  EXPECT_EQ(link.stats().bad_frames, 1u);
  EXPECT_TRUE(sent.empty());
  link.on_frame(std::vector<std::uint8_t>{1, 2, 3}, now);
  EXPECT_EQ(link.stats().bad_frames, 2u);
}

TEST_F(M3Link, TheSubcommandRegionIsAnsweredWithItsOwnStatus) {
  start();
  connect(true, 48, 0x30, 1, 0x10, true);
  auto sub_stat = [&] {
    const FrameView v = sent.back().view();
    return std::pair{v.data[32], static_cast<std::uint32_t>(v.data[33] | (v.data[34] << 8) | (v.data[35] << 16))};
  };
  command(Command::velctrl, 48, 0, true, false, {{32, 0x31}});  // SV_ON is no subcommand
  EXPECT_EQ(last_stat().cmd_alm, CmdAlarm::normal) << "the main command runs all the same";
  EXPECT_EQ(sub_alarm(sub_stat().second), CmdAlarm::unsupported);
  EXPECT_EQ(sub_stat().first, 0x31) << "SUB_RCMD";
  command(Command::alm_rd, 48, 0, true, false, {{32, 0x40}});  // a common command takes only NOP
  EXPECT_EQ(sub_alarm(sub_stat().second), CmdAlarm::subcommand_combination);
  command(Command::velctrl, 48, 0, true, false, {{32, 0x30}});  // SMON with a servo command
  EXPECT_EQ(sub_alarm(sub_stat().second), CmdAlarm::unsupported) << "this test's profile runs no subcommands";
  command(Command::velctrl, 48, 0, true, false, {{32, 0x00}});
  EXPECT_EQ(sub_alarm(sub_stat().second), CmdAlarm::normal);
  EXPECT_NE(sub_stat().second & 0x4, 0u) << "SBCMDRDY";
}

}  // namespace
}  // namespace omnitwin::m3
