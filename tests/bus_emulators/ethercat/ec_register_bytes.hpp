// Test support (not a test file): the register images a master writes to configure an ESC —
// one SyncManager (0x0800 + 8·n: start, length, control, activate) and one FMMU (0x0600 +
// 16·n: logical start, length, start/end bits, physical start and bit, type, activate) — for
// the tests that drive an ESC or an emulated slave by raw datagrams (ec_esc_test, ec_slave_test,
// ec_conformance_test).
#pragma once

#include <cstdint>
#include <vector>

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::ethercat::ec_test {

// control: 0x26 mailbox master-write, 0x22 mailbox master-read, 0x64 buffered master-write
// with watchdog trigger, 0x20 buffered master-read.
inline std::vector<std::uint8_t> sm_bytes(std::uint16_t start, std::uint16_t len, std::uint8_t control, bool enable) {
  std::vector<std::uint8_t> b(8, 0);
  put_u16(b.data(), start);
  put_u16(b.data() + 2, len);
  b[4] = control;
  b[6] = enable ? 1 : 0;
  return b;
}

// An FMMU from logical bit `sbit` … `ebit` of the last byte onto physical bit `pbit`; type 1
// read (inputs), 2 write (outputs), 3 both.
inline std::vector<std::uint8_t> fmmu_bytes(std::uint32_t logical, std::uint16_t len, std::uint8_t sbit,
                                            std::uint8_t ebit, std::uint16_t phys, std::uint8_t pbit,
                                            std::uint8_t type) {
  std::vector<std::uint8_t> b(16, 0);
  put_u32(b.data(), logical);
  put_u16(b.data() + 4, len);
  b[6] = sbit;
  b[7] = ebit;
  put_u16(b.data() + 8, phys);
  b[10] = pbit;
  b[11] = type;
  b[12] = 1;
  return b;
}

// Byte-granular (bits 0 … 7).
inline std::vector<std::uint8_t> fmmu_bytes(std::uint32_t logical, std::uint16_t len, std::uint16_t phys,
                                            std::uint8_t type) {
  return fmmu_bytes(logical, len, 0, 7, phys, 0, type);
}

}  // namespace omnitwin::ethercat::ec_test
