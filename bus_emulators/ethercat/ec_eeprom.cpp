// bus_emulators/ethercat — SII EEPROM interface (see ec_eeprom.hpp).
#include "bus_emulators/ethercat/ec_eeprom.hpp"

#include <utility>

#include "bus_emulators/ethercat/ec_registers.hpp"

namespace omnitwin::ethercat {

SiiEeprom::SiiEeprom(std::vector<std::uint16_t> image, std::int64_t busy_ns)
    : image_(std::move(image)), busy_ns_(busy_ns) {}

std::uint16_t SiiEeprom::word(std::uint32_t a) const noexcept {
  return a < image_.size() ? image_[a] : 0xFFFF;
}

std::uint16_t SiiEeprom::control(const std::uint8_t* regs, SimTime t) const noexcept {
  std::uint16_t c = get_u16(regs + 2);
  if (busy_valid_ && t < busy_until_) c |= reg::kEepromBusy;
  return c;
}

SiiEeprom::Result SiiEeprom::on_control_write(std::uint8_t* regs, SimTime t) noexcept {
  const std::uint16_t written = get_u16(regs + 2);
  if (busy_valid_ && t < busy_until_) {
    put_u16(regs + 2, status_);  // ignored while busy
    return Result::refused;
  }
  const std::uint16_t cmd = written & reg::kEepromCmdMask;
  std::uint16_t status = static_cast<std::uint16_t>(reg::kEepromRead8 | 0x0080);  // 8-byte reads, 2 address bytes
  Result r = Result::none;
  if ((regs[0] & 0x01) != 0 && cmd != 0) {
    // The PDI owns the EEPROM: the master's command is not executed.
    status |= reg::kEepromErrNack;
    r = Result::refused;
  } else {
    const std::uint32_t addr = get_u32(regs + 4);
    switch (cmd) {
      case 0:
        break;  // clearing errors / write enable only
      case reg::kEepromCmdRead:
        for (std::uint32_t i = 0; i < 4; ++i) put_u16(regs + 8 + 2 * i, word(addr + i));
        r = Result::read;
        break;
      case reg::kEepromCmdWrite:
        if ((written & reg::kEepromWriteEnable) == 0) {
          status |= reg::kEepromErrWriteEnable;
          r = Result::refused;
        } else if (addr >= image_.size()) {
          status |= reg::kEepromErrNack;
          r = Result::refused;
        } else {
          image_[addr] = get_u16(regs + 8);
          r = Result::written;
        }
        break;
      case reg::kEepromCmdReload:
        r = Result::reloaded;
        break;
      default:
        status |= reg::kEepromErrNack;
        r = Result::refused;
        break;
    }
  }
  status_ = status;
  put_u16(regs + 2, status);
  if (busy_ns_ > 0 && cmd != 0) {
    busy_until_ = t + busy_ns_;
    busy_valid_ = true;
  }
  return r;
}

}  // namespace omnitwin::ethercat
