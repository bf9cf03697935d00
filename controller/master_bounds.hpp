// controller layer — bounds shared by the master programs' configuration files and the twin.
//
// Every master program checks these, and the twin's scenario loader applies them to the values
// it writes into the masters' files (docs/scenarios.md: a scenario that loads is one whose
// master starts), so each bound has one source.
#pragma once

namespace omnitwin::controller {

inline constexpr double kMinLoopPeriod = 1e-4;        // [s] the platform loop's period (a bus tick)
inline constexpr double kMaxLoopPeriod = 1.0;         // [s]
inline constexpr int kMaxCountsPerRev = 1 << 24;      // the platform loop's counts per wheel revolution
inline constexpr double kMaxStartupTimeout = 3600.0;  // [s] any master's startup_timeout
// What a realtime twin adds to bus.startup in a master's startup_timeout: the master may start
// looking for its slaves before the twin is up. [s]
inline constexpr double kRealtimeStartupGrace = 3.0;
// omni-master: ticks from the first detecting tick to path time 0 when the four slaves answer
// the first detection request: that tick sends the request, the next finds the answers
// (all_found, NMT start), the one after is path time 0. path_done falls as many ticks after
// path + settle (the twin's default CAN run length counts them).
inline constexpr int kStartupTicks = 2;

}  // namespace omnitwin::controller
