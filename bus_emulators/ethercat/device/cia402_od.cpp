// bus_emulators/ethercat/device — the CiA 402 objects of one axis in a CiA 301 dictionary (see
// cia402_od.hpp).
#include "bus_emulators/ethercat/device/cia402_od.hpp"

namespace omnitwin::ethercat {

namespace {

// The object at index accepts only the values `supported` says the drive implements.
void accept_only(ObjectDictionary& od, std::uint16_t index, bool (*supported)(int) noexcept) {
  if (OdObject* o = od.find(index)) {
    o->check = [supported](const OdObject& obj, std::uint8_t sub, std::span<const std::uint8_t> data) {
      const OdEntry* e = obj.entry(sub);
      return e && supported(static_cast<int>(e->int_of(data))) ? SdoAbort::none : SdoAbort::value_range;
    };
  }
}

}  // namespace

void bind_cia402_objects(ObjectDictionary& od, drive::Cia402Drive& d, std::uint16_t off) {
  auto& o = d.objects();
  auto b = [&](std::uint16_t idx, std::uint8_t sub, auto& field) { od.bind(static_cast<std::uint16_t>(idx + off), sub, field); };
  b(0x603F, 0, o.error_code);
  b(0x6040, 0, o.controlword);
  b(0x6041, 0, o.statusword);
  b(0x605A, 0, o.quick_stop_option);
  b(0x605D, 0, o.halt_option);
  b(0x605E, 0, o.fault_reaction_option);
  b(0x6060, 0, o.mode);
  b(0x6061, 0, o.mode_display);
  b(0x6062, 0, o.position_demand);
  b(0x6064, 0, o.position_actual);
  b(0x6065, 0, o.following_error_window);
  b(0x6066, 0, o.following_error_timeout);
  b(0x6067, 0, o.position_window);
  b(0x6068, 0, o.position_window_time);
  b(0x606B, 0, o.velocity_demand);
  b(0x606C, 0, o.velocity_actual);
  b(0x606D, 0, o.velocity_window);
  b(0x606E, 0, o.velocity_window_time);
  b(0x606F, 0, o.velocity_threshold);
  b(0x6071, 0, o.target_torque);
  b(0x6072, 0, o.max_torque);
  b(0x6074, 0, o.torque_demand);
  b(0x6077, 0, o.torque_actual);
  b(0x607A, 0, o.target_position);
  b(0x607C, 0, o.home_offset);
  b(0x607D, 1, o.sw_limit_min);
  b(0x607D, 2, o.sw_limit_max);
  b(0x607E, 0, o.polarity);
  b(0x607F, 0, o.max_profile_velocity);
  b(0x6080, 0, o.max_motor_speed);
  b(0x6081, 0, o.profile_velocity);
  b(0x6082, 0, o.end_velocity);
  b(0x6083, 0, o.profile_acceleration);
  b(0x6084, 0, o.profile_deceleration);
  b(0x6085, 0, o.quick_stop_deceleration);
  b(0x6087, 0, o.torque_slope);
  b(0x6098, 0, o.homing_method);
  b(0x6099, 1, o.homing_speed_switch);
  b(0x6099, 2, o.homing_speed_zero);
  b(0x609A, 0, o.homing_acceleration);
  b(0x60B1, 0, o.velocity_offset);
  b(0x60B2, 0, o.torque_offset);
  b(0x60F4, 0, o.following_error_actual);
  b(0x60FD, 0, o.digital_inputs);
  b(0x60FE, 1, o.digital_outputs);
  b(0x60FE, 2, o.digital_outputs_mask);
  b(0x60FF, 0, o.target_velocity);
  b(0x6502, 0, o.supported_modes);
  // 0x6060 accepts only the advertised modes (0 = none).
  if (OdObject* m = od.find(static_cast<std::uint16_t>(0x6060 + off))) {
    m->check = [dp = &d](const OdObject&, std::uint8_t, std::span<const std::uint8_t> data) {
      const auto v = static_cast<std::int8_t>(data[0]);
      if (v == 0) return SdoAbort::none;
      if (v < 1 || v > 10 || !(dp->objects().supported_modes & (1u << (v - 1)))) return SdoAbort::value_range;
      return SdoAbort::none;
    };
  }
  // Option codes and homing methods: only what the drive core implements.
  accept_only(od, static_cast<std::uint16_t>(0x605A + off), &drive::quick_stop_option_supported);
  accept_only(od, static_cast<std::uint16_t>(0x605D + off), &drive::halt_option_supported);
  accept_only(od, static_cast<std::uint16_t>(0x605E + off), &drive::fault_reaction_option_supported);
  accept_only(od, static_cast<std::uint16_t>(0x6098 + off), &drive::homing_method_supported);
}

}  // namespace omnitwin::ethercat
