// Test support for tests/controller/botnana: a DriveAccess over real drive::Cia402Drive axes
// (C's drive core), standing in for the EtherCAT master's drive layer. Not a mock: every
// cycle() runs the master's side as the contract describes it (controlword from the PDS goal
// with a fault reset on a new goal, `go` cleared on set-point acknowledge, process-image
// outputs applied, SDO downloads completed one at a time after a latency), then one period
// of each drive core, then C's drive::AxisModel (motor + load with friction, a velocity
// servo or the commanded torque) as the physics, then the inputs (statusword, actual values)
// latched for read().
// Objects reach the drive by direct access to drive::Objects fields.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/drive/cia402_drive.hpp"
#include "controller/botnana/drive_access.hpp"

namespace omnitwin::botnana::testing {

class DriveHarness : public DriveAccess {
 public:
  struct Axis {
    int slave = 1, ch = 1;
    std::unique_ptr<drive::Cia402Drive> drive;
    drive::Objects inputs;              // latched after the last step (what read() sees)
    std::uint16_t cw_user = 0;          // the word set's controlword (write of 0x6040)
    std::optional<PdsGoal> goal;
    bool new_goal = false;              // set_goal called: reset a fault once
    int reset_phase = 0;                // fault reset: 0 idle, 1 bit 7 low, 2 bit 7 high
    std::map<std::uint32_t, std::int64_t> pdo_out;  // process-image outputs for the next cycle
    std::unique_ptr<drive::AxisModel> load;
  };
  struct Sdo {
    int ch;
    std::uint16_t index;
    std::uint8_t sub;
    std::int64_t value;
  };

  // The outputs a master would map into RxPDOs; everything else travels by SDO.
  static bool is_pdo_output(std::uint16_t index) {
    return index == 0x6040 || index == 0x607A || index == 0x60FF || index == 0x60B1 || index == 0x6071;
  }

  explicit DriveHarness(std::int64_t period_ns = 1'000'000, int sdo_latency_cycles = 3)
      : period_ns_(period_ns), sdo_latency_(sdo_latency_cycles) {}

  drive::Cia402Drive& add_axis(int slave, int ch, drive::DriveConfig cfg = {}) {
    cfg.period_s = static_cast<double>(period_ns_) * 1e-9;
    Axis a;
    a.slave = slave;
    a.ch = ch;
    a.drive = std::make_unique<drive::Cia402Drive>(cfg);
    a.load = std::make_unique<drive::AxisModel>();
    a.inputs = a.drive->objects();
    axes_.push_back(std::move(a));
    if (slave > slaves_) slaves_ = slave;
    return *axes_.back().drive;
  }

  // One master cycle (see the header comment).
  void cycle() {
    ++cycle_;
    for (auto& [slave, q] : sdo_) {
      if (!q.empty() && cycle_ >= sdo_due_[slave]) {
        const Sdo s = q.front();
        q.pop_front();
        if (Axis* a = find(slave, s.ch)) set_object(a->drive->objects(), s.index, s.sub, s.value);
        sdo_due_[slave] = cycle_ + sdo_latency_;
      }
    }
    for (Axis& a : axes_) {
      drive::Objects& o = a.drive->objects();
      for (const auto& [key, v] : a.pdo_out) set_object(o, static_cast<std::uint16_t>(key >> 8), key & 0xFF, v);
      // `go`: the master clears bit 4 once the drive acknowledged the set-point.
      if ((a.cw_user & drive::cw::new_set_point) != 0 && (a.inputs.statusword & drive::sw::set_point_ack) != 0) {
        a.cw_user = static_cast<std::uint16_t>(a.cw_user & ~drive::cw::new_set_point);
      }
      o.controlword = a.goal ? static_cast<std::uint16_t>((a.cw_user & ~0x008Fu) | goal_bits(a)) : a.cw_user;
      const drive::Command c = a.drive->step(t_, a.load->feedback());
      a.load->step(c, static_cast<double>(period_ns_) * 1e-9);
      a.inputs = o;
    }
    t_ += period_ns_;
  }
  void run(int cycles) {
    for (int k = 0; k < cycles; ++k) cycle();
  }

  Axis* find(int slave, int ch) {
    for (Axis& a : axes_) {
      if (a.slave == slave && a.ch == ch) return &a;
    }
    return nullptr;
  }
  const Axis* find(int slave, int ch) const {
    for (const Axis& a : axes_) {
      if (a.slave == slave && a.ch == ch) return &a;
    }
    return nullptr;
  }
  drive::Cia402Drive& drive(int slave, int ch) { return *find(slave, ch)->drive; }
  std::uint16_t user_controlword(int slave, int ch) const { return find(slave, ch)->cw_user; }
  std::optional<PdsGoal> goal(int slave, int ch) const { return find(slave, ch)->goal; }
  std::int64_t cycles() const { return cycle_; }

