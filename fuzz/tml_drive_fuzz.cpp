// fuzz/tml_drive_fuzz — libFuzzer target: arbitrary CAN frames (TMLCAN and TechCAN nodes) and
// arbitrary serial bytes (an RS-232 and an RS-485 drive port) into emulated IDM drives, with
// drive periods in between. Finds crashes, UB and runaway state in tml_drive / tml_can_node
// and their use of the tml codecs; it asserts that every frame a node sends is valid CAN.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "bus_emulators/tml/tml_can_node.hpp"
#include "bus_emulators/tml/tml_drive.hpp"
#include "bus_emulators/tml/tml_serial.hpp"

using namespace omnitwin;

namespace {

constexpr tml::SimTime kMs = 1'000'000;

tml::DriveSetup setup(std::uint8_t axis, tml::Protocol p) {
  tml::DriveSetup s;
  s.axis = axis, s.protocol = p, s.host_axis = 3;
  return s;
}

bool check_frame(const can::Frame& f, tml::SimTime) {
  if (!f.valid()) std::abort();
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  tml::TmlCanNode tmlcan(setup(5, tml::Protocol::tmlcan), check_frame);
  tml::TmlCanNode techcan(setup(5, tml::Protocol::techcan), check_frame);
  tml::TmlDrive rs232(setup(255, tml::Protocol::rs232), nullptr);
  tml::TmlDrive rs485(setup(1, tml::Protocol::rs485), nullptr);
  tml::SerialDriveLink link232({tml::Link::rs232, 255, 1, 115200}, nullptr,
                               [&](const tml::Message& m, std::int64_t t) { rs232.on_message(m, t); });
  tml::SerialDriveLink link485({tml::Link::rs485, 1, 1, 115200}, nullptr,
                               [&](const tml::Message& m, std::int64_t t) { rs485.on_message(m, t); });
  rs232.set_sender([&](const tml::Message& m, tml::SimTime t) { link232.send(m, t); });
  rs485.set_sender([&](const tml::Message& m, tml::SimTime t) { link485.send(m, t); });
  tmlcan.power_on(0), techcan.power_on(0), rs232.power_on(0), rs485.power_on(0);
  tml::SimTime now = 0;
  std::size_t i = 0;
  // Records: a tag byte picks a CAN frame (flags, 4 id bytes, dlc, 8 data), a serial byte, or a period.
  while (i < size) {
    const std::uint8_t tag = data[i++];
    if (tag < 0x80 && i + 14 <= size) {
      can::Frame f;
      f.extended = (tag & 1) != 0;
      f.kind = (tag & 6) == 2 ? can::FrameKind::remote : can::FrameKind::data;
      f.id = static_cast<std::uint32_t>(data[i] | data[i + 1] << 8 | data[i + 2] << 16 | (data[i + 3] & 0x1F) << 24);
      if (!f.extended) f.id &= 0x7FF;
      f.dlc = data[i + 4] % 9;
      for (int k = 0; k < 8; ++k) f.data[k] = data[i + 5 + k];
      i += 13;
      tmlcan.on_frame(f, now);
      techcan.on_frame(f, now);
    } else if (tag < 0xF0 && i < size) {
      link232.on_byte(data[i], now);
      link485.on_byte(data[i], now);
      ++i;
    } else {
      const drive::Feedback fb{static_cast<double>(tag & 0x0F) * 0.01, 0, 0};
      tmlcan.step(now, fb), techcan.step(now, fb), rs232.step(now, fb), rs485.step(now, fb);
      now += kMs;
    }
  }
  return 0;
}
