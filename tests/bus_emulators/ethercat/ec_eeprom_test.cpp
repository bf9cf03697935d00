// Tests bus_emulators/ethercat/ec_eeprom: the SII interface commands on a known image — 4/8-byte
// reads, reads past the end (0xFFFF), writes with and without write enable, writes past the end
// (NACK), reload, unknown commands, PDI ownership and the optional busy time.
#include "bus_emulators/ethercat/ec_eeprom.hpp"

#include <gtest/gtest.h>

#include "bus_emulators/ethercat/ec_registers.hpp"

namespace omnitwin::ethercat {
namespace {

struct Regs {
  std::array<std::uint8_t, 16> b{};
  void command(std::uint16_t cmd, std::uint32_t addr) {
    put_u32(b.data() + 4, addr);
    put_u16(b.data() + 2, cmd);
  }
  std::uint16_t status() const { return get_u16(b.data() + 2); }
  std::uint16_t data(int i) const { return get_u16(b.data() + 8 + 2 * i); }
};

std::vector<std::uint16_t> image() {
  std::vector<std::uint16_t> v(10);
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = static_cast<std::uint16_t>(0x1100 + i);
  return v;
}

TEST(EcEeprom, ReadsEightBytesAndPastTheEnd) {
  SiiEeprom e(image());
  Regs r;
  r.command(reg::kEepromCmdRead, 2);
  EXPECT_EQ(e.on_control_write(r.b.data(), 0), SiiEeprom::Result::read);
  EXPECT_EQ(r.data(0), 0x1102);
  EXPECT_EQ(r.data(3), 0x1105);
  EXPECT_EQ(r.status() & reg::kEepromRead8, reg::kEepromRead8);
  EXPECT_EQ(r.status() & (reg::kEepromCmdMask | reg::kEepromErrNack | reg::kEepromBusy), 0);
  r.command(reg::kEepromCmdRead, 8);
  e.on_control_write(r.b.data(), 0);
  EXPECT_EQ(r.data(0), 0x1108);
  EXPECT_EQ(r.data(1), 0x1109);
  EXPECT_EQ(r.data(2), 0xFFFF);
  EXPECT_EQ(r.data(3), 0xFFFF);
  EXPECT_EQ(e.word(1000000), 0xFFFF);
}

TEST(EcEeprom, WritesNeedEnableAndStayInRange) {
  SiiEeprom e(image());
  Regs r;
  put_u16(r.b.data() + 8, 0xBEEF);
  r.command(reg::kEepromCmdWrite, 3);
  EXPECT_EQ(e.on_control_write(r.b.data(), 0), SiiEeprom::Result::refused);
  EXPECT_EQ(r.status() & reg::kEepromErrWriteEnable, reg::kEepromErrWriteEnable);
  EXPECT_EQ(e.word(3), 0x1103);
  r.command(reg::kEepromCmdWrite | reg::kEepromWriteEnable, 3);
  EXPECT_EQ(e.on_control_write(r.b.data(), 0), SiiEeprom::Result::written);
  EXPECT_EQ(e.word(3), 0xBEEF);
  EXPECT_EQ(r.status() & (reg::kEepromErrWriteEnable | reg::kEepromErrNack), 0);
  r.command(reg::kEepromCmdWrite | reg::kEepromWriteEnable, 10);
  EXPECT_EQ(e.on_control_write(r.b.data(), 0), SiiEeprom::Result::refused);
  EXPECT_EQ(r.status() & reg::kEepromErrNack, reg::kEepromErrNack);
  EXPECT_EQ(e.image().size(), 10u);
}

TEST(EcEeprom, ReloadUnknownCommandAndPdiOwnership) {
  SiiEeprom e(image());
  Regs r;
  r.command(reg::kEepromCmdReload, 0);
  EXPECT_EQ(e.on_control_write(r.b.data(), 0), SiiEeprom::Result::reloaded);
  r.command(0x0300, 0);  // read|write: not a command
  EXPECT_EQ(e.on_control_write(r.b.data(), 0), SiiEeprom::Result::refused);
  EXPECT_EQ(r.status() & reg::kEepromErrNack, reg::kEepromErrNack);
  r.b[0] = 1;  // the PDI owns it
  r.command(reg::kEepromCmdRead, 0);
  EXPECT_EQ(e.on_control_write(r.b.data(), 0), SiiEeprom::Result::refused);
}

TEST(EcEeprom, BusyWindowIgnoresCommands) {
  SiiEeprom e(image(), 20'000);
  Regs r;
  r.command(reg::kEepromCmdRead, 0);
  EXPECT_EQ(e.on_control_write(r.b.data(), 1000), SiiEeprom::Result::read);
  EXPECT_EQ(e.control(r.b.data(), 5000) & reg::kEepromBusy, reg::kEepromBusy);
  r.command(reg::kEepromCmdRead, 4);
  EXPECT_EQ(e.on_control_write(r.b.data(), 5000), SiiEeprom::Result::refused);
  EXPECT_EQ(r.data(0), 0x1100);  // still the first read
  EXPECT_EQ(r.status() & reg::kEepromCmdMask, 0);
  EXPECT_EQ(e.control(r.b.data(), 21'000) & reg::kEepromBusy, 0);
  r.command(reg::kEepromCmdRead, 4);
  EXPECT_EQ(e.on_control_write(r.b.data(), 21'000), SiiEeprom::Result::read);
  EXPECT_EQ(r.data(0), 0x1104);
}

}  // namespace
}  // namespace omnitwin::ethercat
