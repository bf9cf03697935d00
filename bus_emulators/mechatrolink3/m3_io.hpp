// bus_emulators/mechatrolink3 — the standard I/O profile (profile type 30h): a slave with
// digital inputs and outputs, exchanged every cycle. The link (m3_link) hands it the
// commands its phase allows.
//
// Commands (codes of the profile as we read the public I/O module manuals; the field layout
// is ours, docs/protocols/mechatrolink3.md): DATA_RWA 20h (asynchronous: phases 2 and 3) and
// DATA_RWS 21h (synchronous: phase 3 only, else a phase error) write the outputs from
// command bytes 4… and answer the inputs in response bytes 4…, as many bytes as the station
// has and the frame holds; ID_RD (device name as the servo does), ALM_RD (no device alarms:
// zeros), ALM_CLR. Data lengths 16, 32, 48, 64 (seed 000 table 3). On a lost connection or a
// communication alarm (stop()) the outputs go to 0, the safe state (ours). Real-time safe
// after construction.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "bus_emulators/mechatrolink3/m3_link.hpp"

namespace omnitwin::m3 {

inline constexpr std::uint8_t kDataRwa = 0x20, kDataRws = 0x21;

struct IoConfig {
  std::size_t inputs = 8, outputs = 8;  // bytes of each
  std::string id = "OMNITWIN M3-IO";
};

class IoProfile final : public Profile {
 public:
  explicit IoProfile(const IoConfig& config);

  std::uint8_t profile_type() const override { return 0x30; }
  bool accepts_length(std::size_t n) const override { return n == 16 || n == 32 || n == 48 || n == 64; }
  bool synchronous_only(Command c) const override { return static_cast<std::uint8_t>(c) == kDataRws; }
  CmdAlarm execute(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, SimTime t) override;
  void stop(SimTime t) override;

  // The plant side: inputs the station reads, outputs the master last wrote. Real-time safe.
  void set_input(std::size_t byte, std::uint8_t value) { inputs_.at(byte) = value; }
  std::uint8_t output(std::size_t byte) const { return outputs_.at(byte); }
  std::uint64_t writes() const { return writes_; }

 private:
  IoConfig cfg_;
  std::vector<std::uint8_t> inputs_, outputs_;
  std::uint64_t writes_ = 0;
};

}  // namespace omnitwin::m3
