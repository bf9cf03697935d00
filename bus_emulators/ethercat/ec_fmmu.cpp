// bus_emulators/ethercat — FMMU decoding and overlap arithmetic (see ec_fmmu.hpp).
#include "bus_emulators/ethercat/ec_fmmu.hpp"

#include <algorithm>

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::ethercat {

Fmmu decode_fmmu(const std::uint8_t* r) noexcept {
  Fmmu f;
  f.logical_start = get_u32(r);
  f.length = get_u16(r + 4);
  f.start_bit = r[6] & 7;
  f.end_bit = r[7] & 7;
  f.physical_start = get_u16(r + 8);
  f.physical_bit = r[10] & 7;
  f.type = r[11];
  f.active = (r[12] & 0x01) != 0;
  return f;
}

FmmuSpan fmmu_overlap(const Fmmu& f, std::uint32_t address, std::uint16_t length) noexcept {
  FmmuSpan s;
  if (!f.active || f.length == 0 || length == 0) return s;
  const std::uint64_t lb0 = static_cast<std::uint64_t>(f.logical_start) * 8 + f.start_bit;
  const std::uint64_t lb1 = (static_cast<std::uint64_t>(f.logical_start) + f.length - 1) * 8 + f.end_bit;  // inclusive
  if (lb1 < lb0) return s;
  const std::uint64_t db0 = static_cast<std::uint64_t>(address) * 8;
  const std::uint64_t db1 = db0 + static_cast<std::uint64_t>(length) * 8 - 1;
  const std::uint64_t b0 = std::max(lb0, db0);
  const std::uint64_t b1 = std::min(lb1, db1);
  if (b1 < b0) return s;
  s.frame_bit = static_cast<std::uint32_t>(b0 - db0);
  s.physical_bit = static_cast<std::uint32_t>(static_cast<std::uint64_t>(f.physical_start) * 8 + f.physical_bit + (b0 - lb0));
  s.bits = static_cast<std::uint32_t>(b1 - b0 + 1);
  return s;
}

}  // namespace omnitwin::ethercat
