// bus_emulators/mechatrolink3 — the standard I/O profile; see m3_io.hpp.
#include "bus_emulators/mechatrolink3/m3_io.hpp"

#include <algorithm>

namespace omnitwin::m3 {

IoProfile::IoProfile(const IoConfig& config)
    : cfg_(config), inputs_(config.inputs, 0), outputs_(config.outputs, 0) {}

CmdAlarm IoProfile::execute(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, SimTime) {
  const auto code = static_cast<std::uint8_t>(c);
  const std::size_t room = cmd.size() - kCommandHeader;
  if (code == kDataRwa || code == kDataRws) {
    const std::size_t out = std::min(room, outputs_.size()), in = std::min(room, inputs_.size());
    std::copy_n(cmd.begin() + kCommandHeader, out, outputs_.begin());
    std::copy_n(inputs_.begin(), in, rsp.begin() + kCommandHeader);
    ++writes_;
    return CmdAlarm::normal;
  }
  switch (c) {
    case Command::id_rd: {
      std::copy_n(cmd.begin() + 12, 3, rsp.begin() + 12);
      const std::size_t offset = cmd[13], size = std::min<std::size_t>(cmd[14], rsp.size() - 16);
      if (cmd[12] != 0 || size > 16) return CmdAlarm::invalid_data;
      for (std::size_t i = 0; i < size; ++i)
        rsp[16 + i] = offset + i < cfg_.id.size() ? static_cast<std::uint8_t>(cfg_.id[offset + i]) : 0;
      return CmdAlarm::normal;
    }
    case Command::alm_rd:
    case Command::alm_clr: return CmdAlarm::normal;  // an I/O station with no device alarms
    default: return CmdAlarm::unsupported;
  }
}

void IoProfile::stop(SimTime) { std::fill(outputs_.begin(), outputs_.end(), std::uint8_t{0}); }

}  // namespace omnitwin::m3
