// controller layer — the seam between the Botnana Control word set (the interpreter in this
// folder) and whatever master owns the drives (docs/botnana.md).
//
// The word set of seed 004 names drives as (slave, channel), both 1-based, and CiA 402 objects
// by index and sub-index. The interpreter never talks to a bus: every drive word becomes one of
// these calls, and the master behind them (our EtherCAT master's drive layer, or a test harness
// over the drive core) decides whether an object travels in the process image (PDO, next
// cycle) or as a queued SDO transfer. The power drive system is driven by goal (set_goal): the
// master writes the controlword state machine itself, the words only say where to go.
// Values are carried as std::int64_t whatever the object's OD type (INTEGER8..UNSIGNED32 all
// fit); the implementation converts to and from the object's width, and refuses a write
// whose value does not fit the object's type (last_error() names the value and the range;
// nothing is sent), never truncating it.
// Real-time safety: the interpreter calls these from the master's cycle (background tasks are
// stepped there), so implementations must not block; SDO transfers are queued, not awaited.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace omnitwin::botnana {

// The PDS state the master should drive an axis to (values as in the word set's pds-goal!).
enum class PdsGoal : std::uint8_t {
  switch_on_disabled = 1,
  ready_to_switch_on = 2,
  switched_on = 3,
  operation_enabled = 4,
  quick_stop_active = 5
};

// The user-planned PDO entries of seed 004 (drive-wpdo1!/@, drive-wpdo2!/@: master → slave;
// drive-rpdo1@, drive-rpdo2@: slave → master); which object each one is comes from the
// master's configuration file.
enum class UserPdo : std::uint8_t { wpdo1, wpdo2, rpdo1, rpdo2 };

// One CiA 402 object of an axis.
struct ObjectRef {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
};

// Conventions every implementation follows (docs/botnana.md):
//  * 0x6040 (controlword): write() stores the word set's controlword (drive-cw!, go, the
//    +/- bit words do read-modify-write through read()/write()). While a goal is set the
//    master owns bits 0–3 and 7 and overlays them from its goal logic each cycle; the other
//    bits (4–6 mode specific, 8 halt, 9) go out as written. release_goal() (drive-cw!, which
//    seed 004 says sets the controlword directly) ends the goal: the whole word goes out as
//    written until the next set_goal(). The master clears bit 4 (`go`)
//    itself once the drive acknowledges the set-point (statusword bit 12) so the next `go`
//    is a new rising edge.
//  * set_goal() is a new request each time it is called: an axis in Fault is first given a
//    fault reset (bit 7 rising edge), then driven to the goal through the FSA transitions.
//    A fault that happens afterwards is not reset until the next set_goal().
//  * read() of 0x6041 (statusword) is the last cycle's value seen by the master.
class DriveAccess {  // implemented by the EtherCAT master's drive layer (E)
 public:
  virtual ~DriveAccess() = default;
  // True when slave `slave` has a CiA 402 axis at channel `ch` (both 1-based, as in the word set).
  virtual bool has_drive(int slave, int ch) const = 0;
  // The last cycle's value of object index:sub (PDO-mapped), or the last SDO-read value;
  // nullopt when the object is unknown or not (yet) available. Never blocks.
  virtual std::optional<std::int64_t> read(int slave, int ch, std::uint16_t index,
                                           std::uint8_t sub) = 0;
  // Writes index:sub: into the process image for the next cycle when PDO-mapped, else a
  // queued SDO download. False when refused (unknown drive or object, or a value outside the
  // object's type); nothing is sent then. Never blocks.
  virtual bool write(int slave, int ch, std::uint16_t index, std::uint8_t sub,
                     std::int64_t value) = 0;
  // From now on the master drives the controlword of (slave, ch) towards `goal`.
  virtual void set_goal(int slave, int ch, PdsGoal goal) = 0;
  // From now on the master no longer drives the controlword of (slave, ch): it goes out as
  // written, bits 0–3 and 7 included, until the next set_goal().
  virtual void release_goal(int slave, int ch) = 0;
  // True while SDO requests queued for `slave` are not done yet.
  virtual bool requests_pending(int slave) const = 0;
  // A human-readable description of the last refused call ("" when none).
  virtual std::string last_error() const = 0;

  // Members below have defaults so that an implementation may leave them out.
  // The highest slave number the master knows (until-no-requests asks slaves 1..slaves()
  // besides those the interpreter itself sent requests to); 0 when unknown.
  virtual int slaves() const { return 0; }
  // The failures (abort, timeout) of the SDO downloads write() queued for `slave` since the
  // last call, as one sentence naming each object and its abort code; "" when none. Taking
  // them clears them: until-no-requests fails with them once the slave's queue is empty.
  virtual std::string take_request_failures(int /*slave*/) { return ""; }
  // The master's homed record of (slave, ch), which +drive-homed / -drive-homed set and
  // drive-homed? reads (seed 004: a record the master provides; ours also sets it when the
  // drive reports homing attained); nullopt when the master keeps none (the interpreter then
  // keeps its own).
  virtual std::optional<bool> homed(int /*slave*/, int /*ch*/) const { return std::nullopt; }
  // Sets that record; false when the master keeps none.
  virtual bool set_homed(int /*slave*/, int /*ch*/, bool /*homed*/) { return false; }
  // The error code of the last emergency the drive sent for this channel (0x0000 after its
  // reset); nullopt: none received, or the master does not receive emergencies.
  virtual std::optional<std::uint16_t> last_emergency(int /*slave*/, int /*ch*/) const { return std::nullopt; }
  // The object behind a user-planned PDO entry of (slave, ch); nullopt when none is
  // configured (the drive-wpdo/rpdo words then fail with an error naming the word).
  virtual std::optional<ObjectRef> user_pdo(int slave, int ch, UserPdo which) const {
    (void)slave; (void)ch; (void)which;
    return std::nullopt;
  }
};

}  // namespace omnitwin::botnana