  // ---- DriveAccess ----
  bool has_drive(int slave, int ch) const override { return find(slave, ch) != nullptr; }
  std::optional<std::int64_t> read(int slave, int ch, std::uint16_t index, std::uint8_t sub) override {
    const Axis* a = find(slave, ch);
    if (a == nullptr) {
      error_ = fmt::format("no axis {}:{}", slave, ch);
      return std::nullopt;
    }
    if (index == 0x6040 && sub == 0) return a->cw_user;
    if (is_pdo_output(index)) {
      const auto it = a->pdo_out.find(key(index, sub));
      if (it != a->pdo_out.end()) return it->second;
    }
    const auto v = get_object(a->inputs, index, sub);
    if (!v) error_ = fmt::format("object 0x{:04X}:{} not in the drive", index, sub);
    return v;
  }
  bool write(int slave, int ch, std::uint16_t index, std::uint8_t sub, std::int64_t value) override {
    Axis* a = find(slave, ch);
    if (a == nullptr) {
      error_ = fmt::format("no axis {}:{}", slave, ch);
      return false;
    }
    drive::Objects probe = a->drive->objects();
    if (!set_object(probe, index, sub, value)) {
      error_ = fmt::format("object 0x{:04X}:{} not writable", index, sub);
      return false;
    }
    if (index == 0x6040 && sub == 0) {
      a->cw_user = static_cast<std::uint16_t>(value);
    } else if (is_pdo_output(index)) {
      a->pdo_out[key(index, sub)] = value;
    } else {
      auto& q = sdo_[slave];
      if (q.empty()) sdo_due_[slave] = cycle_ + sdo_latency_;
      q.push_back({ch, index, sub, value});
    }
    return true;
  }
  void set_goal(int slave, int ch, PdsGoal g) override {
    if (Axis* a = find(slave, ch)) {
      a->goal = g;
      a->new_goal = true;
      a->reset_phase = 0;
    }
  }
  void release_goal(int slave, int ch) override {
    if (Axis* a = find(slave, ch)) a->goal.reset();
  }
  bool requests_pending(int slave) const override {
    const auto it = sdo_.find(slave);
    return it != sdo_.end() && !it->second.empty();
  }
  std::string last_error() const override { return error_; }
  int slaves() const override { return slaves_; }
  std::optional<ObjectRef> user_pdo(int slave, int ch, UserPdo which) const override {
    if (!has_drive(slave, ch)) return std::nullopt;
    switch (which) {
      case UserPdo::wpdo1: return ObjectRef{0x60FF, 0};  // target velocity (CSV)
      case UserPdo::wpdo2: return ObjectRef{0x6071, 0};  // target torque (CST)
      case UserPdo::rpdo1: return ObjectRef{0x60F4, 0};  // following error actual
      case UserPdo::rpdo2: return ObjectRef{0x6074, 0};  // torque demand
    }
    return std::nullopt;
  }

