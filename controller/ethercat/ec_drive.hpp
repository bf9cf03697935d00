// controller/ethercat — the master-side CiA 402 layer: one record per drive axis on top of the
// EtherCAT master core (facts/cia402.md; controller/botnana/drive_access.hpp).
//
// Each cycle (update(), after the cyclic frame came back and before the next tick) it reads
// the statusword, drives the controlword towards the axis's goal (if it has one: a released
// goal leaves the word set's controlword as written) (shutdown / switch on /
// enable operation / quick stop / disable voltage, with a fault-reset rising edge first when
// a goal is set on a faulted axis), clears the `go` bit (controlword bit 4) once the drive
// acknowledges (statusword bit 12) and writes the controlword into the process image.
// Objects mapped into the PDOs are read and written in the image; any other object goes
// through the master's SDO queue (reads answer the last uploaded value and refresh it); a
// download the drive aborts (or that times out) is kept per slave for
// take_request_failures(), which until-no-requests turns into the script's error. Objects
// the master read back at start-up (EcMasterConfig::read_back: the software limits 0x607D:1/2
// of drive-nsl@/drive-psl@) are answered from that copy, or from the value written since,
// without an upload; a drive that aborted the read-back has no such object, and read() says so.
// Axes are (slave, channel), both 1-based as in the Botnana word set; channel n > 1 of a
// multi-axis slave uses the CiA 402 objects offset by 0x800 × (n − 1). Signedness and sizes
// come from the slave's ESI object dictionary; write() refuses a value outside the object's
// type (its range in last_error(), nothing sent) rather than truncating it. A homed record per axis is kept (set when the
// drive reports homing attained in HM mode). When the master reports a lost segment
// (EcMaster::segment_lost, counted in its stats), update() stops every axis: goal quick stop,
// velocity/torque set-points 0, position set-point = position actual; stopped() holds until
// a new goal is set. No allocation in update() once the axes exist.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "controller/botnana/drive_access.hpp"
#include "controller/ethercat/ec_master.hpp"

namespace omnitwin::controller::ethercat {

// CiA 402 power drive states as decoded from the statusword.
enum class PdsState : std::uint8_t {
  not_ready_to_switch_on, switch_on_disabled, ready_to_switch_on, switched_on, operation_enabled,
  quick_stop_active, fault_reaction_active, fault
};
const char* to_string(PdsState s);
PdsState decode_statusword(std::uint16_t sw);
// The controlword bits 0–3 and 7 that take state `s` one transition towards `goal`
// (fault handling apart: see EcDrives). Real-time safe.
std::uint16_t controlword_towards(PdsState s, botnana::PdsGoal goal);

class EcDrives : public botnana::DriveAccess {
 public:
  explicit EcDrives(EcMaster& master);

  // Once per cycle after the cyclic exchange: builds the axis list when the image first
  // exists, then per axis statusword → state, goal → controlword, go-bit acknowledge.
  void update();

  int axis_count() const { return static_cast<int>(axes_.size()); }
  // The axis of (slave, ch) 1-based; nullopt when none.
  std::optional<PdsState> state(int slave, int ch) const;
  std::uint16_t statusword(int slave, int ch) const;
  bool all_enabled() const;  // every axis in operation enabled (false without axes)
  bool any_enabled() const;  // some axis in operation enabled
  // Every axis was stopped because the segment was lost (until a new goal is set).
  bool stopped() const { return stopped_; }
  // Homed record per axis (the Botnana words' +drive-homed, -drive-homed, drive-homed?): set
  // when the drive reports homing attained (mode display HM, statusword bits 12 and 10 set,
  // 13 clear), or by set_homed(); nullopt (set_homed: false) for no such axis.
  std::optional<bool> homed(int slave, int ch) const override;
  bool set_homed(int slave, int ch, bool homed) override;

  // botnana::DriveAccess
  bool has_drive(int slave, int ch) const override;
  std::optional<std::int64_t> read(int slave, int ch, std::uint16_t index, std::uint8_t sub) override;
  bool write(int slave, int ch, std::uint16_t index, std::uint8_t sub, std::int64_t value) override;
  void set_goal(int slave, int ch, botnana::PdsGoal goal) override;
  void release_goal(int slave, int ch) override;
  bool requests_pending(int slave) const override;
  std::string last_error() const override { return error_; }
  std::string take_request_failures(int slave) override;
  int slaves() const override { return m_.slave_count(); }
  std::optional<std::uint16_t> last_emergency(int slave, int ch) const override;
  std::optional<botnana::ObjectRef> user_pdo(int slave, int ch, botnana::UserPdo which) const override;

  // The objects behind drive-wpdo1/2 and drive-rpdo1/2 (CiA 402 base indices, every axis).
  void set_user_pdo(botnana::UserPdo which, botnana::ObjectRef object);
  // Every axis to quick stop, set-points zero (what a lost segment does; see above), e.g. at
  // the end of a run.
  void stop_axes();

 private:
  struct Axis {
    int slave = 0, ch = 0;                   // 1-based
    std::optional<botnana::PdsGoal> goal;
    bool reset_pending = false;              // a fault reset edge before going to the goal
    int reset_phase = 0;
    std::uint16_t cw_user = 0;               // the word set's controlword
    std::uint16_t sw = 0;
    PdsState state = PdsState::not_ready_to_switch_on;
    int go_cycles = 0;                       // cycles bit 4 has been out
    bool homed = false;
    std::optional<EntryLocation> mode_display_at;
    std::optional<EntryLocation> cw_at, sw_at;
  };
  Axis* find(int slave, int ch);
  const Axis* find(int slave, int ch) const;
  static std::uint16_t object(int ch, std::uint16_t index);
  bool object_signed(int slave, std::uint16_t index, std::uint8_t sub) const;
  unsigned object_bytes(int slave, std::uint16_t index, std::uint8_t sub) const;
  // Whether `value` fits an object of `bits` bits; if not, error_ says why (value and range).
  bool fits(std::int64_t value, unsigned bits, bool is_signed, std::uint16_t index, std::uint8_t sub);
  const ReadBack* read_back(int slave, std::uint16_t index, std::uint8_t sub) const;
  std::optional<std::int64_t> read_back_value(const ReadBack& rb, const std::tuple<int, std::uint16_t, std::uint8_t>& key);

  EcMaster& m_;
  std::vector<Axis> axes_;
  bool built_ = false;
  std::uint64_t losses_seen_ = 0;  // the master's segment_losses already acted upon
  bool stopped_ = false;
  std::map<std::tuple<int, std::uint16_t, std::uint8_t>, std::int64_t> sdo_values_;
  std::map<std::tuple<int, std::uint16_t, std::uint8_t>, bool> sdo_reading_;
  std::map<int, std::string> request_failures_;  // slave → failed downloads not taken yet
  std::array<std::optional<botnana::ObjectRef>, 4> user_pdos_{};
  std::string error_;
};

}  // namespace omnitwin::controller::ethercat
