// bus_emulators/mechatrolink3 — the slave stations of one line, built and wired once: the
// line model (m3_line) and N servo slaves (m3_link + m3_servo on the shared drive core),
// slave k at address 03h + k on the topology's k-th cable, its frames going onto the line and
// the line's frames for it into its link, powered on at t = 0. The twin's segment (transport/
// m3_segment), the cycle study and the benchmark put their master's side around it (the
// owner attaches the master's end: line().attach_master()).
// Set-up allocates; advance() is real-time safe.
#pragma once

#include <memory>
#include <vector>

#include "bus_emulators/mechatrolink3/m3_line.hpp"
#include "bus_emulators/mechatrolink3/m3_link.hpp"
#include "bus_emulators/mechatrolink3/m3_servo.hpp"

namespace omnitwin::m3 {

struct StationsConfig {
  Topology topology = Topology::cascade_of(4, 10.0);
  ServoConfig servo;              // every slave's servo (one per cable in the topology)
  SimTime response_ns = 2'000;    // every slave's response time
};

class M3Stations {
 public:
  // Throws std::invalid_argument for a topology check() refuses (programmer error).
  explicit M3Stations(const StationsConfig& config);
  M3Stations(const M3Stations&) = delete;
  M3Stations& operator=(const M3Stations&) = delete;

  int size() const { return static_cast<int>(links_.size()); }
  Line& line() { return line_; }
  const Line& line() const { return line_; }
  SlaveLink& link(int k) { return *links_[static_cast<std::size_t>(k)]; }
  const SlaveLink& link(int k) const { return *links_[static_cast<std::size_t>(k)]; }
  ServoProfile& servo(int k) { return *servos_[static_cast<std::size_t>(k)]; }
  const ServoProfile& servo(int k) const { return *servos_[static_cast<std::size_t>(k)]; }
  // Every slave's communication timers up to t (missing sync or commands). Real-time safe.
  void advance(SimTime t);

 private:
  Line line_;
  std::vector<std::unique_ptr<ServoProfile>> servos_;
  std::vector<std::unique_ptr<SlaveLink>> links_;
};

}  // namespace omnitwin::m3
