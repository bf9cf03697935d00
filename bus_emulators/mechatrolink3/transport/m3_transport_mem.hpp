// bus_emulators/mechatrolink3/transport — in-process M-III transport (`mem:NAME`), for tests and
// for running our C1 master and the emulated slaves inside one process over the transport
// interface (the line model, m3_line, is the in-process path with wire timing; this one has
// none: a frame is there as soon as it is sent). The frame buses' shared in-process pair
// (bus_emulators/mem_pair_transport.hpp, which says how it behaves) with M-III frames: 9 to
// 73 bytes, checked by check_frame() on receipt (the FCS is left to the receiving station).
#pragma once

#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"
#include "bus_emulators/mem_pair_transport.hpp"

namespace omnitwin::m3 {

// M-III for the frame buses' shared transports (in-process pair, UDP).
struct M3FrameTraits {
  using Base = M3Transport;
  using Role = m3::Role;
  using Error = TransportError;
  static constexpr std::size_t kMaxFrame = m3::kMaxFrame, kMinFrame = m3::kHeaderSize + m3::kFcsSize;
  static constexpr std::size_t kDefaultCapacity = 256;  // a cycle of 62 slaves with retries
  static const char* role_name(Role r) { return to_string(r); }
  static std::size_t end_of(Role r) { return r == Role::master ? 0 : 1; }
  static bus_emulators::FrameVerdict check(const std::uint8_t* data, std::size_t n, std::size_t& size) noexcept {
    return check_frame(data, n, size) == FrameCheck::ok ? bus_emulators::FrameVerdict::ok
                                                        : bus_emulators::FrameVerdict::malformed;
  }
};

using MemTransport = bus_emulators::MemPairTransport<M3FrameTraits>;

}  // namespace omnitwin::m3
