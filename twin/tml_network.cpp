// twin layer — the twin's side of a TML network; see tml_network.hpp.
#include "twin/tml_network.hpp"

#include <fmt/format.h>

namespace omnitwin::twin {

namespace {

CanDriveSetup setup_of(const Scenario& s) {
  return CanDriveSetup{"tml", s.bus.tml.drive_period, s.bus.tml.drift, s.bus.tml.counts_per_rev};
}

}  // namespace

TmlNetwork::TmlNetwork(const Scenario& s, Scheduler& sched, Hooks hooks)
    : CanDriveNetwork(s, sched, std::move(hooks), setup_of(s)), spec_(s.bus.tml) {
  for (int i = 0; i < 4; ++i) {
    tml::DriveSetup ds;
    ds.axis = static_cast<std::uint8_t>(i + 1);
    ds.host_axis = spec_.protocol == "techcan" ? 31 : 120;
    ds.protocol = spec_.protocol == "techcan" ? tml::Protocol::techcan : tml::Protocol::tmlcan;
    ds.sample_period_s = spec_.drive_period;
    ds.drive.counts_per_rev = spec_.counts_per_rev;
    ds.drive.gear_ratio = 1.0;
    ds.drive.period_s = spec_.drive_period;
    ds.drive.max_speed_rad_s = s.platform.motor.speed_limit;
    ds.drive.rated_torque_nm = s.platform.motor.torque_limit;
    drives_[static_cast<std::size_t>(i)] =
        std::make_unique<tml::TmlCanNode>(ds, [this, i](const can::Frame& f, SimTime at) { return submit(i, f, at); });
  }
  start();
}

void TmlNetwork::deliver(int axis0, const can::Frame& f, SimTime t) {
  tml::TmlCanNode& d = *drives_[static_cast<std::size_t>(axis0)];
  d.on_frame(f, t);
  // The master's first AXISON reaching a drive marks the start of the run's motion.
  if (d.drive().srl() & tml::bits::srl_axis_on) note_master_start(t);
}

void TmlNetwork::drive_power(int axis0, bool on, SimTime t) {
  tml::TmlCanNode& d = *drives_[static_cast<std::size_t>(axis0)];
  if (on) d.power_on(t);
  else d.power_off();
}

bool TmlNetwork::drive_running(int axis0) const {
  return drives_[static_cast<std::size_t>(axis0)]->drive().core().state() == drive::State::operation_enabled;
}

BusNetwork::DriveDetail TmlNetwork::drive_detail(int axis0) const {
  if (!powered(axis0)) return {"off", ""};
  const tml::TmlDrive& d = drives_[static_cast<std::size_t>(axis0)]->drive();
  return {(d.srl() & tml::bits::srl_axis_on) ? "axis on" : "axis off", drive::to_string(d.core().state())};
}

std::string TmlNetwork::drive_protocol_state(int axis0) const {
  if (!powered(axis0)) return "off";
  const tml::TmlDrive& d = drives_[static_cast<std::size_t>(axis0)]->drive();
  return fmt::format("axis {}", (d.srl() & tml::bits::srl_axis_on) ? "on" : "off");
}

nlohmann::json TmlNetwork::drive_json(int axis0) const {
  const tml::TmlCanNode& n = *drives_[static_cast<std::size_t>(axis0)];
  const tml::DriveStats& s = n.drive().stats();
  return {{"axis_id", n.drive().axis()},
          {"srl", n.drive().srl()},
          {"mer", n.drive().mer()},
          {"handled", s.handled},
          {"answers", s.answers_sent},
          {"take_data2", s.take_data2_sent},
          {"unknown_opcodes", s.unknown_opcodes},
          {"bad_frames", n.stats().malformed}};
}

nlohmann::json TmlNetwork::bus_metrics(SimTime now) const {
  nlohmann::json j = wire_metrics(now);
  j["protocol"] = spec_.protocol;
  return j;
}

}  // namespace omnitwin::twin
