// bus_emulators/can — the classic CAN frame; see can_frame.hpp.
#include "bus_emulators/can/can_frame.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>

namespace omnitwin::can {

bool Frame::valid() const {
  const std::uint32_t max_id = extended ? 0x1FFFFFFFu : 0x7FFu;
  return id <= max_id && dlc <= 8;
}

bool operator==(const Frame& a, const Frame& b) {
  if (a.id != b.id || a.extended != b.extended || a.kind != b.kind || a.dlc != b.dlc) return false;
  const int n = a.payload_size();
  return std::equal(a.data.begin(), a.data.begin() + n, b.data.begin());
}

std::string to_string(const Frame& f) {
  std::string s = f.extended ? fmt::format("0x{:08X}", f.id) : fmt::format("0x{:03X}", f.id);
  if (f.extended) s += " X";
  if (f.kind == FrameKind::remote) s += " R";
  if (f.kind == FrameKind::error) s += " E";
  s += fmt::format(" [{}]", f.dlc);
  for (int i = 0; i < f.payload_size(); ++i) s += fmt::format(" {:02X}", f.data[i]);
  return s;
}

Frame make_data(std::uint32_t id, std::initializer_list<std::uint8_t> bytes, bool extended) {
  if (bytes.size() > 8) throw std::invalid_argument("CAN data frame: more than 8 bytes");
  Frame f;
  f.id = id;
  f.extended = extended;
  f.dlc = static_cast<std::uint8_t>(bytes.size());
  std::copy(bytes.begin(), bytes.end(), f.data.begin());
  if (!f.valid()) throw std::invalid_argument("CAN data frame: identifier out of range: " + to_string(f));
  return f;
}

Frame make_remote(std::uint32_t id, std::uint8_t dlc, bool extended) {
  Frame f;
  f.id = id;
  f.extended = extended;
  f.kind = FrameKind::remote;
  f.dlc = dlc;
  if (!f.valid()) throw std::invalid_argument("CAN remote frame: bad identifier or DLC: " + to_string(f));
  return f;
}

}  // namespace omnitwin::can
