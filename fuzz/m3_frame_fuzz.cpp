// libFuzzer target for bus_emulators/mechatrolink3/m3_frame: the M-III frame decoder, both
// bare (decode) and inside an Ethernet frame (decapsulate).
//
// Properties checked on every input: neither call crashes (ASan/UBSan) or throws; every
// status has a name; a frame that decodes re-encodes to exactly the same bytes, and once
// wrapped in Ethernet decapsulates to the same fields; an input that decapsulates re-encodes
// from its fields to the frame it carried. Abort on any mismatch.
//
//   clang++ -std=c++20 -g -O1 -fsanitize=fuzzer,address,undefined -I. \
//     fuzz/m3_frame_fuzz.cpp bus_emulators/mechatrolink3/m3_frame.cpp -lz
//   ./a.out -max_total_time=30
#include "bus_emulators/mechatrolink3/m3_frame.hpp"

#include <cstdlib>
#include <cstring>
#include <vector>

using namespace omnitwin::m3;

namespace {

// The bytes encode() gives for a decoded view (0 size: it refused).
std::vector<std::uint8_t> reencode(const FrameView& v) {
  std::vector<std::uint8_t> out(kMaxFrame);
  const FrameSpec spec{.dst = v.dst, .src = v.src, .type = v.type, .sequence = v.sequence(), .retry = v.retry(),
                       .data = v.data};
  out.resize(encode(spec, out));
  return out;
}

bool same_fields(const FrameView& a, const FrameView& b) {
  return a.dst == b.dst && a.src == b.src && a.control == b.control && a.type == b.type &&
         a.data.size() == b.data.size() && std::memcmp(a.data.data(), b.data.data(), a.data.size()) == 0;
}

void check_bare(std::span<const std::uint8_t> in) {
  FrameView v;
  const FrameStatus s = decode(in, v);
  if (to_string(s)[0] == '?') std::abort();
  if (s != FrameStatus::ok) return;
  const auto again = reencode(v);
  if (again.size() != in.size() || std::memcmp(again.data(), in.data(), in.size()) != 0) std::abort();
  std::vector<std::uint8_t> eth(kEthHeaderSize + kMaxFrame);
  eth.resize(encapsulate(in, eth));
  FrameView w;
  if (eth.empty() || decapsulate(eth, w) != FrameStatus::ok || !same_fields(v, w)) std::abort();
}

void check_ethernet(std::span<const std::uint8_t> in) {
  FrameView v;
  const FrameStatus s = decapsulate(in, v);
  if (to_string(s)[0] == '?') std::abort();
  if (s != FrameStatus::ok) return;
  const auto again = reencode(v);
  if (again.empty() || again.size() + kEthHeaderSize > in.size()) std::abort();
  if (std::memcmp(again.data(), in.data() + kEthHeaderSize, again.size()) != 0) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> in(data, size);
  check_bare(in);
  check_ethernet(in);
  return 0;
}
