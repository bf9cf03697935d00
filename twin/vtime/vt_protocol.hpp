// twin layer — the virtual-time channel: how the twin lends its simulated clock to a master
// program it did not write (docs/protocols/vtime.md).
//
// The preload library (vt_preload.cpp, libomnitwin_vtime.so) lives inside the master process
// and the twin (twin/master_vtime) at the other end of one Unix SOCK_SEQPACKET connection. The
// library reports each moment the master's process as a whole waits (Wait: until when, whether
// a frame should wake it, how many bus frames it has sent); the twin runs the simulation to the
// earlier of that deadline and the arrival of the master's next frame and answers Wake. Every
// record is 64 bytes, little-endian, unused bytes zero, so that the codec is a pure function and
// can be fuzzed; this header has no dependencies beyond the C++ library because the preload
// library must stay small.
#pragma once

#include <array>
#include <cstdint>
#include <cstring>
#include <optional>

namespace omnitwin::vtime {

inline constexpr std::uint32_t kMagic = 0x4d54564f;  // bytes "OVTM"
inline constexpr std::uint16_t kVersion = 1;
inline constexpr std::size_t kRecordSize = 64;
inline constexpr std::int64_t kNever = INT64_MAX;  // a deadline that never comes [ns]

// Environment the twin gives the master process (the library reads it at load time).
inline constexpr const char* kEnvChannel = "OMNITWIN_VTIME";         // "@abstract-name" of the channel
inline constexpr const char* kEnvBus = "OMNITWIN_VTIME_BUS";         // the bus spec: raw:IF, udp:HOST:PORT
inline constexpr const char* kEnvEpoch = "OMNITWIN_VTIME_EPOCH";     // CLOCK_REALTIME at t = 0 [s]
inline constexpr const char* kEnvWatchdog = "OMNITWIN_VTIME_WATCHDOG";  // wall-clock limit of a wait [s]

enum class Type : std::uint8_t {
  hello = 1,   // library → twin: pid, parent pid; the first record on a connection
  welcome = 2, // twin → library: the simulated time now
  wait = 3,    // library → twin: every thread waits; until `deadline`, woken by a frame if `wake_on_frame`
  wake = 4,    // twin → library: the simulated time now, frames put on the master's transport so far
  end = 5,     // twin → library: the run is over; time runs on the wall clock from `now`
  refuse = 6,  // twin → library: this process may not join (a second process); `code` says why
};

struct Record {
  Type type = Type::hello;
  std::uint32_t pid = 0;        // hello
  std::uint32_t ppid = 0;       // hello
  std::uint32_t code = 0;       // refuse: 1 = a second process; wake: the signal the twin has just sent the process (0: none)
  std::uint64_t seq = 0;        // wait/wake: the wait's number (a wake answers the same)
  std::int64_t now = 0;         // welcome/wait/wake/end: simulated time [ns]
  std::int64_t deadline = kNever;  // wait: wake no later than this [ns]
  std::uint64_t frames = 0;     // wait: bus frames the master sent; wake: frames the twin put on the transport
  std::uint8_t wake_on_frame = 0;  // wait: 1 = a frame reaching the master ends the wait early
};

namespace detail {
template <class T>
inline void put(std::uint8_t* p, T v) {
  for (std::size_t i = 0; i < sizeof(T); ++i) p[i] = static_cast<std::uint8_t>(static_cast<std::uint64_t>(v) >> (8 * i));
}
template <class T>
inline T get(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) v |= static_cast<std::uint64_t>(p[i]) << (8 * i);
  return static_cast<T>(v);
}
}  // namespace detail

// Layout: 0 magic u32, 4 version u16, 6 type u8, 7 wake_on_frame u8, 8 pid u32, 12 ppid u32,
// 16 seq u64, 24 now i64, 32 deadline i64, 40 frames u64, 48 code u32, 52..63 zero.
inline std::array<std::uint8_t, kRecordSize> encode(const Record& r) {
  std::array<std::uint8_t, kRecordSize> b{};
  detail::put<std::uint32_t>(&b[0], kMagic);
  detail::put<std::uint16_t>(&b[4], kVersion);
  b[6] = static_cast<std::uint8_t>(r.type);
  b[7] = r.wake_on_frame;
  detail::put<std::uint32_t>(&b[8], r.pid);
  detail::put<std::uint32_t>(&b[12], r.ppid);
  detail::put<std::uint64_t>(&b[16], r.seq);
  detail::put<std::int64_t>(&b[24], r.now);
  detail::put<std::int64_t>(&b[32], r.deadline);
  detail::put<std::uint64_t>(&b[40], r.frames);
  detail::put<std::uint32_t>(&b[48], r.code);
  return b;
}

// Accepts exactly 64 bytes with the magic, the version, a known type, wake_on_frame 0 or 1 and
// zero padding; nullopt otherwise. Every accepted record re-encodes to the same bytes.
inline std::optional<Record> decode(const std::uint8_t* p, std::size_t n) {
  if (n != kRecordSize || detail::get<std::uint32_t>(p) != kMagic || detail::get<std::uint16_t>(p + 4) != kVersion)
    return std::nullopt;
  if (p[6] < 1 || p[6] > 6 || p[7] > 1) return std::nullopt;
  for (std::size_t i = 52; i < kRecordSize; ++i)
    if (p[i] != 0) return std::nullopt;
  Record r;
  r.type = static_cast<Type>(p[6]);
  r.wake_on_frame = p[7];
  r.pid = detail::get<std::uint32_t>(p + 8);
  r.ppid = detail::get<std::uint32_t>(p + 12);
  r.seq = detail::get<std::uint64_t>(p + 16);
  r.now = detail::get<std::int64_t>(p + 24);
  r.deadline = detail::get<std::int64_t>(p + 32);
  r.frames = detail::get<std::uint64_t>(p + 40);
  r.code = detail::get<std::uint32_t>(p + 48);
  return r;
}

}  // namespace omnitwin::vtime
