// bus_emulators/ethercat — the SII EEPROM and its ESC interface (registers 0x0500–0x050F).
//
// The master (owner bit 0x0500.0 = 0) writes a word address to 0x0504 and a command to the
// control/status register 0x0502 (bits 8–10: 1 read, 2 write, 4 reload). Commands execute when
// the control register is written: a read fills 0x0508 with 4 bytes, or 8 bytes since bit 6
// (8-byte reads) is set; words past the end of the image read 0xFFFF. A write stores the word in
// 0x0508 at the address; it needs the write-enable bit 0 in the same control write (else
// bit 14), and a write past the end is NACKed (bit 13). Reload re-reads the configuration area
// (the Esc copies the alias, word 4, to 0x0012 and the PDI control, word 0, to 0x0140). An
// unknown command value sets NACK. Optionally (busy_ns > 0) the busy bit 15 stays set for that
// long after a command, and control writes while busy are ignored.
#pragma once

#include <cstdint>
#include <vector>

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::ethercat {

class SiiEeprom {
 public:
  explicit SiiEeprom(std::vector<std::uint16_t> image = {}, std::int64_t busy_ns = 0);

  enum class Result : std::uint8_t { none, read, written, reloaded, refused };

  // The master wrote the control register: `regs` is the 16-byte window 0x0500–0x050F holding
  // the bytes just written. Executes the command and rewrites the control/status and data
  // bytes. Real-time safe (no allocation).
  Result on_control_write(std::uint8_t* regs, SimTime t) noexcept;
  // Control/status as the master reads it at t (busy bit).
  std::uint16_t control(const std::uint8_t* regs, SimTime t) const noexcept;

  std::uint16_t word(std::uint32_t address) const noexcept;  // 0xFFFF past the end
  const std::vector<std::uint16_t>& image() const { return image_; }

 private:
  std::vector<std::uint16_t> image_;
  std::int64_t busy_ns_;
  SimTime busy_until_ = -1;
  bool busy_valid_ = false;
  std::uint16_t status_ = 0x00C0;  // control/status after the last command
};

}  // namespace omnitwin::ethercat
