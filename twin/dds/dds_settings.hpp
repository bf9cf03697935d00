// twin/dds — what a DDS publisher is asked to do (domain, interface, rate). A header of its
// own, without Cyclone's, so that the scenario can hold these settings as they are.
#pragma once

#include <cstddef>
#include <string>

namespace omnitwin::twin {

struct DdsSettings {
  int domain = -1;            // −1: $OMNITWIN_DDS_DOMAIN, else 0; otherwise 0..232
  std::string interface;      // e.g. "lo"; "": $OMNITWIN_DDS_INTERFACE, else Cyclone's default
                              // (which honours $CYCLONEDDS_URI)
  std::string config_file;    // a Cyclone DDS XML file; overrides interface
  double rate_hz = 100;       // state topics [Hz] (> 0), decimated by simulated time
  std::size_t queue_capacity = 256;  // state samples the ring holds between the two threads
  double finish_timeout_s = 1.0;     // finish(): longest wait for run events to be acknowledged [s]
  // Before the run starts: wait until this many readers match the state topic (0 = do not
  // wait), at most wait_s of wall time. A lockstep run publishes its first states within
  // milliseconds, before a reader in another process is discovered; best-effort state
  // samples sent before then are not delivered to it.
  int wait_for_readers = 0;
  double wait_s = 10.0;
};

}  // namespace omnitwin::twin