  // Object access by index/sub on drive::Objects (the objects the word set uses, and a few).
  static std::optional<std::int64_t> get_object(const drive::Objects& o, std::uint16_t index, std::uint8_t sub) {
    switch (index) {
      case 0x6040: return o.controlword;
      case 0x6041: return o.statusword;
      case 0x603F: return o.error_code;
      case 0x605D: return o.halt_option;
      case 0x6060: return o.mode;
      case 0x6061: return o.mode_display;
      case 0x6062: return o.position_demand;
      case 0x6064: return o.position_actual;
      case 0x606B: return o.velocity_demand;
      case 0x606C: return o.velocity_actual;
      case 0x6071: return o.target_torque;
      case 0x6074: return o.torque_demand;
      case 0x6077: return o.torque_actual;
      case 0x607A: return o.target_position;
      case 0x607D:
        if (sub == 1) return o.sw_limit_min;
        if (sub == 2) return o.sw_limit_max;
        return std::nullopt;
      case 0x607E: return o.polarity;
      case 0x6080: return o.max_motor_speed;
      case 0x6081: return o.profile_velocity;
      case 0x6083: return o.profile_acceleration;
      case 0x6084: return o.profile_deceleration;
      case 0x6087: return o.torque_slope;
      case 0x6098: return o.homing_method;
      case 0x6099:
        if (sub == 1) return o.homing_speed_switch;
        if (sub == 2) return o.homing_speed_zero;
        return std::nullopt;
      case 0x609A: return o.homing_acceleration;
      case 0x60B1: return o.velocity_offset;
      case 0x60F4: return o.following_error_actual;
      case 0x60FD: return o.digital_inputs;
      case 0x60FE:
        if (sub == 1) return o.digital_outputs;
        if (sub == 2) return o.digital_outputs_mask;
        return std::nullopt;
      case 0x60FF: return o.target_velocity;
      default: return std::nullopt;
    }
  }
  static bool set_object(drive::Objects& o, std::uint16_t index, std::uint8_t sub, std::int64_t v) {
    switch (index) {
      case 0x6040: o.controlword = static_cast<std::uint16_t>(v); return true;
      case 0x605D: o.halt_option = static_cast<std::int16_t>(v); return true;
      case 0x6060: o.mode = static_cast<std::int8_t>(v); return true;
      case 0x6071: o.target_torque = static_cast<std::int16_t>(v); return true;
      case 0x607A: o.target_position = static_cast<std::int32_t>(v); return true;
      case 0x607D:
        if (sub == 1) o.sw_limit_min = static_cast<std::int32_t>(v);
        else if (sub == 2) o.sw_limit_max = static_cast<std::int32_t>(v);
        else return false;
        return true;
      case 0x607E: o.polarity = static_cast<std::uint8_t>(v); return true;
      case 0x6080: o.max_motor_speed = static_cast<std::uint32_t>(v); return true;
      case 0x6081: o.profile_velocity = static_cast<std::uint32_t>(v); return true;
      case 0x6083: o.profile_acceleration = static_cast<std::uint32_t>(v); return true;
      case 0x6084: o.profile_deceleration = static_cast<std::uint32_t>(v); return true;
      case 0x6087: o.torque_slope = static_cast<std::uint32_t>(v); return true;
      case 0x6098: o.homing_method = static_cast<std::int8_t>(v); return true;
      case 0x6099:
        if (sub == 1) o.homing_speed_switch = static_cast<std::uint32_t>(v);
        else if (sub == 2) o.homing_speed_zero = static_cast<std::uint32_t>(v);
        else return false;
        return true;
      case 0x609A: o.homing_acceleration = static_cast<std::uint32_t>(v); return true;
      case 0x60B1: o.velocity_offset = static_cast<std::int32_t>(v); return true;
      case 0x60FE:
        if (sub == 1) o.digital_outputs = static_cast<std::uint32_t>(v);
        else if (sub == 2) o.digital_outputs_mask = static_cast<std::uint32_t>(v);
        else return false;
        return true;
      case 0x60FF: o.target_velocity = static_cast<std::int32_t>(v); return true;
      default: return false;
    }
  }

 private:
  static std::uint32_t key(std::uint16_t index, std::uint8_t sub) {
    return (static_cast<std::uint32_t>(index) << 8) | sub;
  }

  // Bits 7,3,2,1,0 of the controlword towards the goal from the last latched state.
  static std::uint16_t goal_bits(Axis& a) {
    using drive::State;
    namespace cw = drive::cw;
    const State s = drive::decode_statusword(a.inputs.statusword);
    if (s == State::fault || s == State::fault_reaction_active) {
      if (!a.new_goal || s == State::fault_reaction_active) return cw::kDisableVoltage;
      // a new goal resets the fault once: bit 7 low for a cycle, then high (rising edge)
      if (a.reset_phase == 0) {
        a.reset_phase = 1;
        return cw::kDisableVoltage;
      }
      a.reset_phase = 2;
      return cw::kFaultReset;
    }
    a.reset_phase = 0;  // not (or no longer) in fault: the request's reset is used up
    a.new_goal = false;
    switch (*a.goal) {
      case PdsGoal::switch_on_disabled: return cw::kDisableVoltage;
      case PdsGoal::ready_to_switch_on: return cw::kShutdown;
      case PdsGoal::switched_on:
        return s == State::switch_on_disabled ? cw::kShutdown : cw::kSwitchOn;
      case PdsGoal::operation_enabled:
        return s == State::switch_on_disabled ? cw::kShutdown : cw::kEnableOperation;
      case PdsGoal::quick_stop_active:
        return (s == State::operation_enabled || s == State::quick_stop_active) ? cw::kQuickStop
                                                                                : cw::kDisableVoltage;
    }
    return cw::kDisableVoltage;
  }

  std::int64_t period_ns_;
  std::int64_t sdo_latency_;
  std::vector<Axis> axes_;
  std::map<int, std::deque<Sdo>> sdo_;
  std::map<int, std::int64_t> sdo_due_;
  std::int64_t cycle_ = 0;
  drive::SimTime t_ = 0;
  int slaves_ = 0;
  std::string error_;
};

}  // namespace omnitwin::botnana::testing
