// controller/tml — our TML master (seed 003) as a protocol core, on TMLCAN (29-bit) or TechCAN
// (11-bit): it finds the four wheel drives (a group GiveMeData2 of SRL answered by each), puts
// them in speed mode with their acceleration (MODE SP, CACC, CSPD = 0, UPD), switches the axes
// on (AXISON) and reads back each axis's SR32 and CACC until SRL.15 is on, SRH.15 clear and CACC
// the value sent (an axis not confirmed within kConfirmTicks gets its set-up again, at most
// kSetupSends times in all); then every tick it sends each axis its command speed
// (CSPD, 32-bit 16.16 counts per sampling period), one UPD to the group and one group
// GiveMeData2 of APOS, whose TakeData2 answers feed the platform loop's odometry; every
// kStatusTicks ticks also a group GiveMeData2 of SR32 (SRL and SRH), so that an axis that went
// off or into fault (a power blip shorter than the answer timeout brings a drive back off)
// stops the platform as a lost axis does.
//
// Frames and time [ns] in (on_frame, on_tick), frames out through a callback; no sockets, no
// clock. Messages are built and read only through the TML codec (tml_message, tml_can). The
// group is group 1 (every drive's power-on group). Configuration fixed at construction;
// on_frame/on_tick do not allocate.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>

#include "bus_emulators/can/can_frame.hpp"
#include "bus_emulators/tml/tml_message.hpp"
#include "controller/sim_clock.hpp"
#include "controller/tml/tml_config.hpp"

namespace omnitwin::controller::tml {

using SimTime = std::int64_t;  // [ns]

// While running, the axis status (SR32) is read every this many ticks (10 ms at 2 ms).
inline constexpr std::uint64_t kStatusTicks = 5;
// Start-up: ticks an axis's set-up has to be confirmed in, and how often it is sent at most.
inline constexpr std::uint64_t kConfirmTicks = 10;
inline constexpr int kSetupSends = 4;

// Phases (MasterReport: detecting, starting = detecting). Legal in each:
//  detecting — each tick a group GiveMeData2 of SRL; every axis answering → starting (its
//              speed-mode set-up and AXISON sent). Legal: all_found, startup_timeout.
//  starting  — each tick the SR32 or the CACC query (in turn); every axis confirmed (SRL.15 on,
//              SRH.15 clear, CACC as sent) → running; an axis not confirmed within kConfirmTicks
//              of its set-up gets it again. Legal: all_confirmed, setup_resent, startup_timeout,
//              config_failed (kSetupSends sends unconfirmed).
//  running   — each tick CSPD per axis, UPD, the APOS query; every kStatusTicks ticks the SR32
//              query. Legal: axis_lost, axis_off (SRL.15 0 or SRH.15 fault), finish, shutdown.
//  stopped   — an axis stopped answering, or went off or into fault: every axis gets CSPD 0
//              and UPD, then holds; each tick the APOS query (SR32 every kStatusTicks), so
//              the axes stay watched and the master's silence never reads as its loss.
//  finished  — the application ended: CSPD 0 and UPD, then the queries as in stopped;
//              shutdown sends AXISOFF.
//  failed    — start-up did not complete.
enum class TmlPhase : std::uint8_t { detecting, starting, running, stopped, finished, failed };
const char* to_string(TmlPhase p);

struct TmlMasterStats {
  std::uint64_t ticks = 0, frames_rx = 0, frames_tx = 0, tx_refused = 0, answers = 0, not_tml = 0,
                axes_lost = 0, setup_resends = 0;
};

class TmlMaster {
 public:
  using SendFn = std::function<bool(const can::Frame& f, SimTime at)>;
  using EventFn = std::function<void(SimTime t, const std::string& text, bool warning)>;

  TmlMaster(const TmlProgramConfig& config, SendFn send);
  void set_event_callback(EventFn fn) { event_ = std::move(fn); }

  // A frame from the bus at t. Real-time safe.
  void on_frame(const can::Frame& f, SimTime t);
  // One tick at t. Real-time safe (events excepted).
  void on_tick(SimTime t);
  // The application: wheel i's speed [counts/s] (sent from the next tick on).
  void set_speed(int wheel, double counts_per_s) { speed_[static_cast<std::size_t>(wheel)] = counts_per_s; }
  // Wheel i's last APOS [counts].
  std::int32_t position(int wheel) const { return axes_[static_cast<std::size_t>(wheel)].apos; }
  void finish(SimTime t);
  void shutdown(SimTime t);
  // TML's end is the one tick shutdown() sends (CSPD 0, UPD, AXISOFF): over once it is sent.
  bool shut_down() const { return shut_down_; }
  void note_send_failures(std::uint64_t n) { stats_.tx_refused += n; }

  TmlPhase phase() const { return phase_; }
  simclock::MasterState report_state() const;
  simclock::StopReason reason() const { return reason_; }
  std::uint8_t reason_node() const { return reason_node_; }
  const TmlMasterStats& stats() const { return stats_; }
  std::uint16_t srl(int wheel) const { return axes_[static_cast<std::size_t>(wheel)].srl; }
  const TmlProgramConfig& config() const { return cfg_; }
  // 16.16 IU (counts per sampling period) of a speed in counts/s. RT-safe.
  std::int32_t speed_iu(double counts_per_s) const;

 private:
  struct Axis {
    std::int32_t apos = 0;
    std::uint16_t srl = 0, srh = 0;
    bool found = false;
    std::uint64_t last_answer_tick = 0;
    std::uint32_t cacc = 0;            // as read back at start-up
    std::uint64_t setup_tick = 0;      // when its set-up was last sent
    int setup_sends = 0;
  };
  bool send(const omnitwin::tml::Message& m, SimTime t);
  void event(SimTime t, const std::string& text, bool warning = false);
  void enter(TmlPhase p, SimTime t);
  void stop(simclock::StopReason r, std::uint8_t axis, SimTime t, const std::string& why);
  void query(std::uint16_t address, bool wide, SimTime t);
  void set_up(std::size_t i, SimTime t);
  std::uint32_t cacc_iu() const;
  bool confirmed(const Axis& a) const;
  bool confirm_set_up(SimTime t);
  void speeds(SimTime t, bool zero);
  void check_answers(SimTime t);
  void check_status(SimTime t);
  std::uint16_t group() const;
  int wheel_of(std::uint8_t axis) const;

  TmlProgramConfig cfg_;
  SendFn send_;
  EventFn event_;
  std::array<Axis, 4> axes_{};
  std::array<double, 4> speed_{};
  TmlPhase phase_ = TmlPhase::detecting;
  simclock::StopReason reason_ = simclock::StopReason::none;
  std::uint8_t reason_node_ = 0;
  SimTime start_ = -1;
  bool shut_down_ = false;  // shutdown() sent the end
  TmlMasterStats stats_;
};

}  // namespace omnitwin::controller::tml
