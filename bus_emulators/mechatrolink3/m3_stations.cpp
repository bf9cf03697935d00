// bus_emulators/mechatrolink3 — the slave stations of one line; see m3_stations.hpp.
#include "bus_emulators/mechatrolink3/m3_stations.hpp"

namespace omnitwin::m3 {

M3Stations::M3Stations(const StationsConfig& config) : line_(config.topology) {
  for (int k = 0; k < config.topology.slaves(); ++k) {
    servos_.push_back(std::make_unique<ServoProfile>(config.servo));
    const LinkConfig lc{.address = static_cast<std::uint8_t>(kFirstSlave + k), .response_ns = config.response_ns};
    links_.push_back(std::make_unique<SlaveLink>(
        lc, *servos_.back(), [this, k](std::span<const std::uint8_t> f, SimTime t) { line_.from_slave(k, f, t); }));
    line_.attach_slave(k, [this, k](std::span<const std::uint8_t> f, SimTime t) {
      links_[static_cast<std::size_t>(k)]->on_frame(f, t);
    });
    links_.back()->power_on(0);
  }
}

void M3Stations::advance(SimTime t) {
  for (auto& l : links_) l->advance(t);
}

}  // namespace omnitwin::m3
